"""Faults of the simulated world: the registered kinds (``adcs list``, ``docs/scenarios.md``:
each kind's description and parameters) and how a component applies them.

A scenario's ``faults:`` (validated by :func:`adcs_nodes.scenario.check_fault`) strike at
exact sim time ``at_s`` for ``params.duration_s`` (0: to the end), seeded
(``derive_seed(seed, 'fault/<index>')``), announced on ``sim/faults`` (``docs/topics.md``).
The components apply them, so every engine sees the same faults: a sensor's to its sample
(:class:`SensorFaults`; a star tracker's bias is a rotation vector), an actuator's to the held
command (:class:`ActuatorFaults`). ``node_killed`` silences a node for good at ``at_s`` (a
graph run then SIGKILLs it) and the run ends degraded naming it (:func:`lost_text`); the world
and the recorder cannot be killed. Live faults (``adcs fault``): JSON on :data:`INJECT_TOPIC`,
checked as a scenario's (:func:`injected`), from ``at_s`` or the next frame: not deterministic.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from adcs_nodes.core import attitude as att
from adcs_nodes.core.lockstep import NS_PER_S, derive_seed
from adcs_nodes.registry import Entry, Param, register

#: What a fault kind may strike.
SENSOR, WHEEL, MAGNETORQUER, NODE = 'sensor', 'wheel', 'magnetorquer', 'node'
AXES = ('x', 'y', 'z')

#: The node parameter that carries a node's faults (JSON text of the scenario's entries).
FAULTS_PARAM = Param('faults', 'str', '', '-', "the scenario's faults this node applies (JSON "
                     "list of {index, at_s, kind, target, params}; '': none)", read_only=True)

_DURATION = Param('duration_s', 'float', 0.0, 's', 'how long the fault lasts (0: to the end of '
                  'the run)', min=0.0)


def _fault(name: str, description: str, targets: Sequence[str], *params: Param) -> None:
    register(Entry('fault', name, description, 'sim_node.faults', tuple(params),
                   lambda p, ctx: p, targets=tuple(targets)))


_fault('dropout', 'the sensor publishes nothing', (SENSOR,), _DURATION)
_fault('nan', 'samples with every value NaN ("no data")', (SENSOR,), _DURATION)
_fault('stuck', 'samples repeat the last values before the fault', (SENSOR,), _DURATION)
_fault('bias_step', 'a constant added to the samples (a star tracker: a rotation vector)',
       (SENSOR,), _DURATION,
       Param('bias', 'float[]', [0.0, 0.0, 0.0], 'sensor unit', 'the step per axis (T, '
             'rad/s or rad; horizon sensor: roll, pitch, unused)', length=3, min=-1.0, max=1.0))
_fault('noise_burst', 'white noise added to the samples (seeded)', (SENSOR,), _DURATION,
       Param('std', 'float[]', [0.0, 0.0, 0.0], 'sensor unit', 'noise std per axis', length=3,
             min=0.0, max=1.0))
_fault('wheel_stuck', "the wheel's motor gives no torque: its speed freezes", (WHEEL,),
       _DURATION)
_fault('wheel_torque_lost', "the wheel's motor delivers a fraction of its command", (WHEEL,),
       _DURATION, Param('fraction', 'float', 0.0, '-', 'share of the commanded torque '
                        'delivered', min=0.0, max=1.0))
_fault('coil_open', 'a magnetorquer axis gives no dipole', (MAGNETORQUER,), _DURATION)
_fault('node_killed', 'the node stops for good: it publishes nothing more (graph: the '
       'launcher SIGKILLs its process)', (NODE,))

#: The node parameter that carries a node's kill time [s] (``tools.graph.build_graph`` sets
#: it; every lockstep node has it: ``adcs_nodes.nodes.params.COMMON``).
KILLED_PARAM = 'killed_at_s'
#: Nodes a ``node_killed`` fault cannot strike: the simulated world and the recorder.
UNKILLABLE = ('dynamics', 'environment', 'recorder')


def node_kills(faults: Sequence[Dict[str, Any]]) -> Dict[str, Dict[str, Any]]:
    """``{node name: fault}`` of a scenario's validated ``node_killed`` faults (the earliest
    one per node)."""
    out: Dict[str, Dict[str, Any]] = {}
    for f in sorted(faults or [], key=lambda f: float(f['at_s'])):
        if f['kind'] == 'node_killed':
            out.setdefault(str(f['target']), f)
    return out


def lost_text(faults: Sequence[Dict[str, Any]], reached_s: float,
              skip: Sequence[str] = ()) -> List[str]:
    """``'<node> (killed at sim t = <at_s> s: the scenario's faults[<i>])'`` for each node a
    ``node_killed`` fault struck by sim time ``reached_s`` (a degraded run's reason), but
    those in ``skip``."""
    return [f'{name} (killed at sim t = {float(f["at_s"]):g} s: the scenario\'s '
            f'faults[{f["index"]}])' for name, f in sorted(node_kills(faults).items())
            if float(f['at_s']) <= reached_s + 1e-9 and name not in skip]


@dataclass
class Fault:
    """One validated fault of a scenario (times in integer nanoseconds)."""

    index: int
    kind: str
    target: str
    start_ns: int
    end_ns: Optional[int]            #: None: to the end of the run
    params: Dict[str, Any] = field(default_factory=dict)

    def active(self, t_ns: int) -> bool:
        """True at frame ``t_ns`` while the fault lasts."""
        return t_ns >= self.start_ns and (self.end_ns is None or t_ns < self.end_ns)

    def describe(self) -> str:
        """``kind target (params)`` for logs and reports."""
        extra = {k: v for k, v in self.params.items() if k != 'duration_s'}
        return f'{self.kind} {self.target}' + (f' {extra}' if extra else '')


def parse(text: str) -> List[Fault]:
    """Faults from the JSON text of a node parameter (what the graph builder writes)."""
    if not text:
        return []
    out = []
    for item in json.loads(text):
        start = int(round(float(item['at_s']) * NS_PER_S))
        duration = float(item.get('params', {}).get('duration_s', 0.0))
        out.append(Fault(int(item['index']), str(item['kind']), str(item['target']), start,
                         start + int(round(duration * NS_PER_S)) if duration > 0 else None,
                         dict(item.get('params', {}))))
    return out


# ---------------------------------------------------------------------- sensors
class SensorFaults:
    """The faults striking one sensor, applied to its samples.

    ``values(msg)`` / ``with_values(msg, v)`` give and set the sample's values (the sensor
    component's accessors); ``kind`` of the sensor selects the star tracker's rotation.
    """

    def __init__(self, faults: Sequence[Fault], seed: int, rotation: bool = False) -> None:
        self.faults = list(faults)
        self.rotation = rotation
        self._rng = {f.index: np.random.default_rng(derive_seed(seed, f'fault/{f.index}'))
                     for f in self.faults if f.kind == 'noise_burst'}
        self._last_good: Optional[np.ndarray] = None

    def add(self, fault: Fault, seed: int) -> None:
        """One more fault (a live one: :func:`injected`), seeded as a scenario's from
        ``seed`` and its index."""
        self.faults.append(fault)
        if fault.kind == 'noise_burst':
            self._rng[fault.index] = np.random.default_rng(derive_seed(seed,
                                                                       f'fault/{fault.index}'))

    def apply(self, t_ns: int, values: np.ndarray) -> Optional[np.ndarray]:
        """The sample's values under the active faults, or None (silent: a dropout)."""
        out = np.array(values, dtype=float)
        stuck = False
        for f in self.faults:
            if not f.active(t_ns):
                continue
            if f.kind == 'dropout':
                return None
            if f.kind == 'nan':
                out[:] = np.nan
            elif f.kind == 'stuck':
                stuck = True
            elif f.kind == 'bias_step':
                out = self._add(out, np.asarray(f.params['bias'], dtype=float))
            elif f.kind == 'noise_burst':
                noise = self._rng[f.index].standard_normal(3) * np.asarray(f.params['std'])
                out = self._add(out, noise)
        if stuck and self._last_good is not None:
            return self._last_good.copy()
        if not any(f.active(t_ns) for f in self.faults):
            self._last_good = np.array(values, dtype=float)
        return out

    def _add(self, values: np.ndarray, delta: np.ndarray) -> np.ndarray:
        if self.rotation:                           # q_eci_body * exp(delta): a small rotation
            return att.multiply(values, att.from_rotation_vector(delta))
        n = min(values.size, 3)
        out = values.copy()
        out[:n] = out[:n] + delta[:n]
        return out


# ---------------------------------------------------------------------- actuators
class ActuatorFaults:
    """Wheel and magnetorquer faults applied to the held command, and the ``sim/faults``
    announcements of every fault of the scenario."""

    def __init__(self, faults: Sequence[Fault], wheel_names: Sequence[str]) -> None:
        self.all = list(faults)
        self.wheel_index = {n: i for i, n in enumerate(wheel_names)}
        self.faults = [f for f in self.all if f.kind in ('wheel_stuck', 'wheel_torque_lost',
                                                         'coil_open')]

    def add(self, fault: Fault) -> None:
        """One more fault (a live one: :func:`injected`): announced by :meth:`events`, and
        applied when it strikes an actuator."""
        if fault.kind in ('wheel_stuck', 'wheel_torque_lost') \
                and fault.target not in self.wheel_index:
            raise ValueError(f'{fault.kind}: no wheel {fault.target!r}; wheels: '
                             f'{", ".join(self.wheel_index) or "none"}')
        self.all.append(fault)
        if fault.kind in ('wheel_stuck', 'wheel_torque_lost', 'coil_open'):
            self.faults.append(fault)

    def apply(self, t_ns: int, dipole: np.ndarray, wheel_torque: np.ndarray):
        """``(dipole, wheel_torque)`` as the faulty actuators deliver them at ``t_ns``."""
        if not any(f.active(t_ns) for f in self.faults):
            return dipole, wheel_torque
        dipole, wheel_torque = np.array(dipole, float), np.array(wheel_torque, float)
        for f in self.faults:
            if not f.active(t_ns):
                continue
            if f.kind == 'coil_open':
                dipole[AXES.index(f.target)] = 0.0
            elif f.kind == 'wheel_stuck':
                wheel_torque[self.wheel_index[f.target]] = 0.0
            else:
                wheel_torque[self.wheel_index[f.target]] *= float(f.params['fraction'])
        return dipole, wheel_torque

    def events(self, t_ns: int, frame_ns: int) -> List[Dict[str, Any]]:
        """Faults that start (``active``) or end (``cleared``) in the frame at ``t_ns``."""
        out = []
        for f in self.all:
            if f.start_ns <= t_ns < f.start_ns + frame_ns:
                out.append({'fault': f, 'active': True})
            elif f.end_ns is not None and f.end_ns <= t_ns < f.end_ns + frame_ns:
                out.append({'fault': f, 'active': False})
        return out


# ---------------------------------------------------------------------- live faults
#: Where a running graph takes live faults (``adcs fault``): ``std_msgs/String``, JSON.
INJECT_TOPIC = 'sim/inject_fault'


def check(kind: str, target: str, params: Optional[Dict[str, Any]], sensors: Sequence[str],
          wheels: Sequence[str], magnetorquer: bool) -> Dict[str, Any]:
    """The parameters of live fault ``kind`` striking ``target`` among ``sensors``,
    ``wheels`` and the magnetorquer axes, validated and filled as a scenario's fault is
    (:func:`adcs_nodes.scenario.check_fault`: ``ValueError`` with the reason)."""
    from adcs_nodes.scenario import check_fault
    return check_fault(kind, target, params, {
        SENSOR: list(sensors), WHEEL: list(wheels),
        MAGNETORQUER: list(AXES) if magnetorquer else []}, scripted=False)


def injected(text: str, earliest_ns: int, sensors: Optional[Sequence[str]] = (),
             wheels: Sequence[str] = (), magnetorquer: bool = False) -> Optional[Fault]:
    """The live fault of an :data:`INJECT_TOPIC` message for a node that applies faults to
    ``sensors`` (None: any sensor, the dynamics, which announces them all), ``wheels`` and
    (``magnetorquer``) the coils; None when it is not this node's, ``ValueError`` with the
    reason when malformed. It starts at ``at_s``, no earlier than ``earliest_ns`` (the next
    frame; also when ``at_s`` is null), and lasts ``params.duration_s`` (0: to the end)."""
    try:
        item = json.loads(text)
    except ValueError as exc:
        raise ValueError(f'not JSON: {exc}') from None
    if not isinstance(item, dict) or not {'kind', 'target'} <= set(item):
        raise ValueError('a live fault needs kind and target (and index, at_s, params)')
    kind, target = str(item['kind']), str(item['target'])
    from adcs_nodes import registry
    entry = registry.get('fault', kind)
    if SENSOR in entry.targets and sensors is not None and target not in sensors:
        return None                                  # another sensor's
    if SENSOR not in entry.targets and sensors and not wheels and not magnetorquer:
        return None                                  # an actuator's: the dynamics'
    params = check(kind, target, item.get('params'), [target] if sensors is None else sensors,
                   wheels, magnetorquer)
    at = item.get('at_s')
    start = int(earliest_ns)
    if at is not None:
        at = float(at)
        if not np.isfinite(at) or at < 0.0:
            raise ValueError(f'at_s must be a finite time >= 0, got {at!r}')
        start = max(start, int(round(at * NS_PER_S)))
    duration = float(params.get('duration_s', 0.0))
    return Fault(int(item.get('index', 1000)), kind, target, start,
                 start + int(round(duration * NS_PER_S)) if duration > 0 else None, params)
