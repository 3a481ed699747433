"""Scenario files: load, validate (unknown keys rejected, errors name the key and line).

A scenario is a YAML mapping. Its schema is :data:`SCHEMA` below: every key, its type, its
default and a one-line meaning. ``adcs list`` prints the scenarios, ``docs/scenarios.md``
documents the keys. Sections whose allowed keys depend on a selector (``orbit.type``,
``field.model``) are checked against the keys of the selected variant.

Pure Python + PyYAML; no rclpy.
"""
from __future__ import annotations

import datetime
import copy
import difflib
import math
import os
import re
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple

import yaml

from adcs_nodes import inputs as _inputs
from adcs_nodes import registry
from adcs_nodes.registry import Param


class ScenarioError(ValueError):
    """A scenario file is malformed; the message names the file, line and key."""


@dataclass(frozen=True)
class F:
    """Schema leaf: expected type, default (``REQUIRED`` if none) and meaning."""

    kind: str
    default: Any
    doc: str
    choices: Tuple[str, ...] = ()


REQUIRED = object()
OPTIONAL = None


class Opt(dict):
    """A schema section that exists only when the scenario gives it (a sensor, a node)."""


_ORBIT_COMMON = {'type': F('str', 'circular', 'orbit model', ('circular', 'tle'))}
ORBIT_VARIANTS = {
    'circular': {
        'altitude_km': F('float', REQUIRED, 'altitude above the reference radius [km]'),
        'inclination_deg': F('float', REQUIRED, 'inclination [deg]'),
        'raan_deg': F('float', 0.0, 'right ascension of the ascending node [deg]'),
        'arg_latitude0_deg': F('float', 0.0, 'argument of latitude at the epoch [deg]'),
    },
    'tle': {
        'line1': F('str', REQUIRED, 'TLE line 1'),
        'line2': F('str', REQUIRED, 'TLE line 2'),
    },
}
_FIELD_COMMON = {'model': F('str', 'dipole', 'geomagnetic model',
                            ('dipole', 'igrf_dipole', 'igrf'))}
FIELD_VARIANTS = {
    'dipole': {
        'b0_T': F('float', OPTIONAL, 'dipole strength at the reference radius [T]'),
        'r_ref_m': F('float', OPTIONAL, 'reference radius of b0_T [m]'),
        'pole_colatitude_deg': F('float', OPTIONAL,
                                 'geographic colatitude of the dipole axis [deg]'),
        'pole_longitude_deg': F('float', OPTIONAL, 'geographic east longitude of the axis [deg]'),
    },
    'igrf_dipole': {
        'coefficient_date': F('str', OPTIONAL, 'date of the IGRF degree-1 coefficients '
                              '(ISO 8601; default: the epoch)'),
    },
    'igrf': {
        'max_degree': F('int', OPTIONAL, 'truncation degree of the IGRF expansion'),
    },
}

SCHEMA: Dict[str, Any] = {
    'name': F('str', REQUIRED, 'scenario name'),
    'description': F('str', '', 'one-paragraph description'),
    'paper': F('str', '', 'source paper (file in papers/original) this scenario reproduces'),
    'epoch': F('str', '2026-01-01T00:00:00Z', 'UTC date-time of sim time 0 (ISO 8601)'),
    'seed': F('int', 0, 'scenario seed; every node derives its own random stream from it'),
    'plugins': F('strlist', [], 'registry plugin modules or .py files (relative to the '
                 'scenario) that register more controllers, estimators or sensors'),
    'duration_s': F('float', REQUIRED, 'simulated duration [s]'),
    'timing': {
        'frame_s': F('float', 1.0, 'base frame period [s]; every period is a multiple of it'),
        'substeps': F('int', 10, 'RK4 substeps per frame in the dynamics'),
        'timeout_s': F('float', 5.0, 'wall-clock wait for a missing input before going on [s]'),
    },
    'orbit': 'ORBIT',
    'field': 'FIELD',
    'spacecraft': {
        'inertia_kgm2': F('matrix3', REQUIRED, 'inertia tensor about the centre of mass, '
                          'body axes [kg m^2]: 3 diagonal values or a 3x3 matrix'),
        'gravity_gradient': F('bool', True, 'apply the gravity-gradient torque'),
        'magnetorquer': {
            'max_dipole_Am2': F('vec3', REQUIRED, 'per-axis dipole limit [A m^2]'),
        },
        'ideal_torque': {
            'max_torque_Nm': F('vec3', REQUIRED, 'per-axis limit of an ideal body-torque '
                               'actuator (thrusters, or a stand-in for wheels) [N m]'),
        },
        'wheels': F('wheels', [], 'reaction wheels: list of {name, axis, max_torque_Nm, '
                    'max_momentum_Nms, inertia_kgm2, h0_Nms}'),
        'wheel_error_std_Nms': F('float', 0.0, 'momentum control error of every wheel, 1-sigma '
                                 '[N m s], redrawn each wheel_error_period_s (paper 001: '
                                 '0.01/3); 0: none'),
        'wheel_error_period_s': F('float', OPTIONAL, 'period of the momentum error draws [s] '
                                  '(default: controllers.period_s, else timing.frame_s)'),
        'flexible': Opt({
            'model': F('str', 'paper001', 'flexible appendage modes: paper 001\'s two solar '
                       'wings (5 modes each, coupling (32))', ('paper001',)),
            'wings': F('str', 'two', 'two: both wings (the -X wing mirrored, 10 modes); one: '
                       'the +X wing only (5 modes)', ('one', 'two')),
            'damping': F('float', 0.005, 'modal damping ratio of every mode (the paper gives '
                         'none)'),
        }),
        'disturbance': {
            'constant_torque_Nm': F('vec3', [0.0, 0.0, 0.0], 'constant body torque [N m]'),
            'random_std_Nm': F('float', 0.0, 'std of the random body torque per axis [N m]'),
            'random_period_s': F('float', 2.0, 'hold time of each random draw [s]'),
            'aerodynamic_Nm': F('vec3', [0.0, 0.0, 0.0], 'aerodynamic torque amplitude per '
                                'body axis, a sin(2 pi t / harmonic_period_s + seeded phase) '
                                '[N m]'),
            'solar_pressure_Nm': F('vec3', [0.0, 0.0, 0.0], 'solar pressure torque amplitude, '
                                   'same waveform [N m]'),
            'synthetic_gravity_gradient_Nm': F('vec3', [0.0, 0.0, 0.0], 'a harmonic stand-in '
                                               'for the gravity gradient at twice that '
                                               'frequency (paper 001 magnitudes) [N m]'),
            'harmonic_period_s': F('float', OPTIONAL, 'period of the harmonic torques [s] '
                                   '(default: the orbital period)'),
            'residual_magnetic_Nm': F('vec3', [0.0, 0.0, 0.0], 'constant residual magnetic '
                                      'torque [N m]'),
            'unloading_Nm': F('vec3', [0.0, 0.0, 0.0], 'momentum unloading torque per axis, '
                              'seeded signs, on unloading_duration_s every unloading_period_s '
                              '[N m]'),
            'unloading_period_s': F('float', 600.0, 'unloading period [s]'),
            'unloading_duration_s': F('float', 60.0, 'unloading pulse length [s]'),
            'unloading_start_s': F('float', 0.0, 'first unloading pulse [s]'),
        },
    },
    'initial': {
        'q_orbit_body_wxyz': F('quat', OPTIONAL, 'initial attitude body->orbit, scalar FIRST '
                               "(paper 000's Lambda)"),
        'q_orbit_body_xyzw': F('quat', OPTIONAL, 'initial attitude body->orbit, scalar last'),
        'omega_body_eci_body_deg_s': F('vec3', OPTIONAL,
                                       'initial rate w.r.t. ECI, body axes [deg/s]'),
        'omega_body_orbit_body_deg_s': F('vec3', OPTIONAL,
                                         'initial rate w.r.t. the orbit frame, body axes [deg/s]'),
    },
    'sensors': 'SENSORS',
    'estimator': 'ESTIMATOR',
    'controllers': 'CONTROLLERS',
    'guidance': Opt({
        'period_s': F('float', OPTIONAL, 'target period [s] (default: controllers.period_s)'),
        'frame': F('str', 'orbit', 'frame of the profile attitudes', ('orbit', 'eci')),
        'profile': F('profile', [], 'time-tagged segments: list of {t_s, type: hold|slew|'
                     'track, q_xyzw, duration_s (slew), axis_body, amplitude_deg, period_s '
                     '(track)}; empty: hold the orbital frame'),
        'euler312_profile': F('euler312', [], "paper 001's profile instead: list of {type: "
                              'maneuver|hold|sine, start_s, end_s, euler_deg | center_deg, '
                              'amplitude_deg, period_s, phase_deg} in LVLH 3-1-2 Euler '
                              'angles [deg] (orbit frame)'),
    }),
    'manager': Opt({
        'safe': F('str', 'bdot', 'safe-mode controller (fallback)'),
        'fallback': F('strlist', [], 'controllers tried in order before the safe one when the '
                      "active command is unusable (e.g. [magnetic]: a failed wheel's "
                      'controller hands over to the magnetorquers)'),
        'initial': F('str', '', 'controller active at start (default: auto detumble or safe)'),
        'stale_after_s': F('float', 0.0, 'a command older than this is stale [s] (0: the '
                           'frame stamp only)'),
        'schedule': F('schedule', [], 'scripted switches: list of {t_s, controller}'),
        'auto': Opt({
            'detumble': F('str', 'bdot', 'controller of the detumble mode'),
            'acquire': F('str', 'magnetic', 'controller of the acquire mode'),
            'rate_enter_deg_s': F('float', 0.5, 'detumble -> acquire below this rate [deg/s]'),
            'rate_exit_deg_s': F('float', 1.0, 'acquire -> detumble above this rate [deg/s]'),
            'confirm_frames': F('int', 10, 'frames the forward condition must hold'),
            'exit_confirm_frames': F('int', 1, 'frames the back condition must hold'),
            'rate_frame': F('str', 'eci', 'rate compared: w.r.t. ECI or the orbit frame',
                            ('eci', 'orbit')),
            'point': F('str', OPTIONAL, 'controller of the optional point mode (after '
                       'acquire, once the attitude error is below angle_enter_deg)'),
            'angle_enter_deg': F('float', OPTIONAL, 'acquire -> point below this attitude '
                                 'error to the orbital frame [deg]'),
            'angle_exit_deg': F('float', OPTIONAL, 'point -> acquire above this error [deg] '
                                '(> angle_enter_deg)'),
        }),
    }),
    'record': {
        'topics': F('strlist', [], 'topics to record (empty: every topic of the graph)'),
    },
    'faults': F('faults', [], 'scripted faults of the world: list of {at_s, kind, target, '
                'params}; kinds: `adcs list` (sensor: dropout, nan, stuck, bias_step, '
                'noise_burst; wheel: wheel_stuck, wheel_torque_lost; magnetorquer axis x|y|z: '
                'coil_open; node: node_killed); params.duration_s: how long (0: to the end); '
                'the kinds: the table below'),
}

