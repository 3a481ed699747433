"""The run's fork server (zygote): imports the node modules (no ``rclpy.init``: no DDS, one
thread) and loads their numba kernels once, then forks a child per request that runs its module
as ``python -m`` would. ``python -m adcs_nodes.tools.run.zygote FD MODULE...``, FD: a
``SOCK_SEQPACKET`` socket. Request: ``{"module", "args", "env"}`` + the log's descriptor;
answers ``{"pid"}``, then ``{"exit": pid, "code": returncode}``. At end of file it exits (its
children get SIGTERM). Its log's ``start cost`` line holds its CPU (a child counts its own)."""
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
    """Import ``modules``, the registry, every loaded message's type support; load each
    signature in numba's on-disk cache of the loaded kernels (never compile); their count."""
    for module in ['rclpy.node'] + modules:
        importlib.import_module(module)
    from adcs_nodes import registry
    from adcs_nodes.core import kernels
    registry.load_plugins([])
    loaded = [v for n, m in list(sys.modules.items()) if m is not None
              and n.rpartition('.')[0].endswith(('.msg', '.srv', '.action'))
              for v in list(vars(m).values()) if hasattr(type(v), '__import_type_support__')]
    for msg_type in loaded:
        type(msg_type).__import_type_support__()
    inspect.getframeinfo(sys._getframe())   # rclpy's logger's inspect: scan sys.modules once
    kernels.compile_all()
    from numba.core.registry import CPUDispatcher
    found = {id(v): v for n, m in list(sys.modules.items())
             if n.startswith(('adcs_nodes.', 'sim_node.')) and m is not None
             for v in list(vars(m).values()) if isinstance(v, CPUDispatcher)}
    sigs = [(d, key[0]) for d in found.values() if hasattr(d._cache, '_cache_file')
            for key in d._cache._cache_file._load_index()
            if key == d._cache._index_key(key[0], d.targetctx.codegen())]   # this source, CPU
    for disp, sig in sigs:
        disp.compile(sig)
    return len(sigs)


def child(req: dict, log_fd: int, zygote_pid: int) -> None:
    """The forked child: own session, parent-death signal, the log on stdout/stderr, the
    request's environment and argv; runs the module as ``__main__``, exits with its code."""
    os.setsid()
    if ctypes.CDLL(None).prctl(1, int(signal.SIGTERM), 0, 0, 0) != 0 \
            or os.getppid() != zygote_pid:    # 1 = PR_SET_PDEATHSIG
        os._exit(1)                           # the zygote died already: no orphan
    null = os.open(os.devnull, os.O_RDONLY)
    for fd, target in ((null, 0), (log_fd, 1), (log_fd, 2)):
        os.dup2(fd, target)
    os.close(null)
    os.close(log_fd)
    os.environ.clear()
    os.environ.update(req['env'])
    sys.argv = ['-m'] + list(req['args'])
    sys.modules.pop(req['module'], None)   # run afresh as __main__, as ``python -m`` does
    code = 1
    try:
        runpy.run_module(req['module'], run_name='__main__', alter_sys=True)
        code = 0
    except SystemExit as exc:   # as the interpreter: None is 0, a message printed and 1
        code = 0 if exc.code is None else exc.code
        if not isinstance(code, int):
            print(code, file=sys.stderr)
            code = 1
    except BaseException:
        traceback.print_exc()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def serve(sock: socket.socket, cost: dict) -> None:
    """Fork a child per request, report each child's end; return at end of file. LTTng-UST's
    fork hooks around each fork (as ``liblttng-ust-fork.so``): no lock of its threads held."""
    wake_r, wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGCHLD, lambda *_: None)
    ust = next((ctypes.CDLL(ln.split()[-1]) for ln in open('/proc/self/maps')
                if '/liblttng-ust-' in ln and 'tracepoint' not in ln), None)
    sigset = ctypes.create_string_buffer(128)
    if ust is not None:
        os.register_at_fork(before=lambda: ust.ust_before_fork(sigset),
                            after_in_parent=lambda: ust.ust_after_fork_parent(sigset),
                            after_in_child=lambda: ust.ust_after_fork_child(sigset))
    while True:
        cost['cpu_s'] = round(time.process_time(), 3)
        print(f'[zygote]: start cost {json.dumps(cost)}', flush=True)
        while wake_r in select.select([sock, wake_r], [], [])[0]:
            os.read(wake_r, 4096)
            while (ended := _waitpid()) is not None:
                sock.send(json.dumps({'exit': ended[0], 'code': ended[1]}).encode())
        msg, fds, _, _ = socket.recv_fds(sock, 1 << 20, 1)
        if not msg:
            return
        pid = os.fork()
        if pid == 0:
            signal.set_wakeup_fd(-1)
            signal.signal(signal.SIGCHLD, signal.SIG_DFL)
            for fd in (sock.fileno(), wake_r, wake_w):
                os.close(fd)
            child(json.loads(msg), fds[0], os.getppid())
        os.close(fds[0])
        sock.send(json.dumps({'pid': pid}).encode())


def _waitpid():
    """``(pid, returncode)`` of a child that ended, None if none."""
    try:
        pid, status = os.waitpid(-1, os.WNOHANG)
    except ChildProcessError:
        return None
    return (pid, os.waitstatus_to_exitcode(status)) if pid else None


if __name__ == '__main__':
    _sock = socket.socket(fileno=int(sys.argv[1]))
    _kernels = preload(sys.argv[2:])
    _cpu = round(time.process_time(), 3)
    try:
        serve(_sock, {'t_s': 0.0, 'import_cpu_s': _cpu, 'kernels': _kernels})
    except (BrokenPipeError, ConnectionResetError):   # the launcher is gone
        pass
