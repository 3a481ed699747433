"""The FrameLoop: one scenario's world and flight software stepped in the lockstep order, in one
process, without ROS (the ``plain`` engine).

It builds every component from the node parameters :func:`adcs_nodes.tools.graph.build_graph`
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

import os
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
from adcs_nodes.components.base import (DEFAULT_EPOCH, FrameClock, Mounts, epoch_to_ns,
                                        param_values, parse_epoch, section)
from adcs_nodes.components.guidance import PARAMS as GUIDANCE_PARAMS
from adcs_nodes.components.guidance import GuidanceComponent
from adcs_nodes.components.manager import MANAGER_PARAMS, ManagerComponent, manager_core
from adcs_nodes.core.lockstep import REVIVE_HOLD_FRAMES, ZERO, derive_seed, seconds_to_ns
from adcs_nodes.nodes.actuator_topics import MAGNETORQUER_TOPIC, WHEELS_TOPIC, wheel_names_for
from adcs_nodes.nodes.convert import stamp_ns
from adcs_nodes.nodes.messages import make
from adcs_nodes.tools.graph import NodeSpec, build_graph
from sim_node.components.dynamics import DynamicsComponent
from sim_node.components.environment import DEFAULT_FIELD, DEFAULT_ORBIT, EnvironmentComponent
from sim_node.components.sensors import SENSOR_COMPONENTS, sensor_faults
from sim_node.faults import parse as parse_faults
from sim_node.models.spacecraft_config import DEFAULT_INITIAL, DEFAULT_SPACECRAFT

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
        env_p = by_name['environment'].params
        self.epoch = parse_epoch(env_p.get('epoch', DEFAULT_EPOCH))
        self.clock = FrameClock(epoch_to_ns(self.epoch))
        self.seed = int(env_p.get('seed', 0))
        self.frame_ns = seconds_to_ns(env_p.get('frame_period_s', 1.0))
        self.duration_ns = seconds_to_ns(duration_s)
        if self.frame_ns <= 0 or self.duration_ns % self.frame_ns:
            raise EngineError(f'duration {duration_s} s is not a multiple of the frame '
                              f'{self.frame_ns / 1e9:g} s')
        self.environment = EnvironmentComponent(
            section(env_p, 'orbit', DEFAULT_ORBIT, merge=False),
            section(env_p, 'field', DEFAULT_FIELD, merge=False), self.epoch, self.clock)
        dyn_p = by_name['dynamics'].params
        self.dynamics = DynamicsComponent(
            section(dyn_p, 'spacecraft', DEFAULT_SPACECRAFT),
            section(dyn_p, 'initial', DEFAULT_INITIAL), self.seed, self.frame_ns,
            int(dyn_p.get('substeps', 10)), self.clock, _log_into(self.warnings, 'dynamics'),
            parse_faults(str(dyn_p.get('faults', ''))))
        #: a due input missing this many frames in a row is dead (not awaited), as in a node
        self.dead_after = int(env_p.get('dead_after_frames', 3))
        #: after a revival, an input is dropped and not awaited for this long (FrameSync)
        self.revive_hold_ns = REVIVE_HOLD_FRAMES * self.frame_ns
        cmd_s = float(dyn_p.get('command_period_s', 0.0))
        self.command_ns = seconds_to_ns(cmd_s) if cmd_s > 0 else 0
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
        """The FrameLoop of a validated scenario (:func:`adcs_nodes.tools.scenario.load_scenario`);
        :class:`EngineError` for what the plain engine cannot run (external sensors).
        ``ideal_estimate``: the controllers get the true state as the estimate (a study's
        perfect-knowledge reference; not a graph mode)."""
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
            entry, p, own, section(spec.params, 'onboard_orbit', ccomp.DEFAULT_ORBIT, False),
            section(spec.params, 'onboard_field', ccomp.DEFAULT_FIELD, False), self.epoch,
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
            section(spec.params, 'onboard_orbit', ccomp.DEFAULT_ORBIT, False),
            section(spec.params, 'onboard_field', ccomp.DEFAULT_FIELD, False))
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
        comp = ManagerComponent(manager_core(p, section(spec.params, 'auto', {}, False),
                                             live=False),
                                self.clock, _log_into(self.warnings, spec.name))
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


# ---------------------------------------------------------------------- the bag
class BagSink:
    """Writes frames to a rosbag2 MCAP bag, as the recorder does (message definitions
    embedded; log time = the message's sim time, so the bag reads like a recorded one).

    The bytes are the project's CDR encoder's (:mod:`adcs_nodes.nodes.cdr`: byte-identical to
    a typed publish, read back by ``rosbags``): no rclpy.
    """

    def __init__(self, path: str, scenario_text: Optional[str] = None,
                 flush_every_frames: int = 200, topics: Sequence[str] = ()) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        from adcs_nodes.bag import BAG_VERSION, ensure_type, make_typestore
        self._ensure_type = ensure_type
        self.path = path
        self._store = make_typestore()
        self._writer = Writer(path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        try:
            self._writer.open()
        except OSError as exc:
            raise EngineError(f'cannot create the bag {path}: {exc.strerror or exc}') from None
        self._writer.set_custom_data('recorder', 'sim_node.engine (plain engine)')
        self._conns: Dict[str, Tuple[Any, Any]] = {}
        #: the scenario's ``record.topics`` (relative names; empty: every data topic)
        self._only = {t.lstrip('/') for t in topics}
        self._frames = 0
        self._flush_every = max(1, int(flush_every_frames))
        self.messages = 0
        if scenario_text is not None:
            with open(os.path.join(path, 'scenario.yaml'), 'w') as fh:
                fh.write(scenario_text)

    def _connection(self, topic: str, msg: Any) -> Tuple[Any, Any]:
        got = self._conns.get(topic)
        if got is None:
            from adcs_nodes.nodes.cdr import codec
            from adcs_nodes.tools.graph import topic_type
            msgtype = topic_type(topic)
            if not self._ensure_type(self._store, msgtype):
                raise EngineError(f'no .msg definition found for {msgtype}')
            name = topic if topic.startswith('/') else '/' + topic    # resolved, as recorded
            got = self._conns[topic] = (
                self._writer.add_connection(name, msgtype, typestore=self._store),
                codec(type(msg)))
        return got

    def write(self, frame: Frame) -> None:
        """Write one frame's messages (flushed to the file every ``flush_every_frames``)."""
        from adcs_nodes.bag import flush_writer
        t_log = self._clock_ns(frame.t_ns)
        for topic, msg in frame.outputs:
            if self._only and topic.lstrip('/') not in self._only:
                continue
            conn, cdc = self._connection(topic, msg)
            self._writer.write(conn, t_log, cdc.encode(msg))
            self.messages += 1
        self._frames += 1
        if self._frames % self._flush_every == 0:
            flush_writer(self._writer)

    def _clock_ns(self, t_ns: int) -> int:
        return self._epoch_ns + t_ns

    def bind(self, loop: FrameLoop) -> 'BagSink':
        """Log times from ``loop``'s epoch."""
        self._epoch_ns = loop.clock.epoch_ns
        return self

    def close(self) -> None:
        """Finish the bag (index, metadata)."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None


# ---------------------------------------------------------------------- adcs run --engine plain
def run_plain(sc: Dict[str, Any], duration_s: Optional[float] = None,
              record: Optional[str] = None, progress: bool = True,
              out=None) -> Any:
    """``adcs run SCENARIO --engine plain``: the FrameLoop to the end, the bag if asked.

    Returns a :class:`adcs_nodes.tools.launcher.RunResult`: exit code 0, 3 (degraded: the
    manager could not forward the active controller in some frames) or 130 (Ctrl-C: the bag
    keeps every frame run so far, closed properly), and 2 when the bag cannot be written (disk
    full: the frames written so far are kept).
    """
    import signal
    import sys
    import time

    import yaml

    from adcs_nodes.tools.launcher import EXIT_DEGRADED, RunResult
    out = out or sys.stderr
    loop = FrameLoop.from_scenario(sc, duration_s)
    duration = loop.duration_ns / 1e9
    sink = None
    if record:
        if os.path.exists(record):
            raise EngineError(f'the bag {record} exists already (give a new directory)')
        sink = BagSink(record, topics=(sc.get('record') or {}).get('topics') or ()).bind(loop)
        effective = {k: v for k, v in sc.items() if not k.startswith('_')}
        effective['duration_s'] = duration
        with open(os.path.join(record, 'scenario.yaml'), 'w') as fh:
            fh.write(f'# effective scenario of this bag (from {sc.get("_path", "?")})\n')
            yaml.safe_dump(effective, fh, sort_keys=False)
    stop = []
    old = signal.signal(signal.SIGINT, lambda *_: stop.append(True))
    t0, cpu0, last = time.monotonic(), time.process_time(), 0.0
    code, message = 0, 'done'
    try:
        for frame in loop.run():
            if sink is not None:
                try:
                    sink.write(frame)
                except OSError as exc:
                    code, message = 2, f'the bag could not be written: {exc.strerror or exc}'
                    break
            now = time.monotonic()
            if progress and now - last > 0.5:
                last = now
                print(f'\r[adcs] plain: {frame.t_ns / 1e9:9.0f} / {duration:g} s sim',
                      end='', file=out, flush=True)
            if stop:
                code, message = 130, 'interrupted (Ctrl-C): the bag keeps every frame run'
                break
    finally:
        signal.signal(signal.SIGINT, old)
        if sink is not None:
            try:
                sink.close()
            except OSError as exc:
                code, message = 2, f'the bag could not be closed: {exc.strerror or exc}'
    if progress:
        print('', file=out)
    wall = time.monotonic() - t0
    manager = getattr(loop, 'manager', None)
    st = manager.core.status() if manager is not None else {}
    from sim_node.faults import lost_text
    why = ['lost ' + ', '.join(lost)] if (lost := lost_text(sc.get('faults') or [],
                                                            loop.t_ns / 1e9)) else []
    if st.get('missed_frames', 0) > 0:
        why.append(f'the controller manager could not forward the active controller in '
                   f'{st["missed_frames"]} frames (last fault: {st.get("last_fault") or "?"})')
    if code == 0 and why:         # (the launcher's words for a degraded graph run)
        code, message = EXIT_DEGRADED, 'done, DEGRADED: ' + '; '.join(why)
    message += f' (plain engine: {time.process_time() - cpu0:.2f} s CPU)'
    return RunResult(code, loop.t_ns / 1e9 if not loop.done else duration, wall, loop.k,
                     0, record, '', message, loop.k / wall if wall > 0 else 0.0)


# ---------------------------------------------------------------------- series and Monte Carlo
def run_series(loop: FrameLoop) -> Dict[str, Any]:
    """Run ``loop`` to the end and return the per-frame series a study or a Monte Carlo run
    needs (numpy arrays, one row per frame).

    ``t_s`` [s]; ``q_orbit_body`` (n, 4) truth; ``w_eci``, ``w_orbit`` (n, 3) true
    ``omega_body_eci_body``, ``omega_body_orbit_body`` [rad/s]; ``q_est`` (n, 4) and
    ``w_est`` (n, 3) the latest estimate (NaN before the first); ``angle_deg`` truth angle
    body to orbit frame; ``est_err_deg``, ``rate_err_deg_s`` estimate errors; ``active``
    the controller whose command was forwarded (``source`` of ``adcs/actuator_command``);
    ``period_s`` the orbital period at the end.

    ``q_orbit_target`` (n, 4): the guidance target the run published (``q_ref_body`` of the
    latest ``adcs/attitude_target``, held between guidance frames; NaN before the first, and
    throughout a run without guidance) in the orbit frame: a target in the ECI frame
    (``header.frame_id`` ``'eci'``) is converted with the frame's truth,
    ``q_orbit_target = q_orbit_body (x) q_eci_body^* (x) q_eci_target``. ``target_judged``
    (n,) bool: False while that target is a paper 001 maneuver's end state (``profile``
    ``'maneuver'``; the capture test leaves those samples out,
    :mod:`adcs_nodes.tools.montecarlo.capture`), else True.
    """
    import math

    import numpy as np

    from adcs_nodes.core import attitude
    from adcs_nodes.nodes.convert import quat, vec3
    from adcs_nodes.tools import metrics
    rows: Dict[str, List[Any]] = {k: [] for k in ('t_s', 'q_orbit_body', 'w_eci', 'w_orbit',
                                                  'q_est', 'w_est', 'active', 'q_orbit_target',
                                                  'target_judged')}
    q_est, w_est = np.full(4, np.nan), np.full(3, np.nan)
    q_target, eci, judged = np.full(4, np.nan), False, True    # the latest target
    active, rate = 'zero', 0.0
    for frame in loop.run():
        state = None
        for topic, msg in frame.outputs:
            if topic == 'sim/state':
                state = msg
            elif topic == 'adcs/attitude_estimate':
                q_est, w_est = quat(msg.q_orbit_body), vec3(msg.omega_body_eci_body)
            elif topic == 'adcs/actuator_command':
                active = msg.source
            elif topic == 'sim/environment':
                rate = float(msg.orbit_rate)
            elif topic == 'adcs/attitude_target':
                q_target, eci = quat(msg.q_ref_body), msg.header.frame_id == 'eci'
                judged = msg.profile != 'maneuver'
        q_body = quat(state.q_orbit_body)
        rows['t_s'].append(frame.t_ns / 1e9)
        rows['q_orbit_body'].append(q_body)
        rows['w_eci'].append(vec3(state.omega_body_eci_body))
        rows['w_orbit'].append(vec3(state.omega_body_orbit_body))
        rows['q_est'].append(q_est)
        rows['w_est'].append(w_est)
        rows['active'].append(active)
        rows['q_orbit_target'].append(attitude.multiply(attitude.multiply(
            q_body, attitude.conjugate(quat(state.q_eci_body))), q_target) if eci else q_target)
        rows['target_judged'].append(judged)
    out = {k: np.asarray(v) for k, v in rows.items()}
    out['angle_deg'] = metrics.angle_to_identity_deg(out['q_orbit_body'])
    out['est_err_deg'] = metrics.angle_between_deg(out['q_est'], out['q_orbit_body'])
    out['rate_err_deg_s'] = np.degrees(np.linalg.norm(out['w_est'] - out['w_eci'], axis=1))
    out['period_s'] = 2.0 * math.pi / rate if rate > 0 else float('nan')
    return out


def mc_worker(run_dir: str) -> int:
    """One Monte Carlo run on the plain engine (``adcs montecarlo``, any scenario).

    Reads ``job.json`` and ``scenario.yaml`` of the prepared run directory, runs the
    FrameLoop, writes ``series.npz`` (per-frame truth, estimate error and the guidance target
    the run published, :func:`run_series`) and ``result.json`` with
    :func:`adcs_nodes.tools.montecarlo.results.series_metrics` (the same result as a graph
    run): capture judged against the recorded target, or the orbit frame, as the scenario's
    ``capture_reference`` says (:mod:`adcs_nodes.tools.montecarlo.capture`); or
    ``failed.json``. Exit code 130 on SIGINT (nothing written).
    """
    import json
    import time

    import numpy as np

    from adcs_nodes.tools import metrics
    from adcs_nodes.tools.montecarlo.capture import ORBIT_FRAME, capture_reference
    from adcs_nodes.tools.montecarlo.files import RESULT_FILE, SERIES_FILE, write_json_atomic
    from adcs_nodes.tools.montecarlo.results import angle_to_target_deg, series_metrics
    from adcs_nodes.tools.montecarlo.runner import fail, result_head
    from adcs_nodes.tools.scenario import ScenarioError, load_scenario

    t0 = time.monotonic()
    with open(os.path.join(run_dir, 'job.json'), encoding='utf-8') as fh:
        job = json.load(fh)
    try:
        sc = load_scenario(os.path.join(run_dir, 'scenario.yaml'))
        reference = capture_reference(sc)
        s = run_series(FrameLoop.from_scenario(sc, job['duration_s']))
    except KeyboardInterrupt:
        return 130
    except (ScenarioError, ValueError) as exc:
        return fail(run_dir, job, 2, str(exc), time.monotonic() - t0)
    tmp = os.path.join(run_dir, 'series.tmp.npz')
    np.savez_compressed(tmp, **{k: s[k] for k in ('t_s', 'q_orbit_body', 'angle_deg',
                                                  'est_err_deg', 'rate_err_deg_s', 'w_eci',
                                                  'w_orbit', 'q_orbit_target',
                                                  'target_judged')})
    os.replace(tmp, os.path.join(run_dir, SERIES_FILE))
    angle = judged = None                 # the orbit frame
    if reference != ORBIT_FRAME:          # the target the run published
        angle = angle_to_target_deg(s['q_orbit_body'], s['q_orbit_target'])
        judged = s['target_judged']
    m = series_metrics(s['t_s'], s['q_orbit_body'], s['w_eci'], s['w_orbit'],
                       job['capture_deg'], job.get('period_s') or s['period_s'],
                       angle_deg=angle, judged=judged)
    est = metrics.hold_stats(s['t_s'], s['est_err_deg'], 0.5 * s['period_s'])
    result = {**result_head(job), **m, 'capture_reference': reference, 'engine': 'plain',
              'bag': None,
              'est_err_median_deg': est.median if est.samples else None,
              'sim_time_s': float(s['t_s'][-1]), 'wall_time_s': time.monotonic() - t0,
              'frames': int(s['t_s'].size), 'missed_frames': 0, 'compose': False,
              'message': 'plain engine (sim_node.engine.FrameLoop)'}
    write_json_atomic(os.path.join(run_dir, RESULT_FILE), result)
    return 0


def one_blas_thread() -> None:
    """One BLAS/OpenMP thread in this process and its children (tiny LAPACK calls: extra
    threads cost CPU, same bits; DESIGN section 6)."""
    for key in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
        os.environ[key] = '1'
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - pinned in ros2_ws/requirements.txt
        return
    threadpool_limits(limits=1)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``python -m sim_node.engine _mc_worker RUN_DIR`` (the Monte Carlo's plain worker)."""
    import sys
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ['_mc_worker'] and len(argv) == 2:
        return mc_worker(argv[1])
    print('usage: python -m sim_node.engine _mc_worker RUN_DIR (adcs run --engine plain runs '
          'a scenario)', file=sys.stderr)
    return 2


if __name__ == '__main__':
    import signal
    # a Monte Carlo run started under ``--dask-local`` inherits an ignored SIGINT: the
    # supervisor's SIGINT must stop it
    signal.signal(signal.SIGINT, signal.default_int_handler)
    one_blas_thread()
    raise SystemExit(main())