_WHEEL_KEYS = {
    'name': F('str', REQUIRED, 'wheel name'),
    'axis': F('vec3', REQUIRED, 'spin axis, body axes (normalised)'),
    'max_torque_Nm': F('float', REQUIRED, 'motor torque limit [N m]'),
    'max_momentum_Nms': F('float', REQUIRED, 'momentum limit [N m s]'),
    'inertia_kgm2': F('float', 1e-3, 'wheel inertia about its axis [kg m^2]'),
    'h0_Nms': F('float', 0.0, 'initial wheel momentum [N m s]'),
}

#: Keys of the estimator section that every algorithm has (the rest come from its entry).
_ESTIMATOR_COMMON = {
    'algorithm': F('str', 'magnetic_filter', 'attitude estimator (a registered estimator; '
                   '`adcs list`)'),
    'period_s': F('float', 2.0, 'estimator period [s] (paper 000: prediction every 2 s)'),
    'initial_q_orbit_body_xyzw': F('quat', [0.0, 0.0, 0.0, 1.0],
                                   'initial attitude estimate (paper 000: identity)'),
    'initial_omega_body_orbit_body_deg_s': F('vec3', [0.0, 0.0, 0.0],
                                             'initial relative rate estimate [deg/s] '
                                             "(paper 000: omega' = (0, omega0, 0))"),
    'onboard_orbit': 'ORBIT?',
    'onboard_field': 'FIELD?',
}
_EXTERNAL = F('bool', False, 'a real driver publishes this topic: the launcher starts no '
              'simulated node for it and says so')


def schema() -> Dict[str, Any]:
    """The whole scenario schema, with the registry's sections filled in.

    ``sensors.<name>``, ``estimator`` (per algorithm) and ``controllers.<name>`` come from the
    registry entries' parameter specs (:mod:`adcs_nodes.registry`), so a plugin that registers
    a controller gets its scenario keys with nothing else to write.
    """
    sensors = {name: Opt({**{p.name: p for p in e.params}, 'external': _EXTERNAL})
               for name, e in registry.entries('sensor').items()}
    estimator = Variant('algorithm', _ESTIMATOR_COMMON,
                        {name: {p.name: p for p in e.params}
                         for name, e in registry.entries('estimator').items()})
    controllers = {'period_s': F('float', 2.0, 'control period of every controller [s] '
                                 '(paper 000 assumption: 2 s, dipole held in between)')}
    controllers.update({name: Opt({p.name: p for p in e.params})
                        for name, e in registry.entries('controller').items()})
    out = dict(SCHEMA)
    out['sensors'] = sensors
    out['estimator'] = estimator
    out['controllers'] = Opt(controllers)
    return out


class Variant:
    """A section whose keys depend on a selector key (``estimator.algorithm``)."""

    def __init__(self, selector: str, common: Dict[str, Any], variants: Dict[str, Any]):
        self.selector, self.common, self.variants = selector, common, variants


# ---------------------------------------------------------------------- YAML with lines
#: Largest scenario file read [bytes] (a real one is a few kB).
MAX_FILE_BYTES = 1_000_000
#: Largest number of YAML nodes after alias expansion (an alias bomb of a few hundred bytes
#: expands to billions; a real scenario has a few hundred).
MAX_NODES = 100_000
#: Longest run of characters without a space echoed in an error message, and longest message.
MAX_SHOWN = 80
MAX_MESSAGE = 600


class _LineLoader(yaml.SafeLoader):
    """SafeLoader that remembers the line of every mapping key and refuses alias bombs."""

    def construct_document(self, node):
        _check_expansion(node)
        return super().construct_document(node)


def _check_expansion(root) -> None:
    """Raise ``ScenarioError`` if the YAML node graph expands to more than ``MAX_NODES``.

    Aliases make the composed graph a DAG: the expanded size of a node is computed once per
    node (memoised, iterative: no recursion limit), so the check costs the size of the text.
    """
    size: Dict[int, int] = {}
    open_nodes = set()
    stack = [(root, False)]
    while stack:
        node, children_done = stack.pop()
        if id(node) in size:
            continue
        if isinstance(node, yaml.ScalarNode):
            size[id(node)] = 1
            continue
        kids = ([n for pair in node.value for n in pair] if isinstance(node, yaml.MappingNode)
                else list(node.value))
        if children_done:
            open_nodes.discard(id(node))
            total = 1 + sum(size[id(k)] for k in kids)
            if total > MAX_NODES:
                raise ScenarioError(
                    f'line {node.start_mark.line + 1}: this value expands to more than '
                    f'{MAX_NODES} YAML nodes (aliases of aliases?)')
            size[id(node)] = total
            continue
        if id(node) in open_nodes:
            raise ScenarioError(f'line {node.start_mark.line + 1}: a value that contains '
                                'itself (recursive alias)')
        open_nodes.add(id(node))
        stack.append((node, True))
        for kid in kids:
            if id(kid) in open_nodes:
                raise ScenarioError(f'line {kid.start_mark.line + 1}: a value that contains '
                                    'itself (recursive alias)')
            if id(kid) not in size:
                stack.append((kid, False))


