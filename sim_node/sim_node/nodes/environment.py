"""``environment`` node: orbit state and geomagnetic field of the simulated world.

Subscribes ``/clock``; for every clock tick t_k publishes ``sim/environment`` stamped t_k:
r, v (ECI), q_eci_orbit, orbit rate, argument of latitude, B (ECI) and dB/dt, q_eci_ecef.

In a launched lockstep run (``duration_s`` given, not real-time) it runs one frame ahead: the
environment depends on time only, so on ``/clock`` t_k it also publishes t_k+1 (never past
the duration), each message once; consumers take them by stamp (``FrameSync``). Started alone
it answers each clock tick only. Models: ``core.orbit`` and ``core.geomag`` (parameters
``orbit.*`` and ``field.*``, the scenario's sections).
"""
from __future__ import annotations

from rosgraph_msgs.msg import Clock

from adcs_msgs.msg import Environment
from adcs_nodes.core.geomag import FIELD
from adcs_nodes.core.orbit import ORBIT
from adcs_nodes.msgs.convert import ENVIRONMENT
from adcs_nodes.msgs.fields import stamp_ns
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.lockstep_node import LockstepNode
from adcs_nodes.nodes.tf import TfPublisher, earth_transforms
from sim_node.components.environment import EnvironmentComponent


class EnvironmentNode(LockstepNode):
    """Publishes the orbit and field at each ``/clock`` tick (see module docstring)."""

    SIMULATED_WORLD = True      # the simulator: lockstep only

    def __init__(self, name: str = 'environment', **kwargs) -> None:
        super().__init__(name, **kwargs)
        self.component = EnvironmentComponent(
            self.section('orbit', ORBIT), self.section('field', FIELD), self.epoch)
        node_params.refuse_unknown(self)
        node_params.install_validator(self)
        self.orbit, self.field = self.component.orbit, self.component.field
        self.pub = self.publisher(Environment, 'sim/environment')
        self.tf_pub = TfPublisher(self)            # /tf: eci -> ecef
        self.subscription(Clock, '/clock', self.on_clock)
        self._last_ns = None
        self._ahead_ns = None        # frame already published ahead (lockstep)
        self.start_handshake()

    def on_clock(self, msg: Clock) -> None:
        """One frame: publish for the clock's time unless that was done ahead, then (lockstep)
        the next frame ahead (duplicate clocks ignored)."""
        t_ns = self.elapsed_ns(stamp_ns(msg.clock))
        if t_ns == self._last_ns:
            return
        self._last_ns = t_ns
        if t_ns != self._ahead_ns:
            self.publish_frame(t_ns)
        t_next = t_ns + self.frame_ns
        if not self.real_time and 0 < t_next <= self.duration_ns:
            self.publish_frame(t_next)
            self._ahead_ns = t_next
        self.report_progress(t_ns, final=self.is_last_frame(t_ns, self.frame_ns))

    def publish_frame(self, t_ns: int) -> None:
        """Compute and publish ``sim/environment`` (and ``/tf``, ``/diagnostics``) of ``t_ns``."""
        x = self.component.step(t_ns)
        msg = ENVIRONMENT.to_msg(x, self.epoch_ns)
        self.pub.publish(msg)
        if self.tf_pub.wanted():           # only built when someone reads /tf
            self.tf_pub.send(earth_transforms(msg.header.stamp, x.q_eci_ecef))
        self.frames += 1
        self.sim_t_ns = t_ns
        self.diagnostics.frame(t_ns)      # /diagnostics once per sim second


def main(args=None) -> int:
    """``ros2 run sim_node environment``."""
    return runtime.run(EnvironmentNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
