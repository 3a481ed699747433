"""Bare lockstep ring of two rclpy processes: the transport limit of a lockstep frame.

A frame of the real graph is a chain of dependent messages ("hops") between processes; for
paper 000's closed loop at 1 s frames: ``/clock`` -> environment -> dynamics is 2 hops; on a
frame with a command due, ``/clock`` -> estimator -> controller -> manager -> dynamics is 4;
on a magnetometer frame ``... dynamics -> sim/state -> magnetometer -> estimator -> controller
-> manager -> dynamics`` is 7 (:func:`perf.bench.hop_pattern`). This ring relays one
message ``hops[k % len(hops)]`` times for frame ``k`` between process A and process B (the
message carries frame ``k`` in ``clock.sec`` and the hop index in ``clock.nanosec``), with the
same QoS as the graph (``QOS_DATA``) and the same executor (``runtime.make_executor``). No
model work: this is the ceiling of a graph with that critical path.

Start without fixed sleeps: B publishes a hello (``sec = -1``) once its publisher and its
subscription are matched, until the first hop arrives; A starts when it has the hello and its
own publisher has a matched subscription. After ``warmup`` untimed frames, the process that
receives the first hop of frame ``warmup`` notes the time (``time.monotonic``: one system-wide
clock, comparable between the two processes), the one that receives the first hop of frame
``warmup + frames`` notes the end, forwards that message once (so the other one also ends)
and exits. Each process prints one JSON line: its times and its CPU seconds over the timed
frames (``time.process_time`` at its first timed message and at the end). Each ring runs in
its own ``ROS_DOMAIN_ID`` (101..200, claimed with a lock file next to the launcher's 1..100)
with localhost-only discovery.

Usage (what :func:`run_ring` does)::

    PYTHONPATH=tests python -m perf.bench_ring pong --hops 7,2,4,2 &
    PYTHONPATH=tests python -m perf.bench_ring ping --hops 7,2,4,2 --frames 3000 --warmup 200
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

from adcs_nodes.tools.run.launcher import LaunchError, acquire_domain, child_env

PING, PONG = 'bench/ping', 'bench/pong'
#: ``ROS_DOMAIN_ID`` range of the bench rings (the launcher uses 1..100).
DOMAINS = range(101, 201)
#: Wall seconds a ring process gives its ROS teardown after printing its result.
TEARDOWN_S = 10.0


class RingError(RuntimeError):
    """The ring did not start or did not finish; the message says which process and why."""


@dataclass
class RingResult:
    """One timed ring run.

    Attributes
    ----------
    frames : int
        Timed frames (after the warm-up).
    hops : int
        Messages relayed in the timed frames.
    seconds : float
        Wall time of the timed frames [s].
    frames_per_s : float
        ``frames / seconds`` [1/s].
    cpu_s : float
        CPU seconds of both processes over the timed frames [s].
    cpu_total_s : float
        CPU seconds of both processes from start to exit (start-up included) [s].
    executor : str
        Executor class of the ping process.
    rmw : str
        RMW implementation identifier.
    """

    frames: int
    hops: int
    seconds: float
    frames_per_s: float
    cpu_s: float
    cpu_total_s: float
    executor: str
    rmw: str


# ---------------------------------------------------------------------- processes
def _start_node(name: str):
    """Init rclpy (no signal handlers), create ``name`` and an executor holding it."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from adcs_nodes.nodes.runtime import make_executor

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(name, start_parameter_services=False)
    executor = make_executor()
    executor.add_node(node)
    return rclpy, node, executor


def _stamp(k: int, j: int = 0):
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock
    return Clock(clock=Time(sec=k, nanosec=j))