def _construct_mapping(loader, node, deep=False):
    mapping = {}
    lines = {}
    for key_node, value_node in node.value:
        if not isinstance(key_node, yaml.ScalarNode):
            raise ScenarioError(f'line {key_node.start_mark.line + 1}: a mapping key must be '
                                f'plain text, not a {key_node.id} (complex key "? ...")')
        key = loader.construct_object(key_node, deep=deep)
        try:
            hash(key)
        except TypeError:
            raise ScenarioError(f'line {key_node.start_mark.line + 1}: a mapping key must be '
                                f'plain text, got {type(key).__name__}') from None
        if key in mapping:
            raise ScenarioError(f'line {key_node.start_mark.line + 1}: duplicate key {key!r}')
        mapping[key] = loader.construct_object(value_node, deep=True)
        lines[key] = key_node.start_mark.line + 1
    return _Map(mapping, lines)


class _Map(dict):
    """dict that carries ``lines``: key -> line number in the YAML file."""

    def __init__(self, data, lines):
        super().__init__(data)
        self.lines = lines


_LineLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
# YAML 1.1 (PyYAML) reads 1e-5 and 2.0e6 as text; engineers write them: read them as floats
_LineLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(r'^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$'),
    list('-+0123456789.'))


# ---------------------------------------------------------------------- validation
class _Checker:
    def __init__(self, path: str) -> None:
        self.path = path

    def fail(self, line: Optional[int], key: str, msg: str) -> None:
        where = f'{self.path}:{line}' if line else self.path
        raise ScenarioError(f'{where}: {key}: {msg}')

    def mapping(self, data: Any, schema: Dict[str, Any], prefix: str, line: Optional[int]):
        if data is None:
            data = _Map({}, {})
        if not isinstance(data, dict):
            self.fail(line, prefix or '<top>', f'expected a mapping, got {type(data).__name__}')
        lines = getattr(data, 'lines', {})
        out: Dict[str, Any] = {}
        for key in data:
            if key not in schema:
                near = difflib.get_close_matches(str(key), list(schema), n=1)
                hint = f' (did you mean {near[0]!r}?)' if near else ''
                self.fail(lines.get(key), prefix + str(key),
                          f'unknown key{hint}; allowed: {", ".join(sorted(schema))}')
        for key, spec in schema.items():
            full = prefix + key
            kline = lines.get(key, line)
            if isinstance(spec, dict):
                if key not in data and (isinstance(spec, Opt) or _has_required(spec)):
                    continue  # optional section, or one with required keys: absent as a whole
                out[key] = self.mapping(data.get(key), spec, full + '.', kline)
            elif isinstance(spec, Variant):
                if key in data:   # an optional section whose keys depend on its selector
                    out[key] = self.variant(data[key], spec.common, spec.selector,
                                            spec.variants, full, kline)
            elif isinstance(spec, Param):
                out[key] = (self.leaf(data[key], spec, full, kline) if key in data
                            else copy.deepcopy(spec.default))
            elif spec in ('ORBIT?', 'FIELD?') and key not in data:
                continue  # optional variant section (the caller supplies a default)
            elif spec in ('ORBIT', 'ORBIT?'):
                out[key] = self.variant(data.get(key), _ORBIT_COMMON, 'type', ORBIT_VARIANTS,
                                        full, kline)
            elif spec in ('FIELD', 'FIELD?'):
                out[key] = self.variant(data.get(key), _FIELD_COMMON, 'model', FIELD_VARIANTS,
                                        full, kline)
            elif key in data:
                out[key] = self.leaf(data[key], spec, full, kline)
            elif spec.default is REQUIRED:
                self.fail(line, full, f'missing required key ({spec.doc})')
            elif spec.default is not OPTIONAL:
                out[key] = spec.default
        return out

    def variant(self, data, common, selector, variants, full, line):
        if data is None:
            self.fail(line, full, 'missing required section')
        if not isinstance(data, dict):
            self.fail(line, full, 'expected a mapping')
        sel = data.get(selector, common[selector].default)
        if not isinstance(sel, str) or sel not in variants:
            self.fail(getattr(data, 'lines', {}).get(selector, line), f'{full}.{selector}',
                      f'unknown {selector} {sel!r}; allowed: {", ".join(variants)}')
        return self.mapping(data, {**common, **variants[sel]}, full + '.', line)

    def leaf(self, value: Any, spec: F, key: str, line: Optional[int]) -> Any:
        if isinstance(spec, Param):   # a registry parameter: its own type and range check
            try:
                return spec.validate(value)
            except ValueError as exc:
                self.fail(line, key, str(exc).split(': ', 1)[-1] + f' ({spec.doc()})')
        try:
            return _convert(value, spec)
        except (TypeError, ValueError) as exc:
            self.fail(line, key, f'{exc} ({spec.doc})')
        return None


def _has_required(spec: Dict[str, Any]) -> bool:
    return any(isinstance(v, F) and v.default is REQUIRED for v in spec.values())


def _finite(x: Any) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise ValueError(f'expected a number, got {x!r}')
    if not math.isfinite(float(x)):
        raise ValueError(f'expected a finite number, got {x!r}')
    return float(x)


def _vector(value: Any, n: int) -> List[float]:
    if not isinstance(value, list) or len(value) != n:
        raise ValueError(f'expected a list of {n} numbers, got {value!r}')
    return [_finite(v) for v in value]


def _convert(value: Any, spec: F) -> Any:
    kind = spec.kind
    if kind == 'str':
        if not isinstance(value, str):
            raise ValueError(f'expected text, got {value!r}')
        if spec.choices and value not in spec.choices:
            raise ValueError(f'{value!r} is not one of {", ".join(spec.choices)}')
        return value
    if kind == 'float':
        return _finite(value)
    if kind == 'int':
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f'expected an integer, got {value!r}')
        return value
    if kind == 'bool':
        if not isinstance(value, bool):
            raise ValueError(f'expected true or false, got {value!r}')
        return value
    if kind == 'vec3':
        return _vector(value, 3)
    if kind == 'vec2':
        return _vector(value, 2)
    if kind == 'list9':
        return _vector(value, 9)
    if kind == 'quat':
        q = _vector(value, 4)
        norm = math.sqrt(sum(c * c for c in q))
        if abs(norm - 1.0) > 1e-3:
            raise ValueError(f'quaternion norm is {norm:.6f}, expected 1')
        return [c / norm for c in q]
    if kind == 'matrix3':
        if isinstance(value, list) and len(value) == 3 and all(
                not isinstance(v, list) for v in value):
            d = _vector(value, 3)
            return [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]]
        if isinstance(value, list) and len(value) == 3:
            return [_vector(row, 3) for row in value]
        raise ValueError(f'expected 3 numbers or a 3x3 matrix, got {value!r}')
    if kind == 'strlist':
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise ValueError(f'expected a list of text, got {value!r}')
        return value
    if kind == 'schedule':
        if not isinstance(value, list):
            raise ValueError(f'expected a list of {{t_s, controller}}, got {value!r}')
        out = []
        for item in value:
            if not isinstance(item, dict) or set(item) != {'t_s', 'controller'}:
                raise ValueError(f'schedule entries need exactly t_s and controller: {item!r}')
            out.append({'t_s': _finite(item['t_s']), 'controller': str(item['controller'])})
        return sorted(out, key=lambda e: e['t_s'])
    if kind == 'profile':
        return _profile(value)
    if kind == 'euler312':
        from adcs_nodes.core.guidance_profiles import profile_from_dicts
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise ValueError(f'expected a list of segments, got {registry.short(value)}')
        value = [{k: (list(v) if isinstance(v, list) else v) for k, v in item.items()}
                 for item in value]       # plain dicts and lists (no line-number maps)
        if value:
            profile_from_dicts(value)     # ValueError with the reason
        return value
    if kind == 'faults':
        if not isinstance(value, list):
            raise ValueError(f'expected a list of {{at_s, kind, target, params}}, got '
                             f'{registry.short(value)}')
        out = []
        for i, item in enumerate(value):
            if isinstance(item, dict):      # a loaded scenario's faults carry their index
                item = {k: v for k, v in item.items() if k != 'index'}
            if not isinstance(item, dict) or not {'at_s', 'kind', 'target'} <= set(item) \
                    or not set(item) <= {'at_s', 'kind', 'target', 'params'}:
                raise ValueError(f'fault {i} needs at_s, kind, target and optional params: '
                                 f'{registry.short(item)}')
            params = item.get('params') or {}
            if not isinstance(params, dict):
                raise ValueError(f'fault {i}: params must be a mapping, got '
                                 f'{registry.short(params)}')
            if not isinstance(item['kind'], str) or not isinstance(item['target'], str):
                raise ValueError(f'fault {i}: kind and target are names (text)')
            out.append({'index': i, 'at_s': _finite(item['at_s']), 'kind': item['kind'],
                        'target': item['target'],
                        'params': {k: (list(v) if isinstance(v, list) else v)
                                   for k, v in params.items()}})
        return out
    if kind == 'wheels':
        if not isinstance(value, list):
            raise ValueError(f'expected a list of wheels, got {value!r}')
        return value  # entries are checked by _check_wheels (with lines)
    raise AssertionError(f'unknown schema kind {kind}')


