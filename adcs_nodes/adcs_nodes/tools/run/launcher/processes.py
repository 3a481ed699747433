"""The processes of a run: one per node (or one composed), each in its own session with a
parent-death signal and its log in the run directory; stopped in order."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from typing import Dict, List, Optional

#: Run via ``python -S -c``: sets the parent-death signal, checks the parent is still there,
#: then executes the command (``preexec_fn`` is unsafe while DDS threads run).
PDEATHSIG_SHIM = (
    'import ctypes, os, signal, sys\n'
    'libc = ctypes.CDLL(None, use_errno=True)\n'
    'if libc.prctl(1, int(signal.SIGTERM), 0, 0, 0) != 0:\n'   # 1 = PR_SET_PDEATHSIG
    '    sys.exit("prctl(PR_SET_PDEATHSIG) failed: errno %d" % ctypes.get_errno())\n'
    'if os.getppid() != int(sys.argv[1]):\n'
    '    sys.exit(0)\n'  # the launcher died before prctl: do not start an orphan
    'os.execv(sys.argv[2], sys.argv[2:])\n')
#: Test only: ``<node>[@<starts>]:<ros args>[;...]`` appended to that node's command.
TEST_NODE_ARGS_ENV = 'ADCS_TEST_NODE_ROS_ARGS'


def with_parent_death_signal(cmd: List[str]) -> List[str]:
    """``cmd`` run so that it gets SIGTERM when this process dies (:data:`PDEATHSIG_SHIM`)."""
    return [sys.executable, '-S', '-c', PDEATHSIG_SHIM, str(os.getpid())] + list(cmd)


def cpu_seconds(pid: int) -> Optional[float]:
    """CPU time (user + system) of process ``pid`` [s], None if it cannot be read."""
    try:
        with open(f'/proc/{pid}/stat', 'rb') as fh:
            fields = fh.read().rsplit(b')', 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    except (OSError, ValueError, IndexError):
        return None


class Processes:
    """The child processes of one run, by node name, and their logs (``RUN_DIR/logs``)."""

    def __init__(self, run_dir: str, log=print) -> None:
        self.run_dir = run_dir
        self.log = log
        self.procs: Dict[str, subprocess.Popen] = {}
        self.log_start: Dict[str, int] = {}       # each log's offset at its process's start
        self.spawn_count: Dict[str, int] = {}

    def log_path(self, name: str) -> str:
        return os.path.join(self.run_dir, 'logs', f'{name}.log')

    def test_args(self) -> Dict[str, List[str]]:
        """Extra ROS arguments per node from :data:`TEST_NODE_ARGS_ENV` (tests only)."""
        extra: Dict[str, List[str]] = {}
        for item in filter(None, os.environ.get(TEST_NODE_ARGS_ENV, '').split(';')):
            node, _, args = item.partition(':')
            node, _, starts = node.strip().partition('@')
            if not starts or self.spawn_count.get(node, 0) < int(starts):
                extra[node] = args.split()
        return extra

    def spawn(self, name: str, cmd: List[str], env: Dict[str, str], note: str = '') -> None:
        """Start one node; its log is created, or appended to after ``note`` (a restart)."""
        os.makedirs(os.path.join(self.run_dir, 'logs'), mode=0o700, exist_ok=True)
        flags = os.O_WRONLY | os.O_CREAT | os.O_CLOEXEC | (os.O_APPEND if note else os.O_TRUNC)
        fd = os.open(self.log_path(name), flags, 0o600)
        with os.fdopen(fd, 'w') as fh:
            if note:
                fh.write(f'\n----- {note} -----\n')
                fh.flush()
            self.log_start[name] = fh.tell()
            self.spawn_count[name] = self.spawn_count.get(name, 0) + 1
            # own session: a Ctrl-C in the terminal reaches the launcher only, which
            # stops the graph in order; the parent-death signal covers a killed launcher
            self.procs[name] = subprocess.Popen(with_parent_death_signal(cmd), env=env,
                                                stdout=fh, stderr=subprocess.STDOUT,
                                                stdin=subprocess.DEVNULL,
                                                start_new_session=True)

    def tail(self, name: str, lines: int = 15) -> str:
        try:
            with open(self.log_path(name), encoding='utf-8', errors='replace') as fh:
                return ''.join(fh.readlines()[-lines:])
        except OSError:
            return ''

    def current_log(self, name: str) -> str:
        """What the node's current process logged (from its start offset)."""
        try:
            with open(self.log_path(name), 'rb') as fh:
                fh.seek(self.log_start.get(name, 0))
                return fh.read().decode('utf-8', errors='replace')
        except OSError:
            return ''

    def signal_and_wait(self, names: List[str], grace_s: float) -> None:
        """SIGINT the named children, wait up to ``grace_s``, SIGKILL what is left."""
        for name in names:
            if self.procs[name].poll() is None:
                _killpg(self.procs[name], signal.SIGINT)
        deadline = time.monotonic() + grace_s
        for name in names:
            proc = self.procs[name]
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                self.log(f'[adcs] {name} did not stop within {grace_s:g} s: killing it')
                _killpg(proc, signal.SIGKILL)
                proc.wait()

    def stop_all(self, monitor=None, grace_s: float = 10.0) -> None:
        """Stop the graph, then the recorder once it has written everything."""
        self.signal_and_wait([n for n in self.procs if n != 'recorder'], grace_s)
        if 'recorder' in self.procs:
            if monitor is not None and self.procs['recorder'].poll() is None:
                monitor.wait_recorder_settled(time.monotonic() + grace_s)
            self.signal_and_wait(['recorder'], grace_s)

    def dump_stack(self, name: str, wait_s: float = 5.0) -> str:
        """A live node's Python stacks (SIGUSR1): its log's last lines (``''``: none)."""
        proc = self.procs.get(name)
        if proc is None or proc.poll() is not None or not hasattr(signal, 'SIGUSR1'):
            return ''
        try:
            before = os.path.getsize(self.log_path(name))
            os.kill(proc.pid, signal.SIGUSR1)
        except OSError:
            return ''
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            try:
                with open(self.log_path(name), 'rb') as fh:
                    fh.seek(before)
                    new = fh.read()
            except OSError:
                return ''
            if b'File ' in new:
                time.sleep(0.2)          # the dump is written in one go; let it finish
                return '(its Python stacks, asked with SIGUSR1)\n' + self.tail(name, 60)
            time.sleep(0.05)
        return ''


def _killpg(proc: subprocess.Popen, sig: int) -> None:
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        pass
