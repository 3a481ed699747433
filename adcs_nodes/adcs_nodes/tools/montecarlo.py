"""``adcs montecarlo``: dispersed closed-loop campaigns, local or on a Dask cluster, resumable.

Usage::

    adcs montecarlo SCENARIO --runs N [--jobs J | --scheduler ADDRESS] [--out DIR]
                    [--duration S] [--seed S] [--max-rate-deg-s 3.0] [--capture-deg 5.0]
                    [--mag-bias-nT 120] [--misalignment-deg 1.0] [--compose]

Dispersions
-----------
Run ``i`` of a campaign with seed ``s`` draws, from ``numpy.random.default_rng([s, i])`` and in
this order (the order is part of the file format: changing it changes every campaign):

1. ``q_orbit_body`` uniform on SO(3): a 4-D standard normal vector, normalised, sign chosen
   with ``w >= 0`` (scalar last);
2. ``omega_body_eci_body``: each body component uniform in ``[-max_rate, +max_rate]`` deg/s
   (issue 5: "initial rates up to 3 deg/s" per axis; the paper's (-3, 3, 3) deg/s is a corner
   of that cube, so the magnitude reaches ``sqrt(3) max_rate``);
3. magnetometer bias: each sensor axis uniform in ``+-mag_bias`` (default 120 nT, paper 000);
4. magnetometer misalignment: a body -> sensor rotation vector, each component uniform in
   ``+-misalignment`` deg (default 1 deg: the ~1 deg assumption of ``paper000_control``);
5. the run's scenario ``seed`` (sensor noise, random torque): an integer in ``[0, 2**31 - 1)``.

Every draw is made even when the scenario has no magnetometer (then 3 and 4 are unused), so a
run's values never depend on the scenario's sensor set.

Execution
---------
Each run is one ``python -m adcs_nodes.tools.montecarlo _worker RUN_DIR`` process that starts
the graph with :class:`~adcs_nodes.tools.launcher.Launcher` in its own main thread (the
launcher needs signal handlers and sets ``ROS_DOMAIN_ID`` in its environment; a fresh process
per run keeps every graph isolated, each with its own domain). ``--jobs J`` supervises J such
processes at once from a thread pool; ``--scheduler ADDRESS`` submits the same supervisor
function (:func:`execute_run`) to an existing Dask distributed scheduler, whose workers start
the run processes on their machines. Workers need this package (and ROS 2) installed and
``--out`` on a file system they see under the same path.

Files (``OUT`` = ``--out``)
---------------------------
``campaign.json``
    The campaign's identity (:data:`IDENTITY_KEYS`: scenario content hash, seed, duration,
    dispersion bounds, capture threshold) plus the last ``runs`` and ``compose``; a restart
    with a different identity is refused. ``--runs``, ``--jobs``, ``--scheduler`` and
    ``--compose`` may change between restarts (run ``i``'s draws depend only on the seed and
    ``i``, so a larger ``--runs`` extends the campaign; composed and per-process graphs give
    the same trajectory).
``runs/run_<i>/``
    ``scenario.yaml`` (the dispersed scenario: ``adcs run`` reproduces the run), ``job.json``,
    ``bag/`` (rosbag2 MCAP), ``logs/``, ``worker.log`` and ``result.json`` (written atomically
    when the run completed; its presence, with the bag, marks the run as done).
``campaign.csv``
    One row per run (:data:`CSV_COLUMNS`): dispersed values, status, metrics and the initial
    truth read back from the bag's first ``/sim/state``.
``summary.md``, ``capture_vs_rate.png``
    Success rate, capture-time statistics, success rate per initial-rate bin.

Status of a run: ``captured`` (the angle to the orbit frame stays below ``--capture-deg``
from some time to the end), ``not_captured`` (completed, never captured), ``error`` (the
graph failed: message in the table, rerun on restart), ``interrupted`` / ``pending``
(Ctrl-C; rerun on restart). Exit codes: 0 every run completed, 1 some run failed, 2 bad
arguments, 130 interrupted.
"""
from __future__ import annotations

import argparse
import copy
import csv
import fcntl
import hashlib
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import asdict, dataclass
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence

import numpy as np
import yaml

#: Keys of ``campaign.json`` that must match for a restart to resume the campaign.
IDENTITY_KEYS = ('scenario_sha256', 'seed', 'duration_s', 'max_rate_deg_s', 'capture_deg',
                 'mag_bias_nT', 'misalignment_deg')

#: Statuses of a run that ended (the others: ``interrupted``, ``pending``).
_FINISHED = ('captured', 'not_captured', 'error')
STATE_TOPIC = '/sim/state'
RESULT_FILE = 'result.json'
FAILED_FILE = 'failed.json'
#: Seconds a supervisor waits for an interrupted run to close its bag before killing it.
STOP_GRACE_S = 60.0

_VEC = ('x', 'y', 'z')
_QUAT = ('x', 'y', 'z', 'w')
CSV_COLUMNS: List[str] = (
    ['index', 'seed', 'status']
    + [f'disp_q_orbit_body_{c}' for c in _QUAT]
    + [f'disp_omega_body_eci_body_{c}_deg_s' for c in _VEC]
    + ['disp_rate_deg_s']
    + [f'disp_mag_bias_{c}_T' for c in _VEC]
    + [f'disp_mag_misalignment_{c}_deg' for c in _VEC]
    + ['capture_time_s', 'final_angle_deg', 'final_rate_deg_s', 'max_rate_deg_s']
    + [f'bag_q_orbit_body_{c}' for c in _QUAT]
    + [f'bag_omega_body_eci_body_{c}_deg_s' for c in _VEC]
    + ['sim_time_s', 'wall_time_s', 'missed_frames', 'host', 'supervisor_pid', 'message'])