_SEGMENT_KEYS = {'t_s', 'type', 'q_xyzw', 'duration_s', 'axis_body', 'amplitude_deg',
                 'period_s'}


def _profile(value: Any) -> List[dict]:
    """A guidance profile: checked segments with every key filled in, sorted by ``t_s``."""
    if not isinstance(value, list):
        raise ValueError(f'expected a list of segments, got {registry.short(value)}')
    out = []
    for item in value:
        if not isinstance(item, dict) or not {'t_s', 'type'} <= set(item) or \
                not set(item) <= _SEGMENT_KEYS:
            raise ValueError(f'a segment needs t_s and type, and only the keys '
                             f'{sorted(_SEGMENT_KEYS)}: {registry.short(item)}')
        seg = {'t_s': _finite(item['t_s']), 'type': item['type'],
               'q_xyzw': _convert(item.get('q_xyzw', [0.0, 0.0, 0.0, 1.0]),
                                  F('quat', None, 'segment attitude')),
               'duration_s': _finite(item.get('duration_s', 0.0)),
               'axis_body': _vector(item.get('axis_body', [0.0, 0.0, 1.0]), 3),
               'amplitude_deg': _finite(item.get('amplitude_deg', 0.0)),
               'period_s': _finite(item.get('period_s', 0.0))}
        if seg['type'] not in ('hold', 'slew', 'track'):
            raise ValueError(f'segment type {registry.short(seg["type"])} is not one of hold, '
                             'slew, track')
        if seg['t_s'] < 0 or seg['duration_s'] < 0 or seg['period_s'] < 0:
            raise ValueError(f'segment times must be >= 0: {registry.short(item)}')
        if seg['type'] == 'slew' and not seg['duration_s'] > 0:
            raise ValueError(f'a slew needs duration_s > 0: {registry.short(item)}')
        if seg['type'] == 'track' and not seg['period_s'] > 0:
            raise ValueError(f'a track needs period_s > 0: {registry.short(item)}')
        out.append(seg)
    return sorted(out, key=lambda e: e['t_s'])


def _check_wheels(checker: _Checker, wheels: List[Any], line: Optional[int]) -> List[dict]:
    out = []
    for i, w in enumerate(wheels):
        out.append(checker.mapping(w, _WHEEL_KEYS, f'spacecraft.wheels[{i}].', line))
    names = [w['name'] for w in out]
    if len(set(names)) != len(names):
        checker.fail(line, 'spacecraft.wheels', f'duplicate wheel names {names}')
    return out


#: Registry input -> the sensor section that provides it (from the input records).
SENSOR_OF_INPUT = {i.name: i.sensor for i in _inputs.INPUTS if i.sensor}


def controller_names(sc: Dict[str, Any]) -> List[str]:
    """Names of the controllers a validated scenario configures, in file order."""
    return [k for k in sc.get('controllers', {}) if k != 'period_s']


def default_safe(names: List[str]) -> str:
    """The safe controller without a manager section: B-dot when configured, else the first."""
    return 'bdot' if 'bdot' in names or not names else names[0]


def controller_problems(sc: Dict[str, Any], name: str) -> List[str]:
    """Why controller ``name`` cannot run on this scenario's spacecraft (empty: it can)."""
    entry = registry.get('controller', name)
    craft, sensors, out = sc['spacecraft'], sc.get('sensors', {}), []
    for need in entry.inputs:
        sensor = SENSOR_OF_INPUT.get(need)
        if sensor and sensor not in sensors:
            out.append(f'needs sensors.{sensor} (input {need})')
        if need == 'estimate' and 'estimator' not in sc:
            out.append('needs an estimator')
    if 'magnetorquer' in entry.actuators and 'magnetorquer' not in craft:
        out.append('commands magnetorquers: needs spacecraft.magnetorquer')
    if 'wheels' in entry.actuators and not craft.get('wheels'):
        out.append('commands reaction wheels: needs spacecraft.wheels')
    if 'torque' in entry.actuators and 'ideal_torque' not in craft and not craft.get('wheels'):
        out.append('commands a body torque: needs spacecraft.ideal_torque or '
                   'spacecraft.wheels (torque allocation)')
    for section in entry.requires:
        head, _, tail = section.partition('.')
        if not (sc.get(head, {}).get(tail) if tail else sc.get(head)):
            out.append(f'needs {section}')
    return out


def node_targets(sc: Dict[str, Any]) -> List[str]:
    """The names of the nodes of scenario ``sc`` (validated or raw) a ``node_killed``
    fault may strike: its simulated sensors, the estimator, guidance, each controller
    (``<name>_controller``) and the controller manager."""
    out = [k for k, cfg in (sc.get('sensors') or {}).items()
           if not (isinstance(cfg, dict) and cfg.get('external'))]
    if sc.get('estimator'):
        out.append('estimator')
    ctrl = sc.get('controllers')
    if isinstance(ctrl, dict):
        out += ['guidance'] + [f'{k}_controller' for k in ctrl if k != 'period_s']
        out.append('controller_manager')
    return out


def _check_faults(checker: _Checker, sc: Dict[str, Any], lines: Dict[str, int]) -> None:
    """Each fault: a registered kind, a target it can strike, a time inside the run, its
    parameters in range (filled with their defaults)."""
    line = lines.get('faults')
    sensors = sc.get('sensors', {})
    craft = sc['spacecraft']
    wheels = [w['name'] for w in craft.get('wheels') or []]
    for f in sc.get('faults', []):
        key = f'faults[{f["index"]}]'
        try:
            entry = registry.get('fault', f['kind'])
        except ValueError as exc:
            checker.fail(line, f'{key}.kind', str(exc))
            continue
        if not 0.0 <= f['at_s'] <= sc['duration_s']:
            checker.fail(line, f'{key}.at_s', f'{f["at_s"]:g} s is outside the run '
                         f'[0, {sc["duration_s"]:g}] s')
        target = f['target']
        if 'sensor' in entry.targets:
            known = [k for k, cfg in sensors.items() if not cfg.get('external')]
        elif 'wheel' in entry.targets:
            known = wheels
        elif 'node' in entry.targets:
            known = node_targets(sc)
        else:
            known = ['x', 'y', 'z'] if 'magnetorquer' in craft else []
        if target not in known:
            checker.fail(line, f'{key}.target', f'{f["kind"]} cannot strike {target!r}; '
                         f'it strikes {", ".join(entry.targets)}: '
                         f'{", ".join(known) or "none in this scenario"}')
        try:
            f['params'] = entry.validate(f['params'])
        except ValueError as exc:
            checker.fail(line, f'{key}.params', str(exc))


