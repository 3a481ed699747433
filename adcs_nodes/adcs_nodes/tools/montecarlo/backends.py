"""Where the runs execute: a local thread pool of run processes, or a Dask cluster."""
from __future__ import annotations

from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from typing import Any, Dict, Iterator, List

from adcs_nodes.tools.montecarlo.config import CampaignError
from adcs_nodes.tools.montecarlo.runner import execute_run


class LocalBackend:
    """J runs at once, each in its own process, supervised from a thread pool."""

    def __init__(self, jobs: int) -> None:
        self.pool = ThreadPoolExecutor(max_workers=jobs, thread_name_prefix='mc-run')
        self.futures: set = set()

    def submit(self, job: Dict[str, Any]) -> None:
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


class DaskBackend:
    """Runs submitted to an existing Dask distributed scheduler."""

    def __init__(self, address: str, session: str) -> None:
        try:
            from distributed import Client
        except ImportError as exc:
            raise CampaignError('--scheduler needs the dask and distributed packages '
                                f'({exc})') from exc
        try:
            self.client = Client(address, timeout=30)
        except (OSError, TimeoutError) as exc:
            raise CampaignError(f'cannot connect to the Dask scheduler {address}: {exc}') \
                from exc
        self.session = session
        self.futures: list = []

    def submit(self, job: Dict[str, Any]) -> None:
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
        # the client cannot tell running from queued tasks, and cancelling does not stop a
        # running one: with the stop file present, running runs end and queued ones return
        # at once, so wait for all of them, then cancel what is left
        from distributed import wait as dask_wait
        try:
            dask_wait(self.futures, timeout=timeout_s)
        except Exception:  # noqa: BLE001 - dask raises its own TimeoutError type
            pass
        done = [f.result() for f in self.futures if f.status == 'finished']
        self.client.cancel([f for f in self.futures if f.status == 'pending'])
        return done

    def close(self) -> None:
        self.client.close()


def _future_index(fut: Any) -> int:
    return int(str(fut.key).split('-')[2])