class CampaignError(ValueError):
    """Bad campaign arguments, or a restart whose arguments differ from ``campaign.json``."""


# ---------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class CampaignConfig:
    """What defines a campaign (its identity) plus how many runs it has.

    Attributes
    ----------
    scenario_path : str
        Absolute path of the base scenario YAML.
    scenario_sha256 : str
        Hash of the validated base scenario (comments and key order do not count).
    runs : int
        Number of runs, indices ``0 .. runs - 1``.
    seed : int
        Campaign seed; run ``i`` draws from ``default_rng([seed, i])``.
    duration_s : float
        Simulated duration of every run [s].
    max_rate_deg_s : float
        Bound of each initial rate component [deg/s].
    capture_deg : float
        Capture threshold on the angle between body and orbit frame [deg].
    mag_bias_nT : float
        Bound of each magnetometer bias component [nT].
    misalignment_deg : float
        Bound of each magnetometer misalignment rotation-vector component [deg].
    compose : bool
        Run each graph composed in one process (same trajectory, faster; not part of the
        identity).
    """

    scenario_path: str
    scenario_sha256: str
    runs: int
    seed: int
    duration_s: float
    max_rate_deg_s: float = 3.0
    capture_deg: float = 5.0
    mag_bias_nT: float = 120.0
    misalignment_deg: float = 1.0
    compose: bool = False

    def identity(self) -> Dict[str, Any]:
        """The values a restart must repeat (see :data:`IDENTITY_KEYS`)."""
        return {k: getattr(self, k) for k in IDENTITY_KEYS}


@dataclass(frozen=True)
class Dispersion:
    """Dispersed values of one run (see the module docstring for the distributions).

    Attributes
    ----------
    index : int
        Run index in the campaign.
    seed : int
        The run's scenario seed.
    q_orbit_body_xyzw : list of float, shape (4,)
        Initial attitude, body -> orbit, scalar last, ``w >= 0``.
    omega_body_eci_body_deg_s : list of float, shape (3,)
        Initial rate of body w.r.t. ECI, body axes [deg/s].
    mag_bias_T : list of float, shape (3,)
        Magnetometer bias, sensor axes [T].
    mag_misalignment_deg : list of float, shape (3,)
        Magnetometer misalignment, body -> sensor rotation vector [deg].
    """

    index: int
    seed: int
    q_orbit_body_xyzw: List[float]
    omega_body_eci_body_deg_s: List[float]
    mag_bias_T: List[float]
    mag_misalignment_deg: List[float]


def scenario_hash(scenario: Dict[str, Any]) -> str:
    """SHA-256 of a validated scenario dict (``_path`` and other private keys excluded)."""
    clean = {k: v for k, v in scenario.items() if not k.startswith('_')}
    return hashlib.sha256(json.dumps(clean, sort_keys=True).encode()).hexdigest()


def draw_dispersion(cfg: CampaignConfig, index: int) -> Dispersion:
    """Draw the dispersion of run ``index`` (deterministic in ``cfg.seed`` and ``index``).

    Returns
    -------
    Dispersion
        Attitude uniform on SO(3), rate components uniform in ``+-max_rate_deg_s``,
        magnetometer bias and misalignment uniform per axis, and the run's scenario seed.
    """
    rng = np.random.default_rng([cfg.seed, index])
    q = rng.standard_normal(4)
    q /= np.linalg.norm(q)
    if q[3] < 0.0:
        q = -q
    rate = rng.uniform(-cfg.max_rate_deg_s, cfg.max_rate_deg_s, 3)
    bias = rng.uniform(-cfg.mag_bias_nT, cfg.mag_bias_nT, 3) * 1e-9
    mis = rng.uniform(-cfg.misalignment_deg, cfg.misalignment_deg, 3)
    seed = int(rng.integers(0, 2**31 - 1))
    return Dispersion(index, seed, q.tolist(), rate.tolist(), bias.tolist(), mis.tolist())


def apply_dispersion(base: Dict[str, Any], disp: Dispersion, duration_s: float
                     ) -> Dict[str, Any]:
    """Deep copy of the validated scenario ``base`` with the run's dispersion written in.

    The initial attitude and rate replace any of the alternative keys of ``initial``
    (``q_orbit_body_wxyz``, ``omega_body_orbit_body_deg_s``); the magnetometer errors are
    written only when the scenario has a magnetometer.
    """
    sc = copy.deepcopy({k: v for k, v in base.items() if not k.startswith('_')})
    sc['seed'] = disp.seed
    sc['duration_s'] = float(duration_s)
    init = sc.setdefault('initial', {})
    init.pop('q_orbit_body_wxyz', None)
    init.pop('omega_body_orbit_body_deg_s', None)
    init['q_orbit_body_xyzw'] = list(disp.q_orbit_body_xyzw)
    init['omega_body_eci_body_deg_s'] = list(disp.omega_body_eci_body_deg_s)
    mag = sc.get('sensors', {}).get('magnetometer')
    if mag is not None:
        mag['bias_T'] = list(disp.mag_bias_T)
        mag['misalignment_deg'] = list(disp.mag_misalignment_deg)
    return sc


