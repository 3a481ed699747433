"""The launcher behind ``adcs run``: start the scenario's graph, watch it, stop it cleanly.

* Isolation: each run takes a free ``ROS_DOMAIN_ID`` drawn at random from
  :data:`RUN_DOMAINS` (claimed with a lock file in a per-user directory, opened with
  ``O_NOFOLLOW``, so parallel runs of one user never share one) and localhost-only discovery.
  Isolation is not a security boundary: ``docs/security.md``.
* One process per node (``python -m <module> --ros-args -r __node:=<name> --params-file ...``),
  or all nodes in one process (``--compose``, :mod:`adcs_nodes.tools.run.compose`).
* Lifecycle: the managed nodes (estimator, controllers, manager, guidance;
  :data:`adcs_nodes.tools.run.launch_graph.MANAGED_CLASSES`) start with ``autostart: false``;
  the launcher calls ``configure`` then ``activate`` on each through its standard
  ``/<node>/change_state`` service, all nodes in parallel, each as soon as its service is
  there (no fixed sleep), within :data:`LIFECYCLE_DEADLINE_S`. A failed configure stops the
  run with exit code 2 and the node's reason (its ``configuration error:`` log line). The
  start handshake counts a managed node ready only once it is active. ``--compose`` drives
  the same transitions in process (:mod:`adcs_nodes.tools.run.compose`).
* Progress: sim time, real-time factor, frames/s and missed frames, read from
  ``lockstep/status`` by a small monitor node in the launcher process.
* End: the clock master (dynamics) exits 0 after the last frame; the launcher waits until the
  recorder has seen the final clock, then stops every child with SIGINT (SIGKILL after a grace
  period). An essential child (world, recorder) that dies first stops the run with a message
  naming it and the tail of its log; a flight-software node that dies is reported and the run
  goes on (its consumers time out and fall back). A configuration error (exit code 2) of any
  node stops the run.
* Ctrl-C stops every child the same way; the bag is closed and valid.
* Crash safety: every child gets a parent-death signal (``prctl(PR_SET_PDEATHSIG, SIGTERM)``
  set before it executes the node, :data:`PDEATHSIG_SHIM`), so a launcher killed with SIGKILL
  takes its nodes with it (the recorder closes its bag on SIGTERM). A full disk (``ENOSPC``)
  stops the run with a message saying so; what was written is kept.
* Self-healing before frame 0 (one process per node): a node whose expected endpoints stay
  unmatched for :data:`HEAL_WAIT_S` while every other node of the handshake is ready, or a
  managed node whose lifecycle requests go unanswered for :data:`HEAL_UNANSWERED_S`, is
  stopped and started again (at most :data:`MAX_RESTARTS` times; nothing has happened yet,
  so the run stays deterministic). A consumer that already locked the restarted node's
  publisher identity is restarted with it, and the clock master too when a node that had
  said ready is restarted. Each restart is logged and counted in the run summary; a node
  stuck again after its restart fails the run with the reason (:func:`heal_decision`).
* Privacy: the run directory (logs, parameters) and the manifests are readable by the owner
  only (0700 / 0600); ``~/.cache/adcs/runs`` keeps the last :data:`KEEP_RUNS` run directories.
* While a run is active, ``~/.cache/adcs/runs/active-<pid>.json`` names its domain, run
  directory, bag and node PIDs (for ``adcs switch``/``adcs status`` and the tests).
"""
from __future__ import annotations

import errno
import fcntl
import glob
import json
import math
import os
import random
import re
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from typing import Any, Dict, Iterable, List, Optional, Tuple

import yaml

from adcs_nodes.graph import NodeSpec, build_graph, params_file_text
from adcs_nodes.tools.run.launch_graph import is_managed

#: Run directories and active-run manifests: ``$ADCS_RUNS_DIR`` when set (the test suite sets
#: its own temporary directory), else ``~/.cache/adcs/runs``.
RUNS_DIR = os.environ.get('ADCS_RUNS_DIR') or os.path.join(os.path.expanduser('~'), '.cache',
                                                           'adcs', 'runs')
#: ``ROS_DOMAIN_ID`` values a run draws from (at random among the free ones). Fast DDS over
#: UDP accepts 0..232; 0 is everybody's default domain; 100..199 are used without a lock by
#: the node tests and claimed by the bench rings; 102..214 put the DDS ports inside Linux's
#: ephemeral port range (32768-60999), where the OS may hand them to another socket. Left:
#: 1..99 and 215..232 (117 ids).
RUN_DOMAINS = tuple(range(1, 100)) + tuple(range(215, 233))
#: Run directories kept in ``RUNS_DIR`` (older ones are removed when a run starts).
KEEP_RUNS = 50
#: Scenario names allowed in run directory names (no path separators, no ``..`` escape).
NAME_PATTERN = re.compile(r'[A-Za-z0-9_.-]+')
#: Run directory names made by :class:`Launcher` (only these are pruned).
RUN_DIR_PATTERN = re.compile(r'\d{8}T\d{6}-[A-Za-z0-9_.-]+-\d+')
#: Exit code of the recorder after a write error (``recorder.EXIT_WRITE_FAILED``).
RECORDER_WRITE_FAILED = 3
#: Exit code of ``adcs run`` for a run that completed but lost its controller or estimator for
#: part of the time (a flight-software node died, or the controller manager fell back).
EXIT_DEGRADED = 3
#: Run via ``python -S -c``: sets the parent-death signal, checks the parent is still the
#: launcher (it may have died between fork and prctl), then executes the node command. A
#: separate tiny process image instead of ``preexec_fn``, which is unsafe in a launcher whose
#: DDS threads run while it forks.
PDEATHSIG_SHIM = (
    'import ctypes, os, signal, sys\n'
    'libc = ctypes.CDLL(None, use_errno=True)\n'
    'if libc.prctl(1, int(signal.SIGTERM), 0, 0, 0) != 0:\n'   # 1 = PR_SET_PDEATHSIG
    '    sys.exit("prctl(PR_SET_PDEATHSIG) failed: errno %d" % ctypes.get_errno())\n'
    'if os.getppid() != int(sys.argv[1]):\n'
    '    sys.exit(0)\n'  # the launcher died before prctl: do not start an orphan
    'os.execv(sys.argv[2], sys.argv[2:])\n')
#: Wall seconds without sim progress before the launcher says the run is stalled.
STALL_NOTICE_S = 30.0
#: Nodes whose death ends the run: the simulated world, the recorder, the composed process.
#: Any other node (flight software) may die; the run goes on and its consumers fall back.
ESSENTIAL = {'dynamics', 'environment', 'recorder', 'composed'}
#: Wall-clock limit for a managed node to become active after it was started [s]: process
#: start (imports), service discovery, configure (parameters, core, endpoints), activate.
#: The clock master's own start limit (``start_timeout_s``) is the same.
LIFECYCLE_DEADLINE_S = 120.0
#: Self-healing (issue 20): wall seconds a node's handshake may wait for its endpoints (its
#: ``still waiting for endpoints after N s`` log line) while every other node is ready,
#: before it is restarted.
HEAL_WAIT_S = 30.0
#: ... seconds a managed node's lifecycle requests (change_state, get_state) may go
#: unanswered before it is restarted (a lost answer is asked again after 5 s).
HEAL_UNANSWERED_S = 30.0
#: A node that used at least this much CPU time [s] over :data:`HEAL_BUSY_WINDOW_S` while
#: its lifecycle requests went unanswered is busy (configuring, compiling a kernel), not
#: stuck: it is given another :data:`HEAL_UNANSWERED_S` instead of a restart.
HEAL_BUSY_CPU_S = 1.0
HEAL_BUSY_WINDOW_S = 10.0
#: Restarts per node before frame 0; a node stuck again after them fails the run.
MAX_RESTARTS = 1
#: The clock master's start limit (``start_timeout_s``) in a launched run: the launcher's own
#: deadlines (lifecycle, restarts) end a stuck start first and say why.
START_TIMEOUT_S = 180.0
#: Test only: ``<node>[@<starts>]:<ros args>[;...]`` appended to that node's command (e.g.
#: ``guidance:-r /clock:=/nowhere``: a node that never matches; ``guidance@1:...``: only its
#: first process), to test the self-healing.
TEST_NODE_ARGS_ENV = 'ADCS_TEST_NODE_ROS_ARGS'
_WAITING = re.compile(r'still waiting for endpoints after ([0-9.]+) s: (.*)')