def _check_consistency(checker: _Checker, sc: Dict[str, Any], lines: Dict[str, int]) -> None:
    if sc['duration_s'] <= 0:
        checker.fail(lines.get('duration_s'), 'duration_s', 'must be positive')
    timing = sc['timing']
    if timing['frame_s'] <= 0:
        checker.fail(lines.get('timing'), 'timing.frame_s', 'must be positive')
    if timing['substeps'] < 1:
        checker.fail(lines.get('timing'), 'timing.substeps', 'must be >= 1')
    if timing['timeout_s'] <= 0:
        checker.fail(lines.get('timing'), 'timing.timeout_s', 'must be positive')
    frames = sc['duration_s'] / timing['frame_s']
    if abs(frames - round(frames)) > 1e-9:
        checker.fail(lines.get('duration_s'), 'duration_s',
                     f'{sc["duration_s"]} s is not a whole number of {timing["frame_s"]} s frames')
    init = sc['initial']
    if 'q_orbit_body_wxyz' in init and 'q_orbit_body_xyzw' in init:
        checker.fail(lines.get('initial'), 'initial',
                     'give q_orbit_body_wxyz or q_orbit_body_xyzw, not both')
    if 'omega_body_eci_body_deg_s' in init and 'omega_body_orbit_body_deg_s' in init:
        checker.fail(lines.get('initial'), 'initial',
                     'give omega_body_eci_body_deg_s or omega_body_orbit_body_deg_s, not both')
    sensors = sc.get('sensors', {})
    if 'estimator' in sc:
        entry = registry.get('estimator', sc['estimator']['algorithm'])
        for need in entry.inputs:
            sensor = SENSOR_OF_INPUT.get(need)
            if sensor and sensor not in sensors:
                checker.fail(lines.get('estimator'), 'estimator.algorithm',
                             f'{entry.name} needs sensors.{sensor}')
    if 'wheel_tachometer' in sensors and not sc['spacecraft'].get('wheels'):
        checker.fail(lines.get('sensors'), 'sensors.wheel_tachometer',
                     'needs spacecraft.wheels')
    if 'controllers' in sc:
        names = controller_names(sc)
        if not names:
            checker.fail(lines.get('controllers'), 'controllers', 'no controller configured '
                         f'(registered: {", ".join(registry.names("controller"))})')
        for name in names:
            for why in controller_problems(sc, name):
                checker.fail(lines.get('controllers'), f'controllers.{name}', why)
        man = sc.get('manager', {'safe': default_safe(names), 'initial': '', 'schedule': []})
        allowed = names + (['auto'] if 'auto' in man else [])
        for key in ('safe', 'initial'):
            if man.get(key) and man[key] not in names:
                checker.fail(lines.get('manager'), f'manager.{key}',
                             f'{man[key]!r} is not a configured controller ({names})')
        for name in man.get('fallback') or []:
            if name not in names or name == man.get('safe'):
                checker.fail(lines.get('manager'), 'manager.fallback',
                             f'{name!r} is not a configured controller other than the safe '
                             f'one ({names})')
        if len(set(man.get('fallback') or [])) != len(man.get('fallback') or []):
            checker.fail(lines.get('manager'), 'manager.fallback', 'names a controller twice')
        for mode in ('detumble', 'acquire', 'point'):
            name = man.get('auto', {}).get(mode)
            if name and name not in names:
                checker.fail(lines.get('manager'), f'manager.auto.{mode}',
                             f'{name!r} is not a configured controller ({names})')
        if 'auto' in man:
            try:
                from adcs_nodes.core.manager import AutoSequence
                AutoSequence.from_dict(man['auto'])
            except ValueError as exc:
                checker.fail(lines.get('manager'), 'manager.auto', str(exc))
        for entry in man.get('schedule', []):
            if entry['controller'] not in allowed:
                checker.fail(lines.get('manager'), 'manager.schedule',
                             f'{entry["controller"]!r} is not one of {allowed}')
    elif 'manager' in sc:
        checker.fail(lines.get('manager'), 'manager', 'needs a controllers section')
    frame = timing['frame_s']
    periods = [('estimator.period_s', sc.get('estimator', {}).get('period_s')),
               ('controllers.period_s', sc.get('controllers', {}).get('period_s'))]
    periods += [(f'sensors.{k}.period_s', v['period_s']) for k, v in sc['sensors'].items()]
    for key, period in periods:
        if period is not None and (period <= 0 or abs(period / frame - round(period / frame))
                                   > 1e-9):
            checker.fail(lines.get(key.split('.')[0]), key,
                         f'{period} s is not a positive multiple of the frame {frame} s')
    _check_faults(checker, sc, lines)
    inertia = sc['spacecraft']['inertia_kgm2']
    sym = all(abs(inertia[i][j] - inertia[j][i]) <= 1e-9 * max(1.0, abs(inertia[i][j]))
              for i in range(3) for j in range(3))
    if not sym:
        checker.fail(lines.get('spacecraft'), 'spacecraft.inertia_kgm2', 'must be symmetric')


def load_scenario(path: str, plugins: Optional[List[str]] = None) -> Dict[str, Any]:
    """Read and validate a scenario file.

    ``plugins``, when given, are imported instead of the file's own ``plugins:`` list, which
    is then only data (a bag's ``scenario.yaml``: a bag is data, never code).

    Returns
    -------
    dict
        The scenario with every default filled in, plus ``_path`` (absolute path).

    Raises
    ------
    ScenarioError
        On a missing, too large (> ``MAX_FILE_BYTES``) or non-UTF-8 file, YAML syntax error,
        alias bomb (> ``MAX_NODES`` nodes once expanded), unknown or missing key, bad value,
        or a physically impossible value (:func:`_check_physical`); the message names the file,
        the line and the key, with long values cut (``MAX_SHOWN`` characters).
    """
    try:
        return _load_scenario(path, plugins)
    except ScenarioError as exc:
        text, name = str(exc), str(path)
        if text.startswith(name):      # the file's path is never cut, only what follows it
            raise ScenarioError(name + shorten_message(text[len(name):])) from None
        raise ScenarioError(shorten_message(text)) from None


def shorten_message(text: str, max_run: int = MAX_SHOWN, max_len: int = MAX_MESSAGE) -> str:
    """``text`` with every run of more than ``max_run`` non-space characters cut in its middle,
    and the whole cut to ``max_len`` characters (a rejected 100 kB value is not echoed)."""
    def cut(match) -> str:
        run = match.group(0)
        return f'{run[:max_run // 2]}...<{len(run)} characters>...{run[-(max_run // 4):]}'

    text = re.sub(r'\S{%d,}' % (max_run + 1), cut, text)
    if len(text) > max_len:
        text = f'{text[:max_len - 80]} ...<{len(text)} characters>... {text[-60:]}'
    return text


def _read_text(path: str) -> str:
    """The file as text: size-limited, UTF-8 (``ScenarioError`` naming the problem)."""
    if not os.path.isfile(path):
        raise ScenarioError(f'{path}: no such scenario file')
    try:
        with open(path, 'rb') as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ScenarioError(f'{path}: cannot read: {exc.strerror or exc}') from None
    if len(raw) > MAX_FILE_BYTES:
        raise ScenarioError(f'{path}: larger than {MAX_FILE_BYTES} bytes: not a scenario file')
    try:
        return raw.decode('utf-8')
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b'\n') + 1
        raise ScenarioError(f'{path}:{line}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at '
                            f'offset {exc.start})') from None


def read_yaml(path: str) -> Any:
    """The YAML data of ``path`` through the scenario file's guards (size, UTF-8, alias
    expansion, nesting, syntax: ``ScenarioError`` naming the file and line); nothing is
    validated or imported."""
    text = _read_text(path)
    try:
        return yaml.load(text, Loader=_LineLoader)  # noqa: S506 - SafeLoader subclass
    except ScenarioError as exc:
        raise ScenarioError(f'{path}: {exc}') from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f'{path}:{mark.line + 1}' if mark else path
        raise ScenarioError(f'{where}: YAML syntax error: {getattr(exc, "problem", exc)}') \
            from None
    except RecursionError:
        raise ScenarioError(f'{path}: YAML nested too deeply') from None


def _load_scenario(path: str, trusted: Optional[List[str]] = None) -> Dict[str, Any]:
    data = read_yaml(path)
    checker = _Checker(path)
    if not isinstance(data, dict):
        checker.fail(None, '<top>', 'a scenario must be a YAML mapping')
    if trusted is not None:
        data['plugins'] = list(trusted)
    plugins = data.get('plugins') or []
    if not isinstance(plugins, list) or not all(isinstance(x, str) for x in plugins):
        checker.fail(getattr(data, 'lines', {}).get('plugins'), 'plugins',
                     'expected a list of module names or .py paths')
    try:   # plugins register their components before the schema is built from the registry
        registry.load_plugins(plugins, os.path.dirname(os.path.abspath(path)))
    except ValueError as exc:
        checker.fail(getattr(data, 'lines', {}).get('plugins'), 'plugins', str(exc))
    top = schema()
    out = checker.mapping(data, top, '', None)
    for key, spec in top.items():   # a section with required keys is skipped when absent
        if isinstance(spec, dict) and not isinstance(spec, Opt) and key not in out:
            checker.fail(None, key, 'missing required section')
    base = os.path.dirname(os.path.abspath(path))   # plugin files: absolute for every node
    out['plugins'] = [os.path.join(base, x) if x.endswith('.py') and not os.path.isabs(x)
                      else x for x in out['plugins']]
    sc_lines = getattr(data.get('spacecraft') or {}, 'lines', {})
    out['spacecraft']['wheels'] = _check_wheels(
        checker, out['spacecraft'].get('wheels', []), sc_lines.get('wheels'))
    if 'estimator' in out:   # the flight software's own models default to the truth's
        out['estimator'].setdefault('onboard_orbit', dict(out['orbit']))
        out['estimator'].setdefault('onboard_field', dict(out['field']))
    _check_consistency(checker, out, getattr(data, 'lines', {}))
    _check_physical(checker, out, getattr(data, 'lines', {}))
    out['_path'] = os.path.abspath(path)
    return out