# ---------------------------------------------------------------------- metrics
def capture_index(angle_deg: np.ndarray, threshold_deg: float) -> Optional[int]:
    """First sample from which ``angle_deg`` stays below ``threshold_deg`` to the end.

    Parameters
    ----------
    angle_deg : numpy.ndarray, shape (n,)
        Angle between body and orbit frame per sample [deg].
    threshold_deg : float
        Capture threshold [deg].

    Returns
    -------
    int or None
        The index, or ``None`` when the last sample is not below the threshold (or n = 0).
    """
    below = np.asarray(angle_deg) < threshold_deg
    if below.size == 0 or not below[-1]:
        return None
    above = np.flatnonzero(~below)
    return int(above[-1]) + 1 if above.size else 0


def read_truth(bag: str) -> Dict[str, np.ndarray]:
    """``/sim/state`` of a bag as arrays, one entry per sim-time stamp (repeats dropped).

    Returns
    -------
    dict
        ``t_s`` (n,) sim time since the first sample [s], ``q`` (n, 4) ``q_orbit_body`` scalar
        last, ``w_eci`` (n, 3) ``omega_body_eci_body`` [rad/s], ``w_orbit`` (n, 3)
        ``omega_body_orbit_body`` [rad/s].

    Raises
    ------
    ValueError
        If the bag has no ``/sim/state`` message.
    """
    from adcs_nodes.tools.bag import header_stamp_ns, read_messages

    stamps: List[int] = []
    q, w_eci, w_orb = [], [], []
    for _, _, msg in read_messages(bag, [STATE_TOPIC]):
        stamp = header_stamp_ns(msg)
        if stamps and stamp <= stamps[-1]:
            continue
        stamps.append(stamp)
        o = msg.q_orbit_body
        q.append((o.x, o.y, o.z, o.w))
        w_eci.append(_xyz(msg.omega_body_eci_body))
        w_orb.append(_xyz(msg.omega_body_orbit_body))
    if not stamps:
        raise ValueError(f'{bag}: no {STATE_TOPIC} message')
    t = (np.asarray(stamps, dtype=np.int64) - stamps[0]) / 1e9
    return {'t_s': t, 'q': np.asarray(q), 'w_eci': np.asarray(w_eci),
            'w_orbit': np.asarray(w_orb)}


def _xyz(v: Any) -> tuple:
    return (v.x, v.y, v.z)


def bag_metrics(bag: str, capture_deg: float) -> Dict[str, Any]:
    """Capture time, final angle and rates, and the initial truth of a run's bag.

    Parameters
    ----------
    bag : str
        rosbag2 directory with ``/sim/state`` (``adcs_msgs/AttitudeState``, truth).
    capture_deg : float
        Capture threshold on the body-to-orbit angle [deg].

    Returns
    -------
    dict
        ``capture_time_s`` (None if never), ``final_angle_deg``, ``final_rate_deg_s``
        (rate w.r.t. the orbit frame), ``max_rate_deg_s`` (largest rate w.r.t. ECI),
        ``samples``, and ``bag_initial`` (first sample: ``q_orbit_body_xyzw``,
        ``omega_body_eci_body_rad_s``, ``omega_body_eci_body_deg_s``).
    """
    from adcs_nodes.core.attitude import angle_between

    truth = read_truth(bag)
    identity = np.array([0.0, 0.0, 0.0, 1.0])
    angle = np.degrees([angle_between(q, identity) for q in truth['q']])
    k = capture_index(angle, capture_deg)
    w0 = truth['w_eci'][0]
    return {
        'capture_time_s': None if k is None else float(truth['t_s'][k]),
        'final_angle_deg': float(angle[-1]),
        'final_rate_deg_s': float(np.degrees(np.linalg.norm(truth['w_orbit'][-1]))),
        'max_rate_deg_s': float(np.degrees(np.linalg.norm(truth['w_eci'], axis=1).max())),
        'samples': int(truth['t_s'].size),
        'bag_initial': {
            'q_orbit_body_xyzw': [float(c) for c in truth['q'][0]],
            'omega_body_eci_body_rad_s': [float(c) for c in w0],
            'omega_body_eci_body_deg_s': [math.degrees(c) for c in w0],
        },
    }


# ---------------------------------------------------------------------- files
def write_json_atomic(path: str, data: Any) -> None:
    """Write ``data`` as JSON to ``path`` atomically (temporary file + ``os.replace``)."""
    tmp = f'{path}.tmp-{os.getpid()}-{threading.get_ident()}'
    with open(tmp, 'w', encoding='utf-8') as fh:
        json.dump(data, fh, indent=1)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _write_text_atomic(path: str, text: str) -> None:
    tmp = f'{path}.tmp-{os.getpid()}'
    with open(tmp, 'w', encoding='utf-8', newline='') as fh:
        fh.write(text)
    os.replace(tmp, path)


def run_dir_of(out: str, index: int) -> str:
    """``OUT/runs/run_<index>`` (zero-padded to 4 digits so listings sort)."""
    return os.path.join(out, 'runs', f'run_{index:04d}')


