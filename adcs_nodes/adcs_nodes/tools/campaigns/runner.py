"""One run: the worker process that runs it, and the supervisor that starts and watches it."""
from __future__ import annotations

import fcntl
import json
import os
import signal
import socket
import subprocess
import sys
import time
from typing import Any, Dict, Optional

from adcs_nodes.tools.campaigns.capture import capture_reference
from adcs_nodes.tools.campaigns.config import CampaignError
from adcs_nodes.tools.campaigns.files import (FAILED_FILE, RESULT_FILE, load_result,
                                              write_json_atomic)
from adcs_nodes.tools.campaigns.results import bag_metrics

#: Seconds a supervisor waits for an interrupted run to close its bag before killing it.
STOP_GRACE_S = 60.0
#: Seconds between repeated SIGINTs to a run being stopped (see :func:`_supervise`).
SIGINT_REPEAT_S = 2.0
#: Per-engine worker command (``python`` + these + ``RUN_DIR``). The plain engine's worker is
#: a simulator tool: the flight-software package names it but never imports it.
WORKER_COMMANDS = {
    'graph': ['-m', 'adcs_nodes.tools.campaigns', '_worker'],
    'plain': ['-m', 'adcs_nodes.tools.campaigns.worker'],
}
#: Set in every run process's environment: one BLAS/OpenMP/numba thread per run (J runs share
#: J cores; the models make only tiny LAPACK calls, where extra threads cost CPU and give the
#: same bits: :mod:`adcs_nodes.nodes.runtime`). The numba kernels use their on-disk cache
#: (``cache=True``), so a run process loads them instead of compiling.
ONE_THREAD_ENV = {key: '1' for key in (
    'OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'BLIS_NUM_THREADS',
    'VECLIB_MAXIMUM_THREADS', 'NUMEXPR_NUM_THREADS', 'NUMBA_NUM_THREADS')}


def worker_env() -> Dict[str, str]:
    """Environment of a run process: this process's, with :data:`ONE_THREAD_ENV`."""
    return {**os.environ, **ONE_THREAD_ENV}


def worker_main(run_dir: str) -> int:
    """Body of the per-run process: launch the dispersed scenario, record, write the result.

    Writes ``result.json`` (atomically; capture judged against the recorded guidance target,
    :mod:`.capture`) when the graph ran to its end, ``failed.json`` when it failed; writes
    nothing when interrupted (exit code 130).
    """
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


def result_head(job: Dict[str, Any]) -> Dict[str, Any]:
    return {'index': job['index'], 'dispersion': job['dispersion'], 'bag': 'bag',
            'host': socket.gethostname(), 'supervisor_pid': os.getppid(),
            'finished_utc': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}


def fail(run_dir: str, job: Dict[str, Any], code: int, message: str, wall: float) -> int:
    write_json_atomic(os.path.join(run_dir, FAILED_FILE),
                      {**result_head(job), 'status': 'error', 'exit_code': code,
                       'message': message, 'wall_time_s': wall})
    print(f'[montecarlo] run failed: {message}', flush=True)
    return code or 1


