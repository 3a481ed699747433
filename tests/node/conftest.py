"""In-process rclpy fixtures: a private context on a private ROS domain per test."""
import itertools
import time

import pytest

rclpy = pytest.importorskip('rclpy')

from domains import worker_domain  # noqa: E402
from adcs_nodes.tools.run.launcher import child_env, use_dds_env  # noqa: E402

#: One domain per test (150-199, outside the launcher's run domains): a participant of an
#: earlier test that DDS still lists (its lease not expired) is not discovered by the next.
_TEST_NUMBER = itertools.count()


@pytest.fixture
def ros_context():
    """A fresh rclpy context on this test's own domain (localhost discovery)."""
    # the launcher's middleware settings: loopback discovery and UDP by its Fast DDS profile
    use_dds_env(child_env(worker_domain(150, 50, next(_TEST_NUMBER))))
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    if ctx.ok():
        rclpy.shutdown(context=ctx)


@pytest.fixture
def spin(ros_context):
    """``spin(nodes, until, timeout, executor=None)``: spin nodes on one executor (a
    ``SingleThreadedExecutor`` unless one is given) until ``until()`` or timeout.

    Returns True when ``until()`` became true, False on timeout. The default timeout (30 s)
    only costs time when the condition never comes: beside CPU burners a wait of a few
    seconds can run out before a correct node answered.
    """
    from rclpy.executors import SingleThreadedExecutor

    executors = []

    def _spin(nodes, until, timeout=30.0, executor=None):
        ex = executor if executor is not None else SingleThreadedExecutor(context=ros_context)
        executors.append(ex)
        for n in nodes:
            ex.add_node(n)
        deadline = time.monotonic() + timeout
        try:
            while time.monotonic() < deadline:
                ex.spin_once(timeout_sec=0.01)
                if until():
                    return True
            return False
        finally:
            for n in nodes:
                ex.remove_node(n)
            if executor is not None:   # (an EventsExecutor keeps its entities' callbacks
                ex.shutdown()          # until shut down)

    yield _spin
    for ex in executors:
        ex.shutdown()