def relay_main(starter: bool, hops: Sequence[int], frames: int, warmup: int,
               timeout_s: float) -> int:
    """One ring process (A if ``starter`` else B): relay hops, print the result as JSON."""
    from rclpy.task import Future
    from rosgraph_msgs.msg import Clock

    from adcs_nodes.nodes.lockstep_node import QOS_DATA

    rclpy, node, executor = _start_node('bench_ping' if starter else 'bench_pong')
    pub = node.create_publisher(Clock, PING if starter else PONG, QOS_DATA)
    done = Future()
    end = warmup + frames
    st: Dict[str, Optional[float]] = {'started': False, 'hello': False, 'got': False,
                                      't0': None, 't1': None, 'cpu0': None, 'cpu1': None}

    def try_start() -> None:
        if starter and not st['started'] and st['hello'] and pub.get_subscription_count() >= 1:
            st['started'] = True
            pub.publish(_stamp(0, 0))

    def on_msg(msg: Clock) -> None:
        k, j = int(msg.clock.sec), int(msg.clock.nanosec)
        if k < 0:   # B's hello
            st['hello'] = True
            try_start()
            return
        st['got'] = True
        if st['cpu0'] is None and k >= warmup:
            st['cpu0'] = time.process_time()
        if k == warmup and j == 0:
            st['t0'] = time.monotonic()
        if k >= end:
            if st['t1'] is None and j == 0:
                st['t1'] = time.monotonic()
                pub.publish(_stamp(k, 1))   # once, untimed: the other process ends too
            st['cpu1'] = time.process_time()
            if not done.done():
                done.set_result(True)
            return
        j += 1
        if j >= hops[k % len(hops)]:
            k, j = k + 1, 0
        pub.publish(_stamp(k, j))

    sub = node.create_subscription(Clock, PONG if starter else PING, on_msg, QOS_DATA)

    def on_timer() -> None:
        if starter:
            try_start()
        elif not st['got'] and pub.get_subscription_count() >= 1 \
                and sub.get_publisher_count() >= 1:
            pub.publish(_stamp(-1))

    def on_signal(signum, frame) -> None:
        if not done.done():
            done.set_result(False)

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    node.create_timer(0.02, on_timer)
    deadline = time.monotonic() + timeout_s
    while not done.done() and time.monotonic() < deadline:
        executor.spin_until_future_complete(done, timeout_sec=0.1)
    if done.done() and done.result():
        executor.spin_until_future_complete(Future(), timeout_sec=0.05)  # let the forward go
    ok = done.done() and bool(done.result())
    print(json.dumps({'t0': st['t0'], 't1': st['t1'], 'cpu0': st['cpu0'], 'cpu1': st['cpu1'],
                      'executor': type(executor).__name__,
                      'rmw': rclpy.get_rmw_implementation_identifier()}), flush=True)
    if not ok:
        print(f'{"ping" if starter else "pong"}: did not finish (started={st["started"]}, '
              f'hello={st["hello"]}, matched subscriptions={pub.get_subscription_count()}) '
              f'after {timeout_s:g} s', file=sys.stderr)
    code = 0 if ok else 1

    def teardown() -> None:
        executor.remove_node(node)
        node.destroy_node()
        executor.shutdown()
        rclpy.shutdown()
    # the result is printed: a ROS teardown that blocks (seen once at load 5: the ping process
    # printed nothing more and was killed 80 s later) must not lose it
    closer = threading.Thread(target=teardown, daemon=True)
    closer.start()
    closer.join(TEARDOWN_S)
    if closer.is_alive():
        print(f'{"ping" if starter else "pong"}: ROS teardown did not finish within '
              f'{TEARDOWN_S:g} s; exiting without it', file=sys.stderr, flush=True)
        os._exit(code)
    return code


# ---------------------------------------------------------------------- driver
def acquire_bench_domain() -> Tuple[int, object]:
    """Claim a free ``ROS_DOMAIN_ID`` in 101..200 (apart from ``adcs run``'s 1..100)."""
    try:
        return acquire_domain(DOMAINS)
    except LaunchError as exc:
        raise RingError(str(exc)) from None