# ---------------------------------------------------------------------- physical sanity
#: Scenario names: they name the run directory (no ``/``, no ``..`` escape).
NAME_PATTERN = re.compile(r'[A-Za-z0-9_.-]{1,100}')
#: Mean equatorial radius [m] (WGS-84 a); a circular orbit must stay above the atmosphere.
EARTH_RADIUS_M = 6378137.0
#: ASSUMPTION: lowest circular-orbit altitude accepted [km] (the Karman line; below, an orbit
#: decays within hours and the models have no drag) and highest [km] (beyond the Moon the
#: two-body Earth orbit is meaningless).
MIN_ALTITUDE_KM, MAX_ALTITUDE_KM = 100.0, 400_000.0
#: ASSUMPTION: limits that catch typing errors, not design choices.
MAX_RATE_DEG_S = 100.0          # initial body rate norm [deg/s]
FRAME_S_RANGE = (1e-6, 86400.0)  # base frame period [s]
MAX_SUBSTEPS = 10_000           # RK4 substeps per frame
MAX_TIMEOUT_S = 3600.0          # wall-clock wait for an input [s]
MAX_FRAMES = 100_000_000        # frames in one run
MAX_INERTIA_KGM2 = 1e10         # largest principal moment [kg m^2]
MAX_SEED = 2**63 - 1            # ROS integer parameters are int64
#: ROS time stamps are int32 seconds since 1970: the run must end before 2038-01-19T03:14:07Z.
_ROS_TIME_END = datetime.datetime(2038, 1, 19, 3, 14, 7, tzinfo=datetime.timezone.utc)
_UNIX_EPOCH = datetime.datetime(1970, 1, 1, tzinfo=datetime.timezone.utc)


def parse_epoch_text(text: Any) -> datetime.datetime:
    """ISO-8601 text -> aware UTC ``datetime`` (naive means UTC); ``ValueError`` if not one."""
    if not isinstance(text, str):
        raise ValueError(f'expected ISO-8601 text, got {type(text).__name__}')
    try:
        dt = datetime.datetime.fromisoformat(text.strip().replace('Z', '+00:00'))
    except ValueError:
        raise ValueError(f'{text!r} is not an ISO-8601 date-time '
                         '(e.g. 2026-01-01T00:00:00Z)') from None
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=datetime.timezone.utc)
    return dt.astimezone(datetime.timezone.utc)


def check_epoch(epoch: Any, duration_s: float, line: Optional[int] = None,
                path: str = 'scenario') -> datetime.datetime:
    """Parse ``epoch`` and check that ``[epoch, epoch + duration_s]`` fits ROS time stamps.

    Raises
    ------
    ScenarioError
        If the epoch does not parse, or the run starts before 1970 or ends after
        2038-01-19T03:14:07Z (``builtin_interfaces/Time.sec`` is an int32).
    """
    checker = _Checker(path)
    try:
        start = parse_epoch_text(epoch)
    except ValueError as exc:
        checker.fail(line, 'epoch', str(exc))
    if start < _UNIX_EPOCH:
        checker.fail(line, 'epoch', f'{epoch} is before 1970 (ROS time starts in 1970)')
    try:
        end = start + datetime.timedelta(seconds=float(duration_s))
    except OverflowError:
        end = datetime.datetime.max.replace(tzinfo=datetime.timezone.utc)
    if end > _ROS_TIME_END:
        checker.fail(line, 'epoch', f'the run ({epoch} + {duration_s:g} s) ends after '
                     '2038-01-19T03:14:07Z, the last ROS time stamp (int32 seconds)')
    return start


def _sym3_eigenvalues(m: List[List[float]]) -> List[float]:
    """Eigenvalues (ascending) of a symmetric 3x3 matrix, closed form (Smith 1961)."""
    p1 = m[0][1] ** 2 + m[0][2] ** 2 + m[1][2] ** 2
    q = (m[0][0] + m[1][1] + m[2][2]) / 3.0
    if p1 == 0.0:
        return sorted([m[0][0], m[1][1], m[2][2]])
    p2 = sum((m[i][i] - q) ** 2 for i in range(3)) + 2.0 * p1
    p = math.sqrt(p2 / 6.0)
    b = [[(m[i][j] - (q if i == j else 0.0)) / p for j in range(3)] for i in range(3)]
    det_b = (b[0][0] * (b[1][1] * b[2][2] - b[1][2] * b[2][1])
             - b[0][1] * (b[1][0] * b[2][2] - b[1][2] * b[2][0])
             + b[0][2] * (b[1][0] * b[2][1] - b[1][1] * b[2][0]))
    phi = math.acos(max(-1.0, min(1.0, det_b / 2.0))) / 3.0
    e1 = q + 2.0 * p * math.cos(phi)
    e3 = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    return sorted([e3, 3.0 * q - e1 - e3, e1])


#: Naming conventions checked in every section (whatever the registry checks besides):
#: a key matching the pattern must hold values in the range (each element of a list).
_CONVENTIONS = (
    (re.compile(r'(^|_)std(_|$)|noise_std'), 0.0, math.inf, 'standard deviation'),
    (re.compile(r'probability'), 0.0, 1.0, 'probability'),
    (re.compile(r'^max_|_max$|limit|saturation|lsb'), 0.0, math.inf, 'limit'),
    (re.compile(r'p0_diag'), 0.0, math.inf, 'covariance diagonal'),
)


def _check_conventions(checker: _Checker, data: Any, prefix: str,
                       lines: Dict[str, int]) -> None:
    if isinstance(data, dict):
        for key, value in data.items():
            full = f'{prefix}{key}'
            for pattern, low, high, what in _CONVENTIONS:
                if not pattern.search(str(key)):
                    continue
                values = value if isinstance(value, list) else [value]
                for v in values:
                    if isinstance(v, (int, float)) and not isinstance(v, bool) and not (
                            low <= v <= high):
                        checker.fail(lines.get(full.split('.')[0]), full,
                                     f'{v!r} is not a valid {what} (must be in '
                                     f'[{low:g}, {high:g}])')
            _check_conventions(checker, value, full + '.', lines)
    elif isinstance(data, list):
        for i, item in enumerate(data):
            _check_conventions(checker, item, f'{prefix[:-1]}[{i}].', lines)


def _check_orbit(checker: _Checker, orbit: Dict[str, Any], key: str, line: Optional[int],
                 epoch: datetime.datetime) -> None:
    if orbit.get('type') == 'circular':
        alt = orbit['altitude_km']
        if not MIN_ALTITUDE_KM <= alt <= MAX_ALTITUDE_KM:
            where = 'below the Earth\'s surface' if alt <= 0 else (
                'inside the atmosphere' if alt < MIN_ALTITUDE_KM else 'beyond the Moon')
            checker.fail(line, f'{key}.altitude_km', f'{alt:g} km is {where} (accepted: '
                         f'{MIN_ALTITUDE_KM:g} to {MAX_ALTITUDE_KM:g} km)')
        inc = orbit['inclination_deg']
        if not 0.0 <= inc <= 180.0:
            checker.fail(line, f'{key}.inclination_deg', f'{inc:g} deg is not in [0, 180]')
        for angle in ('raan_deg', 'arg_latitude0_deg'):
            if abs(orbit.get(angle, 0.0)) > 3600.0:
                checker.fail(line, f'{key}.{angle}', f'{orbit[angle]:g} deg: give an angle '
                             'within +-3600 deg')
    elif orbit.get('type') == 'tle':
        try:
            from sgp4.api import Satrec, jday
        except ImportError:  # pragma: no cover - pinned in ros2_ws/requirements.txt
            return
        try:
            sat = Satrec.twoline2rv(orbit['line1'], orbit['line2'])
            jd, fr = jday(epoch.year, epoch.month, epoch.day, epoch.hour, epoch.minute,
                          epoch.second + epoch.microsecond * 1e-6)
            err, r_km, _ = sat.sgp4(jd, fr)
        except Exception as exc:  # noqa: BLE001 - sgp4 raises several types for bad text
            checker.fail(line, key, f'the TLE does not parse: {exc}')
        if err != 0 or not all(math.isfinite(c) for c in r_km):
            checker.fail(line, key, f'SGP4 cannot propagate the TLE to the epoch {epoch} '
                         f'(error code {err}: decayed or bad elements)')
        radius = math.sqrt(sum(c * c for c in r_km)) * 1e3
        if radius < EARTH_RADIUS_M + MIN_ALTITUDE_KM * 1e3:
            checker.fail(line, key, f'the TLE puts the satellite at '
                         f'{(radius - EARTH_RADIUS_M) / 1e3:.0f} km altitude at the epoch')