def load_result(run_dir: str) -> Optional[Dict[str, Any]]:
    """The run's ``result.json`` when the run is done (result and bag present), else None."""
    path = os.path.join(run_dir, RESULT_FILE)
    metadata = os.path.join(run_dir, 'bag', 'metadata.yaml')
    if not (os.path.isfile(path) and os.path.isfile(metadata)):
        return None
    try:
        with open(path, encoding='utf-8') as fh:
            return json.load(fh)
    except (OSError, ValueError):
        return None


# ---------------------------------------------------------------------- one run (worker side)
def _worker_main(run_dir: str) -> int:
    """Body of the per-run process: launch the dispersed scenario, record, write the result.

    Writes ``result.json`` (atomically) when the graph ran to its end, ``failed.json`` when
    it failed; writes nothing when interrupted (exit code 130).
    """
    from adcs_nodes.tools.launcher import LaunchError, Launcher
    from adcs_nodes.tools.scenario import ScenarioError, load_scenario

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
        return _fail(run_dir, job, 2, str(exc), time.monotonic() - t0)
    print(f'[montecarlo] launcher: exit {res.exit_code}: {res.message}', flush=True)
    if res.exit_code == 130:
        return 130
    if res.exit_code != 0:
        return _fail(run_dir, job, res.exit_code, res.message, time.monotonic() - t0)
    try:
        metrics = bag_metrics(bag, job['capture_deg'])
    except (FileNotFoundError, ValueError) as exc:
        return _fail(run_dir, job, 1, f'bag unreadable: {exc}', time.monotonic() - t0)
    result = {**_result_head(job), **metrics,
              'status': 'not_captured' if metrics['capture_time_s'] is None else 'captured',
              'sim_time_s': res.sim_time_s, 'launcher_wall_s': res.wall_time_s,
              'wall_time_s': time.monotonic() - t0, 'frames': res.frames,
              'missed_frames': res.missed_frames, 'compose': job['compose'],
              'message': res.message}
    write_json_atomic(os.path.join(run_dir, RESULT_FILE), result)
    return 0


def _result_head(job: Dict[str, Any]) -> Dict[str, Any]:
    return {'index': job['index'], 'dispersion': job['dispersion'], 'bag': 'bag',
            'host': socket.gethostname(), 'supervisor_pid': os.getppid(),
            'finished_utc': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}


def _fail(run_dir: str, job: Dict[str, Any], code: int, message: str, wall: float) -> int:
    write_json_atomic(os.path.join(run_dir, FAILED_FILE),
                      {**_result_head(job), 'status': 'error', 'exit_code': code,
                       'message': message, 'wall_time_s': wall})
    print(f'[montecarlo] run failed: {message}', flush=True)
    return code or 1


