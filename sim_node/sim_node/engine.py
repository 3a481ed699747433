"""The FrameLoop: one scenario's world and flight software stepped in the lockstep order, in one
process, without ROS (the ``plain`` engine).

It builds every component from the node parameters :func:`adcs_nodes.graph.build_graph`
gives the graph (the single source of wiring and parameters), with the same parameter
defaults, validation and seeds as the nodes, and calls the same component ``step`` the nodes
call. Components exchange core samples (:mod:`adcs_nodes.core.samples`); each consumer takes
its inputs through its own :class:`~adcs_nodes.core.lockstep.FrameSync`, built from the same
input records as its node's: one rule for due inputs, misses, dead producers and their
return. So the plain, composed and graph engines give the same series on every data topic to
the last bit (the parity test, ``tests/graph/test_engine_parity.py``).

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

Nothing waits: every producer runs before its consumers, so an input due and absent is
missing for good (a silent producer: counted, and dead after ``dead_after_frames``).

What the FrameLoop does not have: drivers (an ``external: true`` sensor is refused), live and
real-time timing, ``/tf`` and ``/diagnostics`` (no data topics), the slew action and operator
switches (no services: a scenario's schedule and automatic sequence work as in the graph).
The bag sink (:mod:`adcs_nodes.tools.run.plain`) makes the messages.

Pure Python: no rclpy, no message type (``tests/unit/test_layering.py``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Tuple

from adcs_nodes import inputs as input_records
from adcs_nodes import registry
from adcs_nodes.components import controller as ccomp
from adcs_nodes.components import estimator as ecomp
from adcs_nodes.components.base import Mounts, epoch_to_ns, param_values, parse_epoch
from adcs_nodes.components.guidance import PARAMS as GUIDANCE_PARAMS
from adcs_nodes.components.guidance import GuidanceComponent
from adcs_nodes.components.manager import (MANAGER_PARAMS, ManagerComponent,
                                           actuator_commands, manager_core, status_key,
                                           wheel_names_for)
from adcs_nodes.core.geomag import FIELD
from adcs_nodes.core.lockstep import (REVIVE_HOLD_FRAMES, ZERO, FrameSync, derive_seed,
                                      seconds_to_ns)
from adcs_nodes.core.manager import AUTO_SEQUENCE
from adcs_nodes.core.orbit import ORBIT
from adcs_nodes.core.samples import Tick
from adcs_nodes.graph import NodeSpec, build_graph
from adcs_nodes.scenario import check_scenario
from adcs_nodes.spec import COMMON
from sim_node.components.dynamics import DynamicsComponent
from sim_node.components.environment import EnvironmentComponent
from sim_node.components.sensors import component_class, sensor_faults
from sim_node.faults import parse as parse_faults
from sim_node.entries import DYNAMICS_PARAMS
from sim_node.models.spacecraft_config import INITIAL, SPACECRAFT

#: ``(topic, sample)`` published in a frame.
Output = Tuple[str, Any]


class EngineError(ValueError):
    """A scenario the plain engine cannot run (the message says why)."""


@dataclass
class _Consumer:
    """A flight-software component: its period, its inputs' :class:`FrameSync` and
    ``fire(t_ns, samples, missing) -> outputs``."""

    name: str
    period_ns: int
    sync: FrameSync
    fire: Callable[[int, Dict[str, Any], List[str]], List[Output]]


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
        self.epoch_ns = epoch_to_ns(self.epoch)
        self.seed = common['seed']
        self.frame_ns = seconds_to_ns(common['frame_period_s'])
        self.duration_ns = seconds_to_ns(duration_s)
        if self.frame_ns <= 0 or self.duration_ns % self.frame_ns:
            raise EngineError(f'duration {duration_s} s is not a multiple of the frame '
                              f'{self.frame_ns / 1e9:g} s')
        self.environment = EnvironmentComponent(
            ORBIT.read(env_p, 'orbit'), FIELD.read(env_p, 'field'), self.epoch)
        self.dynamics = DynamicsComponent(
            SPACECRAFT.read(dyn_p, 'spacecraft'), INITIAL.read(dyn_p, 'initial'), self.seed,
            self.frame_ns, dyn['substeps'], _log_into(self.warnings, 'dynamics'),
            parse_faults(str(dyn_p.get('faults', ''))))
        #: a due input missing this many frames in a row is dead (not awaited), as in a node
        self.dead_after = common['dead_after_frames']
        cmd_s = dyn['command_period_s']
        self.command_ns = seconds_to_ns(cmd_s) if cmd_s else 0
        self.mounts = Mounts()
        #: node name -> its ``node_killed`` time [ns]: it fires no frame from then on
        self.killed_ns = {s.name: seconds_to_ns(float(s.params['killed_at_s'])) for s in specs
                          if float(s.params.get('killed_at_s', -1.0)) >= 0}
        self.sensors: List[Tuple[str, int, Any]] = []          # (topic, period, component)
        self._sensor_node: Dict[str, str] = {}                  # sensor topic -> node name
        self.consumers: List[_Consumer] = []
        self._subs: Dict[str, List[Tuple[FrameSync, str]]] = {}  # topic -> (sync, key)
        self._build(specs)
        self.k = 0
        self.done = False
        self._latest: Dict[str, Any] = {}                  # topic -> latest sample
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

    def _build(self, specs: Sequence[NodeSpec]) -> None:
        """Every component of the graph's node specs, in the lockstep order."""
        modules = {e.node[1] for e in registry.entries('sensor').values() if e.node}
        for s in specs:
            if s.module in modules:
                self._add_sensor(s, registry.get('sensor', s.params.get('sensor', s.name)))
        for module, add in (('adcs_nodes.nodes.estimator', self._add_estimator),
                            ('adcs_nodes.nodes.guidance', self._add_guidance),
                            ('adcs_nodes.nodes.controller', self._add_controller),
                            ('adcs_nodes.nodes.controller_manager', self._add_manager)):
            for s in specs:
                if s.module == module:
                    add(s)

    def _add_sensor(self, spec: NodeSpec, entry: Any) -> None:
        from adcs_nodes.registry import Param
        frame = Param('frame_id', 'str', entry.name)
        p = param_values(entry.params + (frame,), spec.params)
        model = entry.build(p, {'seed': derive_seed(self.seed, spec.name)})
        comp = component_class(entry.name)(
            model, p['frame_id'], _log_into(self.warnings, spec.name),
            sensor_faults(entry.name, str(spec.params.get('faults', '')), self.seed))
        self.mounts.set(p['frame_id'], p.get('q_body_sensor_xyzw', [0.0, 0.0, 0.0, 1.0]))
        self._sensor_node[entry.node[3]] = spec.name
        self.sensors.append((entry.node[3], seconds_to_ns(p['period_s']), comp))

    def _period(self, seconds: float, what: str) -> int:
        ns = seconds_to_ns(seconds)
        if ns <= 0 or ns % self.frame_ns:
            raise EngineError(f'{what}: {seconds} s is not a positive multiple of the frame')
        return ns

    def _consumer(self, name: str, period_ns: int, inputs: Dict[str, Tuple[str, str, int]],
                  fire: Callable[[int, Dict[str, Any], List[str]], List[Output]]) -> None:
        """A consumer with ``inputs`` ``{key: (topic, kind, period_ns)}`` (as its node's
        ``lockstep_inputs``: period 0 is never awaited)."""
        sync = FrameSync({k: (p, kind) for k, (_, kind, p) in inputs.items()},
                         dead_after=self.dead_after,
                         revive_hold_ns=REVIVE_HOLD_FRAMES * self.frame_ns)
        for key, (topic, _, _) in inputs.items():
            self._subs.setdefault(topic, []).append((sync, key))
        self.consumers.append(_Consumer(name, period_ns, sync, fire))

    @staticmethod
    def _input_specs(names: Sequence[str], periods: Dict[str, Any]
                     ) -> Dict[str, Tuple[str, str, int]]:
        """``{key: (topic, kind, period_ns)}`` of declared inputs (the input records)."""
        return {rec.key: (rec.topic, rec.kind, seconds_to_ns(periods[rec.period_param]))
                for rec in map(input_records.get, names)}

    def _add_estimator(self, spec: NodeSpec) -> None:
        p = param_values(ecomp.CONTEXT_PARAMS, spec.params)
        entry = registry.get('estimator', p['algorithm'])
        own = param_values(entry.params, spec.params)
        comp = ecomp.build_estimator(
            entry, p, own, ORBIT.read(spec.params, 'onboard_orbit'),
            FIELD.read(spec.params, 'onboard_field'), self.epoch,
            self.seed, self.mounts, _log_into(self.warnings, spec.name))
        inputs = self._input_specs(entry.inputs, p)

        def fire(t_ns: int, samples: Dict[str, Any], missing: List[str]) -> List[Output]:
            est = comp.step(t_ns, samples, self._fresh(samples, t_ns),
                            ['/' + inputs[k][0] for k in missing])
            if self.ideal_estimate:      # the truth of the frame (the study's reference)
                return [('adcs/attitude_estimate', self._latest['sim/state'])]
            if est is None:
                return []
            return [('adcs/attitude_estimate', est),
                    ('adcs/estimator/diagnostics', comp.diagnostics(t_ns))]
        self.estimator = comp
        self._consumer(spec.name, self._period(p['period_s'], 'estimator period_s'), inputs,
                       fire)

    def _add_guidance(self, spec: NodeSpec) -> None:
        p = param_values(GUIDANCE_PARAMS, spec.params)
        comp = GuidanceComponent(p)
        self._consumer(spec.name, self._period(p['period_s'], 'guidance period_s'), {},
                       lambda t_ns, x, missing: [('adcs/attitude_target', comp.step(t_ns))])

    def _add_controller(self, spec: NodeSpec) -> None:
        ctx_p = param_values(ccomp.CONTEXT_PARAMS, spec.params)
        entry = registry.get('controller', ctx_p['controller'])
        ctx_p.update(param_values(ccomp.plugin_period_params(entry), spec.params))
        own = param_values(entry.params, spec.params)
        ctx = ccomp.controller_context(
            entry, ctx_p, self.epoch, self.seed,
            ORBIT.read(spec.params, 'onboard_orbit'), FIELD.read(spec.params, 'onboard_field'))
        comp = ccomp.ControllerComponent(entry.build(own, ctx), entry.name, ctx, self.mounts)
        topic = f'adcs/controllers/{entry.name}/command'
        self._consumer(spec.name, self._period(ctx_p['period_s'], f'{spec.name} period_s'),
                       self._input_specs(entry.inputs, ctx_p),
                       lambda t_ns, x, missing: [(topic, comp.step(
                           t_ns, x, self._fresh(x, t_ns)))])

    def _add_manager(self, spec: NodeSpec) -> None:
        p = param_values(MANAGER_PARAMS, spec.params)
        auto = AUTO_SEQUENCE.read(spec.params, 'auto')
        comp = ManagerComponent(manager_core(p, auto, live=False),
                                _log_into(self.warnings, spec.name))
        ctrl_ns = seconds_to_ns(float(p['controller_period_s']) or p['period_s'])
        inputs = {n: (f'adcs/controllers/{n}/command', 'frame', ctrl_ns) for n in comp.names}
        if p['estimator_period_s'] > 0:
            inputs['_estimate'] = ('adcs/attitude_estimate', 'frame',
                                   seconds_to_ns(p['estimator_period_s']))
        limits = list(p['max_wheel_torque_Nm'])
        wheel_names = wheel_names_for(0 if limits == [-1.0] else len(limits), p['wheel_names'])
        self.manager = comp

        def fire(t_ns: int, samples: Dict[str, Any], missing: List[str]) -> List[Output]:
            cmd, status = comp.step(t_ns, samples)
            out = [('adcs/actuator_command', cmd)] + actuator_commands(cmd, wheel_names)
            key = status_key(status, comp.core.active)
            if key != self._status_key:
                self._status_key = key
                out.append(('adcs/controller_status', comp.status(t_ns, status)))
            return out
        self._consumer(spec.name, self._period(p['period_s'], 'manager period_s'), inputs, fire)

    # ------------------------------------------------------------------ stepping
    @staticmethod
    def _fresh(samples: Dict[str, Any], t_ns: int) -> Callable[[str], bool]:
        """Lockstep freshness: a sample stamped with the frame."""
        def fresh(key: str) -> bool:
            x = samples.get(key)
            return x is not None and x.t_ns == t_ns
        return fresh

    def _publish(self, frame: Frame, topic: str, sample: Any) -> None:
        frame.outputs.append((topic, sample))
        self._latest[topic] = sample
        for sync, key in self._subs.get(topic, ()):
            sync.add(key, sample.t_ns, sample)

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
        t = self.k * self.frame_ns
        frame = Frame(t)
        self._publish(frame, '/clock', Tick(t))
        env = self.environment.step(t)
        self._publish(frame, 'sim/environment', env)
        faults = self.dynamics.fault_events(t)
        if faults is not None:
            self._publish(frame, 'sim/faults', faults)
        state = self.dynamics.truth(t, env)
        self._publish(frame, 'sim/state', state)
        wheels = self.dynamics.wheels(t)
        self._publish(frame, 'sim/wheels', wheels)
        appendages = self.dynamics.appendages(t)
        if appendages is not None:
            self._publish(frame, 'sim/appendages', appendages)
        truth = {'state': state, 'env': env, 'wheels': wheels}
        for topic, period, comp in self.sensors:
            if t % period == 0 and not self._stopped(self._sensor_node[topic], t):
                x = comp.step(t, truth)
                if x is not None:
                    self._publish(frame, topic, x)
        for c in self.consumers:      # as its node fires (``LockstepNode._fire``): the
            if t % c.period_ns == 0 and not self._stopped(c.name, t):   # misses, the samples
                samples, missing = c.sync.take(t)
                for topic, x in c.fire(t, samples, missing):
                    self._publish(frame, topic, x)
        if t >= self.duration_ns:
            self.done = True
            return frame
        cmd = None                                      # hold (no command due)
        if self.command_ns and t % self.command_ns == 0:
            x = self._latest.get('adcs/actuator_command')
            cmd = ZERO if x is None or x.t_ns != t else self.dynamics.to_command(x)
        self.dynamics.step(t, env, cmd)
        self.k += 1
        return frame

    def run(self) -> Iterator[Frame]:
        """Every frame to the end of the run."""
        while not self.done:
            yield self.step()