def _check_physical(checker: _Checker, sc: Dict[str, Any], lines: Dict[str, int]) -> None:
    """Reject values no spacecraft can have or no run can do (after the schema checks).

    Checks the scenario-level keys: ``name`` (``NAME_PATTERN``), ``seed`` (int64, >= 0),
    ``epoch`` (parses; the run fits ROS time, :func:`check_epoch`), ``duration_s`` and
    ``timing`` (``FRAME_S_RANGE``, ``MAX_SUBSTEPS``, ``MAX_TIMEOUT_S``, ``MAX_FRAMES``),
    ``orbit`` and ``estimator.onboard_orbit`` (circular: altitude, inclination; TLE: SGP4
    propagates it to the epoch, above the atmosphere), ``spacecraft`` (inertia positive
    definite, principal moments obeying the triangle inequality, non-negative limits, wheels
    with a spin axis, positive inertia and ``|h0| <= max_momentum``), ``initial`` (rate norm
    at most ``MAX_RATE_DEG_S``) and, in every section, the naming conventions of
    ``_CONVENTIONS`` (standard deviations >= 0, probabilities in [0, 1], limits >= 0).
    Node parameter ranges are the registry's.
    """
    name = sc['name']
    if not NAME_PATTERN.fullmatch(name):
        checker.fail(lines.get('name'), 'name', f'{name!r}: use 1 to 100 letters, digits, '
                     '"_", "." or "-" (it names the run directory)')
    if not 0 <= sc['seed'] <= MAX_SEED:
        checker.fail(lines.get('seed'), 'seed', f'{sc["seed"]} is not in [0, 2^63 - 1]')
    timing = sc['timing']
    frame = timing['frame_s']
    if not FRAME_S_RANGE[0] <= frame <= FRAME_S_RANGE[1]:
        checker.fail(lines.get('timing'), 'timing.frame_s', f'{frame:g} s is not in '
                     f'[{FRAME_S_RANGE[0]:g}, {FRAME_S_RANGE[1]:g}] s')
    if not 1 <= timing['substeps'] <= MAX_SUBSTEPS:
        checker.fail(lines.get('timing'), 'timing.substeps', f'{timing["substeps"]} is not in '
                     f'[1, {MAX_SUBSTEPS}]')
    if not 0 < timing['timeout_s'] <= MAX_TIMEOUT_S:
        checker.fail(lines.get('timing'), 'timing.timeout_s', f'{timing["timeout_s"]:g} s is '
                     f'not in (0, {MAX_TIMEOUT_S:g}] s')
    duration = sc['duration_s']
    if not duration > 0 or duration / frame > MAX_FRAMES:
        checker.fail(lines.get('duration_s'), 'duration_s', f'{duration:g} s is not in (0, '
                     f'{MAX_FRAMES:g} frames of {frame:g} s]')
    epoch = check_epoch(sc['epoch'], duration, lines.get('epoch'), checker.path)
    _check_orbit(checker, sc['orbit'], 'orbit', lines.get('orbit'), epoch)
    if 'onboard_orbit' in sc.get('estimator', {}):
        _check_orbit(checker, sc['estimator']['onboard_orbit'], 'estimator.onboard_orbit',
                     lines.get('estimator'), epoch)

    craft, line = sc['spacecraft'], lines.get('spacecraft')
    inertia = craft['inertia_kgm2']
    sym = [[0.5 * (inertia[i][j] + inertia[j][i]) for j in range(3)] for i in range(3)]
    moments = _sym3_eigenvalues(sym)
    if moments[0] <= 0.0:
        checker.fail(line, 'spacecraft.inertia_kgm2', 'not positive definite (principal '
                     f'moments {", ".join(f"{m:.6g}" for m in moments)} kg m^2)')
    if moments[2] > MAX_INERTIA_KGM2:
        checker.fail(line, 'spacecraft.inertia_kgm2', f'principal moment {moments[2]:.6g} '
                     f'kg m^2 is above {MAX_INERTIA_KGM2:g}')
    if moments[2] > (moments[0] + moments[1]) * (1.0 + 1e-9):
        checker.fail(line, 'spacecraft.inertia_kgm2', 'principal moments '
                     f'{", ".join(f"{m:.6g}" for m in moments)} kg m^2 break the triangle '
                     'inequality (largest <= sum of the others): no rigid body has them')
    for i, wheel in enumerate(craft.get('wheels', [])):
        key = f'spacecraft.wheels[{i}]'
        if math.sqrt(sum(a * a for a in wheel['axis'])) < 1e-9:
            checker.fail(line, f'{key}.axis', 'a spin axis of zero length')
        if not wheel['inertia_kgm2'] > 0:
            checker.fail(line, f'{key}.inertia_kgm2', 'must be positive')
        if abs(wheel['h0_Nms']) > wheel['max_momentum_Nms']:
            checker.fail(line, f'{key}.h0_Nms', f'|{wheel["h0_Nms"]:g}| N m s is above '
                         f'max_momentum_Nms {wheel["max_momentum_Nms"]:g}')
    dist = craft.get('disturbance', {})
    if 'random_period_s' in dist and not dist['random_period_s'] > 0:
        checker.fail(line, 'spacecraft.disturbance.random_period_s', 'must be positive')
    for key in ('aerodynamic_Nm', 'solar_pressure_Nm', 'synthetic_gravity_gradient_Nm',
                'unloading_Nm'):
        if any(a < 0 for a in dist.get(key, [])):
            checker.fail(line, f'spacecraft.disturbance.{key}', 'amplitudes must be >= 0')
    for key in ('harmonic_period_s', 'unloading_period_s'):
        if key in dist and not dist[key] > 0:
            checker.fail(line, f'spacecraft.disturbance.{key}', 'must be positive')
    if not 0 <= dist.get('unloading_duration_s', 0.0) <= dist.get('unloading_period_s', 1.0):
        checker.fail(line, 'spacecraft.disturbance.unloading_duration_s',
                     'must be in [0, unloading_period_s]')
    if craft.get('wheel_error_std_Nms', 0.0) < 0:
        checker.fail(line, 'spacecraft.wheel_error_std_Nms', 'must be >= 0')
    if craft.get('wheel_error_std_Nms', 0.0) > 0 and not craft.get('wheels'):
        checker.fail(line, 'spacecraft.wheel_error_std_Nms', 'needs spacecraft.wheels')
    if 'wheel_error_period_s' in craft and not craft['wheel_error_period_s'] > 0:
        checker.fail(line, 'spacecraft.wheel_error_period_s', 'must be positive')
    flex = craft.get('flexible')
    if flex is not None:
        if not 0 <= flex['damping'] < 1:
            checker.fail(line, 'spacecraft.flexible.damping', f'{flex["damping"]:g} is not in '
                         '[0, 1)')

    init = sc['initial']
    for key in ('omega_body_eci_body_deg_s', 'omega_body_orbit_body_deg_s'):
        if key in init:
            rate = math.sqrt(sum(w * w for w in init[key]))
            if rate > MAX_RATE_DEG_S:
                checker.fail(lines.get('initial'), f'initial.{key}', f'rate {rate:.6g} deg/s '
                             f'is above {MAX_RATE_DEG_S:g} deg/s')
    _check_conventions(checker, {k: v for k, v in sc.items() if not k.startswith('_')}, '',
                       lines)