def external_devices(sc: Dict[str, Any]) -> List[str]:
    """One line per sensor the scenario marks ``external``: no simulated node, a driver."""
    from adcs_nodes import registry
    out = []
    for name, cfg in sc.get('sensors', {}).items():
        if cfg.get('external'):
            entry = registry.get('sensor', name)
            out.append(f'external {name}: no simulated node; expecting a driver publishing '
                       f'{entry.node[3]} ({entry.node[4]}) on ROS_DOMAIN_ID of this run '
                       '(docs/topics.md); frame 0 waits until its publisher is matched (at '
                       'most 60 s)')
    return out


_SUMMARY = re.compile(r'\[([A-Za-z0-9_./]+)\]: run summary (\{.*\})\s*$', re.M)


def node_summaries(run_dir: str) -> Dict[str, Dict[str, Any]]:
    """Each flight-software node's run summary (the JSON it logs at its last frame,
    ``LockstepNode.run_summary``), by node name, from the run's logs (either deployment)."""
    out: Dict[str, Dict[str, Any]] = {}
    for path in sorted(glob.glob(os.path.join(run_dir, 'logs', '*.log'))):
        try:
            with open(path, encoding='utf-8', errors='replace') as fh:
                text = fh.read()
        except OSError:
            continue
        for m in _SUMMARY.finditer(text):
            try:
                out[m.group(1).rsplit('.', 1)[-1]] = json.loads(m.group(2))
            except ValueError:
                continue
    return out


def summary_lines(summaries: Dict[str, Dict[str, Any]]) -> List[str]:
    """One line per node with inputs: samples used per topic, rejected by reason,
    superseded, filter resets (issue 23)."""
    lines = []
    for name, s in sorted(summaries.items()):
        used = s.get('samples_used') or {}
        if not used and not s.get('rejected') and not s.get('starved'):
            continue
        rejected = ', '.join(f'{r} {n}' for r, n in sorted(s.get('rejected', {}).items()))
        lines.append(f'{name}: samples used ' + (', '.join(
            f'{t} {n}' for t, n in sorted(used.items())) or 'none')
            + f'; rejected {rejected or "none"}; superseded {s.get("superseded", 0)}'
            + ('' if s.get('resets') is None else f'; filter resets {s["resets"]}'))
    return lines


def starved_text(summaries: Dict[str, Dict[str, Any]]) -> str:
    """The degraded reason of the nodes that got nothing usable from a topic for too long
    ('' if none)."""
    return '; '.join(
        f'{name} got nothing usable from {topic} (external or sample-timed input) for '
        f'{e["frames"]} of its frames from sim t = {e["since_s"]:g} s'
        for name, s in sorted(summaries.items())
        for topic, e in sorted((s.get('starved') or {}).items()))


def heal_decision(expected: List[str], ready: Iterable[str], waiting: Dict[str, Tuple[float, str]],
                  master: str, restarts: Dict[str, int], guards: Dict[str, List[str]],
                  wait_s: float = HEAL_WAIT_S, max_restarts: int = MAX_RESTARTS):
    """Which nodes to restart before frame 0, from the start handshake's state.

    ``expected``: the nodes that say ``lockstep/ready`` (the clock master among them);
    ``ready``: those that did; ``waiting``: per node, ``(seconds, unmatched)`` of its last
    ``still waiting for endpoints`` line; ``restarts``: restarts so far per node; ``guards``:
    per node, the nodes that accept its messages only from its publisher identity.

    Nothing is decided while a node that is not ready has not waited ``wait_s`` for its
    endpoints (it is starting, or being configured): a node is restarted only when its
    expected endpoints stay unmatched after all its peers matched. Of the nodes stuck, the
    clock master is restarted only when it is the only one (its missing matches are
    otherwise those of the others).

    Returns None, ``('restart', [(node, reason), ...])``, or ``('fail', node, reason)`` for
    a node stuck again after ``max_restarts`` restarts.
    """
    ready = set(ready)
    unready = [n for n in expected if n not in ready]
    if not unready or any(waiting.get(n, (0.0, ''))[0] < wait_s for n in unready):
        return None
    targets = [n for n in unready if n != master] or [master]
    for name in targets:
        if restarts.get(name, 0) >= max_restarts:
            return ('fail', name, f'node {name} still has unmatched endpoints after '
                    f'{restarts.get(name, 0)} restart(s) before frame 0: {waiting[name][1]}')
    return ('restart', restart_plan(
        [(n, f'its endpoints stayed unmatched for {waiting[n][0]:g} s while every other '
          f'node was ready: {waiting[n][1]}') for n in targets], ready, master, guards))


def restart_plan(targets: List[Tuple[str, str]], ready: Iterable[str], master: str,
                 guards: Dict[str, List[str]]) -> List[Tuple[str, str]]:
    """``targets`` ``(node, reason)`` and the nodes to restart with them: each ready consumer
    that accepts a target's messages only from the publisher identity it locked at its
    handshake (it would refuse the new process), and the clock master when a node that had
    said ready is restarted (the master must wait for its new ready)."""
    ready = set(ready)
    out = list(targets)
    names = {n for n, _ in targets}
    for name, _ in targets:
        for guard in guards.get(name, []):
            if guard in ready and guard not in names:
                names.add(guard)
                out.append((guard, f'it accepts {name}\'s messages only from the publisher it '
                            'locked at its handshake (the old process)'))
    if master not in names and names & ready:
        out.append((master, 'a node that had said ready is restarted: the clock master must '
                    'wait for its new ready'))
    return out