# ---------------------------------------------------------------------- one run (supervisor)
def execute_run(job: Dict[str, Any]) -> Dict[str, Any]:
    """Run one prepared run directory in its own process and return its result dict.

    This is the unit of work submitted to the local thread pool or to Dask workers. It
    starts ``python -m adcs_nodes.tools.montecarlo _worker RUN_DIR`` (output to
    ``worker.log``), and while waiting watches ``job['stop_file']``: when that file appears
    (Ctrl-C on the campaign) the run gets SIGINT, closes its bag and is reported
    ``interrupted``.

    Parameters
    ----------
    job : dict
        ``index``, ``run_dir`` (prepared: ``job.json`` and ``scenario.yaml``), ``stop_file``.

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
    cmd = [sys.executable, '-m', 'adcs_nodes.tools.montecarlo', '_worker', run_dir]
    with open(os.path.join(run_dir, 'worker.log'), 'w') as log:
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True)
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
    """Wait for ``proc``; on ``stop_file`` send SIGINT, then SIGKILL after the grace time."""
    stopped_at: Optional[float] = None
    while True:
        try:
            return proc.wait(timeout=0.5)
        except subprocess.TimeoutExpired:
            pass
        if stopped_at is None and os.path.exists(stop_file):
            stopped_at = time.monotonic()
            _signal_group(proc, signal.SIGINT)
        elif stopped_at is not None and time.monotonic() - stopped_at > STOP_GRACE_S:
            _signal_group(proc, signal.SIGKILL)
            return proc.wait()


def _signal_group(proc: subprocess.Popen, sig: int) -> None:
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        pass


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


# ---------------------------------------------------------------------- backends
class _LocalBackend:
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


class _DaskBackend:
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


# ---------------------------------------------------------------------- campaign
class Campaign:
    """One invocation of a campaign in ``out``: check, prepare, execute, tabulate.

    Parameters
    ----------
    cfg : CampaignConfig
        Campaign definition.
    base : dict
        The validated base scenario (:func:`~adcs_nodes.tools.scenario.load_scenario`).
    out : str
        Output directory.
    log : callable
        Receives one progress line at a time.
    """

    def __init__(self, cfg: CampaignConfig, base: Dict[str, Any], out: str,
                 log: Callable[[str], None] = print) -> None:
        self.cfg = cfg
        self.base = base
        self.out = os.path.abspath(out)
        self.log = log
        self.session = uuid.uuid4().hex[:12]
        self.stop_file = os.path.join(self.out, f'.stop-{self.session}')
        self.rows: Dict[int, Dict[str, Any]] = {}
        self.executed = 0

    # -------------------------------------------------------------- set-up
    def check_or_create(self) -> None:
        """Create ``campaign.json``, or refuse a restart whose identity differs."""
        path = os.path.join(self.out, 'campaign.json')
        if os.path.isfile(path):
            with open(path, encoding='utf-8') as fh:
                old = json.load(fh)
            new = self.cfg.identity()
            diff = [f'{k}: {old.get(k)!r} in campaign.json, {new[k]!r} now'
                    for k in IDENTITY_KEYS if old.get(k) != new[k]]
            if diff:
                raise CampaignError(f'{self.out} holds a campaign with other arguments ('
                                    + '; '.join(diff) + '). Repeat its arguments to resume, '
                                    'or choose another --out.')
        data = {**asdict(self.cfg), 'version': 1,
                'updated_utc': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}
        write_json_atomic(path, data)

    def prepare(self, index: int) -> Dict[str, Any]:
        """Fresh run directory with ``scenario.yaml`` and ``job.json``; returns the job."""
        run_dir = run_dir_of(self.out, index)
        if os.path.exists(run_dir):
            shutil.rmtree(run_dir)   # an incomplete run: half-written bag, logs
        os.makedirs(run_dir)
        disp = draw_dispersion(self.cfg, index)
        sc = apply_dispersion(self.base, disp, self.cfg.duration_s)
        with open(os.path.join(run_dir, 'scenario.yaml'), 'w', encoding='utf-8') as fh:
            fh.write(f'# run {index} of the Monte Carlo campaign in {self.out} '
                     f'(seed {self.cfg.seed}), dispersed from {self.cfg.scenario_path}\n')
            yaml.safe_dump(sc, fh, sort_keys=False)
        job = {'index': index, 'run_dir': run_dir, 'stop_file': self.stop_file,
               'duration_s': self.cfg.duration_s, 'capture_deg': self.cfg.capture_deg,
               'compose': self.cfg.compose, 'dispersion': asdict(disp)}
        write_json_atomic(os.path.join(run_dir, 'job.json'), job)
        return job

    # -------------------------------------------------------------- execution
    def run(self, jobs: int = 1, scheduler: Optional[str] = None) -> int:
        """Execute every run not done yet; write the table, summary and plot. Exit code."""
        os.makedirs(self.out, exist_ok=True)
        with _campaign_lock(self.out):
            self.check_or_create()
            _clean_old_stop_files(self.out)
            todo = self._collect_done()
            interrupted = False
            if todo:
                backend = (_DaskBackend(scheduler, self.session) if scheduler
                           else _LocalBackend(jobs))
                interrupted = self._execute(backend, todo)
            for i in range(self.cfg.runs):
                self.rows.setdefault(i, {'index': i, 'status': 'pending', 'dispersion':
                                         asdict(draw_dispersion(self.cfg, i))})
            self.write_outputs()
        return self._exit_code(interrupted)

    def _collect_done(self) -> List[int]:
        todo = []
        for i in range(self.cfg.runs):
            result = load_result(run_dir_of(self.out, i))
            if result is None:
                todo.append(i)
            else:
                self.rows[i] = result
        if len(todo) < self.cfg.runs:
            self.log(f'[montecarlo] resuming: {self.cfg.runs - len(todo)} of {self.cfg.runs} '
                     f'runs already done, {len(todo)} to run')
        return todo

    def _execute(self, backend: Any, todo: Sequence[int]) -> bool:
        t0 = time.monotonic()
        old_term = _sigterm_as_interrupt()
        try:
            for i in todo:
                backend.submit(self.prepare(i))
            for result in backend.results():
                self._record(result, t0)
            return False
        except KeyboardInterrupt:
            self.log('[montecarlo] interrupted: stopping the runs in progress '
                     '(finished runs are kept; run the same command again to resume)')
            _touch(self.stop_file)
            for result in backend.drain(STOP_GRACE_S + 15.0):
                self._record(result, t0)
            return True
        finally:
            backend.close()
            if old_term is not None:
                signal.signal(signal.SIGTERM, old_term)

    def _record(self, result: Dict[str, Any], t0: float) -> None:
        index = int(result['index'])
        result.setdefault('dispersion', asdict(draw_dispersion(self.cfg, index)))
        self.rows[index] = result
        if result.get('status') in _FINISHED:
            self.executed += 1
        done = sum(1 for r in self.rows.values() if r.get('status') in _FINISHED)
        self.log(_progress_line(result, done, self.cfg.runs, time.monotonic() - t0))
        write_table(os.path.join(self.out, 'campaign.csv'), self._sorted_rows())

    def _sorted_rows(self) -> List[Dict[str, Any]]:
        return [self.rows[i] for i in sorted(self.rows) if i < self.cfg.runs]

    def _exit_code(self, interrupted: bool) -> int:
        rows = self._sorted_rows()
        failed = sum(1 for r in rows if r.get('status') == 'error')
        self.log(f'[montecarlo] executed {self.executed} run(s) in this call; '
                 f'{sum(1 for r in rows if r.get("status") == "captured")} captured, '
                 f'{failed} failed, of {self.cfg.runs}; table in '
                 f'{os.path.join(self.out, "campaign.csv")}')
        if interrupted:
            return 130
        return 1 if failed else 0

    # -------------------------------------------------------------- outputs
    def write_outputs(self) -> None:
        """``campaign.csv``, ``summary.md`` and ``capture_vs_rate.png`` from the rows."""
        rows = self._sorted_rows()
        write_table(os.path.join(self.out, 'campaign.csv'), rows)
        _write_text_atomic(os.path.join(self.out, 'summary.md'),
                           summary_markdown(self.cfg, rows, self.base))
        plot_capture_vs_rate(os.path.join(self.out, 'capture_vs_rate.png'), self.cfg, rows)


def _progress_line(result: Dict[str, Any], done: int, total: int, elapsed: float) -> str:
    status = result.get('status')
    wall = result.get('wall_time_s')
    wall_txt = f', {wall:.1f} s wall' if isinstance(wall, (int, float)) else ''
    if status == 'captured':
        what = (f'captured at {result["capture_time_s"]:g} s, final '
                f'{result["final_angle_deg"]:.2f} deg')
    elif status == 'not_captured':
        what = f'not captured, final {result["final_angle_deg"]:.1f} deg'
    else:
        what = f'{status}: {str(result.get("message", "")).splitlines()[0][:200]}'
    return (f'[montecarlo] {done}/{total} run {result["index"]}: {what}{wall_txt} '
            f'(campaign {elapsed:.0f} s)')


class _campaign_lock:
    """Exclusive lock on ``OUT/.lock``: two campaigns never share one directory at once."""

    def __init__(self, out: str) -> None:
        self.path = os.path.join(out, '.lock')
        self.fh = None

    def __enter__(self) -> '_campaign_lock':
        self.fh = open(self.path, 'w')
        try:
            fcntl.flock(self.fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self.fh.close()
            raise CampaignError(f'another campaign is running in {os.path.dirname(self.path)}')
        return self

    def __exit__(self, *exc: Any) -> None:
        self.fh.close()


def _touch(path: str) -> None:
    with open(path, 'w'):
        pass


def _clean_old_stop_files(out: str, age_s: float = 3600.0) -> None:
    """Remove stop files of sessions interrupted more than ``age_s`` ago."""
    now = time.time()
    for name in os.listdir(out):
        path = os.path.join(out, name)
        if name.startswith('.stop-') and now - os.path.getmtime(path) > age_s:
            os.unlink(path)


def _sigterm_as_interrupt() -> Any:
    """Make SIGTERM stop the campaign like Ctrl-C (main thread only); returns the old handler."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    return signal.signal(signal.SIGTERM, handler)


