"""The processes of a run: one per node (or one composed), each in its own session with a
parent-death signal and its log in the run directory; stopped in order. Node processes are
forked by the run's zygote (:mod:`adcs_nodes.tools.run.zygote`), else executed."""
from __future__ import annotations

import io
import json
import math
import os
import select
import signal
import socket
import subprocess
import sys
import time
from typing import Dict, List, Optional, Union

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
#: ``0``: no zygote, every node process executed (``python -m``).
ZYGOTE_ENV = 'ADCS_ZYGOTE'
#: Wall seconds the zygote may take to answer a request (its first: its imports).
ZYGOTE_ANSWER_S = 60.0


def with_parent_death_signal(cmd: List[str]) -> List[str]:
    """``cmd`` run so that it gets SIGTERM when this process dies (:data:`PDEATHSIG_SHIM`)."""
    return [sys.executable, '-S', '-c', PDEATHSIG_SHIM, str(os.getpid())] + list(cmd)


def _stat(pid: int) -> List[bytes]:
    """The fields of ``/proc/PID/stat`` after the command name (state first); [] if gone."""
    try:
        with open(f'/proc/{pid}/stat', 'rb') as fh:
            return fh.read().rsplit(b')', 1)[1].split()
    except (OSError, IndexError):
        return []


def cpu_seconds(pid: int) -> Optional[float]:
    """CPU time (user + system) of process ``pid`` [s], None if it cannot be read."""
    try:
        fields = _stat(pid)
        return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    except (ValueError, IndexError):
        return None


class Zygote:
    """The launcher's end of the run's fork server (:mod:`adcs_nodes.tools.run.zygote`)."""

    def __init__(self, modules: List[str], env: Dict[str, str], log_path: str,
                 log=print) -> None:
        self.log_path, self.log, self.alive = log_path, log, True
        self.codes: Dict[int, int] = {}
        self.pids: List[int] = []
        self.sock, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        env = dict(env, OPENBLAS_NUM_THREADS='1', OMP_NUM_THREADS='1', MKL_NUM_THREADS='1')
        cmd = [sys.executable, '-m', 'adcs_nodes.tools.run.zygote', str(theirs.fileno())]
        with open(log_path, 'wb', opener=lambda p, f: os.open(p, f | os.O_CLOEXEC, 0o600)) as fh:
            self.proc = subprocess.Popen(with_parent_death_signal(cmd + modules), env=env,
                                         stdout=fh, stderr=subprocess.STDOUT,
                                         stdin=subprocess.DEVNULL, start_new_session=True,
                                         pass_fds=[theirs.fileno()])
        theirs.close()

    def pump(self, timeout: float) -> None:
        """Read the zygote's answers for up to ``timeout`` seconds (0: what is there)."""
        if not self.alive:
            time.sleep(max(0.0, timeout))
        while self.alive and select.select([self.sock], [], [], max(0.0, timeout))[0]:
            timeout = 0.0
            try:
                msg = json.loads(self.sock.recv(4096) or 'null')
            except OSError:      # reset: it died with a request unread
                msg = None
            if msg is None:
                self.close('ended')
            elif 'exit' in msg:
                self.codes[msg['exit']] = msg['code']
            else:
                self.pids.append(msg['pid'])

    def spawn(self, cmd: List[str], env: Dict[str, str], log_fd: int) -> Optional['Forked']:
        """Fork ``cmd`` (``[python, '-m', module, args...]``) logging to ``log_fd``; None if
        the zygote is lost."""
        try:
            socket.send_fds(self.sock, [json.dumps(
                {'module': cmd[2], 'args': cmd[3:], 'env': env}).encode()], [log_fd])
        except OSError as exc:
            self.close(f'cannot be reached ({exc.strerror or exc})')
        deadline = time.monotonic() + ZYGOTE_ANSWER_S
        while not self.pids and self.alive and time.monotonic() < deadline:
            self.pump(deadline - time.monotonic())
        if not self.pids and self.alive:
            self.close(f'did not answer in {ZYGOTE_ANSWER_S:g} s')
        return Forked(self, self.pids.pop(0)) if self.pids else None

    def close(self, lost: str = '') -> None:
        """Stop the zygote (its remaining children get SIGTERM); ``lost``: why, said in one
        line (later nodes are executed)."""
        self.alive = False
        self.sock.close()
        if self.proc.poll() is None:
            _killpg(self.proc, signal.SIGKILL)
        code = self.proc.wait()
        if lost:
            self.log(f'[adcs] WARNING: the zygote (fork server) {lost} (exit code {code}, log '
                     f'{self.log_path}): its node processes get SIGTERM; nodes start as '
                     'processes from now on')


