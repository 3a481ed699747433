"""The FrameLoop: one scenario's world and flight software stepped in the lockstep order, in one
process, without ROS (the ``plain`` engine).

It builds every component from the node parameters :func:`adcs_nodes.graph.build_graph`
gives the graph (the single source of wiring and parameters), with the same parameter
defaults, validation and seeds as the nodes, and calls the same component ``step`` the nodes
call. The messages between components are the generated message objects, passed in process:
so each input reaches its consumer with the same values as over DDS, and the plain, composed
and graph engines give the same series on every data topic to the last bit (the parity test,
``tests/graph/test_engine_parity.py``).

Frame k at ``t_k = k * frame`` (DESIGN section 6, the graph's order)::

    /clock(t_k)
    environment            -> sim/environment(t_k)
    dynamics (truth)       -> sim/state, sim/wheels, sim/appendages (t_k)
    sensors due at t_k     -> sensors/*
    estimator due at t_k   <- sensors/* (fresh: stamped t_k), the command of the previous
                              command frame                      -> adcs/attitude_estimate
    guidance due at t_k    -> adcs/attitude_target
    controllers due at t_k <- the latest estimate, target, sensors -> .../command (shadow mode)
    manager due at t_k     <- every controller's command, the estimate -> adcs/actuator_command
    dynamics               <- the command stamped t_k when due, else the held one; RK4 to t_k+1

An input between its producer's frames is the latest message stamped at or before ``t_k`` (what
``FrameSync.value`` gives a node); the estimator's command input is exactly the one stamped
at the last command frame before ``t_k`` (``previous``). Nothing waits, nothing times out: every
producer runs before its consumers.

What the FrameLoop does not have: drivers (an ``external: true`` sensor is refused), live and
real-time timing, ``/tf`` and ``/diagnostics`` (no data topics), the slew action and operator
switches (no services: a scenario's schedule and automatic sequence work as in the graph).

Pure Python: no rclpy (``tests/unit/test_core_purity.py``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Tuple

from geometry_msgs.msg import Vector3Stamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from adcs_msgs.msg import ControllerStatus
from adcs_nodes import inputs as input_records
from adcs_nodes import registry
from adcs_nodes.components import controller as ccomp
from adcs_nodes.components import estimator as ecomp
from adcs_nodes.components.base import FrameClock, Mounts, epoch_to_ns, param_values, parse_epoch
from adcs_nodes.components.guidance import PARAMS as GUIDANCE_PARAMS
from adcs_nodes.components.guidance import GuidanceComponent
from adcs_nodes.components.manager import MANAGER_PARAMS, ManagerComponent, manager_core
from adcs_nodes.core.geomag import FIELD
from adcs_nodes.core.lockstep import REVIVE_HOLD_FRAMES, ZERO, derive_seed, seconds_to_ns
from adcs_nodes.nodes.actuator_topics import MAGNETORQUER_TOPIC, WHEELS_TOPIC, wheel_names_for
from adcs_nodes.nodes.convert import stamp_ns
from adcs_nodes.nodes.messages import make
from adcs_nodes.core.manager import AUTO_SEQUENCE
from adcs_nodes.core.orbit import ORBIT
from adcs_nodes.graph import NodeSpec, build_graph
from adcs_nodes.scenario import check_scenario
from adcs_nodes.spec import COMMON
from sim_node.components.dynamics import DynamicsComponent
from sim_node.components.environment import EnvironmentComponent
from sim_node.components.sensors import SENSOR_COMPONENTS, sensor_faults
from sim_node.faults import parse as parse_faults
from sim_node.entries import DYNAMICS_PARAMS
from sim_node.models.spacecraft_config import INITIAL, SPACECRAFT

#: ``(topic, message)`` published in a frame.
Output = Tuple[str, Any]

#: Topics whose content depends on wall time in the graph (published on change and once per
#: wall second there; on change only here): not part of the engine parity.
WALL_TIMED_TOPICS = ('adcs/controller_status',)


class EngineError(ValueError):
    """A scenario the plain engine cannot run (the message says why)."""


@dataclass
class _Consumer:
    """A flight-software component with its period and inputs ``{key: (topic, kind,
    period_ns)}`` (kind ``frame`` or ``previous``)."""

    name: str
    period_ns: int
    inputs: Dict[str, Tuple[str, str, int]]
    fire: Callable[[int, Dict[str, Any], List[str]], List[Output]]
    #: per frame input, FrameSync's view: misses in a row, dead, the stamp of the last
    #: message seen, the stamp that revived it, the last message it took
    misses: Dict[str, int] = field(default_factory=dict)
    dead: Dict[str, bool] = field(default_factory=dict)
    seen: Dict[str, int] = field(default_factory=dict)
    revived: Dict[str, int] = field(default_factory=dict)
    taken: Dict[str, Any] = field(default_factory=dict)


@dataclass
class Frame:
    """What one frame published, in order."""

    t_ns: int
    outputs: List[Output] = field(default_factory=list)


def _log_into(sink: List[Tuple[str, str, str]], name: str) -> Callable[[str, str], None]:
    def log(level: str, text: str) -> None:
        if level in ('warning', 'error'):
            sink.append((name, level, text))
    return log


class FrameLoop:
    """One scenario in the lockstep order, without ROS (see module docstring).

    Build with :meth:`from_scenario`; then :meth:`step` until :attr:`done`, or iterate
    :meth:`run`.
    """

    def __init__(self, specs: Sequence[NodeSpec], duration_s: float,
                 ideal_estimate: bool = False) -> None:
        by_name = {s.name: s for s in specs}
        #: a study's reference: ``adcs/attitude_estimate`` is the truth (``sim/state``) of
        #: each estimator frame instead of the estimator's (perfect knowledge)
        self.ideal_estimate = bool(ideal_estimate)
        for s in specs:
            registry.load_plugins(s.params.get('plugins', []) or [])
        self.warnings: List[Tuple[str, str, str]] = []
        env_p, dyn_p = by_name['environment'].params, by_name['dynamics'].params
        common = param_values(COMMON.values(), env_p)     # validated as the nodes declare them
        dyn = param_values(DYNAMICS_PARAMS, dyn_p)
        self.epoch = parse_epoch(common['epoch'])
        self.clock = FrameClock(epoch_to_ns(self.epoch))
        self.seed = common['seed']
        self.frame_ns = seconds_to_ns(common['frame_period_s'])
        self.duration_ns = seconds_to_ns(duration_s)
        if self.frame_ns <= 0 or self.duration_ns % self.frame_ns:
            raise EngineError(f'duration {duration_s} s is not a multiple of the frame '
                              f'{self.frame_ns / 1e9:g} s')
        self.environment = EnvironmentComponent(
            ORBIT.read(env_p, 'orbit'), FIELD.read(env_p, 'field'), self.epoch, self.clock)
        self.dynamics = DynamicsComponent(
            SPACECRAFT.read(dyn_p, 'spacecraft'), INITIAL.read(dyn_p, 'initial'), self.seed,
            self.frame_ns, dyn['substeps'], self.clock, _log_into(self.warnings, 'dynamics'),
            parse_faults(str(dyn_p.get('faults', ''))))
        #: a due input missing this many frames in a row is dead (not awaited), as in a node
        self.dead_after = common['dead_after_frames']
        #: after a revival, an input is dropped and not awaited for this long (FrameSync)
        self.revive_hold_ns = REVIVE_HOLD_FRAMES * self.frame_ns
        cmd_s = dyn['command_period_s']
        self.command_ns = seconds_to_ns(cmd_s) if cmd_s else 0
        self.mounts = Mounts()
        #: node name -> its ``node_killed`` time [ns]: it fires no frame from then on
        self.killed_ns = {s.name: seconds_to_ns(float(s.params['killed_at_s'])) for s in specs
                          if float(s.params.get('killed_at_s', -1.0)) >= 0}
        self._sensor_node: Dict[str, str] = {}              # sensor topic -> node name
        self.sensors: List[Tuple[str, int, Any]] = []
        self.consumers: List[_Consumer] = []
        for s in specs:
            entry = self._sensor_entry(s)
            if entry is not None:
                self._add_sensor(s, entry)
        for s in specs:
            if s.module == 'adcs_nodes.nodes.estimator':
                self._add_estimator(s)
        for s in specs:
            if s.module == 'adcs_nodes.nodes.guidance':
                self._add_guidance(s)
        for s in specs:
            if s.module == 'adcs_nodes.nodes.controller':
                self._add_controller(s)
        for s in specs:
            if s.module == 'adcs_nodes.nodes.controller_manager':
                self._add_manager(s)
        self.k = 0
        self.done = False
        self._latest: Dict[str, Any] = {}                  # topic -> latest message
        self._by_stamp: Dict[str, Dict[int, Any]] = {}      # 'previous' topics: stamp -> msg
        self._previous_topics = {topic for c in self.consumers
                                 for topic, kind, _ in c.inputs.values() if kind == 'previous'}
        self._status_key: Optional[tuple] = None

    # ------------------------------------------------------------------ building
    @classmethod
    def from_scenario(cls, sc: Dict[str, Any], duration_s: Optional[float] = None,
                      ideal_estimate: bool = False) -> 'FrameLoop':
        """The FrameLoop of a validated scenario (:func:`adcs_nodes.scenario.load_scenario`);
        :class:`EngineError` for what the plain engine cannot run (external sensors).
        ``ideal_estimate``: the controllers get the true state as the estimate (a study's
        perfect-knowledge reference; not a graph mode)."""
        check_scenario(sc)     # the validator's refusal and message (a ScenarioError)
        external = [k for k, cfg in sc.get('sensors', {}).items() if cfg.get('external')]
        if external:
            raise EngineError(f'the plain engine has no drivers: sensors {", ".join(external)} '
                              'are external (run it as a graph: --engine graph)')
        duration = float(sc['duration_s'] if duration_s is None else duration_s)
        return cls(build_graph(sc, duration), duration, ideal_estimate)

    @staticmethod
    def _sensor_entry(spec: NodeSpec) -> Optional[Any]:
        for entry in registry.entries('sensor').values():
            if entry.node and entry.node[1] == spec.module and entry.name in SENSOR_COMPONENTS:
                return entry
        return None

    def _add_sensor(self, spec: NodeSpec, entry: Any) -> None:
        from adcs_nodes.registry import Param
        frame = Param('frame_id', 'str', entry.name)
        p = param_values(entry.params + (frame,), spec.params)
        model = entry.build(p, {'seed': derive_seed(self.seed, spec.name)})
        comp = SENSOR_COMPONENTS[entry.name](
            model, p['frame_id'], self.clock, _log_into(self.warnings, spec.name),
            sensor_faults(entry.name, str(spec.params.get('faults', '')), self.seed))
        self.mounts.set(p['frame_id'], p.get('q_body_sensor_xyzw', [0.0, 0.0, 0.0, 1.0]))
        self._sensor_node[entry.node[3]] = spec.name
        self.sensors.append((entry.node[3], seconds_to_ns(p['period_s']), comp))

    def _period(self, seconds: float, what: str) -> int:
        ns = seconds_to_ns(seconds)
        if ns <= 0 or ns % self.frame_ns:
            raise EngineError(f'{what}: {seconds} s is not a positive multiple of the frame')
        return ns

    def _add_estimator(self, spec: NodeSpec) -> None:
        p = param_values(ecomp.CONTEXT_PARAMS, spec.params)
        entry = registry.get('estimator', p['algorithm'])
        own = param_values(entry.params, spec.params)
        comp = ecomp.build_estimator(
            entry, p, own, ORBIT.read(spec.params, 'onboard_orbit'),
            FIELD.read(spec.params, 'onboard_field'), self.epoch,
            self.seed, self.mounts, self.clock, _log_into(self.warnings, spec.name))
        inputs = self._input_specs(entry.inputs, p)
        period = self._period(p['period_s'], 'estimator period_s')

        def fire(t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> List[Output]:
            msg = comp.step(t_ns, msgs, lambda key, m: self._fresh(m, t_ns),
                            [self._topic_name(inputs[k][0]) for k in missing])
            if self.ideal_estimate:      # the truth of the frame (the study's reference)
                return [('adcs/attitude_estimate', self._latest['sim/state'])]
            if msg is None:
                return []
            return [('adcs/attitude_estimate', msg),
                    ('adcs/estimator/diagnostics', comp.diagnostics_msg(msg.header))]
        self.estimator = comp
        self.consumers.append(_Consumer(spec.name, period, inputs, fire))

    @staticmethod
    def _input_specs(names: Sequence[str], periods: Dict[str, Any]
                     ) -> Dict[str, Tuple[str, str, int]]:
        """``{key: (topic, kind, period_ns)}`` of declared inputs (the input records)."""
        return {rec.key: (rec.topic, rec.kind, seconds_to_ns(periods[rec.period_param]))
                for rec in map(input_records.get, names)}

    def _add_guidance(self, spec: NodeSpec) -> None:
        p = param_values(GUIDANCE_PARAMS, spec.params)
        comp = GuidanceComponent(p, self.clock)
        self.consumers.append(_Consumer(
            spec.name, self._period(p['period_s'], 'guidance period_s'), {},
            lambda t_ns, msgs, missing: [('adcs/attitude_target', comp.step(t_ns))]))

    def _add_controller(self, spec: NodeSpec) -> None:
        ctx_p = param_values(ccomp.CONTEXT_PARAMS, spec.params)
        entry = registry.get('controller', ctx_p['controller'])
        own = param_values(entry.params, spec.params)
        ctx = ccomp.controller_context(
            entry, ctx_p, self.epoch, self.seed,
            ORBIT.read(spec.params, 'onboard_orbit'), FIELD.read(spec.params, 'onboard_field'))
        comp = ccomp.ControllerComponent(entry.build(own, ctx), entry.name, ctx, self.mounts,
                                         self.clock)
        inputs = self._input_specs(entry.inputs, ctx_p)
        topic = f'adcs/controllers/{entry.name}/command'
        self.consumers.append(_Consumer(
            spec.name, self._period(ctx_p['period_s'], f'{spec.name} period_s'), inputs,
            lambda t_ns, msgs, missing: [(topic, comp.step(
                t_ns, msgs, lambda key, m: self._fresh(m, t_ns)))]))

    def _add_manager(self, spec: NodeSpec) -> None:
        p = param_values(MANAGER_PARAMS, spec.params)
        auto = AUTO_SEQUENCE.read(spec.params, 'auto')
        comp = ManagerComponent(manager_core(p, auto, live=False), self.clock,
                                _log_into(self.warnings, spec.name))
        period = self._period(p['period_s'], 'manager period_s')
        ctrl_ns = seconds_to_ns(float(p['controller_period_s']) or p['period_s'])
        inputs = {n: (f'adcs/controllers/{n}/command', 'frame', ctrl_ns) for n in comp.names}
        if p['estimator_period_s'] > 0:
            inputs['_estimate'] = ('adcs/attitude_estimate', 'frame',
                                   seconds_to_ns(p['estimator_period_s']))
        limits = list(p['max_wheel_torque_Nm'])
        wheel_names = wheel_names_for(0 if limits == [-1.0] else len(limits), p['wheel_names'])
        self.manager = comp

        def fire(t_ns: int, msgs: Dict[str, Any], missing: List[str]) -> List[Output]:
            cmd, status = comp.step(t_ns, msgs)
            out = [('adcs/actuator_command', cmd), (MAGNETORQUER_TOPIC, make(
                Vector3Stamped, header=make(Header, stamp=cmd.header.stamp, frame_id='body'),
                vector=cmd.dipole_body))]
            if wheel_names:
                j = JointState()
                j.header.stamp = cmd.header.stamp
                j.name = list(wheel_names)
                torque = list(cmd.wheel_torque)
                j.effort = [float(v) for v in torque] if len(torque) == len(wheel_names) \
                    else [0.0] * len(wheel_names)
                out.append((WHEELS_TOPIC, j))
            key = (status.get('active', comp.core.active), status.get('mode', ''),
                   status.get('switch_count', 0), status.get('source', ''))
            if key != self._status_key:
                self._status_key = key
                out.append(('adcs/controller_status', self._status_msg(t_ns, key, status)))
            return out
        self.consumers.append(_Consumer(spec.name, period, inputs, fire))

    def _status_msg(self, t_ns: int, key: tuple, status: Dict[str, Any]) -> ControllerStatus:
        msg = ControllerStatus()
        msg.header.stamp = self.clock.stamp(t_ns)
        msg.active = str(key[0])
        msg.available = list(self.manager.names)
        msg.mode = str(key[1] or '')
        msg.switch_count = int(key[2])
        msg.missed_frames = int(status.get('missed_frames', 0))
        msg.last_fault = str(status.get('last_fault', ''))
        return msg

    # ------------------------------------------------------------------ stepping
    def _fresh(self, msg: Any, t_ns: int) -> bool:
        """Lockstep freshness: a sample stamped with the frame."""
        return msg is not None and self.clock.elapsed_ns(stamp_ns(msg.header.stamp)) == t_ns

    def _publish(self, frame: Frame, topic: str, msg: Any) -> None:
        frame.outputs.append((topic, msg))
        self._latest[topic] = msg
        if topic in self._previous_topics:
            hist = self._by_stamp.setdefault(topic, {})
            hist[self.clock.elapsed_ns(stamp_ns(msg.header.stamp))] = msg
            if len(hist) > 4:
                del hist[min(hist)]

    def _topic_name(self, topic: str) -> str:
        return topic if topic.startswith('/') else '/' + topic

    def _inputs(self, c: _Consumer, t_ns: int) -> Tuple[Dict[str, Any], List[str]]:
        """A consumer's messages for frame ``t_ns`` and its due inputs that did not come (a
        silent producer), with ``FrameSync``'s rule: missing ``dead_after`` frames in a row,
        an input is dead (no longer missed) until a message of it arrives again; it is then
        re-admitted after ``revive_hold_ns``."""
        msgs: Dict[str, Any] = {}
        missing: List[str] = []
        for key, (topic, kind, period) in c.inputs.items():
            if kind == 'previous':
                s = None if t_ns <= 0 or period <= 0 else ((t_ns - 1) // period) * period
                msgs[key] = None if s is None else self._by_stamp.get(topic, {}).get(s)
                continue
            msg = self._latest.get(topic)
            stamp = -1 if msg is None else self.clock.elapsed_ns(stamp_ns(msg.header.stamp))
            if stamp > c.seen.get(key, -1):              # a message arrived
                c.seen[key], c.misses[key] = stamp, 0
                if c.dead.get(key):                      # a revival: not taken (FrameSync)
                    c.dead[key], c.revived[key] = False, stamp + self.revive_hold_ns
                elif key not in c.revived or stamp > c.revived[key]:   # not in the hold
                    c.taken[key] = msg
            msgs[key] = c.taken.get(key)
            if period > 0 and t_ns % period == 0 and t_ns > c.revived.get(key, -1) \
                    and stamp != t_ns and not c.dead.get(key):
                missing.append(key)
                c.misses[key] = c.misses.get(key, 0) + 1
                c.dead[key] = c.misses[key] >= self.dead_after
        return msgs, missing

    def _stopped(self, name: str, t_ns: int) -> bool:
        """True from the frame of node ``name``'s ``node_killed`` fault on (it publishes
        nothing more, as the node in a graph: ``LockstepNode._stops_at``)."""
        return name in self.killed_ns and t_ns >= self.killed_ns[name]

    @property
    def t_ns(self) -> int:
        """Elapsed sim time of the next frame [ns]."""
        return self.k * self.frame_ns

    def step(self) -> Frame:
        """Run frame k (see module docstring) and return what it published."""
        if self.done:
            raise RuntimeError('the run is over')
        t = self.t_ns
        frame = Frame(t)
        self._publish(frame, '/clock', make(Clock, clock=self.clock.stamp(t)))
        env = self.environment.step(t)
        self._publish(frame, 'sim/environment', env)
        faults = self.dynamics.faults_msg(t)
        if faults is not None:
            self._publish(frame, 'sim/faults', faults)
        state = self.dynamics.state_msg(t, env)
        self._publish(frame, 'sim/state', state)
        self._publish(frame, 'sim/wheels', self.dynamics.wheels_msg(state.header))
        appendages = self.dynamics.appendages_msg(state.header)
        if appendages is not None:
            self._publish(frame, 'sim/appendages', appendages)
        truth = {'state': state, 'env': env, 'wheels': self._latest['sim/wheels']}
        for topic, period, comp in self.sensors:
            if t % period == 0 and not self._stopped(self._sensor_node[topic], t):
                msg = comp.step(t, truth)
                if msg is not None:
                    self._publish(frame, topic, msg)
        for c in self.consumers:
            if t % c.period_ns == 0 and not self._stopped(c.name, t):
                for topic, msg in c.fire(t, *self._inputs(c, t)):
                    self._publish(frame, topic, msg)
        if t >= self.duration_ns:
            self.done = True
            return frame
        cmd = None                                      # hold (no command due)
        if self.command_ns and t % self.command_ns == 0:
            msg = self._latest.get('adcs/actuator_command')
            cmd = ZERO if msg is None or not self._fresh(msg, t) else \
                self.dynamics.to_command(msg)
        self.dynamics.step(t, env, cmd)
        self.k += 1
        return frame

    def run(self) -> Iterator[Frame]:
        """Every frame to the end of the run."""
        while not self.done:
            yield self.step()
