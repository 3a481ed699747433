"""``dynamics`` node: the spacecraft's rigid-body motion, and the clock master of the lockstep.

Frame k (DESIGN section 6), lockstep mode::

    A. publish /clock = epoch + t_k            -> environment publishes sim/environment(t_k)
    B. on sim/environment(t_k): publish sim/state(t_k), sim/wheels(t_k)
                                               -> sensors, estimator, controllers, manager ...
    C. if a command is due at t_k: wait for adcs/actuator_command stamped t_k
       hold it (zero-order hold) and integrate t_k -> t_k+1 (fixed RK4 substeps)
    D. k += 1, back to A (after the last frame: done, the process exits 0)

Missing input past ``timeout_s`` of wall time: log, count a missed frame, and go on with the last
environment (extrapolated by its rates inside the frame) or a zero command.

Real-time mode (``real_time: true``): a wall timer at ``frame_period_s / rate_factor`` steps the
same model with the latest inputs, without waiting.
"""
from __future__ import annotations

import json
import os
import time
from typing import Dict, Optional, Set

import numpy as np
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from adcs_msgs.msg import (ActuatorCommand, AttitudeState, Environment, LockstepStatus,
                           WheelState)
from adcs_nodes.core import attitude as att
from adcs_nodes.core.lockstep import FrameSync, derive_seed, ns_to_seconds, seconds_to_ns
from adcs_nodes.nodes import runtime
from adcs_nodes.nodes.convert import all_finite, quat, stamp_ns, to_quat, to_vec3, vec3
from adcs_nodes.nodes.tf import TfPublisher, truth_transforms
from adcs_nodes.nodes.lockstep_node import (MAX_LAG_FRAMES, QOS_DATA, QOS_READY,
                                            LockstepNode)
from sim_node.models.dynamics import ActuatorCommand as Command
from sim_node.models.dynamics import FrameEnvironment, SpacecraftState
from sim_node.models.spacecraft_config import (DEFAULT_INITIAL, DEFAULT_SPACECRAFT,
                                               initial_state, spacecraft_from_config)

QOS_CLOCK = QOS_DATA
#: The recorder's queues are 1000 deep: it may lag further than the lockstep nodes.
RECORDER_LAG_FRAMES = 400


