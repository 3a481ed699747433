"""Scenario files: load, validate (unknown keys rejected, errors name the key and line).

A scenario is a YAML mapping. Its schema is :data:`SCHEMA` below: every key, its type, its
default and a one-line meaning. ``adcs list`` prints the scenarios, ``docs/scenarios.md``
documents the keys. Sections whose allowed keys depend on a selector (``orbit.type``,
``field.model``) are checked against the keys of the selected variant.

Pure Python + PyYAML; no rclpy.
"""
from __future__ import annotations

import difflib
import math
import os
import re
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple

import yaml


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
        'wheels': F('wheels', [], 'reaction wheels: list of {name, axis, max_torque_Nm, '
                    'max_momentum_Nms, inertia_kgm2, h0_Nms}'),
        'disturbance': {
            'constant_torque_Nm': F('vec3', [0.0, 0.0, 0.0], 'constant body torque [N m]'),
            'random_std_Nm': F('float', 0.0, 'std of the random body torque per axis [N m]'),
            'random_period_s': F('float', 2.0, 'hold time of each random draw [s]'),
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
    'sensors': {
        'magnetometer': Opt({
            'period_s': F('float', 10.0, 'sample period [s] (paper 000: 10 s)'),
            'noise_std_T': F('vec3', [375e-9, 25e-9, 65e-9], 'white noise std per sensor '
                             'axis [T] (paper 000 example)'),
            'bias_T': F('vec3', [0.0, 0.0, 0.0], 'constant bias, sensor axes [T]'),
            'misalignment_deg': F('vec3', [0.0, 0.0, 0.0], 'small rotation body -> sensor '
                                  '(rotation vector) [deg]'),
            'scale_factor_error': F('vec3', [0.0, 0.0, 0.0], 'measured = (1 + s) true, '
                                    'per axis [-]'),
            'lsb_T': F('float', 20e-9, 'quantisation step [T] (0: none)'),
            'saturation_T': F('float', 0.0, 'per-axis range [T] (0: none)'),
            'dropout_probability': F('float', 0.0, 'probability that a sample is lost [-]'),
            'q_body_sensor_xyzw': F('quat', [0.0, 0.0, 0.0, 1.0],
                                    'nominal mounting, sensor -> body, scalar last'),
        }),
        'horizon_sensor': Opt({
            'period_s': F('float', 1.0, 'sample period [s]'),
            'noise_std_deg': F('vec2', [0.1, 0.1], 'white noise std of roll, pitch [deg]'),
            'bias_deg': F('vec2', [0.0, 0.0], 'bias of roll, pitch [deg]'),
            'scale_factor_error': F('vec2', [0.0, 0.0], 'scale-factor error of roll, pitch '
                                    '[-] (paper 004: 0.05 on one channel)'),
            'fov_deg': F('float', 30.0, 'largest |roll|, |pitch| with a valid output [deg]'),
        }),
        'star_tracker': Opt({
            'period_s': F('float', 1.0, 'sample period [s]'),
            'noise_std_deg': F('vec3', [0.02 / 3] * 3, 'attitude noise std per body axis '
                               '[deg] (0.02 deg 3-sigma)'),
        }),
        'gyro': Opt({
            'period_s': F('float', 1.0, 'sample period [s]'),
            'noise_std_deg_s': F('vec3', [1e-4] * 3, 'rate white noise std [deg/s]'),
            'bias_initial_deg_h': F('vec3', [0.0, 0.0, 0.0], 'initial bias [deg/h]'),
            'bias_walk_deg_h_sqrt_h': F('vec3', [0.01 / 3] * 3,
                                        'bias random walk density [deg/h/sqrt(h)]'),
        }),
    },
    'estimator': Opt({
        'algorithm': F('str', 'magnetic_filter', 'attitude estimator',
                       ('magnetic_filter', 'triad', 'horizon_mag_yaw')),
        'period_s': F('float', 2.0, 'estimator period [s] (paper 000: prediction every 2 s)'),
        'theta_T2': F('float', 9e-14, 'magnetic_filter theta of (38) [T^2]'),
        'tau': F('float', 0.01, 'magnetic_filter tau of (38) [-]'),
        'p0_diag': F('list9', [10.0] * 3 + [0.0036] * 3 + [1e-14] * 3,
                     'magnetic_filter initial covariance diagonal: attitude (phi or mu) [-], '
                     'rate [rad^2/s^2], disturbance [1/s^4]'),
        'measurement_form': F('str', 'phi', 'magnetic_filter measurement model, (36) phi or '
                              '(37) mu', ('phi', 'mu')),
        'literal_update': F('bool', False, "magnetic_filter: the paper's literal (38) (raw "
                            'residuals summed) instead of sequential innovations'),
        'substeps': F('int', 1, 'magnetic_filter RK4 substeps per prediction'),
        'initial_q_orbit_body_xyzw': F('quat', [0.0, 0.0, 0.0, 1.0],
                                       'initial attitude estimate (paper 000: identity)'),
        'initial_omega_body_orbit_body_deg_s': F('vec3', [0.0, 0.0, 0.0],
                                                 'initial relative rate estimate [deg/s] '
                                                 '(paper 000: omega\' = (0, omega0, 0))'),
        'onboard_orbit': 'ORBIT?',
        'onboard_field': 'FIELD?',
    }),
    'controllers': Opt({
        'period_s': F('float', 2.0, 'control period of every controller [s] (paper 000 '
                      'assumption: 2 s, dipole held in between)'),
        'magnetic': Opt({
            'mode': F('str', 'three_axis', 'paper 000 law',
                      ('three_axis', 'one_axis', 'two_stage')),
            'alpha_per_s': F('float', 3e-3, 'kinematic gain alpha of (16) [1/s]'),
            'k_Nms': F('float', 0.2, 'rate gain k of (27) [N m s]'),
            'beta': F('float', 0.0, 'Lyapunov weight of (25) for the start-up check '
                      'k > beta/(2 alpha) (28) [J]; 0: no check'),
            'switch_angle_deg': F('float', 15.0, 'two_stage: switch below this angle [deg]'),
            'switch_rate_deg_s': F('float', 0.2, 'two_stage: and below this rate [deg/s]'),
        }),
        'bdot': Opt({
            'gain_Am2s_per_T': F('float', 1.0e6, 'B-dot gain k: m = -k dB/dt [A m^2 s/T]'),
            'filter_time_constant_s': F('float', 0.0, 'low-pass of dB/dt [s] (0: none)'),
        }),
    }),
    'manager': Opt({
        'safe': F('str', 'bdot', 'safe-mode controller (fallback)'),
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
        }),
    }),
    'record': {
        'topics': F('strlist', [], 'topics to record (empty: every topic of the graph)'),
    },
}