# ---------------------------------------------------------------------- table
def table_row(result: Dict[str, Any]) -> Dict[str, Any]:
    """One ``campaign.csv`` row (:data:`CSV_COLUMNS`) from a run's result dict."""
    disp = result.get('dispersion') or {}
    init = result.get('bag_initial') or {}
    row: Dict[str, Any] = {'index': result['index'], 'seed': disp.get('seed', ''),
                           'status': result.get('status', '')}
    _put(row, 'disp_q_orbit_body_{}', _QUAT, disp.get('q_orbit_body_xyzw'))
    omega = disp.get('omega_body_eci_body_deg_s')
    _put(row, 'disp_omega_body_eci_body_{}_deg_s', _VEC, omega)
    row['disp_rate_deg_s'] = repr(float(np.linalg.norm(omega))) if omega else ''
    _put(row, 'disp_mag_bias_{}_T', _VEC, disp.get('mag_bias_T'))
    _put(row, 'disp_mag_misalignment_{}_deg', _VEC, disp.get('mag_misalignment_deg'))
    _put(row, 'bag_q_orbit_body_{}', _QUAT, init.get('q_orbit_body_xyzw'))
    _put(row, 'bag_omega_body_eci_body_{}_deg_s', _VEC, init.get('omega_body_eci_body_deg_s'))
    for key in ('capture_time_s', 'final_angle_deg', 'final_rate_deg_s', 'max_rate_deg_s',
                'sim_time_s', 'wall_time_s', 'missed_frames', 'host', 'supervisor_pid',
                'message'):
        value = result.get(key)
        row[key] = '' if value is None else (repr(value) if isinstance(value, float)
                                             else value)
    return row


def _put(row: Dict[str, Any], pattern: str, names: Sequence[str],
         values: Optional[Sequence[float]]) -> None:
    for j, name in enumerate(names):
        row[pattern.format(name)] = repr(float(values[j])) if values else ''


def write_table(path: str, results: Sequence[Dict[str, Any]]) -> None:
    """Write ``campaign.csv`` atomically; floats in full precision (``repr``)."""
    tmp = f'{path}.tmp-{os.getpid()}'
    with open(tmp, 'w', encoding='utf-8', newline='') as fh:
        writer = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        for result in results:
            writer.writerow(table_row(result))
    os.replace(tmp, path)


def read_table(path: str) -> List[Dict[str, str]]:
    """Rows of a ``campaign.csv`` as dicts of strings."""
    with open(path, encoding='utf-8', newline='') as fh:
        return list(csv.DictReader(fh))


# ---------------------------------------------------------------------- summary and plot
def _rate_of(result: Dict[str, Any]) -> float:
    return float(np.linalg.norm(result['dispersion']['omega_body_eci_body_deg_s']))


