"""Shared process runtime for every ADCS node: init, EventsExecutor spin, clean shutdown.

``EventsExecutor.spin()`` ignores SIGINT (DESIGN section 6), so nodes spin on a future with a
short timeout and stop on SIGINT/SIGTERM or when a node asks to finish (``node.done``).
The same node classes run one per process (``main`` of each node module) or several in one
process with one executor (``adcs_nodes.tools.run.compose``).

One BLAS thread per process (DESIGN section 6): importing this module limits the loaded
BLAS/OpenMP libraries (``threadpoolctl``) and the environment of later ones and children.

Exit within 2 s of SIGINT, also under load: the nodes close, a launched node's samples are
acknowledged (:data:`FLUSH_BUDGET_S`), the executor and nodes are destroyed (their endpoints
leave the graph), and the process ends (:func:`exit_now`) without rclpy's shutdown. A
teardown that hangs in Fast DDS holding the GIL is ended by a watchdog that needs no Python
(:func:`native_exit_watchdog`): one line, the node's exit code. ``docs/reliability.md`` has
the measurements.
"""
from __future__ import annotations

import ctypes
import faulthandler
import json
import logging
import os
import signal
import sys
import threading
import time
from typing import Callable, Dict, Iterable, List, Optional

import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future

from adcs_nodes.core.kernels import limit_blas_threads

#: Wall seconds a closing process waits, in all, for its samples to be acknowledged.
FLUSH_BUDGET_S = 4.0
#: Wall seconds a node process gives rclpy to shut its executor down and destroy its nodes
#: once they are closed and flushed; then it ends with its exit code all the same (nothing is
#: left to save), from Python, or :data:`HANG_S` later from a native thread when the hang
#: holds the GIL. rclpy.shutdown() is skipped (its logging finalisation hung the same way).
TEARDOWN_BUDGET_S = 1.0
HANG_S = 0.5

limit_blas_threads()


def make_executor(context=None):
    """An ``EventsExecutor`` on ``context`` (``ADCS_EXECUTOR=single`` or an older rclpy: a
    ``SingleThreadedExecutor``)."""
    if os.environ.get('ADCS_EXECUTOR', '') != 'single':
        try:
            from rclpy.experimental import EventsExecutor
            return EventsExecutor(context=context)
        except ImportError:  # older rclpy
            pass
    from rclpy.executors import SingleThreadedExecutor
    return SingleThreadedExecutor(context=context)


def flush_publishers(nodes: Iterable[Node], budget_s: float = FLUSH_BUDGET_S) -> List[str]:
    """Wait (at most ``budget_s`` in all) until every publisher's samples are acknowledged
    by its readers (the recorder); the topics still unacknowledged at the deadline."""
    deadline = time.monotonic() + budget_s
    left = []
    for node in nodes:
        for pub in list(getattr(node, 'publishers', [])):
            remaining = max(0.0, deadline - time.monotonic())
            try:
                if pub.get_subscription_count() and not pub.wait_for_all_acked(
                        Duration(seconds=remaining)):
                    left.append(pub.topic_name)
            except Exception:  # noqa: BLE001 - a destroyed publisher: nothing to flush
                continue
    return left


#: Set when SIGINT/SIGTERM arrived before the spin loop took the signals over
#: (:func:`stop_handler_from_start`); the loop then ends as soon as it starts.
STOP_REQUESTED = threading.Event()


def _request_stop(signum, frame) -> None:
    STOP_REQUESTED.set()


def stop_handler_from_start():
    """SIGINT/SIGTERM, from the start of a node process, only ask it to stop: the start-up
    runs to its end and the spin loop ends at once (also with SIGINT inherited ignored, as
    bash starts a script's background jobs). Returns the previous handlers."""
    STOP_REQUESTED.clear()
    return (signal.signal(signal.SIGINT, _request_stop),
            signal.signal(signal.SIGTERM, _request_stop))