_WHEEL_KEYS = {
    'name': F('str', REQUIRED, 'wheel name'),
    'axis': F('vec3', REQUIRED, 'spin axis, body axes (normalised)'),
    'max_torque_Nm': F('float', REQUIRED, 'motor torque limit [N m]'),
    'max_momentum_Nms': F('float', REQUIRED, 'momentum limit [N m s]'),
    'inertia_kgm2': F('float', 1e-3, 'wheel inertia about its axis [kg m^2]'),
    'h0_Nms': F('float', 0.0, 'initial wheel momentum [N m s]'),
}


# ---------------------------------------------------------------------- YAML with lines
class _LineLoader(yaml.SafeLoader):
    """SafeLoader that remembers the line of every mapping key."""


def _construct_mapping(loader, node, deep=False):
    mapping = {}
    lines = {}
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=deep)
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
        if sel not in variants:
            self.fail(getattr(data, 'lines', {}).get(selector, line), f'{full}.{selector}',
                      f'unknown {selector} {sel!r}; allowed: {", ".join(variants)}')
        return self.mapping(data, {**common, **variants[sel]}, full + '.', line)

    def leaf(self, value: Any, spec: F, key: str, line: Optional[int]) -> Any:
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
    if kind == 'wheels':
        if not isinstance(value, list):
            raise ValueError(f'expected a list of wheels, got {value!r}')
        return value  # entries are checked by _check_wheels (with lines)
    raise AssertionError(f'unknown schema kind {kind}')


