"""Bare lockstep ring of two rclpy processes: the transport limit of a 2-hop world frame.

Process A (``ping``) publishes a stamp on ``bench/ping``; process B (``pong``) echoes it on
``bench/pong``; A publishes the next stamp when the echo arrives. One round trip is one
lockstep frame of the world graph (``/clock`` -> ``sim/environment`` -> next ``/clock``), with
the same QoS as the graph (``QOS_DATA``: reliable, keep last 100) and the same executor
(``runtime.make_executor``: ``EventsExecutor``). No model work: this is the ceiling.

Start without fixed sleeps: B publishes a hello (stamp ``sec = -1``) once its publisher and its
subscription are matched, and repeats it until the first ping arrives; A starts when it has
the hello and its own publisher has a matched subscription. A runs ``warmup`` untimed frames,
then ``frames`` timed ones, and prints one JSON line. B stops on SIGINT/SIGTERM or when A's
publisher has gone. Each ring runs in its own ``ROS_DOMAIN_ID`` (101..200, claimed with a lock
file next to the launcher's 1..100) with localhost-only discovery.

Usage (what :func:`run_ring` does)::

    python -m sim_node.tools.bench_ring pong &
    python -m sim_node.tools.bench_ring ping --frames 3000 --warmup 200
"""
from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from typing import Dict, List, Tuple

from adcs_nodes.tools.launcher import LaunchError, acquire_domain, child_env

PING, PONG = 'bench/ping', 'bench/pong'
#: ``ROS_DOMAIN_ID`` range of the bench rings (the launcher uses 1..100).
DOMAINS = range(101, 201)


class RingError(RuntimeError):
    """The ring did not start or did not finish; the message says which process and why."""


@dataclass
class RingResult:
    """One timed ring run.

    Attributes
    ----------
    frames : int
        Timed round trips (after the warm-up).
    seconds : float
        Wall time of the timed round trips [s].
    frames_per_s : float
        ``frames / seconds`` [1/s].
    executor : str
        Executor class of the ping process.
    rmw : str
        RMW implementation identifier.
    """

    frames: int
    seconds: float
    frames_per_s: float
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


def _stamp(k: int):
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock
    return Clock(clock=Time(sec=k, nanosec=0))


def ping_main(frames: int, warmup: int, timeout_s: float) -> int:
    """Process A: drive ``warmup + frames`` round trips, print the result as JSON."""
    from rclpy.task import Future
    from rosgraph_msgs.msg import Clock

    from adcs_nodes.nodes.lockstep_node import QOS_DATA

    rclpy, node, executor = _start_node('bench_ping')
    pub = node.create_publisher(Clock, PING, QOS_DATA)
    done = Future()
    st = {'k': -1, 'hello': False, 't0': 0.0, 't1': 0.0}

    def try_start() -> None:
        if st['k'] < 0 and st['hello'] and pub.get_subscription_count() >= 1:
            st['k'] = 0
            if warmup == 0:
                st['t0'] = time.perf_counter()
            pub.publish(_stamp(0))

    def on_pong(msg: Clock) -> None:
        k = int(msg.clock.sec)
        if k < 0:
            st['hello'] = True
            try_start()
            return
        if k != st['k']:
            return  # a duplicate; lockstep waits for the echo of the current stamp
        k += 1
        st['k'] = k
        if k == warmup:
            st['t0'] = time.perf_counter()
        if k == warmup + frames:
            st['t1'] = time.perf_counter()
            done.set_result(True)
            return
        pub.publish(_stamp(k))

    node.create_subscription(Clock, PONG, on_pong, QOS_DATA)
    node.create_timer(0.02, try_start)   # the publisher may match after the hello
    deadline = time.monotonic() + timeout_s
    while not done.done() and time.monotonic() < deadline:
        executor.spin_until_future_complete(done, timeout_sec=0.1)
    code = 0
    if done.done():
        dt = st['t1'] - st['t0']
        print(json.dumps({'frames': frames, 'seconds': dt, 'frames_per_s': frames / dt,
                          'executor': type(executor).__name__,
                          'rmw': rclpy.get_rmw_implementation_identifier()}), flush=True)
    else:
        print(f'ping: stuck at frame {st["k"]} (hello={st["hello"]}, matched subscriptions='
              f'{pub.get_subscription_count()}) after {timeout_s:g} s', file=sys.stderr)
        code = 1
    executor.remove_node(node)
    node.destroy_node()
    executor.shutdown()
    rclpy.shutdown()
    return code