def list_scenarios(directory: str) -> List[Tuple[str, str]]:
    """(file name, first line of the description) of every scenario in ``directory``."""
    rows = []
    for fname in sorted(os.listdir(directory)):
        if not fname.endswith(('.yaml', '.yml')):
            continue
        try:
            sc = load_scenario(os.path.join(directory, fname))
            desc = sc['description'].strip().splitlines()[0] if sc['description'] else ''
        except ScenarioError as exc:
            desc = f'INVALID: {exc}'
        rows.append((fname, desc))
    return rows


def schema_markdown() -> str:
    """The scenario keys as a Markdown table (``docs/scenarios.md`` is generated from this)."""
    rows = ['# Scenario keys', '',
            'Generated by `adcs schema` from `adcs_nodes/scenario.py` and the registry '
            '(`adcs_nodes/entries.py`, `sim_node/entries.py`); do not edit.',
            'Unknown keys are rejected. Angles in degrees only where the key ends in `_deg`.', '',
            '| key | type | default | meaning |', '|---|---|---|---|']

    def default(spec: F) -> str:
        if spec.default is REQUIRED:
            return 'required'
        if spec.default is OPTIONAL:
            return 'optional'
        return f'`{spec.default}`'

    def walk(prefix: str, schema: Dict[str, Any]) -> None:
        for key, spec in schema.items():
            full = prefix + key
            if isinstance(spec, dict):
                walk(full + '.', spec)
            elif isinstance(spec, Variant):
                walk(full + '.', spec.common)
                for name, keys in spec.variants.items():
                    walk(f'{full}.({spec.selector}={name}).', keys)
            elif isinstance(spec, Param):
                rows.append(f'| `{full}` | {spec.type} | `{spec.default}` | {spec.doc()} |')
            elif spec in ('ORBIT', 'FIELD', 'ORBIT?', 'FIELD?'):
                sel, common, variants = (('type', _ORBIT_COMMON, ORBIT_VARIANTS)
                                         if spec.startswith('ORBIT') else
                                         ('model', _FIELD_COMMON, FIELD_VARIANTS))
                walk(full + '.', common)
                for name, keys in variants.items():
                    walk(f'{full}.({sel}={name}).', keys)
            else:
                choices = f' (one of {", ".join(spec.choices)})' if spec.choices else ''
                rows.append(f'| `{full}` | {spec.kind} | {default(spec)} | {spec.doc}{choices} |')

    walk('', schema())
    walk('spacecraft.wheels[i].', _WHEEL_KEYS)
    rows += ['', '## Fault kinds (`faults:`)', '',
             'Each entry is `{at_s, kind, target, params}`; the kinds are registered in '
             '`sim_node/faults.py` (its docstring says how each engine applies them). A '
             '`node_killed` target is a node of the scenario\'s graph: a simulated sensor '
             '(its key), `estimator`, `guidance`, `<controller>_controller` or '
             '`controller_manager`.', '',
             '| kind | strikes | params | meaning |', '|---|---|---|---|']
    for name, entry in registry.entries('fault').items():
        params = ', '.join(f'`{p.name}` ({p.type}, `{p.default}`)' for p in entry.params)
        rows.append(f'| `{name}` | {", ".join(entry.targets)} | {params or "none"} | '
                    f'{entry.description} |')
    return '\n'.join(rows) + '\n'


# ---------------------------------------------------------------------- overrides (--set)
def parse_overrides(items: Any) -> Dict[str, Any]:
    """``--set`` arguments to overrides: ``['a.b=3', 'x=[1, 2]']`` -> ``{'a.b': 3, 'x': [1, 2]}``.

    The key is a dotted scenario key (a list element by its index: ``spacecraft.wheels.0.
    max_torque_Nm``); the value is YAML, read as a scenario file reads it (``1e-5`` is a
    float); ``null`` removes the key (its default applies again). A dict is returned as is.

    Raises
    ------
    ScenarioError
        An item without ``=``, an empty key or key part, an empty value, or a value that is
        not YAML; the message names the item.
    """
    if isinstance(items, dict):
        return dict(items)
    out: Dict[str, Any] = {}
    for item in items:
        key, sep, text = str(item).partition('=')
        key = key.strip()
        if not sep or not key or not all(part.strip() for part in key.split('.')):
            raise ScenarioError(f'--set {item}: expected KEY=VALUE with a dotted scenario key '
                                '(e.g. seed=3, spacecraft.disturbance.random_period_s=0.5)')
        if not text.strip():
            raise ScenarioError(f'--set {key}: no value (write {key}=null to remove the key)')
        try:
            out[key] = _plain(yaml.load(text, Loader=_LineLoader))  # noqa: S506 - SafeLoader
        except (yaml.YAMLError, ScenarioError, RecursionError) as exc:
            why = getattr(exc, 'problem', None) or str(exc) or type(exc).__name__
            raise ScenarioError(shorten_message(f'--set {key}: the value is not YAML: {why}')) \
                from None
    return out


def _plain(value: Any) -> Any:
    """Plain dicts, lists and Python scalars (what ``yaml.safe_dump`` writes)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, 'tolist') and not isinstance(value, (str, bytes)):
        return _plain(value.tolist())        # numpy arrays and scalars
    return value


def _set_dotted(data: Dict[str, Any], key: str, value: Any) -> None:
    node: Any = data
    *path, leaf = key.split('.')
    for i, part in enumerate(path + [leaf]):
        where = '.'.join(path[:i]) or '<top>'
        last = i == len(path)
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise ScenarioError(f'--set {key}: {where} is a list of {len(node)}: '
                                    f'{part!r} is not an index of it')
            if last:
                if value is None:
                    raise ScenarioError(f'--set {key}: a list element cannot be removed')
                node[int(part)] = value
                return
            node = node[int(part)]
        elif isinstance(node, dict):
            if last:
                if value is None:
                    node.pop(part, None)
                else:
                    node[part] = value
                return
            if node.get(part) is None:
                node[part] = {}            # a new section (the validation names a bad one)
            node = node[part]
        else:
            raise ScenarioError(f'--set {key}: {where} is a value ({node!r}), not a section')


def apply_overrides(sc: Dict[str, Any], overrides: Any) -> Dict[str, Any]:
    """A validated copy of scenario ``sc`` with ``overrides`` set (``--set KEY=VALUE``).

    Parameters
    ----------
    sc : dict
        A validated scenario (:func:`load_scenario`; it is not changed).
    overrides : dict or sequence of str
        ``{dotted key: value}`` (``None`` removes the key) or ``KEY=VALUE`` strings
        (:func:`parse_overrides`).

    Returns
    -------
    dict
        The edited scenario, validated again by every check of :func:`load_scenario` (as if
        the file said so); ``_path`` stays the original file's. The overrides apply to the
        effective scenario: the flight software's onboard models are their own keys
        (``estimator.onboard_orbit.*``, ``estimator.onboard_field.*``), so a change of the
        truth ``orbit`` or ``field`` leaves them as they were (a model error), unless set too.

    Raises
    ------
    ScenarioError
        An unknown key, a bad value or a physically impossible combination; the message starts
        with ``--set`` and the overridden keys and names the offending key (no file line: the
        edit has none).
    """
    import tempfile

    changes = parse_overrides(overrides)
    data = copy.deepcopy({k: v for k, v in sc.items() if not str(k).startswith('_')})
    for key, value in changes.items():
        _set_dotted(data, key, copy.deepcopy(value))
    what = ', '.join(f'{k}={v!r}' for k, v in changes.items())
    with tempfile.TemporaryDirectory(prefix='adcs-set-') as tmp:
        path = os.path.join(tmp, 'scenario.yaml')
        with open(path, 'w', encoding='utf-8') as fh:
            yaml.safe_dump(_plain(data), fh, sort_keys=False)
        try:
            out = load_scenario(path)
        except ScenarioError as exc:
            text = re.sub(r'^' + re.escape(path) + r'(:\d+)?: ', '', str(exc))
            raise ScenarioError(shorten_message(f'--set {what}: {text}')) from None
    out['_path'] = sc.get('_path', out['_path'])
    return out