def _check_wheels(checker: _Checker, wheels: List[Any], line: Optional[int]) -> List[dict]:
    out = []
    for i, w in enumerate(wheels):
        out.append(checker.mapping(w, _WHEEL_KEYS, f'spacecraft.wheels[{i}].', line))
    names = [w['name'] for w in out]
    if len(set(names)) != len(names):
        checker.fail(line, 'spacecraft.wheels', f'duplicate wheel names {names}')
    return out


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
    if 'estimator' in sc:
        sensors = sc.get('sensors', {})
        if 'magnetometer' not in sensors:
            checker.fail(lines.get('estimator'), 'estimator', 'needs sensors.magnetometer')
        if sc['estimator']['algorithm'] != 'magnetic_filter' and 'horizon_sensor' not in sensors:
            checker.fail(lines.get('estimator'), 'estimator.algorithm',
                         f'{sc["estimator"]["algorithm"]} needs sensors.horizon_sensor')
    if 'controllers' in sc:
        names = [k for k in ('magnetic', 'bdot') if k in sc['controllers']]
        if not names:
            checker.fail(lines.get('controllers'), 'controllers', 'no controller configured '
                         '(magnetic and/or bdot)')
        if 'magnetorquer' not in sc['spacecraft']:
            checker.fail(lines.get('controllers'), 'controllers',
                         'needs spacecraft.magnetorquer')
        if 'magnetometer' not in sc.get('sensors', {}):
            checker.fail(lines.get('controllers'), 'controllers', 'needs sensors.magnetometer')
        if 'magnetic' in names and 'estimator' not in sc:
            checker.fail(lines.get('controllers'), 'controllers.magnetic', 'needs an estimator')
        man = sc.get('manager', {'safe': 'bdot', 'initial': '', 'schedule': []})
        allowed = names + (['auto'] if 'auto' in man else [])
        for key in ('safe', 'initial'):
            if man.get(key) and man[key] not in names:
                checker.fail(lines.get('manager'), f'manager.{key}',
                             f'{man[key]!r} is not a configured controller ({names})')
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
    inertia = sc['spacecraft']['inertia_kgm2']
    sym = all(abs(inertia[i][j] - inertia[j][i]) <= 1e-9 * max(1.0, abs(inertia[i][j]))
              for i in range(3) for j in range(3))
    if not sym:
        checker.fail(lines.get('spacecraft'), 'spacecraft.inertia_kgm2', 'must be symmetric')


def load_scenario(path: str) -> Dict[str, Any]:
    """Read and validate a scenario file.

    Returns
    -------
    dict
        The scenario with every default filled in, plus ``_path`` (absolute path).

    Raises
    ------
    ScenarioError
        On a missing file, YAML syntax error, unknown or missing key, or bad value; the
        message names the file, the line and the key.
    """
    if not os.path.isfile(path):
        raise ScenarioError(f'{path}: no such scenario file')
    with open(path, encoding='utf-8') as fh:
        text = fh.read()
    try:
        data = yaml.load(text, Loader=_LineLoader)  # noqa: S506 - SafeLoader subclass
    except ScenarioError as exc:
        raise ScenarioError(f'{path}: {exc}') from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f'{path}:{mark.line + 1}' if mark else path
        raise ScenarioError(f'{where}: YAML syntax error: {getattr(exc, "problem", exc)}') \
            from None
    checker = _Checker(path)
    if not isinstance(data, dict):
        checker.fail(None, '<top>', 'a scenario must be a YAML mapping')
    out = checker.mapping(data, SCHEMA, '', None)
    sc_lines = getattr(data.get('spacecraft') or {}, 'lines', {})
    out['spacecraft']['wheels'] = _check_wheels(
        checker, out['spacecraft'].get('wheels', []), sc_lines.get('wheels'))
    if 'estimator' in out:   # the flight software's own models default to the truth's
        out['estimator'].setdefault('onboard_orbit', dict(out['orbit']))
        out['estimator'].setdefault('onboard_field', dict(out['field']))
    _check_consistency(checker, out, getattr(data, 'lines', {}))
    out['_path'] = os.path.abspath(path)
    return out


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
            'Generated by `adcs schema` from `adcs_nodes/tools/scenario.py`; do not edit.',
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

    walk('', SCHEMA)
    walk('spacecraft.wheels[i].', _WHEEL_KEYS)
    return '\n'.join(rows) + '\n'