def _cpu_seconds(pid: int) -> Optional[float]:
    """CPU time (user + system) of process ``pid`` [s], None if it cannot be read."""
    try:
        with open(f'/proc/{pid}/stat', 'rb') as fh:
            fields = fh.read().rsplit(b')', 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    except (OSError, ValueError, IndexError):
        return None


class LaunchError(RuntimeError):
    """The graph could not be started or a node failed; the message says which and why."""


#: The largest ``--rate`` [sim seconds per wall second].
MAX_RATE = 1e6


def check_rate(rate: float) -> float:
    """``rate`` if it is a ``--rate`` (finite, in (0, :data:`MAX_RATE`]), else LaunchError."""
    if not (math.isfinite(rate) and 0 < rate <= MAX_RATE):
        raise LaunchError(f'--rate must be in (0, 1e6] sim seconds per wall second, '
                          f'got {rate:g}')
    return float(rate)


def pace(rate: Optional[float], real_time: bool) -> Tuple[float, float]:
    """``adcs run``'s ``--rate`` as the launcher's ``(rate_factor, max_rate)``: with
    ``--real-time`` the sim seconds per wall second (default 1), without it the lockstep's
    pace limit (default 0: none). A rate outside (0, :data:`MAX_RATE`] is a LaunchError."""
    if rate is not None:
        check_rate(rate)
    if real_time:
        return (1.0 if rate is None else float(rate)), 0.0
    return 1.0, (0.0 if rate is None else float(rate))


@dataclass
class RunResult:
    """Outcome of a run."""

    exit_code: int
    sim_time_s: float
    wall_time_s: float
    frames: int
    missed_frames: int
    bag: Optional[str]
    run_dir: str
    message: str
    #: lockstep throughput measured by the clock master from frame 0 to its end [frames/s]
    frames_per_s: float = 0.0
    #: nodes restarted before frame 0 (self-healing), per node
    restarts: Optional[Dict[str, int]] = None


def _private_dir(path: str) -> str:
    """Create ``path`` (mode 0700) or check an existing one: a real directory (not a symlink)
    owned by this user and not writable by others; ``LaunchError`` otherwise."""
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
        st = os.lstat(path)
    except OSError as exc:
        raise LaunchError(f'cannot create {path}: {exc.strerror or exc}') from None
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid():
        raise LaunchError(f'{path} is not a directory owned by you (a symlink planted by '
                          'someone else?); remove it')
    if st.st_mode & 0o077:
        os.chmod(path, 0o700)
    return path


def domain_lock_dir() -> str:
    """Per-user directory of the domain lock files: ``$XDG_RUNTIME_DIR/adcs-domain-locks``,
    else ``<tmp>/adcs-domain-locks-<uid>`` (created 0700, ownership checked)."""
    runtime = os.environ.get('XDG_RUNTIME_DIR', '')
    if runtime and os.path.isabs(runtime) and os.path.isdir(runtime):
        return os.path.join(runtime, 'adcs-domain-locks')
    return os.path.join(tempfile.gettempdir(), f'adcs-domain-locks-{os.getuid()}')


def acquire_domain(domains: Iterable[int] = RUN_DOMAINS):
    """Claim a free ROS_DOMAIN_ID of ``domains``, drawn at random, with an exclusive lock file.

    The lock files live in :func:`domain_lock_dir` and are opened with ``O_NOFOLLOW`` and
    without truncation: a symlink planted in their place is refused, never followed.
    Returns ``(id, handle)``; the domain stays claimed until the handle is closed.
    """
    lock_dir = _private_dir(domain_lock_dir())
    ids = list(domains)
    random.shuffle(ids)
    for dom in ids:
        try:
            fd = os.open(os.path.join(lock_dir, f'{dom}.lock'),
                         os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
        except OSError:
            continue  # ELOOP: a symlink in place of the lock file; not ours to use
        fh = os.fdopen(fd, 'r+')
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.close()
            continue
        return dom, fh
    raise LaunchError(f'no free ROS_DOMAIN_ID among {len(ids)} ({len(ids)} runs at once?)')


def prune_runs(runs_dir: str = RUNS_DIR, keep: int = KEEP_RUNS,
               protect: Iterable[str] = ()) -> List[str]:
    """Remove the oldest run directories of ``runs_dir`` beyond the newest ``keep``.

    Only directories named like the launcher's (``<time>-<scenario>-<pid>``) are touched, and
    never one in ``protect`` or one of a run whose launcher is alive (its manifest). Returns
    the removed paths.
    """
    try:
        names = [n for n in os.listdir(runs_dir) if RUN_DIR_PATTERN.fullmatch(n)]
    except OSError:
        return []
    busy = {os.path.abspath(p) for p in protect}
    for name in os.listdir(runs_dir):
        if name.startswith('active-') and name.endswith('.json'):
            try:
                with open(os.path.join(runs_dir, name)) as fh:
                    data = json.load(fh)
                os.kill(int(data['pid']), 0)   # a manifest left by a killed launcher: stale
                busy.add(os.path.abspath(data['run_dir']))
            except (OSError, ValueError, KeyError, TypeError):
                continue
    dirs = []
    for name in names:
        path = os.path.join(runs_dir, name)
        try:
            st = os.lstat(path)
        except OSError:
            continue
        if stat.S_ISDIR(st.st_mode):
            dirs.append((st.st_mtime, name, path))
    dirs.sort(reverse=True)
    removed = []
    for _, _, path in dirs[keep:]:
        if os.path.abspath(path) in busy:
            continue
        shutil.rmtree(path, ignore_errors=True)
        removed.append(path)
    return removed


def _write_private(path: str, text: str) -> None:
    """Write ``text`` to ``path`` readable by the owner only (0600), replacing it atomically."""
    tmp = f'{path}.tmp{os.getpid()}'
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW | os.O_CLOEXEC,
                 0o600)
    try:
        with os.fdopen(fd, 'w') as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _disk_full(exc: OSError) -> bool:
    return exc.errno in (errno.ENOSPC, errno.EDQUOT)


#: Fast DDS defaults of every process of a run (UDP only with 4 MiB socket buffers, a 50 ms
#: writer heartbeat): docs/reliability.md, "Reliable samples under load".
FASTDDS_PROFILES = os.path.join(
    os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), 'config',
    'fastdds_profiles.xml')
#: The middleware settings of a run: :func:`child_env` sets them, :func:`use_dds_env` copies
#: them into the calling process (its own rclpy node: the launcher's monitor, ``adcs switch``).
DDS_ENV_KEYS = ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE', 'FASTDDS_BUILTIN_TRANSPORTS',
                'FASTDDS_DEFAULT_PROFILES_FILE')


def child_env(domain: int) -> Dict[str, str]:
    """Environment of every child: the run's domain, localhost discovery, unbuffered output,
    the project's Fast DDS profile (unless the user set a profiles file of their own)."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    # UDP on loopback only, set by the profile (docs/decisions.md): FASTDDS_BUILTIN_TRANSPORTS
    # would change nothing (the profile declares its transport; with LOCALHOST rmw_fastrtps
    # chooses its own)
    env.update(profile_env(env))
    if env.get('FASTDDS_DEFAULT_PROFILES_FILE') == FASTDDS_PROFILES:
        # the profile binds discovery and traffic to loopback itself; with LOCALHOST
        # rmw_fastrtps would replace its transports by UDP plus shared memory, whose ports
        # every run on the host shares (docs/reliability.md, "Shared memory between runs")
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'SYSTEM_DEFAULT'
    if env.get('FASTDDS_DEFAULT_PROFILES_FILE') == '':   # "no file": Fast DDS would log an
        del env['FASTDDS_DEFAULT_PROFILES_FILE']         # error for the empty path
    return env


def profile_env(environ) -> Dict[str, str]:
    """``{'FASTDDS_DEFAULT_PROFILES_FILE': FASTDDS_PROFILES}``, or ``{}`` when ``environ``
    names a profiles file of the user's own (an empty value too: Fast DDS then loads none)."""
    if 'FASTDDS_DEFAULT_PROFILES_FILE' in environ or 'FASTRTPS_DEFAULT_PROFILES_FILE' in environ:
        return {}
    return {'FASTDDS_DEFAULT_PROFILES_FILE': FASTDDS_PROFILES}


def use_dds_env(env: Dict[str, str]) -> None:
    """Give this process the run's middleware settings (:data:`DDS_ENV_KEYS` of ``env``);
    before its first rclpy node, since Fast DDS reads its profiles file once per process."""
    for key in DDS_ENV_KEYS:
        if key in env:
            os.environ[key] = env[key]
        else:
            os.environ.pop(key, None)


