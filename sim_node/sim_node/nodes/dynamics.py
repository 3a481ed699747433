"""``dynamics`` node: the spacecraft's rigid-body motion, and the clock master of the lockstep.

Frame k (DESIGN section 6), lockstep mode::

    A. publish /clock = epoch + t_k            -> environment publishes sim/environment(t_k)
    B. on sim/environment(t_k): publish sim/state(t_k), sim/wheels(t_k)
                                               -> sensors, estimator, controllers, manager ...
    C. if a command is due at t_k: wait for adcs/actuator_command stamped t_k
       hold it (zero-order hold) and integrate t_k -> t_k+1 (fixed RK4 substeps)
    D. k += 1, back to A (after the last frame: done, the process exits 0)

With ``spacecraft.flexible`` phase B also publishes the modal coordinates on
``sim/appendages``; the wheel driver status is in ``/diagnostics`` (``wheels_torque_limited``,
``wheels_momentum_limited``: the wheels limited in the last frame, and frame counters; a wheel
reaching or leaving its momentum limit is logged). Missing input past ``timeout_s``: a missed
frame, the last environment or a zero command; a dead command producer gets a zero command
without waiting (DESIGN section 6). The state machine is the pure
:class:`adcs_nodes.core.lockstep.ClockMaster`; this node executes its actions. Real-time
mode: a wall timer at ``frame_period_s / rate_factor`` steps with the latest inputs.
"""
from __future__ import annotations

import json
import os
import time
from typing import Any, List

from diagnostic_msgs.msg import DiagnosticArray
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from adcs_msgs.msg import (ActuatorCommand, AppendageState, AttitudeState, Environment,
                           LockstepStatus, WheelState)
from adcs_nodes.core.lockstep import Act, Action, ClockMaster, ns_to_seconds, seconds_to_ns
from adcs_nodes.core.samples import all_finite
from adcs_nodes.msgs import convert
from adcs_nodes.msgs.fields import make, stamp_ns, to_stamp
from adcs_nodes.nodes import params as node_params
from adcs_nodes.nodes import publisher_guard, runtime
from adcs_nodes.nodes.adapter import node_log
from adcs_nodes.nodes.lockstep_node import (MAX_LAG_FRAMES, QOS_DATA, QOS_READY,
                                            LockstepNode)
from adcs_nodes.nodes.tf import TfPublisher, truth_transforms
from sim_node.components.dynamics import DynamicsComponent
from sim_node.entries import DYNAMICS_PARAMS
from sim_node.faults import FAULTS_PARAM, INJECT_TOPIC, injected
from sim_node.faults import parse as parse_faults
from sim_node.models.spacecraft_config import INITIAL, SPACECRAFT

QOS_CLOCK = QOS_DATA
#: The recorder may lag no further than the lockstep nodes: what it has not received must
#: still be in the publishers' history (QOS_DATA keeps 100 per topic) to be resent.
RECORDER_LAG_FRAMES = MAX_LAG_FRAMES


