"""One run: the worker process that runs it (started once per campaign thread; a graph run's
its own) and the supervisor that feeds and watches it."""
from __future__ import annotations

import fcntl
import json
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from typing import Any, Callable, Dict, List, Optional, Tuple

from adcs_nodes.tools.campaigns.capture import capture_reference
from adcs_nodes.tools.campaigns.config import CampaignError
from adcs_nodes.tools.campaigns.files import (FAILED_FILE, RESULT_FILE, fail, load_result,
                                              result_head, write_json_atomic)
from adcs_nodes.tools.campaigns.results import bag_metrics

#: Seconds a supervisor waits for an interrupted run to close its bag before killing it.
STOP_GRACE_S = 60.0
#: Seconds between repeated SIGINTs to a run being stopped (see :meth:`RunServer.run`).
SIGINT_REPEAT_S = 2.0
#: A worker process: ``python`` + these + the campaign's stop file (:func:`serve`).
SERVER_COMMAND = ['-m', 'adcs_nodes.tools.campaigns', '_worker']
#: Prefix of a worker's reply line (the rest is JSON ``{"code", "message"}``).
REPLY = '@adcs-run-ended '
#: Set in every worker's environment: one BLAS/OpenMP/numba thread per worker (J workers share
#: J cores: :mod:`adcs_nodes.nodes.runtime`).
ONE_THREAD_ENV = {key: '1' for key in (
    'OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'BLIS_NUM_THREADS',
    'VECLIB_MAXIMUM_THREADS', 'NUMEXPR_NUM_THREADS', 'NUMBA_NUM_THREADS')}


def worker_env() -> Dict[str, str]:
    """Environment of a worker process: this process's, with :data:`ONE_THREAD_ENV`."""
    return {**os.environ, **ONE_THREAD_ENV}


def worker_main(run_dir: str) -> int:
    """A graph-engine run recorded to a bag: ``result.json`` or ``failed.json``."""
    from adcs_nodes.tools.run.launcher import LaunchError, Launcher
    from adcs_nodes.scenario import ScenarioError, load_scenario

    t0 = time.monotonic()
    with open(os.path.join(run_dir, 'job.json'), encoding='utf-8') as fh:
        job = json.load(fh)
    bag = os.path.join(run_dir, 'bag')
    try:
        sc = load_scenario(os.path.join(run_dir, 'scenario.yaml'))
        launcher = Launcher(sc, duration_s=job['duration_s'], record=bag,
                            compose=job['compose'], progress=False, run_dir=run_dir,
                            log=lambda text: print(text, flush=True))
        res = launcher.run()
    except (ScenarioError, LaunchError) as exc:
        return fail(run_dir, job, 2, str(exc), time.monotonic() - t0)
    print(f'[montecarlo] launcher: exit {res.exit_code}: {res.message}', flush=True)
    if res.exit_code == 130:
        return 130
    if res.exit_code != 0:
        return fail(run_dir, job, res.exit_code, res.message, time.monotonic() - t0)
    try:
        metrics = bag_metrics(bag, job['capture_deg'], job.get('period_s'),
                              capture_reference(sc))
    except (FileNotFoundError, ValueError) as exc:
        return fail(run_dir, job, 1, f'bag unreadable: {exc}', time.monotonic() - t0)
    result = {**result_head(job), **metrics, 'engine': 'graph',
              'sim_time_s': res.sim_time_s, 'launcher_wall_s': res.wall_time_s,
              'wall_time_s': time.monotonic() - t0, 'frames': res.frames,
              'missed_frames': res.missed_frames, 'compose': job['compose'],
              'message': res.message}
    write_json_atomic(os.path.join(run_dir, RESULT_FILE), result)
    return 0