def restore_handlers(old) -> None:
    """Put back the handlers :func:`stop_handler_from_start` replaced."""
    signal.signal(signal.SIGINT, old[0])
    signal.signal(signal.SIGTERM, old[1])


def spin_nodes(nodes: Iterable[Node], until: Optional[Callable[[], bool]] = None,
               poll_s: float = 0.1, linger_s: float = 0.3,
               teardown_s: Optional[float] = None) -> None:
    """Spin ``nodes`` on one executor until SIGINT/SIGTERM, ``until()`` or every node is
    ``done`` (then ``linger_s`` more, so reliable DDS can resend the last messages). With
    ``teardown_s`` (the process ends after this) the teardown is bounded (:func:`_close`)."""
    nodes: List[Node] = list(nodes)
    executor = make_executor()
    for node in nodes:
        executor.add_node(node)
    stop = {'flag': STOP_REQUESTED.is_set()}   # a stop asked during the start-up

    def _handler(signum, frame):
        stop['flag'] = True

    old = (signal.signal(signal.SIGINT, _handler), signal.signal(signal.SIGTERM, _handler))
    # a busy executor never times out: a steady timer inside it checks the stop conditions
    wake = {'future': Future()}
    steady = Clock(clock_type=ClockType.STEADY_TIME)
    all_done = (lambda: nodes and all(getattr(n, 'done', False) for n in nodes))

    def _check() -> None:
        if not wake['future'].done() and (
                stop['flag'] or (until is not None and until()) or all_done()):
            wake['future'].set_result(True)

    timers = [nodes[0].create_timer(poll_s, _check, clock=steady)] if nodes else []
    try:
        while rclpy.ok() and not stop['flag']:
            if wake['future'].done():   # a condition that did not last: wait for the next
                wake['future'] = Future()
            executor.spin_until_future_complete(wake['future'], timeout_sec=poll_s)
            if until is not None and until():
                break
            if all_done():
                lingered = Future()
                timers.append(nodes[0].create_timer(
                    linger_s, lambda: lingered.done() or lingered.set_result(True),
                    clock=steady))
                executor.spin_until_future_complete(lingered, timeout_sec=linger_s)
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        # the handlers stay while the nodes close: a parent-death signal arrives once per
        # thread of the dying launcher, and a second SIGTERM must not kill a closing recorder
        try:
            _close(executor, nodes, timers, teardown_s)
        finally:
            signal.signal(signal.SIGINT, old[0])
            signal.signal(signal.SIGTERM, old[1])


def _close(executor, nodes: List[Node], timers: List, teardown_s: Optional[float]) -> None:
    """Close the nodes, flush a launched node's samples, then shut the executor down and
    destroy the nodes, under the teardown watchdogs when the process ends after this."""
    for timer in timers:
        timer.cancel()
    for node in nodes:
        close = getattr(node, 'close', None)
        if close is not None:
            close()
    # a launched node (start handshake expectations) waits for its samples to be
    # acknowledged, in a thread joined with a deadline: shutting down never hangs
    launched = [n for n in nodes if any(getattr(n, '_expected_raw', None) or [])]
    if launched:
        flusher = threading.Thread(target=flush_publishers, args=(launched,), daemon=True)
        flusher.start()
        flusher.join(FLUSH_BUDGET_S + 0.5)
    if teardown_s is not None:     # nothing left to save: never hang in rclpy
        code = max([int(getattr(n, 'exit_code', 0) or 0) for n in nodes] or [0])
        name = nodes[0].get_name() if nodes else 'node'
        line = (f'[{name}] shutdown: the middleware did not let go of the node within '
                f'{{:g}} s; ending the process now (exit code {code}: nothing was left to '
                'save)')
        watchdog = threading.Timer(teardown_s, _exit_saying, args=(line.format(teardown_s),
                                                                   code))
        watchdog.daemon = True
        watchdog.start()
        if not native_exit_watchdog(teardown_s + HANG_S, code,
                                    line.format(teardown_s + HANG_S)):
            faulthandler.dump_traceback_later(teardown_s + HANG_S, exit=True)
    # the executor lets go of the nodes' entities before they are destroyed: an entity
    # destroyed while the executor held it was destroyed inside the executor's shutdown,
    # which then hung for good now and then (holding the GIL, in an event handler's __exit__)
    for node in nodes:
        executor.remove_node(node)
    executor.shutdown()
    for node in nodes:
        node.destroy_node()