class DynamicsNode(LockstepNode):
    """Clock master and rigid-body integrator (see module docstring)."""

    SIMULATED_WORLD = True      # the simulator: lockstep only

    def __init__(self, name: str = 'dynamics', **kwargs) -> None:
        super().__init__(name, **kwargs)
        self.duration_ns = seconds_to_ns(self.param('duration_s', 0.0))
        p = node_params.declare_all(self, DYNAMICS_PARAMS + (FAULTS_PARAM,))
        self.substeps = p['substeps']
        self.rate_factor = p['rate_factor']
        cmd_period_s = p['command_period_s']
        cmd_ns = seconds_to_ns(cmd_period_s) if cmd_period_s else 0
        if cmd_ns % self.frame_ns:
            raise ValueError('command_period_s must be a multiple of frame_period_s')
        self.wait_for_nodes = [n for n in p['wait_for_nodes'] if n]
        self.result_file = p['result_file']
        self.component = DynamicsComponent(
            self.section('spacecraft', SPACECRAFT), self.section('initial', INITIAL),
            self.seed, self.frame_ns, self.substeps, node_log(self), parse_faults(p['faults']))
        self.spacecraft = self.component.spacecraft
        self.wheel_names = self.component.wheel_names

        self.master = ClockMaster(
            self.frame_ns, self.duration_ns, cmd_ns, self.wait_for_nodes, self.timeout_s,
            max_lag_frames=MAX_LAG_FRAMES, lag_frames={'recorder': RECORDER_LAG_FRAMES},
            dead_after=self.dead_after, no_final=['recorder'], always_wait=['recorder'],
            pace_s=(ns_to_seconds(self.frame_ns) / p['lockstep_max_rate']
                    if p['lockstep_max_rate'] > 0 else 0.0))
        self._exec_t = 0              # frame of the action being executed
        self._topics_of = {'env': 'sim/environment', 'cmd': 'adcs/actuator_command'}
        self.clock_pub = self.publisher(Clock, '/clock', QOS_CLOCK)
        self.state_pub = self.publisher(AttitudeState, 'sim/state')
        self.wheels_pub = self.publisher(WheelState, 'sim/wheels')
        self.appendages_pub = (self.publisher(AppendageState, 'sim/appendages')
                               if self.spacecraft.n_modes else None)
        self.tf_pub = TfPublisher(self)             # /tf: eci -> orbit -> body (truth)
        # sim/faults: the scenario's faults, and live ones (adcs fault: sim/inject_fault, not
        # part of the lockstep handshake), announced at the frame they start or end in; there
        # from the start, so a listener has matched it before a live fault comes
        self.faults_pub = self.publisher(DiagnosticArray, 'sim/faults')
        self.create_subscription(String, INJECT_TOPIC, self.on_inject_fault, QOS_DATA)
        # expected_publishers (the launcher: environment, controller_manager): messages of
        # any other publisher, and duplicate stamps, are dropped and reported (publisher_guard)
        guard = publisher_guard.for_node(self)
        for msg_type, topic, cb in ((Environment, 'sim/environment', self.on_environment),
                                    (ActuatorCommand, 'adcs/actuator_command', self.on_command)):
            self.subscription(msg_type, topic, cb if guard is None else
                              guard.wrap(self.resolve_topic_name(topic), cb))
        self.ready_nodes = set()
        self.create_subscription(String, 'lockstep/ready', self.on_ready_msg, QOS_READY)
        # flow control and end of run: how far every other node got (lockstep/progress)
        self.create_subscription(LockstepStatus, 'lockstep/progress', self.on_progress,
                                 QOS_DATA)
        self.create_subscription(LockstepStatus, 'recorder/status', self.on_recorder, 10)

        self.started = False
        # the watchdog also starts the frames of a paced run (ClockMaster.tick)
        self.create_timer(min(0.05, self.timeout_s / 4.0,
                              self.master.pace_s / 2.0 if self.master.pace_s else 0.05),
                          self.on_watchdog)
        self.start_timeout_s = p['start_timeout_s']
        node_params.refuse_unknown(self)
        node_params.install_validator(self)
        self._created = time.monotonic()
        self.start_handshake(self.try_start)

    # ------------------------------------------------------------------ start
    def on_ready_msg(self, msg: String) -> None:
        """Collect ``lockstep/ready`` announcements of the other nodes."""
        self.ready_nodes.add(msg.data)
        self.try_start()

    def try_start(self) -> None:
        """Start frame 0 once we and every node in ``wait_for_nodes`` are ready."""
        if self.started or not self._ready_sent:
            return
        if any(n not in self.ready_nodes for n in self.wait_for_nodes):
            return
        self.started = True
        self.get_logger().info(
            f'lockstep start: frame {self.frame_ns / 1e9:g} s, {self.substeps} RK4 substeps, '
            f'duration {self.duration_ns / 1e9:g} s, real_time={self.real_time}')
        self.wall_start = time.monotonic()
        self._wall0 = self.wall_start      # status wall_time counts from the lockstep start
        if self.real_time:
            self.create_timer(ns_to_seconds(self.frame_ns) / self.rate_factor, self.on_rt_tick)
        else:
            self._run(self.master.start(time.monotonic()))

    # ------------------------------------------------------------------ lockstep
    @property
    def t_ns(self) -> int:
        """Elapsed sim time of the frame being published or integrated."""
        return self._exec_t

    @property
    def sync(self):
        """The clock master's ``FrameSync`` of ``env`` and ``cmd``."""
        return self.master.sync

    @property
    def throttled_frames(self) -> int:
        """Times the clock waited for a lagging node."""
        return self.master.throttled_frames

    def _run(self, actions: List[Action]) -> None:
        """Execute the clock master's actions in order."""
        for a in actions:
            self._exec_t = a.t_ns
            if a.kind is Act.CLOCK:
                self.clock_pub.publish(make(Clock, clock=to_stamp(self.epoch_ns + a.t_ns)))
            elif a.kind is Act.STATE:
                self.publish_state(a.value)
                self.frame_done(a.t_ns)
            elif a.kind is Act.STEP:
                self.step_frame(a.t_ns, *a.value)
            elif a.kind is Act.MISSED:
                self.count_missed(a.value, a.t_ns, a.text)
            elif a.kind is Act.FINISH:
                self.finish()
            elif a.value == 'error':     # (rclpy: one severity per call site)
                self.get_logger().error(a.text)
            elif a.value == 'warning':
                self.get_logger().warning(a.text)
            else:
                self.get_logger().info(a.text)

    def on_progress(self, msg: LockstepStatus) -> None:
        """A node reports the sim time it has read up to (and whether it is done)."""
        t = self.elapsed_ns(stamp_ns(msg.header.stamp))
        self._run(self.master.on_progress(msg.node, t, msg.final, time.monotonic()))

    def on_recorder(self, msg: LockstepStatus) -> None:
        """The recorder reports the latest /clock it has written (its progress)."""
        t = self.elapsed_ns(stamp_ns(msg.header.stamp))
        self._run(self.master.on_progress('recorder', t, False, time.monotonic()))

    def on_environment(self, msg: Environment) -> None:
        """Store an environment sample (dropped with a warning if it holds NaN)."""
        x = convert.ENVIRONMENT.to_core(msg, self.epoch_ns)
        if not all_finite(x.r_eci_m, x.v_eci_m_s, x.b_eci_T, x.b_dot_eci_T_s, x.q_eci_orbit):
            self.get_logger().warning('sim/environment with non-finite values ignored')
            return
        self._run(self.master.on_environment(x.t_ns, x, time.monotonic()))

    def on_command(self, msg: ActuatorCommand) -> None:
        """Store an actuator command; a malformed one becomes a zero command (safe)."""
        x = convert.COMMAND.to_core(msg, self.epoch_ns)
        self._run(self.master.on_command(x.t_ns, self.component.to_command(x),
                                         time.monotonic()))

    def on_inject_fault(self, msg: String) -> None:
        """A live fault (``adcs fault``): applied if it strikes an actuator, announced on
        ``sim/faults`` in the frame it starts (the next one at the earliest)."""
        next_frame = (self.sim_t_ns // self.frame_ns + 1) * self.frame_ns if self.started \
            else 0
        try:
            fault = injected(msg.data, next_frame, sensors=None, wheels=self.wheel_names,
                             magnetorquer=self.spacecraft.magnetorquer is not None)
            self.component.faults.add(fault)
        except ValueError as exc:
            self.get_logger().warning(f'live fault refused: {exc}')
            return
        self.get_logger().warning(f'live fault {fault.describe()} from t = '
                                  f'{fault.start_ns / 1e9:g} s (not deterministic)')

    def step_frame(self, t: int, env: Any, cmd: Any) -> None:
        """Zero-order-hold the command and integrate from t_k to t_k+1 (the component's)."""
        self.component.step(t, env, cmd)
        self.frames += 1

    @property
    def state(self):
        """The spacecraft state (None before frame 0)."""
        return self.component.state

    @property
    def rejected_commands(self) -> int:
        """Malformed commands replaced by a zero command."""
        return self.component.rejected_commands

    def diagnostic_values(self) -> dict:
        """Wheel driver status for ``/diagnostics`` (wheels only)."""
        return self.component.wheel_diagnostics()

    def on_watchdog(self) -> None:
        """Wall-clock timeout of the current wait: count a missed frame and go on."""
        if not self.started:
            waited = time.monotonic() - self._created
            if waited > self.start_timeout_s and not self.done:
                missing = sorted(set(self.wait_for_nodes) - self.ready_nodes)
                own = ', '.join(self.unmatched(graph_view=True))
                self.get_logger().error(
                    f'lockstep not started after {waited:.0f} s: no ready from '
                    f'{", ".join(missing) or f"(own endpoints: {own})"}'
                    ' (did a node die during start-up?)')
                self.exit_code = 1
                self.done = True
            return
        if self.real_time or self.done:
            return
        self._run(self.master.tick(time.monotonic()))

    # ------------------------------------------------------------------ real time
    def on_rt_tick(self) -> None:
        """Real-time mode: publish frame k, then step with the latest inputs (no waiting)."""
        if not self.done:
            self._run(self.master.free_running_frame())

    # ------------------------------------------------------------------ outputs
    def publish_state(self, env: Any) -> None:
        """Phase B: publish truth state and wheels of frame k (initialises at frame 0)."""
        t, e = self.t_ns, self.epoch_ns
        self.sim_t_ns = t
        faults = self.component.fault_events(t)
        if faults is not None:
            self.faults_pub.publish(convert.FAULTS.to_msg(faults, e))
        x = self.component.truth(t, env)
        msg = convert.ATTITUDE_STATE.to_msg(x, e)
        self.state_pub.publish(msg)
        if self.tf_pub.wanted():     # /tf, sim/wheels, sim/appendages: built only when read
            self.tf_pub.send(truth_transforms(msg.header.stamp, env.r_eci_m, env.q_eci_orbit,
                                              x.q_orbit_body))
        if self.wheels_pub.get_subscription_count() > 0:
            self.wheels_pub.publish(convert.WHEEL_STATE.to_msg(self.component.wheels(t), e))
        if self.appendages_pub is not None and self.appendages_pub.get_subscription_count() > 0:
            self.appendages_pub.publish(convert.APPENDAGES.to_msg(self.component.appendages(t),
                                                                  e))

    def finish(self) -> None:
        """End of the scenario: report and let the runtime stop the process."""
        if self.done:
            return
        wall = time.monotonic() - self.wall_start
        sim = ns_to_seconds(self.t_ns)
        self.get_logger().info(
            f'done: {sim:g} s sim in {wall:.2f} s wall ({sim / max(wall, 1e-9):.1f}x real '
            f'time, {self.frames / max(wall, 1e-9):.0f} frames/s), missed frames '
            f'{self.missed_frames}')
        self.publish_status(final=True)
        if self.result_file:     # for the launcher: no DDS race with a process that exits
            with open(self.result_file + '.tmp', 'w') as fh:
                json.dump({'frames': self.frames, 'wall_time_s': wall,
                           'frames_per_s': self.frames / max(wall, 1e-9),
                           'missed_frames': self.missed_frames,
                           'throttled_frames': self.throttled_frames,
                           'rejected_commands': self.rejected_commands,
                           'security_events': (0 if self._publisher_guard is None
                                               else self._publisher_guard.core.total)}, fh)
            os.replace(self.result_file + '.tmp', self.result_file)
        self.done = True  # the runtime lingers briefly (DDS resends) and exits


def main(args=None) -> int:
    """``ros2 run sim_node dynamics``."""
    return runtime.run(DynamicsNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