def _stop(proc: subprocess.Popen, grace_s: float = 5.0) -> None:
    """SIGTERM one child we started, SIGKILL it after ``grace_s``."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def _children_cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run_ring(frames: int, hops: Sequence[int] = (2,), warmup: int = 200,
             timeout_s: float = 60.0) -> RingResult:
    """Start the two ring processes in a private domain, time ``frames`` frames.

    Parameters
    ----------
    frames : int
        Timed frames, ``>= 1``.
    hops : sequence of int
        Hops (messages) of frame ``k`` are ``hops[k % len(hops)]``, each ``>= 1``.
    warmup : int
        Untimed frames first (discovery tail, caches), ``>= 1``.
    timeout_s : float
        Wall-clock limit for the whole ring, start-up included [s].

    Returns
    -------
    RingResult

    Raises
    ------
    ValueError
        On ``frames < 1``, ``warmup < 1`` or a bad hop list.
    RingError
        If a process fails or the ring does not finish in time (with the processes' output).
    """
    hops = [int(h) for h in hops]
    if frames < 1 or warmup < 1:
        raise ValueError(f'frames and warmup must be >= 1, got {frames}, {warmup}')
    if not hops or min(hops) < 1:
        raise ValueError(f'hops must be a non-empty list of integers >= 1, got {hops}')
    domain, lock = acquire_bench_domain()
    env: Dict[str, str] = child_env(domain)     # the same transport as the graph runs
    cmd: List[str] = [sys.executable, '-m', 'perf.bench_ring']
    env['PYTHONPATH'] = os.pathsep.join(
        [os.path.dirname(os.path.dirname(os.path.abspath(__file__)))]
        + [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p])
    common = ['--hops', ','.join(map(str, hops)), '--frames', str(frames), '--warmup',
              str(warmup)]
    cpu_before = _children_cpu_s()
    pong = subprocess.Popen(cmd + ['pong', *common, '--timeout', str(timeout_s + 10.0)],
                            env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        ping = subprocess.Popen(cmd + ['ping', *common, '--timeout', str(timeout_s)],
                                env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        try:
            out, err = ping.communicate(timeout=timeout_s + 20.0)
        except subprocess.TimeoutExpired:
            ping.kill()
            out, err = ping.communicate()
        try:
            pong_out, pong_err = pong.communicate(timeout=10.0)
        except subprocess.TimeoutExpired:
            _stop(pong)
            pong_out, pong_err = pong.communicate()
    finally:
        _stop(pong)
        lock.close()
    cpu_total = _children_cpu_s() - cpu_before

    def last_json(text: str) -> dict:
        lines = [ln for ln in text.splitlines() if ln.startswith('{')]
        return json.loads(lines[-1]) if lines else {}

    a, b = last_json(out), last_json(pong_out)
    t0 = a.get('t0') if a.get('t0') is not None else b.get('t0')
    t1 = a.get('t1') if a.get('t1') is not None else b.get('t1')
    if ping.returncode != 0 or pong.returncode not in (0, None) or t0 is None or t1 is None:
        raise RingError(f'ring failed (ping exit {ping.returncode}, pong exit '
                        f'{pong.returncode}, domain {domain}):\n'
                        f'ping: {err.strip()[-2000:]}\npong: {pong_err.strip()[-2000:]}')
    cpu = sum(d['cpu1'] - d['cpu0'] for d in (a, b)
              if d.get('cpu0') is not None and d.get('cpu1') is not None)
    n_hops = sum(hops[k % len(hops)] for k in range(warmup, warmup + frames))
    dt = float(t1) - float(t0)
    return RingResult(frames, n_hops, dt, frames / dt, cpu, cpu_total, str(a['executor']),
                      str(a['rmw']))


def parse_hops(text: str) -> List[int]:
    """``"7,2,4,2"`` -> ``[7, 2, 4, 2]``."""
    try:
        hops = [int(h) for h in text.split(',')]
    except ValueError:
        raise argparse.ArgumentTypeError(f'bad --hops {text!r} (want e.g. 7,2,4,2)') from None
    if not hops or min(hops) < 1:
        raise argparse.ArgumentTypeError(f'bad --hops {text!r}: each must be >= 1')
    return hops


def main(argv=None) -> int:
    """Entry point of one ring process (``ping`` starts the relay, ``pong`` answers)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('role', choices=['ping', 'pong'])
    ap.add_argument('--hops', type=parse_hops, default=[2], help='hops per frame, cycled')
    ap.add_argument('--frames', type=int, default=3000, help='timed frames')
    ap.add_argument('--warmup', type=int, default=200, help='untimed frames first (>= 1)')
    ap.add_argument('--timeout', type=float, default=60.0, help='wall-clock limit [s]')
    args = ap.parse_args(argv)
    return relay_main(args.role == 'ping', args.hops, args.frames, max(1, args.warmup),
                      args.timeout)


if __name__ == '__main__':
    raise SystemExit(main())