def pong_main(timeout_s: float) -> int:
    """Process B: echo every ping; say hello until the first ping; stop when A is gone."""
    from rclpy.task import Future
    from rosgraph_msgs.msg import Clock

    from adcs_nodes.nodes.lockstep_node import QOS_DATA

    rclpy, node, executor = _start_node('bench_pong')
    pub = node.create_publisher(Clock, PONG, QOS_DATA)
    st = {'pinged': False, 'stop': False}

    def on_ping(msg: Clock) -> None:
        st['pinged'] = True
        pub.publish(msg)

    sub = node.create_subscription(Clock, PING, on_ping, QOS_DATA)

    def on_timer() -> None:
        if not st['pinged']:
            if pub.get_subscription_count() >= 1 and sub.get_publisher_count() >= 1:
                pub.publish(_stamp(-1))
        elif sub.get_publisher_count() == 0:
            st['stop'] = True   # the ping process has ended

    def on_signal(signum, frame) -> None:
        st['stop'] = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    node.create_timer(0.05, on_timer)
    never = Future()
    deadline = time.monotonic() + timeout_s
    while not st['stop'] and time.monotonic() < deadline:
        executor.spin_until_future_complete(never, timeout_sec=0.1)
    executor.remove_node(node)
    node.destroy_node()
    executor.shutdown()
    rclpy.shutdown()
    return 0


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


def run_ring(frames: int, warmup: int = 200, timeout_s: float = 60.0) -> RingResult:
    """Start the two ring processes in a private domain, time ``frames`` round trips.

    Parameters
    ----------
    frames : int
        Timed round trips (lockstep frames), ``>= 1``.
    warmup : int
        Untimed round trips first (discovery tail, shared-memory set-up, caches).
    timeout_s : float
        Wall-clock limit for the whole ring, start-up included [s].

    Returns
    -------
    RingResult

    Raises
    ------
    RingError
        If a process fails or the ring does not finish in time (with the processes' output).
    """
    if frames < 1:
        raise ValueError(f'frames must be >= 1, got {frames}')
    domain, lock = acquire_bench_domain()
    env: Dict[str, str] = child_env(domain)     # the same transport as the graph runs
    cmd: List[str] = [sys.executable, '-m', 'sim_node.tools.bench_ring']
    pong = subprocess.Popen(cmd + ['pong', '--timeout', str(timeout_s + 10.0)], env=env,
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        ping = subprocess.Popen(cmd + ['ping', '--frames', str(frames), '--warmup',
                                       str(warmup), '--timeout', str(timeout_s)],
                                env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        try:
            out, err = ping.communicate(timeout=timeout_s + 20.0)
        except subprocess.TimeoutExpired:
            ping.kill()
            out, err = ping.communicate()
    finally:
        _stop(pong)
        lock.close()
    lines = [ln for ln in out.splitlines() if ln.startswith('{')]
    if ping.returncode != 0 or not lines:
        pong_err = pong.stderr.read() if pong.stderr else ''
        raise RingError(f'ring failed (ping exit {ping.returncode}, domain {domain}):\n'
                        f'ping: {err.strip()[-2000:]}\npong: {pong_err.strip()[-2000:]}')
    if pong.stderr:
        pong.stderr.close()
    data = json.loads(lines[-1])
    return RingResult(int(data['frames']), float(data['seconds']), float(data['frames_per_s']),
                      str(data['executor']), str(data['rmw']))


def main(argv=None) -> int:
    """Entry point of one ring process (``ping`` or ``pong``)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('role', choices=['ping', 'pong'])
    ap.add_argument('--frames', type=int, default=3000, help='timed round trips')
    ap.add_argument('--warmup', type=int, default=200, help='untimed round trips first')
    ap.add_argument('--timeout', type=float, default=60.0, help='wall-clock limit [s]')
    args = ap.parse_args(argv)
    if args.role == 'ping':
        return ping_main(args.frames, args.warmup, args.timeout)
    return pong_main(args.timeout)


if __name__ == '__main__':
    raise SystemExit(main())