class RunOwner:
    """One run in one worker process at a time: a ``flock`` on ``RUN_DIR.owner``; a holder
    alive on this host is ended first, one on another host refuses the run."""

    def __init__(self, run_dir: str) -> None:
        self.path = run_dir.rstrip('/') + '.owner'
        self.fd: Optional[int] = None

    def acquire(self) -> 'RunOwner':
        """Take the run, naming this process its owner."""
        os.makedirs(os.path.dirname(self.path), exist_ok=True)
        self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        if self._wait_lock(0.0):
            return self._named()
        try:
            with open(self.path, encoding='utf-8') as fh:
                owner = json.load(fh)
            host, pid = owner['host'], int(owner['pid'])
        except (OSError, ValueError, KeyError, TypeError):
            host, pid = socket.gethostname(), 0    # not named yet: it is being started
        if host != socket.gethostname():
            self.release()
            raise CampaignError(f'{self.path}: the run is held by process {pid} on {host}')
        for sig in (signal.SIGTERM, signal.SIGKILL):
            if pid:
                _signal_group(pid, sig)
            if self._wait_lock(STOP_GRACE_S):
                return self._named()
        self.release()
        raise CampaignError(f'{self.path}: the run is still held by its previous run process')

    def _wait_lock(self, seconds: float) -> bool:
        deadline = time.monotonic() + seconds
        while True:
            try:
                fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return True
            except BlockingIOError:
                if time.monotonic() >= deadline:
                    return False
                time.sleep(0.1)

    def _named(self) -> 'RunOwner':
        os.ftruncate(self.fd, 0)
        os.pwrite(self.fd, json.dumps({'host': socket.gethostname(),
                                       'pid': os.getpid()}).encode(), 0)
        return self

    def end_previous(self) -> None:
        """Take the run (ending a previous owner still alive) and let it go again."""
        self.acquire().release()

    def release(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


class RunServer:
    """A worker process (:func:`serve`) seen from its supervisor."""

    def __init__(self, stop_file: str) -> None:
        from adcs_nodes.tools.run.launcher.processes import with_parent_death_signal
        cmd = with_parent_death_signal([sys.executable] + SERVER_COMMAND + [stop_file])
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, start_new_session=True,
                                     env=worker_env(), text=True)
        self.noise: List[str] = []     # its last lines printed outside a run

    def alive(self) -> bool:
        return self.proc.poll() is None

    def run(self, run_dir: str, stop_file: str) -> Tuple[int, str]:
        """Exit code and message of the run in ``run_dir`` (SIGINT once ``stop_file`` is)."""
        try:
            self.proc.stdin.write(run_dir + '\n')
            self.proc.stdin.flush()
        except OSError:
            return self._ended()
        stopped_at: Optional[float] = None
        last_int = 0.0
        while True:
            if select.select([self.proc.stdout], [], [], 0.5)[0]:
                line = self.proc.stdout.readline()
                if not line:
                    return self._ended()
                if line.startswith(REPLY):
                    reply = json.loads(line[len(REPLY):])
                    return int(reply['code']), str(reply['message'])
                self.noise = (self.noise + [line.rstrip()])[-5:]
                continue
            now = time.monotonic()
            if stopped_at is None and os.path.exists(stop_file):
                stopped_at = last_int = now
                _signal_group(self.proc.pid, signal.SIGINT)
            elif stopped_at is not None and now - stopped_at > STOP_GRACE_S:
                _signal_group(self.proc.pid, signal.SIGKILL)
            elif stopped_at is not None and now - last_int >= SIGINT_REPEAT_S:
                last_int = now
                _signal_group(self.proc.pid, signal.SIGINT)

    def _ended(self) -> Tuple[int, str]:
        code = self.proc.wait()
        return code or 1, f'the worker process ended ({code}): {" | ".join(self.noise)}'

    def close(self, grace_s: float = 5.0) -> None:
        """End of input: the worker exits; SIGKILL to its group after ``grace_s``."""
        try:
            self.proc.stdin.close()
            self.proc.wait(timeout=grace_s)
        except (OSError, subprocess.TimeoutExpired):
            _signal_group(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        self.proc.stdout.close()


#: The plain-engine workers of this process by (supervising thread, campaign stop file).
_SERVERS: Dict[Tuple[int, str], RunServer] = {}
_SERVERS_LOCK = threading.Lock()


def _server_for(job: Dict[str, Any]) -> RunServer:
    """This thread's worker for the campaign of ``job`` (started if it has none alive)."""
    key = (threading.get_ident(), job['stop_file'])
    with _SERVERS_LOCK:
        server = _SERVERS.pop(key, None)
    if server is not None and not server.alive():
        server.close()
        server = None
    return server or RunServer(job['stop_file'])


def close_servers(stop_file: Optional[str] = None) -> int:
    """Close this process's workers of the campaign ``stop_file`` (None: all); how many."""
    with _SERVERS_LOCK:
        servers = [_SERVERS.pop(k) for k in list(_SERVERS) if stop_file in (None, k[1])]
    for server in servers:
        server.close()
    return len(servers)


def execute_run(job: Dict[str, Any]) -> Dict[str, Any]:
    """Run one prepared run directory in this thread's worker process; its result dict."""
    run_dir, index = job['run_dir'], job['index']
    if os.path.exists(job['stop_file']):
        return {'index': index, 'status': 'interrupted', 'message': 'not started'}
    t0 = time.monotonic()
    server = _server_for(job)
    code, message = server.run(run_dir, job['stop_file'])
    wall = time.monotonic() - t0
    if job.get('engine', 'graph') == 'plain' and code == 0:
        with _SERVERS_LOCK:         # kept for this thread's next run
            _SERVERS[(threading.get_ident(), job['stop_file'])] = server
    else:
        server.close()
    result = load_result(run_dir) if code == 0 else None
    if result is not None:
        return result
    if code == 130 or os.path.exists(job['stop_file']):
        return {'index': index, 'status': 'interrupted', 'message': 'interrupted (Ctrl-C)',
                'wall_time_s': wall}
    return _failure_of(run_dir, index, code, message, wall)


def serve(stop_file: str, run: Optional[Callable[[str], int]] = None) -> int:
    """Body of a worker process: each run directory from stdin run by ``run`` (its
    :class:`RunOwner` held) and answered with :data:`REPLY` ``{"code", "message"}``."""
    signal.signal(signal.SIGINT, signal.default_int_handler)   # inherited ignored (Dask)
    replies = os.fdopen(os.dup(1), 'w', buffering=1)
    quiet = os.open(os.devnull, os.O_WRONLY)
    os.dup2(quiet, 1)
    try:
        for line in sys.stdin:
            code, message = _serve_one(line.strip(), stop_file, run or run_job, quiet)
            replies.write(REPLY + json.dumps({'code': code, 'message': message}) + '\n')
    except KeyboardInterrupt:    # between runs: the campaign is stopping
        return 130
    return 0


def _serve_one(run_dir: str, stop_file: str, run: Callable[[str], int],
               quiet: int) -> Tuple[int, str]:
    if os.path.exists(stop_file):
        return 130, 'not started'
    try:
        owner = RunOwner(run_dir).acquire()
    except CampaignError as exc:
        return 1, str(exc)
    try:
        clean_attempt(run_dir)
        log = os.open(os.path.join(run_dir, 'worker.log'), os.O_WRONLY | os.O_CREAT, 0o644)
        os.dup2(log, 1)
        os.dup2(log, 2)
        os.close(log)
        try:
            return run(run_dir), ''
        except Exception as exc:  # noqa: BLE001 - a run's bug ends the run, not the worker
            traceback.print_exc()
            return 1, f'{type(exc).__name__}: {exc}'
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(quiet, 1)
            os.dup2(quiet, 2)
    except KeyboardInterrupt:
        return 130, 'interrupted'
    finally:
        owner.release()


def run_job(run_dir: str) -> int:
    """One run on its engine (``job.json``): the FrameLoop or a graph."""
    with open(os.path.join(run_dir, 'job.json'), encoding='utf-8') as fh:
        engine = json.load(fh).get('engine', 'graph')
    if engine == 'plain':
        from adcs_nodes.tools.campaigns.worker import mc_worker
        return mc_worker(run_dir)
    return worker_main(run_dir)


def _signal_group(pid: int, sig: int) -> None:
    try:
        os.killpg(pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


#: What a prepared run directory holds before its first attempt.
PREPARED = ('job.json', 'scenario.yaml')


def clean_attempt(run_dir: str) -> None:
    """Remove what an earlier attempt of this run left (bag, series, logs, results)."""
    import shutil
    for name in os.listdir(run_dir):
        path = os.path.join(run_dir, name)
        if name in PREPARED:
            continue
        if os.path.isdir(path) and not os.path.islink(path):
            shutil.rmtree(path)
        else:
            os.unlink(path)


def _failure_of(run_dir: str, index: int, code: int, message: str,
                wall: float) -> Dict[str, Any]:
    path = os.path.join(run_dir, FAILED_FILE)
    if os.path.isfile(path):
        with open(path, encoding='utf-8') as fh:
            return {**json.load(fh), 'index': index}
    tail = _tail(os.path.join(run_dir, 'worker.log')) or message
    return {'index': index, 'status': 'error', 'exit_code': code, 'wall_time_s': wall,
            'message': f'run process exited with code {code}: {tail}'}


def _tail(path: str, lines: int = 5) -> str:
    try:
        with open(path, encoding='utf-8', errors='replace') as fh:
            return ' | '.join(line.rstrip() for line in fh.readlines()[-lines:])
    except OSError:
        return ''