def _exit_saying(line: str, code: int) -> None:
    print(line, file=sys.stderr, flush=True)
    exit_now(code)


class _Sigevent(ctypes.Structure):
    """glibc's ``struct sigevent`` (x86-64 and aarch64: 64 bytes)."""
    _fields_ = [('value', ctypes.c_void_p), ('signo', ctypes.c_int), ('notify', ctypes.c_int),
                ('function', ctypes.c_void_p), ('attribute', ctypes.c_void_p),
                ('_pad', ctypes.c_int * 8)]


class _Timespec(ctypes.Structure):
    _fields_ = [('sec', ctypes.c_long), ('nsec', ctypes.c_long)]


#: What the native watchdog writes and calls, kept alive for the process's lifetime.
_NATIVE: List = []


def native_exit_watchdog(after_s: float, code: int, line: str) -> bool:
    """In ``after_s`` s, from threads of the C library's POSIX timers (``SIGEV_THREAD``:
    ``puts(line)``, ``fflush(NULL)``, then ``_exit(code)``), which need no Python and so no
    GIL: the end of a process whose teardown hung holding it. False when the C library has
    no such timers (the caller then uses faulthandler's watchdog: a stack dump, exit 1)."""
    try:
        libc = ctypes.CDLL(None)
        create, settime = libc.timer_create, libc.timer_settime
    except (OSError, AttributeError):
        return False
    text = ctypes.create_string_buffer(line.encode())
    _NATIVE.append(text)
    for i, (fn, value) in enumerate(((libc.puts, ctypes.addressof(text)), (libc.fflush, None),
                                     (libc._exit, int(code)))):
        event = _Sigevent(value=value, notify=2,           # SIGEV_THREAD
                          function=ctypes.cast(fn, ctypes.c_void_p).value)
        timer = ctypes.c_void_p()
        at = after_s + 0.2 * i     # each timer has its own thread: well apart, in order
        spec = (_Timespec * 2)(_Timespec(0, 0), _Timespec(int(at), int((at % 1) * 1e9)))
        if create(1, ctypes.byref(event), ctypes.byref(timer)) != 0 or \
                settime(timer, 0, ctypes.byref(spec), None) != 0:   # CLOCK_MONOTONIC
            return False
        _NATIVE.append(timer)
    return True


def given_parameter(name: str, args=None) -> Optional[str]:
    """The value given to parameter ``name`` in the ROS arguments, as text, before a node
    exists: ``-p name:=value`` (or ``--param``; the last wins over a file), else a
    ``--params-file`` whose ``/**`` section sets it; None if not given."""
    import yaml
    argv = list(args) if args is not None else sys.argv
    found: Dict[str, Optional[str]] = {'p': None, 'file': None}
    for flag, value in zip(argv, argv[1:]):
        if flag in ('-p', '--param') and value.startswith(name + ':='):
            found['p'] = value.split(':=', 1)[1]
        elif flag == '--params-file':
            try:
                with open(value) as fh:       # (libyaml's parser when there: 4x less CPU)
                    doc = yaml.load(fh, getattr(yaml, 'CSafeLoader', yaml.SafeLoader)) or {}
                got = doc.get('/**', {}).get('ros__parameters', {}).get(name)
            except (OSError, AttributeError, yaml.YAMLError):
                continue             # (rcl says what is wrong with the file)
            found['file'] = found['file'] if got is None else str(got)
    return found['p'] if found['p'] is not None else found['file']