class _Monitor:
    """Launcher-side rclpy node: progress from lockstep/status and recorder/status.

    It reads no topic that a node of the graph reads (issue 13): a subscriber of ``/clock``
    (or of ``lockstep/progress``) in another process sends that topic over DDS also in composed
    mode, off the composed runner's in-process path, and the mix of the two paths ran at a
    fifth of the speed (the clock master waited for progress messages stuck behind the
    in-process deliveries). ``lockstep/status`` (stamped with the sim time of a node's last
    frame) gives the sim time reached and that the lockstep started; a content filter keeps it
    to the clock master's and to those reporting missed frames. Nodes skip the statuses this
    filter would drop when the monitor is their only reader, and the clock master sends its
    own to the monitor alone at most every ``MONITOR_STATUS_WALL_S`` (0.1 s) of wall time
    (``nodes/lockstep_node.py``); final statuses and missed frames are never held back.
    """

    def __init__(self, epoch_ns: int, watch_ready: bool = False) -> None:
        import rclpy
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from adcs_msgs.msg import LockstepStatus
        from adcs_nodes.nodes.convert import stamp_ns
        from adcs_nodes.nodes.lockstep_node import MONITOR_NODE, MONITOR_STATUS_OF
        from adcs_nodes.nodes.runtime import make_executor

        self._rclpy = rclpy
        self._stamp_ns = stamp_ns
        self.epoch_ns = epoch_ns
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        # the nodes skip the statuses this filter would drop (LockstepNode._status_wanted)
        self.node = rclpy.create_node(MONITOR_NODE, context=self.context,
                                      start_parameter_services=False)
        self.sim_ns = 0
        self.clock_seen = False     # the lockstep has started (a node reported a frame)
        self.status: Dict[str, LockstepStatus] = {}
        self.recorder_clock_ns = -1
        self.recorder_count = 0
        self.recorder_statuses = 0        # recorder/status messages received
        self.recorder_error = ''
        self.recorder_lost = 0            # messages the middleware reported lost to the bag
        self.recorder_lost_topic = ''
        # a DDS content filter (evaluated by the writers where the middleware can): only the
        # clock master's statuses (sim time) and those with missed frames reach this process,
        # not every node's status of every sim second; unfiltered if rclpy cannot
        status_filter = None
        try:
            from rclpy.subscription_content_filter_options import ContentFilterOptions
            status_filter = ContentFilterOptions(
                filter_expression='node = %0 OR missed_frames > 0',
                expression_parameters=[f"'{MONITOR_STATUS_OF}'"])
        except ImportError:
            pass
        try:
            self.node.create_subscription(LockstepStatus, 'lockstep/status',
                                          self._on_status_msg, 50,
                                          content_filter_options=status_filter)
        except Exception:      # a middleware that refuses the filter: take every status
            self.node.create_subscription(LockstepStatus, 'lockstep/status',
                                          self._on_status_msg, 50)
        self.node.create_subscription(LockstepStatus, 'recorder/status', self._on_rec, 10)
        #: nodes that said ``lockstep/ready`` (one process per node: the self-healing)
        self.ready: set = set()
        if watch_ready:
            from std_msgs.msg import String

            from adcs_nodes.nodes.lockstep_node import QOS_READY
            self.node.create_subscription(String, 'lockstep/ready',
                                          lambda m: self.ready.add(m.data), QOS_READY)
        # degraded-run accounting (H-lockstep): the manager's latched status, max missed/node
        from rclpy.qos import DurabilityPolicy

        from adcs_msgs.msg import ControllerStatus
        self.controller_status = None
        self.max_missed: Dict[str, int] = {}
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(ControllerStatus, 'adcs/controller_status',
                                      self._on_controller_status, latched)
        self.executor = make_executor(self.context)
        self.executor.add_node(self.node)

    def _on_status_msg(self, msg) -> None:
        """``lockstep/status``: missed frames, and the sim time of the node's last frame
        (a status with no frame processed yet is the start-up watchdog's)."""
        self._on_status(msg)
        if msg.frames > 0:
            self.clock_seen = True
            self.sim_ns = max(self.sim_ns, self._stamp_ns(msg.header.stamp) - self.epoch_ns)

    def _on_status(self, msg) -> None:
        self.status[msg.node] = msg
        self.max_missed[msg.node] = max(int(msg.missed_frames),
                                        self.max_missed.get(msg.node, 0))

    def _on_controller_status(self, msg) -> None:
        self.controller_status = msg

    def _on_rec(self, msg) -> None:
        self.recorder_clock_ns = self._stamp_ns(msg.header.stamp) - self.epoch_ns
        self.recorder_count = int(msg.frames)
        self.recorder_statuses += 1
        if msg.last_missed_input.startswith('write failed: '):
            self.recorder_error = msg.last_missed_input[len('write failed: '):]
        elif msg.missed_frames > self.recorder_lost:
            self.recorder_lost = int(msg.missed_frames)
            self.recorder_lost_topic = msg.last_missed_input

    def spin(self, seconds: float) -> None:
        from rclpy.task import Future
        self.executor.spin_until_future_complete(Future(), timeout_sec=seconds)

    def wait_recorder_settled(self, deadline: float) -> bool:
        """Spin until two recorder statuses in a row carry the same message count (the bag
        has every message published so far), or until ``deadline`` (monotonic); True if
        settled. Once the graph stops, the recorder's statuses come from its wall timer only
        (``status_period_s``, 0.5 s): a count that did not grow between two of them means its
        queues are empty. Waiting a fixed 0.3 s for the count to change could end between two
        statuses while the recorder was still writing."""
        seen, last = self.recorder_statuses, None
        while time.monotonic() < deadline:
            self.spin(0.1)
            if self.recorder_statuses != seen:
                seen = self.recorder_statuses
                if self.recorder_count == last:
                    return True
                last = self.recorder_count
        return False

    @property
    def missed_frames(self) -> int:
        """Missed frames of every node (the highest count each one reported)."""
        return sum(self.max_missed.values())

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.node.destroy_node()
        self.executor.shutdown()
        self._rclpy.shutdown(context=self.context)


class _Transitions:
    """Drives ``configure`` then ``activate`` of the managed nodes through their standard
    ``/<node>/change_state`` services (``lifecycle_msgs/srv/ChangeState``).

    Non-blocking: :meth:`poll` (called by the launcher's watch loop) sends ``configure`` to
    each node whose service has appeared; the answer's callback sends ``activate`` at once.

    A service answer can be lost: under load Fast DDS may not have matched the server's
    reply writer to the client's reply reader yet, and the node logs "failed to send
    response (timeout)" after doing the transition. So a request unanswered for
    :data:`RESEND_S` is followed by ``/<node>/get_state``, and the node's actual state says
    what to send next (a transition is never sent twice to a node that did it). Late or
    superseded answers are ignored.
    """

    #: seconds without an answer before the node's state is asked
    RESEND_S = 5.0

    def __init__(self, node, names: List[str], deadline_s: float = LIFECYCLE_DEADLINE_S):
        from lifecycle_msgs.msg import State, Transition
        from lifecycle_msgs.srv import ChangeState, GetState

        self._srv = ChangeState
        self._get_srv = GetState
        self._ids = {'configure': Transition.TRANSITION_CONFIGURE,
                     'activate': Transition.TRANSITION_ACTIVATE}
        #: primary state id -> the transition due next ('' once active)
        self._next = {State.PRIMARY_STATE_UNCONFIGURED: 'configure',
                      State.PRIMARY_STATE_INACTIVE: 'activate',
                      State.PRIMARY_STATE_ACTIVE: ''}
        self._node = node
        self.clients = {n: node.create_client(ChangeState, f'/{n}/change_state')
                        for n in names}
        self._get_clients: Dict[str, object] = {}
        #: node -> 'starting' (no service yet), 'configure', 'activate' (awaiting the
        #: answer), 'get_state' (asking after a lost answer) or 'active'
        self.step = {n: 'starting' for n in names}
        self._sent_at: Dict[str, float] = {}
        self._token: Dict[str, int] = {n: 0 for n in names}
        self.resent: Dict[str, int] = {n: 0 for n in names}   # lost answers, per node
        self.failed: Dict[str, str] = {}     # node -> the transition it refused
        self.deadline = time.monotonic() + deadline_s
        self.deadline_s = deadline_s
        #: per node: its deadline (moved on by a restart), the last answer or first request
        self._deadlines: Dict[str, float] = {n: self.deadline for n in names}
        self._heard: Dict[str, float] = {}
        self.unanswered_s = math.inf         # (the launcher sets HEAL_UNANSWERED_S)

    def postpone(self, name: str, seconds: float) -> None:
        """Report ``name`` as unanswered again ``seconds`` from now (at the earliest)."""
        self._heard[name] = time.monotonic() - self.unanswered_s + seconds

    def reset(self, name: str) -> None:
        """Forget ``name``'s progress (its process was restarted): start again from
        'starting', late answers of the old process ignored, a full deadline."""
        self._token[name] += 1
        self.step[name] = 'starting'
        self._heard.pop(name, None)
        self._sent_at.pop(name, None)
        self._deadlines[name] = time.monotonic() + self.deadline_s

    @property
    def pending(self) -> bool:
        """True while a node is not active yet (and none failed)."""
        return not self.failed and any(s != 'active' for s in self.step.values())

    def poll(self) -> Optional[Tuple[str, str]]:
        """Send what is due. Returns ``(node, transition)`` of the first refused transition,
        ``(node, 'deadline')`` for a node not active in time, ``(node, 'unanswered')`` for a
        node whose requests got no answer for ``unanswered_s``, else None."""
        if self.failed:
            return next(iter(self.failed.items()))
        now = time.monotonic()
        for name, step in self.step.items():
            if step == 'starting' and self.clients[name].service_is_ready():
                self._call(name, 'configure')
                self._heard.setdefault(name, now)
            elif step not in ('starting', 'active') and \
                    now - self._sent_at[name] > self.RESEND_S:
                self.resent[name] += 1
                self._ask_state(name)
        late = [n for n, s in self.step.items() if s != 'active']
        for name in late:
            if now > self._deadlines[name]:
                return name, 'deadline'
        for name in late:
            if name in self._heard and now - self._heard[name] > self.unanswered_s:
                return name, 'unanswered'
        return None

    def _send(self, name: str, step: str, client, request, on_answer) -> None:
        self._token[name] += 1
        token = self._token[name]
        self.step[name] = step
        self._sent_at[name] = time.monotonic()
        future = client.call_async(request)
        future.add_done_callback(
            lambda f: on_answer(name, step, f) if self._token[name] == token else None)

    def _call(self, name: str, transition: str) -> None:
        request = self._srv.Request()
        request.transition.id = self._ids[transition]
        self._send(name, transition, self.clients[name], request, self._answered)

    def _ask_state(self, name: str) -> None:
        if name not in self._get_clients:
            self._get_clients[name] = self._node.create_client(self._get_srv,
                                                               f'/{name}/get_state')
        self._send(name, 'get_state', self._get_clients[name], self._get_srv.Request(),
                   self._state_answered)

    def _answered(self, name: str, transition: str, future) -> None:
        result = future.result() if not future.cancelled() else None
        self._heard[name] = time.monotonic()
        if result is None or not result.success:
            self.failed.setdefault(name, transition)
        elif transition == 'configure':
            self._call(name, 'activate')
        else:
            self.step[name] = 'active'

    def _state_answered(self, name: str, _step: str, future) -> None:
        result = future.result() if not future.cancelled() else None
        if result is not None:
            self._heard[name] = time.monotonic()
        due = self._next.get(result.current_state.id) if result is not None else None
        if due is None:          # no answer, or a transition still under way: ask again later
            return
        if due:
            self._call(name, due)
        else:
            self.step[name] = 'active'