class DynamicsNode(LockstepNode):
    """Clock master and rigid-body integrator (see module docstring)."""

    def __init__(self, name: str = 'dynamics', **kwargs) -> None:
        super().__init__(name, **kwargs)
        self.duration_ns = seconds_to_ns(self.param('duration_s', 0.0))
        self.substeps = int(self.param('substeps', 10))
        if self.substeps < 1:
            raise ValueError('substeps must be >= 1')
        self.rate_factor = float(self.param('rate_factor', 1.0))
        if not self.rate_factor > 0:
            raise ValueError('rate_factor must be positive')
        cmd_period_s = float(self.param('command_period_s', 0.0))
        cmd_ns = seconds_to_ns(cmd_period_s) if cmd_period_s > 0 else 0
        if cmd_ns % self.frame_ns:
            raise ValueError('command_period_s must be a multiple of frame_period_s')
        self.wait_for_nodes = [n for n in self.param('wait_for_nodes', ['']) if n]
        self.result_file = str(self.param('result_file', ''))
        cfg = self.section('spacecraft', DEFAULT_SPACECRAFT)
        self.spacecraft = spacecraft_from_config(
            cfg, seed=derive_seed(self.seed, 'dynamics/disturbance'))
        self.initial_cfg = self.section('initial', DEFAULT_INITIAL)
        self.wheel_names = list(cfg.get('wheel_names', [])) or [
            f'wheel{i}' for i in range(self.spacecraft.n_wheels)]
        self.wheel_h0 = cfg.get('wheel_h0_Nms')

        self.sync = FrameSync({'env': self.frame_ns, 'cmd': cmd_ns})
        self.clock_pub = self.publisher(Clock, '/clock', QOS_CLOCK)
        self.state_pub = self.publisher(AttitudeState, 'sim/state')
        self.wheels_pub = self.publisher(WheelState, 'sim/wheels')
        self.tf_pub = TfPublisher(self)             # /tf: eci -> orbit -> body (truth)
        self.subscription(Environment, 'sim/environment', self.on_environment)
        self.subscription(ActuatorCommand, 'adcs/actuator_command', self.on_command)
        self.ready_nodes = set()
        self.create_subscription(String, 'lockstep/ready', self.on_ready_msg, QOS_READY)
        # flow control and end of run: how far every other node got (lockstep/progress)
        self.progress: Dict[str, int] = {}
        self.final_nodes: Set[str] = set()
        self.create_subscription(LockstepStatus, 'lockstep/progress', self.on_progress,
                                 QOS_DATA)
        self.create_subscription(LockstepStatus, 'recorder/status', self.on_recorder, 10)
        self.throttled_frames = 0

        self.k = 0
        self.state: Optional[SpacecraftState] = None
        self._last_q_orbit_body: Optional[np.ndarray] = None
        self.phase = 'idle'          # idle -> wait_env -> wait_cmd -> (integrate) -> wait_env
        self.wait_since = 0.0
        self.last_cmd = self.spacecraft.zero_command()
        self.rejected_commands = 0
        self.applied_wheel_torque = np.zeros(self.spacecraft.n_wheels)
        self.started = False
        self.create_timer(min(0.05, self.timeout_s / 4.0), self.on_watchdog)
        self.start_timeout_s = float(self.param('start_timeout_s', 120.0))
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
            self.begin_frame()

    # ------------------------------------------------------------------ lockstep
    @property
    def t_ns(self) -> int:
        """Elapsed sim time of the current frame."""
        return self.k * self.frame_ns

    def on_progress(self, msg: LockstepStatus) -> None:
        """A node reports the sim time it has read up to (and whether it is done)."""
        t = self.elapsed_ns(stamp_ns(msg.header.stamp))
        self.progress[msg.node] = max(t, self.progress.get(msg.node, -1))
        if msg.final:
            self.final_nodes.add(msg.node)
        self._resume()

    def on_recorder(self, msg: LockstepStatus) -> None:
        """The recorder reports the latest /clock it has written (its progress)."""
        self.progress['recorder'] = max(self.elapsed_ns(stamp_ns(msg.header.stamp)),
                                        self.progress.get('recorder', -1))
        self._resume()

    def _resume(self) -> None:
        if self.phase == 'throttled' and not self._lagging():
            self.begin_frame()
        elif self.phase == 'wait_final' and self._all_final():
            self.finish()

    def _lagging(self) -> Optional[str]:
        """Name of a node too far behind frame k to publish its clock, or None."""
        for node in self.wait_for_nodes:
            lag = RECORDER_LAG_FRAMES if node == 'recorder' else MAX_LAG_FRAMES
            if self.t_ns - self.progress.get(node, 0) > lag * self.frame_ns:
                return node
        return None

    def _all_final(self) -> bool:
        return all(n in self.final_nodes for n in self.wait_for_nodes if n != 'recorder')

    def begin_frame(self) -> None:
        """Phase A: publish the clock of frame k and wait for its environment.

        Flow control: when a node is more than MAX_LAG_FRAMES behind (it has not read the
        messages of those frames yet), the clock waits for it, so no queue overflows and
        the run stays deterministic however slow a node is.
        """
        if self._lagging():
            if self.phase != 'throttled':
                self.throttled_frames += 1
            self.phase = 'throttled'
            self.wait_since = time.monotonic()
            return
        self.phase = 'wait_env'
        self.wait_since = time.monotonic()
        self.clock_pub.publish(Clock(clock=self.stamp(self.t_ns)))
        self.advance()

    def on_environment(self, msg: Environment) -> None:
        """Store an environment message (dropped with a warning if it holds NaN)."""
        vals = (vec3(msg.r_eci), vec3(msg.v_eci), vec3(msg.b_eci), vec3(msg.b_dot_eci),
                quat(msg.q_eci_orbit))
        if not all_finite(*vals):
            self.get_logger().warning('sim/environment with non-finite values ignored')
            return
        self.sync.add('env', self.elapsed_ns(stamp_ns(msg.header.stamp)), msg)
        self.advance()

    def on_command(self, msg: ActuatorCommand) -> None:
        """Store an actuator command; a malformed one becomes a zero command (safe)."""
        t_ns = self.elapsed_ns(stamp_ns(msg.header.stamp))
        cmd = self.to_command(msg)
        self.sync.add('cmd', t_ns, cmd)
        self.advance()

    def to_command(self, msg: ActuatorCommand) -> Command:
        """Message -> model command; NaN or a wrong wheel count -> zero command, logged."""
        n = self.spacecraft.n_wheels
        wheel = np.asarray(msg.wheel_torque, dtype=float)
        if wheel.size == 0:
            wheel = np.zeros(n)
        dipole, torque = vec3(msg.dipole_body), vec3(msg.torque_body)
        if wheel.size != n or not all_finite(dipole, torque, wheel):
            self.rejected_commands += 1
            self.get_logger().warning(
                f'rejected actuator command from {msg.source!r} (non-finite or '
                f'{wheel.size} wheel torques for {n} wheels): using zero command')
            return self.spacecraft.zero_command()
        return Command(dipole_body=dipole, wheel_torque=wheel, torque_body=torque)

    def advance(self) -> None:
        """Run the frame phases as far as the arrived inputs allow."""
        if self.real_time or not self.started:
            return
        t = self.t_ns
        if self.phase == 'wait_env' and self.sync.has('env', t):
            self.publish_state(self.sync.value('env', t))
            if self.duration_ns and t >= self.duration_ns:
                self.phase = 'wait_final'          # every node processes its last frame
                self.wait_since = time.monotonic()
                self._resume()
                return
            self.phase = 'wait_cmd'
            self.wait_since = time.monotonic()
        if self.phase == 'wait_cmd' and not self.sync.missing(t):
            self.integrate(self.sync.value('cmd', t))

    def step_frame(self, cmd: Optional[Command]) -> None:
        """Zero-order-hold the command and integrate from t_k to t_k+1."""
        t = self.t_ns
        env_msg = self.sync.value('env', t)
        if cmd is not None:
            self.last_cmd = cmd
        env = FrameEnvironment(r_eci=vec3(env_msg.r_eci), v_eci=vec3(env_msg.v_eci),
                               b_eci=vec3(env_msg.b_eci), b_dot_eci=vec3(env_msg.b_dot_eci))
        # environment stamped earlier (timeout, real-time mode): extrapolate with its rates
        dt_env = ns_to_seconds(t - self.elapsed_ns(stamp_ns(env_msg.header.stamp)))
        if dt_env:
            env = FrameEnvironment(r_eci=env.r_eci + env.v_eci * dt_env, v_eci=env.v_eci,
                                   b_eci=env.b_eci + env.b_dot_eci * dt_env,
                                   b_dot_eci=env.b_dot_eci)
        self.state, self.applied = self.spacecraft.step(
            self.state, ns_to_seconds(t), ns_to_seconds(self.frame_ns), env, self.last_cmd,
            self.substeps)
        self.applied_wheel_torque = self.applied.get('wheel_torque', self.applied_wheel_torque)
        self.sync.prune(t)
        self.frames += 1
        self.k += 1

    def integrate(self, cmd: Optional[Command]) -> None:
        """Phase C+D of the lockstep: step the frame, then begin the next one."""
        self.step_frame(cmd)
        self.begin_frame()

    def on_watchdog(self) -> None:
        """Wall-clock timeout of the current wait: count a missed frame and go on."""
        if not self.started:
            waited = time.monotonic() - self._created
            if waited > self.start_timeout_s and not self.done:
                missing = sorted(set(self.wait_for_nodes) - self.ready_nodes)
                self.get_logger().error(
                    f'lockstep not started after {waited:.0f} s: no ready from '
                    f'{", ".join(missing) or "(own endpoints: " + ", ".join(self.unmatched())}'
                    ' (did a node die during start-up?)')
                self.exit_code = 1
                self.done = True
            return
        if self.real_time or self.done:
            return
        if time.monotonic() - self.wait_since < self.timeout_s:
            return
        t = self.t_ns
        if self.phase == 'throttled':
            self.get_logger().warning(
                f'frame t={t / 1e9:g} s: {self._lagging()} is more than '
                f'{MAX_LAG_FRAMES} frames behind for {self.timeout_s:g} s; going on')
            self.progress[self._lagging()] = t    # a dead node must not stop the world
            self.begin_frame()
            return
        if self.phase == 'wait_final':
            missing = [n for n in self.wait_for_nodes
                       if n != 'recorder' and n not in self.final_nodes]
            self.get_logger().warning(f'end of run: no final frame from {", ".join(missing)} '
                                      f'within {self.timeout_s:g} s; finishing')
            self.finish()
            return
        if self.phase == 'wait_env':
            if self.sync.value('env', t) is None:
                # nothing to go on with (frame 0): keep waiting but say so, and re-send clock
                self.count_missed(['sim/environment'], t)
                self.wait_since = time.monotonic()
                self.clock_pub.publish(Clock(clock=self.stamp(t)))
                return
            self.count_missed(['sim/environment'], t)
            self.sync.add('env', t, self.sync.value('env', t))
            self.advance()
        elif self.phase == 'wait_cmd':
            self.count_missed(['adcs/actuator_command'], t)
            self.integrate(self.spacecraft.zero_command())

    # ------------------------------------------------------------------ real time
    def on_rt_tick(self) -> None:
        """Real-time mode: publish frame k, then step with the latest inputs (no waiting)."""
        if self.done:
            return
        t = self.t_ns
        self.clock_pub.publish(Clock(clock=self.stamp(t)))
        env_msg = self.sync.value('env', t)
        if env_msg is None:
            return  # the environment has not answered yet: the sim waits at t = 0
        self.publish_state(env_msg)
        if self.duration_ns and t >= self.duration_ns:
            self.finish()
            return
        self.step_frame(self.sync.value('cmd', t))

    # ------------------------------------------------------------------ outputs
    def publish_state(self, env_msg: Environment) -> None:
        """Phase B: publish truth state and wheels of frame k (initialises at frame 0)."""
        q_eci_orbit = quat(env_msg.q_eci_orbit)
        omega_orbit_eci_eci = vec3(env_msg.omega_orbit_eci_eci)
        if self.state is None:
            self.state = initial_state(self.initial_cfg, q_eci_orbit, omega_orbit_eci_eci,
                                       self.spacecraft, self.wheel_h0)
        st = self.state
        self.sim_t_ns = self.t_ns
        r_body_eci = att.to_matrix(st.q_eci_body).T
        msg = AttitudeState()
        msg.header.stamp = self.stamp(self.t_ns)
        msg.header.frame_id = 'body'
        msg.q_eci_body = to_quat(st.q_eci_body)
        q_orbit_body = att.multiply(att.conjugate(q_eci_orbit), st.q_eci_body)
        if self._last_q_orbit_body is not None and q_orbit_body @ self._last_q_orbit_body < 0:
            q_orbit_body = -q_orbit_body     # keep the published sign continuous in time
        self._last_q_orbit_body = q_orbit_body
        msg.q_orbit_body = to_quat(q_orbit_body)
        msg.omega_body_eci_body = to_vec3(st.omega_body_eci_body)
        msg.omega_body_orbit_body = to_vec3(st.omega_body_eci_body
                                            - r_body_eci @ omega_orbit_eci_eci)
        self.state_pub.publish(msg)
        self.tf_pub.send(truth_transforms(msg.header.stamp, vec3(env_msg.r_eci), q_eci_orbit,
                                          q_orbit_body))
        w = WheelState()
        w.header = msg.header
        w.names = self.wheel_names
        h = np.asarray(st.h_wheels, dtype=float)
        w.momentum = h.tolist()
        wheels = self.spacecraft.wheels
        if wheels is not None:
            w.speed = wheels.speed(h, st.omega_body_eci_body).tolist()
            w.torque = np.asarray(self.applied_wheel_torque, dtype=float).tolist()
            w.h_wheels_body = to_vec3(wheels.h_body(h))
        self.wheels_pub.publish(w)

    def finish(self) -> None:
        """End of the scenario: report and let the runtime stop the process."""
        if self.done:
            return
        self.phase = 'done'
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
                           'rejected_commands': self.rejected_commands}, fh)
            os.replace(self.result_file + '.tmp', self.result_file)
        self.done = True  # the runtime lingers briefly (DDS resends) and exits


def main(args=None) -> int:
    """``ros2 run sim_node dynamics``."""
    return runtime.run(DynamicsNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