def _node_name(args, factory) -> str:
    """Node name from ``-r __node:=NAME`` in the arguments, else the factory's name."""
    argv = list(args) if args is not None else sys.argv
    for item in argv:
        if item.startswith('__node:='):
            return item.split(':=', 1)[1]
    return getattr(factory, '__name__', 'node')


def exit_now(code: int) -> None:
    """End the process with ``code`` at once, without the interpreter's teardown, after
    flushing the streams, the logging handlers and a measured subprocess's coverage data."""
    coverage = sys.modules.get('coverage')      # (never imported here: 0.1-0.5 s)
    try:
        cov = coverage.Coverage.current() if coverage is not None else None
        if cov is not None:
            cov.stop()
            cov.save()
    except Exception:  # noqa: BLE001 - it cannot save: exit anyway
        pass
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


def run(factory: Callable[[], Node], args=None, exit_process: bool = True) -> int:
    """Entry point body of a node executable: init rclpy, build the node, spin, shut down.
    Exit code 0, or 2 on a configuration error (a ``ValueError`` while building: one line
    naming the node); a bug propagates (traceback, 1). ``exit_process``: end the process
    (:func:`exit_now`), else return the code. A crash in C dumps the stack (faulthandler)."""
    code = _run(factory, args, exit_process)
    if exit_process:
        exit_now(code)
    return code


#: CPU seconds of this process when a node's ``main`` called :func:`run` (interpreter start
#: and imports); None in a process started otherwise (the composed runner).
CPU_AT_RUN_S: List[Optional[float]] = [None]
#: The line a node logs when it is ready for its first frame (:func:`start_cost`; the bench's
#: start-up row reads it).
START_COST_PREFIX = 'start cost '


def start_cost(t_ns: int) -> str:
    """The start-cost line at the first frame ``t_ns`` [ns]: this process's CPU seconds now,
    and before :func:`run` (``import_cpu_s``), as JSON."""
    out = {'t_s': t_ns / 1e9, 'cpu_s': round(time.process_time(), 3)}
    if CPU_AT_RUN_S[0] is not None:
        out['import_cpu_s'] = round(CPU_AT_RUN_S[0], 3)
    return START_COST_PREFIX + json.dumps(out)


def _run(factory: Callable[[], Node], args, exit_process: bool) -> int:
    CPU_AT_RUN_S[0] = time.process_time()
    old_handlers = stop_handler_from_start()
    try:
        faulthandler.enable()
        # SIGUSR1: every thread's stack to the log, the process goes on (the launcher asks a
        # node that does not become active in time, to say where it is stuck)
        faulthandler.register(signal.SIGUSR1, all_threads=True)
    except (OSError, ValueError, AttributeError):   # stderr without a file descriptor
        pass                                         # (captured in tests); no SIGUSR1
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        try:
            node = factory()
        except ValueError as exc:
            print(f'[{_node_name(args, factory)}] configuration error: {exc}', file=sys.stderr)
            return 2
        prof_dir = os.environ.get('ADCS_NODE_PROFILE', '')
        if prof_dir:   # developer aid (docs/bench.md): cProfile (CPU clock) of the spin
            import cProfile
            name = node.get_name()
            prof = cProfile.Profile(time.process_time)
            prof.runcall(spin_nodes, [node])
            prof.dump_stats(os.path.join(prof_dir, f'{name}.prof'))
        else:
            spin_nodes([node], teardown_s=TEARDOWN_BUDGET_S if exit_process else None)
        return int(getattr(node, 'exit_code', 0))
    except KeyboardInterrupt:   # (a SIGINT before the stop handler; not expected)
        print(f'[{_node_name(args, factory)}] interrupted during start-up', file=sys.stderr)
        return 0
    except BaseException:       # a bug: the traceback and exit code 1, rclpy shut down first
        if rclpy.ok():
            rclpy.shutdown()
        raise
    finally:
        # a process that ends now skips rclpy's shutdown (its logging finalisation hung)
        if not exit_process and rclpy.ok():
            rclpy.shutdown()
        restore_handlers(old_handlers)