class Launcher:
    """Start, watch and stop one scenario run (see module docstring)."""

    def __init__(self, scenario: dict, duration_s: Optional[float] = None,
                 record: Optional[str] = None, real_time: bool = False,
                 rate_factor: float = 1.0, compose: bool = False, progress: bool = True,
                 run_dir: Optional[str] = None, log=print,
                 domain: Optional[int] = None, max_rate: float = 0.0) -> None:
        self.sc = scenario
        if domain is not None and not (isinstance(domain, int) and 0 <= domain <= 232):
            raise LaunchError(f'--domain must be a ROS_DOMAIN_ID in 0..232, got {domain!r}')
        self.domain = domain     # None: a free one drawn at random (RUN_DOMAINS)
        self.duration_s = float(duration_s if duration_s is not None else scenario['duration_s'])
        if not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise LaunchError(f'duration must be a positive finite number of seconds, got '
                              f'{self.duration_s}')
        check_rate(rate_factor)
        if max_rate != 0.0:                      # (0: no pace)
            check_rate(max_rate)
        if not NAME_PATTERN.fullmatch(str(scenario.get('name', ''))):
            raise LaunchError(f'scenario name {str(scenario.get("name"))[:80]!r} must match '
                              f'{NAME_PATTERN.pattern} (it names the run directory)')
        from adcs_nodes.scenario import ScenarioError, check_epoch
        try:
            check_epoch(scenario.get('epoch', ''), self.duration_s)
        except ScenarioError as exc:
            raise LaunchError(str(exc)) from None
        frames = self.duration_s / scenario['timing']['frame_s']
        if abs(frames - round(frames)) > 1e-9:
            raise LaunchError(f'duration {self.duration_s} s is not a whole number of '
                              f'{scenario["timing"]["frame_s"]} s frames')
        self.record = os.path.abspath(record) if record else None
        if self.record and os.path.exists(self.record):
            raise LaunchError(f'bag {self.record} exists already; choose another --record path')
        self.real_time = real_time
        self.rate_factor = rate_factor
        # a paced frame may take long by request: a stall is a wait beyond it
        self.stall_notice_s = STALL_NOTICE_S + (
            scenario['timing']['frame_s'] / max_rate if max_rate > 0 else 0.0)
        self.compose = compose
        self.progress = progress
        self.log = log
        stamp = time.strftime('%Y%m%dT%H%M%S')
        self.run_dir = run_dir or os.path.join(RUNS_DIR, f'{stamp}-{scenario["name"]}-'
                                               f'{os.getpid()}')
        self.nodes: List[NodeSpec] = build_graph(scenario, self.duration_s, real_time,
                                                 rate_factor, record=bool(record),
                                                 max_rate=max_rate)
        if self.record:
            rec = next(n for n in self.nodes if n.name == 'recorder')
            rec.params['output'] = self.record
        self.result_file = os.path.join(self.run_dir, 'dynamics_result.json')
        next(n for n in self.nodes if n.name == 'dynamics').params['result_file'] = \
            self.result_file
        self.procs: Dict[str, subprocess.Popen] = {}
        from sim_node.faults import node_kills
        #: node_killed faults {node: fault}: the launcher SIGKILLs the process (graph runs)
        self.kills = node_kills(scenario.get('faults') or [])
        self.killed: set = set()
        self.lost: set = set()     # non-essential nodes that died during the run
        self.lost_at: Dict[str, float] = {}   # ... and the sim time they were seen dead [s]
        self._stop_requested = False
        #: self-healing: restarts per node, their log lines, each log's start offset
        self.restarts: Dict[str, int] = {}
        self.restart_notes: List[str] = []
        self._log_start: Dict[str, int] = {}
        self._spawn_count: Dict[str, int] = {}
        self._cpu_seen: Dict[str, float] = {}
        #: per node, the nodes that accept its messages only from its publisher identity
        self._guards: Dict[str, List[str]] = {}
        for node in self.nodes:
            for item in node.params.get('expected_publishers', []) or []:
                producer = str(item).rsplit('=', 1)[-1]
                self._guards.setdefault(producer, []).append(node.name)

    # ------------------------------------------------------------------ processes
    def _started_nodes(self) -> List[NodeSpec]:
        """The graph as started: the managed nodes with ``autostart: false`` (the launcher,
        or the composed process, drives their transitions)."""
        out = []
        for n in self.nodes:
            if is_managed(n):
                n = replace(n, params={**n.params, 'autostart': False})
            if n.name == 'dynamics' and not self.compose:
                n = replace(n, params={'start_timeout_s': START_TIMEOUT_S, **n.params})
            out.append(n)
        return out

    def _commands(self, params_path: str) -> Dict[str, List[str]]:
        if self.compose:
            spec = [f'{n.name}={n.module}:{n.cls}' for n in self.nodes]
            return {'composed': [sys.executable, '-m', 'adcs_nodes.tools.run.compose',
                                 '--params-file', params_path, '--nodes', *spec]}
        extra: Dict[str, List[str]] = {}
        for item in filter(None, os.environ.get(TEST_NODE_ARGS_ENV, '').split(';')):
            node, _, args = item.partition(':')
            node, _, starts = node.strip().partition('@')
            if not starts or self._spawn_count.get(node, 0) < int(starts):
                extra[node] = args.split()
        return {n.name: [sys.executable, '-m', n.module, '--ros-args', '-r',
                         f'__node:={n.name}', '--params-file', params_path]
                + extra.get(n.name, []) for n in self.nodes}

    def _spawn(self, env: Dict[str, str], params_path: str) -> None:
        logs = os.path.join(self.run_dir, 'logs')
        os.makedirs(logs, mode=0o700, exist_ok=True)
        self._env, self._params_path = env, params_path
        for name, cmd in self._commands(params_path).items():
            self._spawn_one(name, cmd, env)

    def _spawn_one(self, name: str, cmd: List[str], env: Dict[str, str],
                   note: str = '') -> None:
        """Start one node; its log is created, or appended to after ``note`` (a restart)."""
        shim = [sys.executable, '-S', '-c', PDEATHSIG_SHIM, str(os.getpid())]
        flags = os.O_WRONLY | os.O_CREAT | os.O_CLOEXEC | (os.O_APPEND if note else os.O_TRUNC)
        fd = os.open(os.path.join(self.run_dir, 'logs', f'{name}.log'), flags, 0o600)
        with os.fdopen(fd, 'w') as fh:
            if note:
                fh.write(f'\n----- {note} -----\n')
                fh.flush()
            self._log_start[name] = fh.tell()
            self._spawn_count[name] = self._spawn_count.get(name, 0) + 1
            # own session: a Ctrl-C in the terminal reaches the launcher only, which
            # stops the graph in order; the parent-death signal covers a killed launcher
            self.procs[name] = subprocess.Popen(shim + cmd, env=env, stdout=fh,
                                                stderr=subprocess.STDOUT,
                                                stdin=subprocess.DEVNULL,
                                                start_new_session=True)

    def _log_tail(self, name: str, lines: int = 15) -> str:
        path = os.path.join(self.run_dir, 'logs', f'{name}.log')
        try:
            with open(path, encoding='utf-8', errors='replace') as fh:
                return ''.join(fh.readlines()[-lines:])
        except OSError:
            return ''

    def _signal_and_wait(self, names: List[str], grace_s: float) -> None:
        """SIGINT the named children, wait up to ``grace_s``, SIGKILL what is left."""
        for name in names:
            proc = self.procs[name]
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGINT)
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + grace_s
        for name in names:
            proc = self.procs[name]
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                self.log(f'[adcs] {name} did not stop within {grace_s:g} s: killing it')
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                proc.wait()

    def _stop_all(self, monitor: Optional['_Monitor'] = None, grace_s: float = 10.0) -> None:
        """Stop every child: the graph first, then the recorder once it has written
        everything that was published (its message count stops growing), so an
        interrupted run loses no recorded data."""
        others = [n for n in self.procs if n != 'recorder']
        self._signal_and_wait(others, grace_s)
        if 'recorder' in self.procs:
            if monitor is not None and self.procs['recorder'].poll() is None:
                monitor.wait_recorder_settled(time.monotonic() + grace_s)
            self._signal_and_wait(['recorder'], grace_s)

    # ------------------------------------------------------------------ run
    def run(self) -> RunResult:
        """Run the scenario to its end (or Ctrl-C / a failed node); returns the outcome."""
        t0 = time.monotonic()
        try:
            _private_dir(RUNS_DIR)
            prune_runs(protect=[self.run_dir])
            _private_dir(self.run_dir)
            params_path = os.path.join(self.run_dir, 'params.yaml')
            _write_private(params_path, params_file_text(self._started_nodes()))
        except (OSError, LaunchError) as exc:
            why = ('disk full' if isinstance(exc, OSError) and _disk_full(exc)
                   else str(getattr(exc, 'strerror', None) or exc))
            return RunResult(1, 0.0, time.monotonic() - t0, 0, 0, None, self.run_dir,
                             f'cannot prepare the run directory {self.run_dir}: {why}')
        return self._run(params_path, t0)

    def _run(self, params_path: str, t0: float) -> RunResult:
        from adcs_nodes.nodes.lockstep_node import epoch_to_ns, parse_epoch

        try:
            domain, lock = acquire_domain(RUN_DOMAINS if self.domain is None
                                          else [self.domain])
        except LaunchError as exc:
            return RunResult(2, 0.0, time.monotonic() - t0, 0, 0, None, self.run_dir,
                             f'{exc} (another run holds it: give another --domain)')
        env = child_env(domain)
        use_dds_env(env)
        manifest = {'pid': os.getpid(), 'domain': domain, 'scenario': self.sc['_path'],
                    'epoch': self.sc['epoch'],
                    'bag': self.record, 'run_dir': self.run_dir, 'compose': self.compose}
        manifest_path = os.path.join(RUNS_DIR, f'active-{os.getpid()}.json')
        try:
            _write_private(manifest_path, json.dumps(manifest))
        except OSError as exc:
            lock.close()
            return RunResult(1, 0.0, time.monotonic() - t0, 0, 0, None, self.run_dir,
                             f'cannot write {manifest_path}: {exc.strerror or exc}')
        epoch_ns = epoch_to_ns(parse_epoch(self.sc['epoch']))
        monitor = _Monitor(epoch_ns, watch_ready=not self.compose)
        old_int = signal.signal(signal.SIGINT, self._on_signal)
        old_term = signal.signal(signal.SIGTERM, self._on_signal)
        self.log(f'[adcs] run {self.sc["name"]}: {len(self.nodes)} nodes '
                 f'({"composed in one process" if self.compose else "one process each"}), '
                 f'ROS_DOMAIN_ID={domain}, logs in {self.run_dir}/logs')
        lines = external_devices(self.sc)
        for line in lines:
            self.log(f'[adcs] {line}')
        if lines:      # what a driver needs to join this run's (private) domain
            self.log('[adcs] a driver joins with: ' + ' '.join(
                f'{k}={env[k]}' for k in DDS_ENV_KEYS if env.get(k)))
        code, message = 0, ''
        try:
            self._spawn(env, params_path)
            self._transitions = _Transitions(
                monitor.node, [] if self.compose else
                [n.name for n in self.nodes if is_managed(n)])
            self._transitions.unanswered_s = HEAL_UNANSWERED_S
            self._manifest, self._manifest_path = manifest, manifest_path
            manifest['pids'] = {name: proc.pid for name, proc in self.procs.items()}
            try:
                _write_private(manifest_path, json.dumps(manifest))
            except OSError as exc:  # the first manifest stands; status/switch lack the pids
                self.log(f'[adcs] WARNING: cannot update {manifest_path}: {exc.strerror}')
            code, message = self._watch(monitor, t0)
        except OSError as exc:   # a log file or the node processes could not be created
            code, message = 1, (f'cannot start the nodes: '
                                f'{"disk full" if _disk_full(exc) else exc.strerror or exc}')
        finally:
            self._stop_all(monitor)
            if self.progress:
                sys.stderr.write('\n')
            wall = time.monotonic() - t0
            sim_s = monitor.sim_ns / 1e9
            frames = int(round(sim_s / self.sc['timing']['frame_s']))
            missed = monitor.missed_frames
            fps = self._master_fps()
            if monitor.recorder_error and code == 0:
                code, message = 1, self._write_failed_message(monitor.recorder_error)
            refused = int(self._master_result('security_events'))
            if refused:
                message += (f'\n[adcs] security: dynamics refused {refused} lockstep messages '
                            'from an unexpected publisher or with a repeated stamp '
                            '(adcs/security_events in the bag; docs/security.md)')
            if monitor.recorder_lost:
                message += (f'\n[adcs] WARNING: the bag misses {monitor.recorder_lost} '
                            'message(s) that the middleware reported lost (last on '
                            f'{monitor.recorder_lost_topic}; docs/reliability.md)')
            if self.restarts:
                message += (f'\n[adcs] restarts: {sum(self.restarts.values())} before frame 0 '
                            f'(self-healing: ' + '; '.join(self.restart_notes) + ')')
            summaries = node_summaries(self.run_dir)
            degraded = '; '.join(d for d in (self._degraded(monitor), starved_text(summaries))
                                 if d)
            if degraded and code == 0:
                code, message = EXIT_DEGRADED, f'done, DEGRADED: {degraded}'
            elif degraded:
                message += f'\n[adcs] degraded: {degraded}'
            message += ''.join(f'\n[adcs] {line}' for line in summary_lines(summaries))
            monitor.close()
            signal.signal(signal.SIGINT, old_int)
            signal.signal(signal.SIGTERM, old_term)
            try:
                os.unlink(manifest_path)
            except OSError:
                pass
            lock.close()
            saved = self._save_scenario()
            if saved and code == 0:
                code, message = 1, saved
            elif saved:
                message += f'\n{saved}'
        return RunResult(code, sim_s, wall, frames, missed, self.record, self.run_dir, message,
                         fps, dict(self.restarts))

    def _kill_due(self, monitor: '_Monitor') -> None:
        """A ``node_killed`` fault (graph runs): SIGKILL the node's process once the run's
        clock has reached its time; the node went silent at that frame already
        (``LockstepNode._stops_at``), so the series do not depend on when the signal lands.
        Composed, the node only stops (one process for all)."""
        for name, f in self.kills.items():
            proc = self.procs.get(name)
            if self.compose or proc is None or name in self.killed \
                    or monitor.sim_ns < round(float(f['at_s']) * 1e9):
                continue
            self.killed.add(name)
            try:
                os.kill(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.log(f'[adcs] {name}: killed (SIGKILL) by the scenario\'s faults[{f["index"]}] '
                     f'at sim t = {float(f["at_s"]):g} s')

    def _degraded(self, monitor: '_Monitor') -> str:
        """Why the run lost its controller or estimator for part of the time ('' if not)."""
        from sim_node.faults import lost_text
        why = []
        kills = getattr(self, 'kills', {})
        lost = [f'{n} (died at sim t = {self.lost_at.get(n, 0.0):g} s)'
                for n in sorted(self.lost) if n not in kills]
        if kills:
            lost += lost_text(self.sc.get('faults') or [], monitor.sim_ns / 1e9)
        if lost:
            why.append('lost ' + ', '.join(lost))
        st = monitor.controller_status
        if st is not None and st.missed_frames > 0:
            why.append(f'the controller manager could not forward the active controller in '
                       f'{st.missed_frames} frames (last fault: {st.last_fault or "?"})')
        return '; '.join(why)

    def _write_failed_message(self, error: str) -> str:
        return (f'the recorder stopped: {error} ({self.record}). The run was stopped; the bag '
                'keeps what was written before (adcs export / adcs report read it)')

    def _master_result(self, key: str) -> float:
        """A value of the clock master's result file (``frames_per_s``,
        ``security_events``, ...), 0 if none."""
        try:
            with open(self.result_file) as fh:
                return float(json.load(fh)[key])
        except (OSError, ValueError, KeyError, TypeError):
            return 0.0

    def _master_fps(self) -> float:
        """Lockstep frames/s measured by the clock master (its result file), 0 if none."""
        return self._master_result('frames_per_s')

    def _save_scenario(self) -> str:
        """Store the effective scenario (defaults filled in) beside the bag's files.

        ``<bag>/scenario.yaml`` lets ``adcs report`` pick the paper comparison and lets a
        campaign check what each run really used; rosbag2 readers ignore the extra file.
        Returns ``''``, or a message when it could not be written (disk full): the bag itself
        is kept.
        """
        if not self.record or not os.path.isdir(self.record):
            return ''
        sc = {k: v for k, v in self.sc.items() if not k.startswith('_')}
        sc['duration_s'] = self.duration_s
        path = os.path.join(self.record, 'scenario.yaml')
        try:
            with open(path, 'w') as fh:
                fh.write(f'# effective scenario of this bag (from {self.sc.get("_path", "?")})\n')
                yaml.safe_dump(sc, fh, sort_keys=False)
        except OSError as exc:
            try:
                os.unlink(path)   # a cut scenario.yaml would mislead adcs report
            except OSError:
                pass
            why = 'disk full' if _disk_full(exc) else (exc.strerror or str(exc))
            return f'could not write {path}: {why} (the bag is kept)'
        return ''

    def _on_signal(self, signum, frame) -> None:
        self._stop_requested = True

    def _master_name(self) -> str:
        return 'composed' if self.compose else 'dynamics'

    def _watch(self, monitor: _Monitor, t0: float):
        total_ns = int(round(self.duration_s * 1e9))
        last_print = 0.0
        master = self._master_name()
        transitions = getattr(self, '_transitions', None)
        seen_ns, seen_at = -1, time.monotonic()
        healed_at = 0.0
        while True:
            monitor.spin(0.02 if transitions is not None and transitions.pending else 0.1)
            failed = transitions.poll() if transitions is not None else None
            if failed is not None and failed[1] == 'unanswered':
                failed = self._heal_lifecycle(monitor, failed[0])
            if failed is not None:
                return self._transition_failed(*failed)
            now = time.monotonic()
            if not self.compose and not monitor.clock_seen and now - healed_at >= 1.0:
                healed_at = now
                stuck = self._heal(monitor)
                if stuck is not None:
                    return stuck
            if self.progress and now - last_print > 0.5:
                last_print = now
                self._print_progress(monitor, now - t0, total_ns)
            if monitor.sim_ns != seen_ns:
                seen_ns, seen_at = monitor.sim_ns, now
            elif monitor.clock_seen and now - seen_at > self.stall_notice_s:
                seen_at = now      # a stall is said, not hidden (the run is not stopped)
                waits = [ln for ln in self._log_tail(master, 40).splitlines()
                         if 'waiting' in ln or 'behind' in ln or 'no ' in ln]
                self.log(f'[adcs] WARNING: sim time has not advanced for '
                         f'{self.stall_notice_s:g} s '
                         f'(t = {seen_ns / 1e9:g} s)'
                         + (f'; {master}: {waits[-1].strip()}' if waits else
                            f'; see {self.run_dir}/logs/') + ' (Ctrl-C stops the run)')
            if self._stop_requested:
                return 130, ('interrupted (Ctrl-C): nodes stopped'
                             + (', bag closed' if self.record else ''))
            if monitor.recorder_error:   # also in composed mode, where the process lives on
                return 1, self._write_failed_message(monitor.recorder_error)
            self._kill_due(monitor)
            for name, proc in self.procs.items():
                rc = proc.poll()
                if rc is None or name in self.lost:
                    continue
                if name == master and rc == 0:
                    return self._finish(monitor, total_ns)
                tail = self._log_tail(name)
                if name in ('recorder', 'composed') and monitor.recorder_error:
                    return 1, self._write_failed_message(monitor.recorder_error)
                if name == 'recorder' and rc == RECORDER_WRITE_FAILED:
                    return 1, self._write_failed_message(
                        ('disk full' if 'disk full' in tail else 'write error') + ', see '
                        + os.path.join(self.run_dir, 'logs', 'recorder.log'))
                if name not in ESSENTIAL and rc != 2 and not monitor.clock_seen:
                    # died during start-up: the lockstep can never start without it
                    return 1, (f'node {name} exited with code {rc} during start-up (the '
                               f'lockstep cannot start without it); last lines of its log '
                               f'({self.run_dir}/logs/{name}.log):\n{tail}')
                if name not in ESSENTIAL and rc != 2:
                    # flight software died (a crash, a kill): the graph goes on without it;
                    # its consumers time out and fall back (manager -> safe controller)
                    self.lost.add(name)
                    self.lost_at[name] = monitor.sim_ns / 1e9
                    self.log(f'[adcs] WARNING: node {name} exited with code {rc}; the graph '
                             f'goes on without it (log: {self.run_dir}/logs/{name}.log)')
                    continue
                if rc == 2:   # a node refused its configuration: bad input, as the CLI's
                    return 2, (f'node {name} refused its configuration (exit code 2); last '
                               f'lines of its log ({self.run_dir}/logs/{name}.log):\n{tail}')
                return 1, (f'node {name} exited with code {rc} before the end of the run; '
                           f'last lines of its log ({self.run_dir}/logs/{name}.log):\n{tail}')

    # ------------------------------------------------------------------ self-healing
    def _waiting(self, name: str) -> Tuple[float, str]:
        """``(seconds, unmatched)`` of the last ``still waiting for endpoints`` line that the
        node's current process logged (``(0.0, '')`` if none)."""
        path = os.path.join(self.run_dir, 'logs', f'{name}.log')
        last = (0.0, '')
        try:
            with open(path, 'rb') as fh:
                fh.seek(self._log_start.get(name, 0))
                text = fh.read().decode('utf-8', errors='replace')
        except OSError:
            return last
        for m in _WAITING.finditer(text):
            last = (float(m.group(1)), m.group(2).strip())
        return last

    def _heal(self, monitor: '_Monitor'):
        """The start handshake's self-healing check (before frame 0, about once a second):
        restarts what :func:`heal_decision` says; ``(1, message)`` when a node is stuck
        again after its restarts, else None."""
        expected = [n.name for n in self.nodes if n.lockstep and n.name in self.procs]
        waiting = {n: self._waiting(n) for n in expected if n not in monitor.ready}
        verdict = heal_decision(expected, monitor.ready, waiting, self._master_name(),
                                self.restarts, self._guards, HEAL_WAIT_S, MAX_RESTARTS)
        if verdict is None:
            return None
        if verdict[0] == 'fail':
            name = verdict[1]
            return 1, (f'{verdict[2]}; last lines of its log '
                       f'({self.run_dir}/logs/{name}.log):\n{self._log_tail(name)}')
        for name, reason in verdict[1]:
            self._restart(monitor, name, reason)
        return None

    def _heal_lifecycle(self, monitor: '_Monitor', name: str):
        """A managed node whose lifecycle requests went unanswered: restarted (with what
        :func:`restart_plan` adds), or ``(name, 'unanswered')`` after its restarts."""
        proc = self.procs.get(name)
        cpu = _cpu_seconds(proc.pid) if proc is not None else None
        if cpu is not None:
            if name not in self._cpu_seen:       # measure its CPU time over a window first
                self._cpu_seen[name] = cpu
                self._transitions.postpone(name, HEAL_BUSY_WINDOW_S)
                return None
            used = cpu - self._cpu_seen.pop(name)
            if used >= HEAL_BUSY_CPU_S:          # working (configure, a kernel compile)
                self.log(f'[adcs] node {name} has not answered its lifecycle requests for '
                         f'{HEAL_UNANSWERED_S:g} s but is busy ({used:.1f} s CPU in '
                         f'{HEAL_BUSY_WINDOW_S:g} s): waiting')
                self._transitions.postpone(name, HEAL_UNANSWERED_S)
                return None
        if self.restarts.get(name, 0) >= MAX_RESTARTS:
            return name, 'unanswered'
        reason = (f'its lifecycle requests went unanswered for {HEAL_UNANSWERED_S:g} s '
                  f'and it used no CPU (step: {self._transitions.step.get(name)})')
        for node, why in restart_plan([(name, reason)], monitor.ready, self._master_name(),
                                      self._guards):
            self._restart(monitor, node, why)
        return None

    def _restart(self, monitor: '_Monitor', name: str, reason: str) -> None:
        """Stop node ``name`` and start it again with the same command (before frame 0)."""
        k = self.restarts.get(name, 0) + 1
        self.restarts[name] = k
        self.restart_notes.append(f'{name}: {reason}')
        self.log(f'[adcs] restarting node {name} before frame 0 (restart {k} of at most '
                 f'{MAX_RESTARTS}): {reason}')
        self._signal_and_wait([name], 5.0)
        self._spawn_one(name, self._commands(self._params_path)[name], self._env,
                        f'restarted by the launcher before frame 0: {reason}')
        monitor.ready.discard(name)
        self._cpu_seen.pop(name, None)
        transitions = getattr(self, '_transitions', None)
        if transitions is not None and name in transitions.step:
            transitions.reset(name)
        manifest = getattr(self, '_manifest', None)
        if manifest is not None:
            manifest['pids'] = {n: proc.pid for n, proc in self.procs.items()}
            try:
                _write_private(self._manifest_path, json.dumps(manifest))
            except OSError:
                pass

    def _dump_stack(self, name: str, wait_s: float = 5.0) -> str:
        """Ask a live node process for its Python stacks (SIGUSR1: ``faulthandler`` in
        ``runtime.run`` writes every thread's stack to its log); the log's last lines once
        the dump is there (``''`` if the process is gone or wrote none within ``wait_s``)."""
        proc = self.procs.get(name)
        if proc is None or proc.poll() is not None or not hasattr(signal, 'SIGUSR1'):
            return ''
        log = os.path.join(self.run_dir, 'logs', f'{name}.log')
        try:
            before = os.path.getsize(log)
            os.kill(proc.pid, signal.SIGUSR1)
        except OSError:
            return ''
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            try:
                with open(log, 'rb') as fh:
                    fh.seek(before)
                    new = fh.read()
            except OSError:
                return ''
            if b'File ' in new:
                time.sleep(0.2)          # the dump is written in one go; let it finish
                return ('(its Python stacks, asked with SIGUSR1)\n'
                        + self._log_tail(name, 60))
            time.sleep(0.05)
        return ''

    def _transition_failed(self, name: str, transition: str):
        """Exit code and message for a managed node that was not made active."""
        log = os.path.join(self.run_dir, 'logs', f'{name}.log')
        tail = self._log_tail(name)
        if transition == 'configure':
            reasons = [ln.split('configuration error:', 1)[1].strip()
                       for ln in tail.splitlines() if 'configuration error:' in ln]
            why = reasons[-1] if reasons else 'no reason in its log'
            return 2, (f'node {name} refused its configuration (lifecycle configure failed): '
                       f'{why}; last lines of its log ({log}):\n{tail}')
        if transition == 'unanswered':
            stack = self._dump_stack(name)
            return 1, (f'node {name} did not answer its lifecycle requests for '
                       f'{HEAL_UNANSWERED_S:g} s, also after {self.restarts.get(name, 0)} '
                       f'restart(s) before frame 0; last lines of its log ({log}):\n'
                       f'{stack or tail}')
        if transition == 'deadline':
            step = self._transitions.step.get(name)
            stack = self._dump_stack(name)
            return 1, (f'node {name} was not active {self._transitions.deadline_s:g} s after '
                       f'its start (lifecycle: {step}); last lines of its log ({log}):\n'
                       f'{stack or tail}')
        return 1, (f'node {name} refused the lifecycle transition {transition}; last lines '
                   f'of its log ({log}):\n{tail}')

    def _finish(self, monitor: _Monitor, total_ns: int):
        monitor.sim_ns = max(monitor.sim_ns, total_ns)
        if self.record and not self.compose:
            deadline = time.monotonic() + 15.0
            while monitor.recorder_clock_ns < total_ns and time.monotonic() < deadline:
                if self.procs['recorder'].poll() is not None:
                    break
                monitor.spin(0.1)
            # every node has done its last frame (the master waited for them): the recorder
            # has everything once its message count stops growing
            if self.procs['recorder'].poll() is None:
                monitor.wait_recorder_settled(deadline)
            if monitor.recorder_clock_ns < total_ns:
                return 1, ('recorder did not receive the final frame within 15 s: '
                           'the bag may miss the end of the run')
        return 0, 'done'

    def _print_progress(self, monitor: _Monitor, wall: float, total_ns: int) -> None:
        frac = min(1.0, monitor.sim_ns / total_ns) if total_ns else 0.0
        sim_s = monitor.sim_ns / 1e9
        rtf = sim_s / wall if wall > 0 else 0.0
        width = 30
        bar = '#' * int(frac * width) + '.' * (width - int(frac * width))
        line = (f'[{bar}] sim {sim_s:8.1f}/{total_ns / 1e9:g} s  {rtf:7.1f}x real time  '
                f'missed frames {monitor.missed_frames}')
        if sys.stderr.isatty():
            sys.stderr.write('\r' + line)
        else:
            step = int(frac * 10)
            if step != getattr(self, '_last_step', -1):
                self._last_step = step
                sys.stderr.write(line + '\n')
        sys.stderr.flush()
