"""The run's fork server (zygote): imports numpy, rclpy (no ``rclpy.init``: no DDS, one thread),
the run's node modules and their numba kernels once, then forks a child per request that runs
its module as ``python -m MODULE ARGS`` would. ``python -m adcs_nodes.tools.run.zygote FD
MODULE...`` (``FD``: a ``SOCK_SEQPACKET`` socket; its environment sets one BLAS thread).
Request: ``{"module", "args", "env"}`` with the log's descriptor (``SCM_RIGHTS``); answers:
``{"pid"}``, then ``{"exit": pid, "code": returncode}``. At end of file it exits and its
children get SIGTERM (their parent-death signal). Its log's ``start cost`` line (the nodes'
format) holds its CPU: a forked child counts only its own.
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


def preload(modules) -> int:
    """Import ``modules`` and what every node loads at its start; load each signature in
    numba's on-disk cache of the loaded kernels (never compiled here); returns their count."""
    import rclpy.node  # noqa: F401
    for module in modules:
        importlib.import_module(module)
    from adcs_nodes import registry
    from adcs_nodes.core import kernels
    registry.load_plugins([])        # the built-in entries and the entry-point plugins
    for name, m in list(sys.modules.items()):   # message type support (C libraries)
        if m is not None and name.rpartition('.')[0].endswith(('.msg', '.srv', '.action')):
            for v in list(vars(m).values()):
                if hasattr(type(v), '__import_type_support__'):
                    type(v).__import_type_support__()
    inspect.getframeinfo(sys._getframe())   # rclpy's logger's inspect: scan sys.modules once
    kernels.compile_all()
    from numba.core.registry import CPUDispatcher
    found = {id(v): v for name, m in list(sys.modules.items())
             if name.startswith(('adcs_nodes.', 'sim_node.')) and m is not None
             for v in list(vars(m).values()) if isinstance(v, CPUDispatcher)}
    loaded = 0
    for disp in found.values():
        cache, codegen = disp._cache, disp.targetctx.codegen()
        for key in cache._cache_file._load_index() if hasattr(cache, '_cache_file') else {}:
            if key == cache._index_key(key[0], codegen):   # this source, this CPU
                disp.compile(key[0])
                loaded += 1
    return loaded


def child(req: dict, log_fd: int, zygote_pid: int) -> None:
    """In the forked child: own session, parent-death signal, the log on stdout/stderr, the
    request's environment and argv; runs the module as ``__main__``, exits with its code."""
    os.setsid()
    if ctypes.CDLL(None).prctl(1, int(signal.SIGTERM), 0, 0, 0) != 0 \
            or os.getppid() != zygote_pid:    # 1 = PR_SET_PDEATHSIG
        os._exit(1)                           # the zygote died already: no orphan
    null = os.open(os.devnull, os.O_RDONLY)
    for fd, target in ((null, 0), (log_fd, 1), (log_fd, 2)):
        os.dup2(fd, target)
    os.closerange(3, max(null, log_fd) + 1)
    os.environ.clear()
    os.environ.update(req['env'])
    sys.argv = ['-m'] + list(req['args'])
    sys.modules.pop(req['module'], None)   # run afresh as __main__, as ``python -m`` does
    try:
        runpy.run_module(req['module'], run_name='__main__', alter_sys=True)
        code = 0
    except SystemExit as exc:
        code = 0 if exc.code is None else exc.code
        if not isinstance(code, int):
            print(code, file=sys.stderr)
            code = 1
    except BaseException:
        traceback.print_exc()
        code = 1
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def serve(sock: socket.socket) -> None:
    """Fork a child per request, report each child's end; return at end of file. Around each
    fork, LTTng-UST's fork hooks (as ``liblttng-ust-fork.so``): no lock of its threads held."""
    wake_r, wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGCHLD, lambda *_: None)
    ust = next((ctypes.CDLL(ln.split()[-1]) for ln in open('/proc/self/maps')
                if '/liblttng-ust-' in ln and 'tracepoint' not in ln), None)
    sigset = ctypes.create_string_buffer(128)
    while True:
        if wake_r in select.select([sock, wake_r], [], [])[0]:
            for pid, code in _reaped(wake_r):
                sock.send(json.dumps({'exit': pid, 'code': code}).encode())
            continue
        msg, fds, _, _ = socket.recv_fds(sock, 1 << 20, 1)
        if not msg:
            return
        sys.stdout.flush()
        if ust is not None:
            ust.ust_before_fork(sigset)
        pid = os.fork()
        if ust is not None:
            (ust.ust_after_fork_parent if pid else ust.ust_after_fork_child)(sigset)
        if pid == 0:
            signal.set_wakeup_fd(-1)
            signal.signal(signal.SIGCHLD, signal.SIG_DFL)
            for fd in (sock.fileno(), wake_r, wake_w):
                os.close(fd)
            child(json.loads(msg), fds[0], os.getppid())
        os.close(fds[0])
        sock.send(json.dumps({'pid': pid}).encode())
        log_cost()


def _reaped(wake_r: int):
    """Empty the wake-up pipe; yield ``(pid, returncode)`` of each child that ended."""
    try:
        while os.read(wake_r, 512):
            pass
    except BlockingIOError:
        pass
    while True:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if not pid:
            return
        yield pid, os.waitstatus_to_exitcode(status)


_COST: dict = {}


def log_cost(**first) -> None:
    """The ``start cost`` line (row 7g of the bench reads the largest ``cpu_s`` of a log)."""
    _COST.update(first)
    cost = dict(_COST, cpu_s=round(time.process_time(), 3))
    print(f'[zygote]: start cost {json.dumps(cost)}', flush=True)


if __name__ == '__main__':
    _sock = socket.socket(fileno=int(sys.argv[1]))
    _kernels = preload(sys.argv[2:])
    log_cost(t_s=0.0, import_cpu_s=round(time.process_time(), 3), kernels=_kernels)
    try:
        serve(_sock)
    except (BrokenPipeError, ConnectionResetError):   # the launcher is gone
        pass