class Forked:
    """A process forked by the :class:`Zygote`: ``Popen``'s ``pid``, ``poll``, ``wait`` and
    ``returncode``; one the zygote died before reporting ended by its SIGTERM once gone."""

    def __init__(self, zygote: Zygote, pid: int) -> None:
        self.zygote, self.pid, self.returncode = zygote, pid, None

    def poll(self) -> Optional[int]:
        if self.returncode is None:
            self.zygote.pump(0.0)
            self.returncode = self.zygote.codes.get(self.pid)
        if self.returncode is None and not self.zygote.alive and not _running(self.pid):
            self.returncode = -signal.SIGTERM
        return self.returncode

    def wait(self, timeout: Optional[float] = None) -> int:
        deadline = time.monotonic() + (math.inf if timeout is None else timeout)
        while self.poll() is None:
            if time.monotonic() >= deadline:
                raise subprocess.TimeoutExpired(f'pid {self.pid}', timeout)
            self.zygote.pump(min(deadline - time.monotonic(), 0.05))
        return self.returncode


def _running(pid: int) -> bool:
    """Whether ``pid`` is a process that has not ended (a zombie has)."""
    return _stat(pid)[:1] not in ([], [b'Z'], [b'X'])


class Processes:
    """The child processes of one run, by node name, and their logs (``RUN_DIR/logs``)."""

    def __init__(self, run_dir: str, log=print) -> None:
        self.run_dir = run_dir
        self.log = log
        self.procs: Dict[str, Union[subprocess.Popen, Forked]] = {}
        self.zygote: Optional[Zygote] = None
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

    def spawn_all(self, cmds: Dict[str, List[str]], env: Dict[str, str]) -> None:
        """Start every node; through a zygote when there are several (:data:`ZYGOTE_ENV`)."""
        modules = sorted({c[2] for c in cmds.values() if c[1:2] == ['-m']})
        if len(cmds) > 1 and os.environ.get(ZYGOTE_ENV, '1') != '0':
            os.makedirs(os.path.join(self.run_dir, 'logs'), mode=0o700, exist_ok=True)
            self.zygote = Zygote(modules, env, self.log_path('zygote'), self.log)
        for name, cmd in cmds.items():
            self.spawn(name, cmd, env)

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
            if self.zygote is not None and self.zygote.alive and cmd[1:2] == ['-m']:
                self.procs[name] = self.zygote.spawn(cmd, env, fd)   # None: it is lost
                if self.procs[name] is not None:
                    return
            # own session: a Ctrl-C in the terminal reaches the launcher only, which
            # stops the graph in order; the parent-death signal covers a killed launcher
            self.procs[name] = subprocess.Popen(with_parent_death_signal(cmd), env=env,
                                                stdout=fh, stderr=subprocess.STDOUT,
                                                stdin=subprocess.DEVNULL,
                                                start_new_session=True)

    def _read(self, name: str, offset: int = 0) -> str:
        try:
            with open(self.log_path(name), 'rb') as fh:
                fh.seek(offset)
                return fh.read().decode('utf-8', errors='replace')
        except OSError:
            return ''

    def tail(self, name: str, lines: int = 15) -> str:
        return ''.join(io.StringIO(self._read(name)).readlines()[-lines:])

    def current_log(self, name: str) -> str:
        """What the node's current process logged (from its start offset)."""
        return self._read(name, self.log_start.get(name, 0))

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
        if self.zygote is not None:
            self.zygote.close()

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
            if 'File ' in self._read(name, before):
                time.sleep(0.2)          # the dump is written in one go; let it finish
                return '(its Python stacks, asked with SIGUSR1)\n' + self.tail(name, 60)
            time.sleep(0.05)
        return ''


def _killpg(proc: subprocess.Popen, sig: int) -> None:
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        pass