class RunOwner:
    """One run executed by one run process at a time: an exclusive ``flock`` on
    ``RUN_DIR.owner`` (beside the run directory, which a new attempt recreates), taken by the
    supervisor and handed to the run process (an inherited descriptor), which is named in the
    file (host, pid): the lock lives exactly as long as the run process.

    A run given to another worker while the run process of its lost worker still lives on
    this host: that process group is ended (SIGTERM, SIGKILL after :data:`STOP_GRACE_S`)
    before the run is taken; on another host the run is refused (CampaignError).
    """

    def __init__(self, run_dir: str) -> None:
        self.path = run_dir.rstrip('/') + '.owner'
        self.fd: Optional[int] = None

    def acquire(self) -> 'RunOwner':
        os.makedirs(os.path.dirname(self.path), exist_ok=True)
        self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        if self._wait_lock(0.0):
            return self
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
                return self
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

    def hand_to(self, pid: int) -> None:
        """Name run process ``pid`` (which inherited the descriptor) the owner and let go of
        this process's copy: the lock is the run process's alone."""
        os.ftruncate(self.fd, 0)
        os.pwrite(self.fd, json.dumps({'host': socket.gethostname(), 'pid': pid}).encode(), 0)
        self.release()

    def end_previous(self) -> None:
        """Take the run (ending a previous owner still alive) and let it go again."""
        self.acquire().release()

    def release(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def execute_run(job: Dict[str, Any]) -> Dict[str, Any]:
    """Run one prepared run directory in its own process and return its result dict.

    This is the unit of work submitted to the local thread pool or to Dask workers. It
    starts ``python -m adcs_nodes.tools.campaigns _worker RUN_DIR`` (graph engine) or
    ``python -m adcs_nodes.tools.campaigns.worker RUN_DIR`` (plain engine), output to
    ``worker.log``, one BLAS thread (:func:`worker_env`). While waiting it watches
    ``job['stop_file']``: when that file appears (Ctrl-C on the campaign) the run gets
    SIGINT, closes its bag and is reported ``interrupted``.

    Parameters
    ----------
    job : dict
        ``index``, ``run_dir`` (prepared: ``job.json`` and ``scenario.yaml``), ``stop_file``,
        ``engine`` (default ``'graph'``).

    Returns
    -------
    dict
        ``result.json`` content, or ``{'index', 'status': 'error' | 'interrupted',
        'message', ...}``.
    """
    run_dir, index = job['run_dir'], job['index']
    if os.path.exists(job['stop_file']):
        return {'index': index, 'status': 'interrupted', 'message': 'not started'}
    t0 = time.monotonic()
    from adcs_nodes.tools.run.launcher.processes import with_parent_death_signal
    cmd = with_parent_death_signal([sys.executable] + WORKER_COMMANDS[job.get('engine', 'graph')]
                                   + [run_dir])
    owner = RunOwner(run_dir).acquire()
    try:
        _clean_attempt(run_dir)
        with open(os.path.join(run_dir, 'worker.log'), 'w') as log:
            # its own session (the stop file stops it); the parent-death signal ends it with
            # this supervisor (a lost worker); it holds the run's owner lock
            proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL, start_new_session=True,
                                    env=worker_env(), pass_fds=(owner.fd,))
            owner.hand_to(proc.pid)
    finally:
        owner.release()
    code = _supervise(proc, job['stop_file'])
    wall = time.monotonic() - t0
    result = load_result(run_dir) if code == 0 else None
    if result is not None:
        return result
    if code == 130 or os.path.exists(job['stop_file']):
        return {'index': index, 'status': 'interrupted', 'message': 'interrupted (Ctrl-C)',
                'wall_time_s': wall}
    return _failure_of(run_dir, index, code, wall)


def _supervise(proc: subprocess.Popen, stop_file: str) -> int:
    """Wait for ``proc``; on ``stop_file`` send SIGINT, then SIGKILL after the grace time.

    SIGINT is repeated every :data:`SIGINT_REPEAT_S` (the run's handlers are idempotent): a
    run process started by a ``--dask-local`` worker inherits an ignored SIGINT until its
    Python code installs a handler (``backends.sigint_ignored``), and a signal that arrives
    in that window is lost.
    """
    stopped_at: Optional[float] = None
    last_int = 0.0
    while True:
        try:
            return proc.wait(timeout=0.5)
        except subprocess.TimeoutExpired:
            pass
        now = time.monotonic()
        if stopped_at is None and os.path.exists(stop_file):
            stopped_at = last_int = now
            _signal_group(proc.pid, signal.SIGINT)
        elif stopped_at is not None and now - stopped_at > STOP_GRACE_S:
            _signal_group(proc.pid, signal.SIGKILL)
            return proc.wait()
        elif stopped_at is not None and now - last_int >= SIGINT_REPEAT_S:
            last_int = now
            _signal_group(proc.pid, signal.SIGINT)


def _signal_group(pid: int, sig: int) -> None:
    try:
        os.killpg(pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


#: What a prepared run directory holds before its first attempt.
PREPARED = ('job.json', 'scenario.yaml')


def _clean_attempt(run_dir: str) -> None:
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


def _failure_of(run_dir: str, index: int, code: int, wall: float) -> Dict[str, Any]:
    path = os.path.join(run_dir, FAILED_FILE)
    if os.path.isfile(path):
        with open(path, encoding='utf-8') as fh:
            return {**json.load(fh), 'index': index}
    tail = _tail(os.path.join(run_dir, 'worker.log'))
    return {'index': index, 'status': 'error', 'exit_code': code, 'wall_time_s': wall,
            'message': f'run process exited with code {code}: {tail}'}


def _tail(path: str, lines: int = 5) -> str:
    try:
        with open(path, encoding='utf-8', errors='replace') as fh:
            return ' | '.join(line.rstrip() for line in fh.readlines()[-lines:])
    except OSError:
        return ''
