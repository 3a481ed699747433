"""Where the runs execute: a local thread pool of supervisors, or a Dask cluster."""
from __future__ import annotations

import contextlib
import logging
import signal
import threading
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from typing import Any, Dict, Iterator, List, Optional

from adcs_nodes.tools.campaigns.config import CampaignError
from adcs_nodes.tools.campaigns.runner import close_servers, execute_run


class LocalBackend:
    """J runs at once: a pool of J threads, each feeding the runs to its worker process."""

    def __init__(self, jobs: int) -> None:
        self.pool = ThreadPoolExecutor(max_workers=jobs, thread_name_prefix='mc-run')
        self.futures: set = set()
        self.stop_file = ''

    def submit(self, job: Dict[str, Any]) -> None:
        self.stop_file = job['stop_file']
        self.futures.add(self.pool.submit(execute_run, job))

    def results(self) -> Iterator[Dict[str, Any]]:
        while self.futures:
            done, self.futures = wait(self.futures, timeout=1.0, return_when=FIRST_COMPLETED)
            for fut in done:
                yield fut.result()

    def drain(self, timeout_s: float) -> List[Dict[str, Any]]:
        for fut in self.futures:
            fut.cancel()
        done, _ = wait(self.futures, timeout=timeout_s)
        return [f.result() for f in done if not f.cancelled() and f.exception() is None]

    def close(self) -> None:
        self.pool.shutdown(wait=False, cancel_futures=True)
        close_servers(self.stop_file)


class DaskBackend:
    """Runs submitted to the Dask scheduler at ``address``, or to a ``LocalCluster`` of
    ``local_workers`` processes started and stopped here; ``session`` is in the task keys."""

    def __init__(self, address: Optional[str], session: str,
                 local_workers: Optional[int] = None) -> None:
        try:
            from distributed import Client, LocalCluster
        except ImportError as exc:
            flag = '--dask-local' if local_workers else '--scheduler'
            raise CampaignError(f'{flag} needs the dask and distributed packages '
                                f'({exc})') from exc
        self.cluster = None
        if local_workers is not None:
            if local_workers < 1:
                raise CampaignError(f'a Dask LocalCluster needs >= 1 worker, got {local_workers}')
            with sigint_ignored():   # Ctrl-C stops the runs through the campaign, not here
                self.cluster = LocalCluster(n_workers=local_workers, threads_per_worker=1,
                                            processes=True, dashboard_address=None,
                                            silence_logs=logging.ERROR)
            address = self.cluster.scheduler_address
        try:
            self.client = Client(address, timeout=30)
        except (OSError, TimeoutError) as exc:
            self._close_cluster()
            raise CampaignError(f'cannot connect to the Dask scheduler {address}: {exc}') \
                from exc
        self.address = address
        self.session = session
        self.futures: list = []
        self.stop_file = ''

    def submit(self, job: Dict[str, Any]) -> None:
        self.stop_file = job['stop_file']
        key = f'adcs-montecarlo-{job["index"]}-{self.session}'
        self.futures.append(self.client.submit(execute_run, job, key=key, pure=False))

    def results(self) -> Iterator[Dict[str, Any]]:
        from distributed import as_completed
        for fut in as_completed(self.futures):
            self.futures.remove(fut)
            try:
                yield fut.result()
            except Exception as exc:  # noqa: BLE001 - a worker lost or the task raised
                yield {'index': _future_index(fut), 'status': 'error',
                       'message': f'Dask task failed: {exc!r}'}

    def drain(self, timeout_s: float) -> List[Dict[str, Any]]:
        # cancelling does not stop a running task: with the stop file there, all end soon
        from distributed import wait as dask_wait
        try:
            dask_wait(self.futures, timeout=timeout_s)
        except Exception:  # noqa: BLE001 - dask raises its own TimeoutError type
            pass
        done = [f.result() for f in self.futures if f.status == 'finished']
        self.client.cancel([f for f in self.futures if f.status == 'pending'])
        return done

    def close(self) -> None:
        try:
            if self.stop_file:     # the campaign's worker processes in every Dask worker
                self.client.run(close_servers, self.stop_file)
        except Exception:  # noqa: BLE001 - a lost Dask worker's workers ended with it
            pass
        try:
            self.client.close()
        finally:
            self._close_cluster()

    def _close_cluster(self) -> None:
        if self.cluster is not None:
            self.cluster.close()
            self.cluster = None


@contextlib.contextmanager
def sigint_ignored() -> Iterator[None]:
    """SIGINT ignored meanwhile (main thread): workers started here stop by the stop file."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def _future_index(fut: Any) -> int:
    return int(str(fut.key).split('-')[2])