def rate_bins(cfg: CampaignConfig, n_runs: int) -> np.ndarray:
    """Edges of the initial-rate bins [deg/s]: 0 .. sqrt(3) max_rate, 2 to 6 bins."""
    count = int(min(6, max(2, n_runs // 5)))
    return np.linspace(0.0, math.sqrt(3.0) * cfg.max_rate_deg_s, count + 1)


def _bin_table(cfg: CampaignConfig, done: Sequence[Dict[str, Any]]) -> List[tuple]:
    edges = rate_bins(cfg, len(done))
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        last = hi == edges[-1]
        inside = [r for r in done if lo <= _rate_of(r) < hi or (last and _rate_of(r) >= hi)]
        ok = sum(1 for r in inside if r['status'] == 'captured')
        rows.append((lo, hi, len(inside), ok))
    return rows


def _orbit_period_s(base: Dict[str, Any]) -> Optional[float]:
    orbit = base.get('orbit', {})
    if orbit.get('type') != 'circular':
        return None
    from adcs_nodes.core.orbit import MU_EARTH, R_EARTH
    a = R_EARTH + 1e3 * orbit['altitude_km']
    return 2.0 * math.pi * math.sqrt(a ** 3 / MU_EARTH)


def summary_markdown(cfg: CampaignConfig, results: Sequence[Dict[str, Any]],
                     base: Dict[str, Any]) -> str:
    """``summary.md``: campaign definition, success rate, capture-time statistics, bins."""
    done = [r for r in results if r.get('status') in ('captured', 'not_captured')]
    captured = [r for r in done if r['status'] == 'captured']
    period = _orbit_period_s(base)
    lines = [f'# Monte Carlo campaign: {base.get("name", "?")}', '',
             f'Scenario `{cfg.scenario_path}`, seed {cfg.seed}, {cfg.runs} runs of '
             f'{cfg.duration_s:g} s; initial rate components uniform in '
             f'+-{cfg.max_rate_deg_s:g} deg/s, attitude uniform on SO(3), magnetometer bias '
             f'+-{cfg.mag_bias_nT:g} nT and misalignment +-{cfg.misalignment_deg:g} deg per '
             f'axis. Captured: the angle between body and orbit frame stays below '
             f'{cfg.capture_deg:g} deg to the end of the run.', '',
             '| quantity | value |', '|---|---|',
             f'| runs completed | {len(done)} of {cfg.runs} |',
             f'| runs failed | {sum(1 for r in results if r.get("status") == "error")} |',
             f'| success rate (captured / completed) | {_rate_text(len(captured), len(done))} |']
    lines += _capture_stats(captured, period)
    missed = sum(int(r.get('missed_frames') or 0) for r in done)
    lines += [f'| missed lockstep frames (all runs) | {missed} |', '',
              '## Success rate against initial rate', '',
              '| initial rate |omega0| [deg/s] | runs | captured | success rate |',
              '|---|---|---|---|']
    for lo, hi, n, ok in _bin_table(cfg, done):
        lines.append(f'| {lo:.2f} - {hi:.2f} | {n} | {ok} | {_rate_text(ok, n)} |')
    lines += ['', 'Table: `campaign.csv`; plot: `capture_vs_rate.png`.', '']
    return '\n'.join(lines)


def _rate_text(ok: int, n: int) -> str:
    return f'{ok}/{n} = {100.0 * ok / n:.1f} %' if n else 'n/a'


def _capture_stats(captured: Sequence[Dict[str, Any]], period: Optional[float]) -> List[str]:
    if not captured:
        return ['| capture time | no run captured |']
    times = np.array([r['capture_time_s'] for r in captured])
    finals = np.array([r['final_angle_deg'] for r in captured])
    out = []
    for name, value in (('min', times.min()), ('median', np.median(times)),
                        ('mean', times.mean()), ('90th percentile', np.percentile(times, 90)),
                        ('max', times.max())):
        orbits = f' ({value / period:.2f} orbits)' if period else ''
        out.append(f'| capture time, {name} [s] | {value:.0f}{orbits} |')
    out.append(f'| final angle of captured runs, median / max [deg] | '
               f'{np.median(finals):.2f} / {finals.max():.2f} |')
    return out


def plot_capture_vs_rate(path: str, cfg: CampaignConfig,
                         results: Sequence[Dict[str, Any]]) -> None:
    """Capture time against initial rate magnitude, and success rate per rate bin (PNG)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    done = [r for r in results if r.get('status') in ('captured', 'not_captured')]
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 7), sharex=True)
    cap = [r for r in done if r['status'] == 'captured']
    ax1.plot([_rate_of(r) for r in cap], [r['capture_time_s'] for r in cap], 'o',
             label='captured')
    miss = [r for r in done if r['status'] == 'not_captured']
    if miss:
        ax1.plot([_rate_of(r) for r in miss], [cfg.duration_s] * len(miss), 'rx',
                 label='not captured (plotted at the run end)')
    ax1.set_ylim(bottom=0.0)
    ax1.set_ylabel('capture time [s]')
    ax1.set_title(f'capture (< {cfg.capture_deg:g} deg to the orbit frame), '
                  f'{len(done)} runs')
    ax1.legend(loc='best')
    ax1.grid(True)
    bins = _bin_table(cfg, done)
    centres = [(lo + hi) / 2 for lo, hi, _, _ in bins]
    rates = [100.0 * ok / n if n else 0.0 for _, _, n, ok in bins]
    width = (bins[0][1] - bins[0][0]) * 0.9
    ax2.bar(centres, rates, width=width)
    for x, (_, _, n, _) in zip(centres, bins):
        ax2.annotate(f'n={n}', (x, 2), ha='center', fontsize=8)
    ax2.set_ylim(0, 105)
    ax2.set_xlabel('initial rate |omega_body_eci_body| [deg/s]')
    ax2.set_ylabel('success rate [%]')
    ax2.grid(True)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---------------------------------------------------------------------- command line
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``adcs montecarlo`` arguments to ``parser``."""
    parser.add_argument('scenario', help='base scenario YAML (closed loop, e.g. '
                        'scenarios/paper000_control.yaml)')
    parser.add_argument('--runs', type=int, required=True, metavar='N', help='number of runs')
    parser.add_argument('--jobs', type=int, default=1, metavar='J',
                        help='runs at once on this machine, each in its own processes '
                        '(default 1; ignored with --scheduler)')
    parser.add_argument('--scheduler', metavar='ADDRESS',
                        help='submit the runs to this Dask distributed scheduler '
                        '(e.g. tcp://host:8786); --out must be on a shared file system')
    parser.add_argument('--out', metavar='DIR', help='campaign directory (default '
                        'montecarlo_<scenario name>); an existing campaign there is resumed')
    parser.add_argument('--duration', type=float, metavar='S',
                        help='simulated seconds per run (default: the scenario duration_s)')
    parser.add_argument('--seed', type=int, metavar='S',
                        help='campaign seed (default: the scenario seed)')
    parser.add_argument('--max-rate-deg-s', type=float, default=3.0, metavar='W',
                        help='each initial rate component uniform in +-W deg/s (default 3)')
    parser.add_argument('--capture-deg', type=float, default=5.0, metavar='A',
                        help='captured when the angle to the orbit frame stays below A deg '
                        '(default 5)')
    parser.add_argument('--mag-bias-nT', type=float, default=120.0, metavar='B',
                        help='magnetometer bias per axis uniform in +-B nT (default 120)')
    parser.add_argument('--misalignment-deg', type=float, default=1.0, metavar='M',
                        help='magnetometer misalignment rotation vector per component '
                        'uniform in +-M deg (default 1)')
    parser.add_argument('--compose', action='store_true',
                        help='each run composed in one process (faster, same trajectory)')


def config_from_args(args: argparse.Namespace) -> tuple:
    """Validate the arguments; returns ``(CampaignConfig, base scenario, out dir)``.

    Raises
    ------
    CampaignError, adcs_nodes.tools.scenario.ScenarioError
        On a bad value or scenario.
    """
    from adcs_nodes.tools.scenario import load_scenario

    base = load_scenario(args.scenario)
    if args.runs < 1:
        raise CampaignError(f'--runs must be >= 1, got {args.runs}')
    if args.jobs < 1:
        raise CampaignError(f'--jobs must be >= 1, got {args.jobs}')
    for name in ('max_rate_deg_s', 'mag_bias_nT', 'misalignment_deg'):
        value = getattr(args, name)
        if not (math.isfinite(value) and value >= 0.0):
            raise CampaignError(f'--{name.replace("_", "-")} must be >= 0, got {value}')
    if not (math.isfinite(args.capture_deg) and 0.0 < args.capture_deg <= 180.0):
        raise CampaignError(f'--capture-deg must be in (0, 180], got {args.capture_deg}')
    duration = float(args.duration if args.duration is not None else base['duration_s'])
    frames = duration / base['timing']['frame_s']
    if not duration > 0 or abs(frames - round(frames)) > 1e-9:
        raise CampaignError(f'--duration {duration:g} s is not a positive whole number of '
                            f'{base["timing"]["frame_s"]:g} s frames')
    cfg = CampaignConfig(
        scenario_path=base['_path'], scenario_sha256=scenario_hash(base), runs=args.runs,
        seed=int(args.seed if args.seed is not None else base['seed']), duration_s=duration,
        max_rate_deg_s=args.max_rate_deg_s, capture_deg=args.capture_deg,
        mag_bias_nT=args.mag_bias_nT, misalignment_deg=args.misalignment_deg,
        compose=bool(args.compose))
    out = args.out or f'montecarlo_{base["name"]}'
    return cfg, base, out


def run_from_args(args: argparse.Namespace) -> int:
    """``adcs montecarlo``: run or resume a campaign; returns the exit code."""
    from adcs_nodes.tools.scenario import ScenarioError

    try:
        cfg, base, out = config_from_args(args)
        campaign = Campaign(cfg, base, out, log=lambda text: print(text, flush=True))
        mode = (f'on the Dask scheduler {args.scheduler}' if args.scheduler
                else f'{args.jobs} at a time')
        print(f'[montecarlo] {cfg.runs} runs of {base["name"]} ({cfg.duration_s:g} s each, '
              f'seed {cfg.seed}) {mode}, output in {campaign.out}', flush=True)
        return campaign.run(jobs=args.jobs, scheduler=args.scheduler)
    except (CampaignError, ScenarioError) as exc:
        print(f'adcs montecarlo: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('adcs montecarlo: interrupted (finished runs are kept)', file=sys.stderr)
        return 130


def main(argv: Optional[List[str]] = None) -> int:
    """``python -m adcs_nodes.tools.montecarlo``: the campaign command, or one run's process.

    ``_worker RUN_DIR`` is the internal per-run entry point used by :func:`execute_run`.
    """
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ['_worker'] and len(argv) == 2:
        return _worker_main(argv[1])
    parser = argparse.ArgumentParser(prog='adcs montecarlo',
                                     description='Dispersed Monte Carlo campaign.')
    add_arguments(parser)
    return run_from_args(parser.parse_args(argv))


if __name__ == '__main__':
    # run the imported module, not __main__, so Dask pickles execute_run by reference
    from adcs_nodes.tools.montecarlo import main as _module_main
    raise SystemExit(_module_main())
