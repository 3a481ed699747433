"""A fork server (zygote) for a run's node processes: it pays the imports and the numba kernel
loads once per run, then forks one child per node, each run as ``python -m MODULE ARGS`` would.

Command line (the launcher's :class:`~adcs_nodes.tools.run.launcher.processes.Zygote` starts
it): ``python -m adcs_nodes.tools.run.zygote FD MODULE...``; ``FD``: its end of a
``SOCK_SEQPACKET`` socket pair. One thread, no ``rclpy.init`` (no DDS) before a fork. Requests
(one JSON packet each, the log file descriptor passed with ``SCM_RIGHTS``):
``{"module", "args", "env"}``; answers ``{"pid"}``, then ``{"exit": pid, "code"}`` (a
``Popen.returncode``: negative for a signal) when a child ends. End of file: it exits; its
children get SIGTERM (their parent-death signal). Its log gets a ``start cost`` line (its own
CPU: imports and kernels) in the nodes' format, as a forked child counts only its own CPU.
Its environment must set one BLAS thread (a thread pool cannot be forked).
"""
import ctypes
import importlib
import inspect
import json
import os
import runpy
import select
import signal
import socket
import sys
import time
import traceback

PR_SET_PDEATHSIG = 1
#: The packages whose numba kernels are loaded from the on-disk cache.
KERNEL_PACKAGES = ('adcs_nodes.', 'sim_node.')


def preload(modules) -> int:
    """Import numpy, rclpy (no init) and ``modules``; load every cached signature of the
    loaded kernels (never compiled here); returns the number of signatures loaded."""
    import numpy  # noqa: F401
    import rclpy.node  # noqa: F401
    for module in modules:
        importlib.import_module(module)
    from adcs_nodes import registry
    from adcs_nodes.core import kernels
    registry.load_plugins([])        # the built-in entries and the entry-point plugins
    kernels.compile_all()
    from numba.core.registry import CPUDispatcher
    found = {id(v): v for name, m in list(sys.modules.items())
             if name.startswith(KERNEL_PACKAGES) and m is not None
             for v in list(vars(m).values()) if isinstance(v, CPUDispatcher)}
    for name, m in list(sys.modules.items()):   # message type support: loaded once here
        if m is not None and name.rpartition('.')[0].endswith(('.msg', '.srv', '.action')):
            for v in list(vars(m).values()):
                if hasattr(type(v), '__import_type_support__'):
                    type(v).__import_type_support__()
    inspect.getframeinfo(sys._getframe())   # rclpy's logger's inspect: scan sys.modules once
    loaded = 0
    for disp in found.values():
        cache, codegen = disp._cache, disp.targetctx.codegen()
        index = cache._cache_file._load_index() if hasattr(cache, '_cache_file') else {}
        for key in index:
            if key == cache._index_key(key[0], codegen):   # this source, this CPU
                disp.compile(key[0])
                loaded += 1
    return loaded


class _Lttng:
    """The LTTng-UST fork hooks (what ``liblttng-ust-fork.so`` wraps around ``fork``): its
    listener threads hold no lock across the fork, and the child gets its own."""

    def __init__(self) -> None:
        path = next((ln.split()[-1] for ln in open('/proc/self/maps')
                     if '/liblttng-ust-' in ln and 'tracepoint' not in ln), None)
        self.lib = ctypes.CDLL(path) if path else None
        self.sigset = ctypes.create_string_buffer(128)

    def fork(self) -> int:
        if self.lib is None:
            return os.fork()
        self.lib.ust_before_fork(self.sigset)
        pid = os.fork()
        (self.lib.ust_after_fork_parent if pid else self.lib.ust_after_fork_child)(self.sigset)
        return pid


def child(req: dict, log_fd: int, zygote_pid: int, close) -> None:
    """In the forked child: own session, parent-death signal, the log on stdout/stderr, the
    request's environment and argv; runs the module as ``__main__`` and exits with its code."""
    os.setsid()
    signal.set_wakeup_fd(-1)
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    for fd in close:
        os.close(fd)
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0 \
            or os.getppid() != zygote_pid:
        os._exit(1)          # no parent-death signal, or the zygote died: no orphan
    null = os.open(os.devnull, os.O_RDONLY)
    for fd, target in ((null, 0), (log_fd, 1), (log_fd, 2)):
        os.dup2(fd, target)
    os.close(null)
    os.close(log_fd)
    os.environ.clear()
    os.environ.update(req['env'])
    module = req['module']
    sys.argv = ['-m'] + list(req['args'])
    sys.modules.pop(module, None)   # run afresh as __main__, as ``python -m`` does
    code = 0
    try:
        runpy.run_module(module, run_name='__main__', alter_sys=True)
    except SystemExit as exc:
        code = 0 if exc.code is None else exc.code
        if not isinstance(code, int):
            print(code, file=sys.stderr)
            code = 1
    except BaseException:
        traceback.print_exc()
        code = 1
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    os._exit(code)


def serve(sock: socket.socket) -> None:
    """Fork a child per request, report each child's end; return at end of file."""
    wake_r, wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGCHLD, lambda *_: None)
    lttng = _Lttng()
    while True:
        ready = select.select([sock, wake_r], [], [])[0]
        if wake_r in ready:
            try:
                while os.read(wake_r, 512):
                    pass
            except BlockingIOError:
                pass
            _reap(sock)
        if sock not in ready:
            continue
        msg, fds, _, _ = socket.recv_fds(sock, 1 << 20, 1)
        if not msg:
            return
        req = json.loads(msg)
        sys.stdout.flush()
        sys.stderr.flush()
        pid = lttng.fork()
        if pid == 0:
            child(req, fds[0], os.getppid(), [sock.fileno(), wake_r, wake_w])
        os.close(fds[0])
        sock.send(json.dumps({'pid': pid}).encode())
        log_cost()


def _reap(sock: socket.socket) -> None:
    while True:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        sock.send(json.dumps({'exit': pid, 'code': os.waitstatus_to_exitcode(status)}).encode())


_COST: dict = {}


def log_cost() -> None:
    """The ``start cost`` line (the bench's row 7g reads the largest ``cpu_s`` of a log)."""
    cost = dict(_COST, cpu_s=round(time.process_time(), 3))
    print(f'[INFO] [{time.time():.9f}] [zygote]: start cost {json.dumps(cost)}', flush=True)


def main(argv) -> None:
    sock = socket.socket(fileno=int(argv[0]))
    kernels = preload(argv[1:])
    _COST.update(t_s=0.0, import_cpu_s=round(time.process_time(), 3), kernels=kernels)
    log_cost()
    try:
        serve(sock)
    except (BrokenPipeError, ConnectionResetError):   # the launcher is gone
        pass


if __name__ == '__main__':
    main(sys.argv[1:])
