"""Scenario files: read (YAML with line numbers and guards, ``--set`` overrides) and validate
against the schema generated from the specs; written here are only the cross-field checks."""
from __future__ import annotations

import copy
import datetime
import os
import re
from dataclasses import replace
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import yaml

from adcs_nodes import inputs as _inputs
from adcs_nodes import registry
from adcs_nodes.core.geomag import FIELD
from adcs_nodes.core.guidance import FRAMES
from adcs_nodes.core.lockstep import seconds_to_ns
from adcs_nodes.core.manager import AUTO_SEQUENCE, AutoSequence
from adcs_nodes.core.orbit import ORBIT
from adcs_nodes.spec import (EPOCH, PROFILE, REQUIRED, SCHEDULE, SEED, TIMING, Param,
                             Section, SpecError, iso_time, plain, short)


class ScenarioError(ValueError):
    """A scenario file is malformed; the message names the file, line and key."""


# ---------------------------------------------------------------------- the schema
#: Scenario names: they name the run directory (no ``/``, no ``..`` escape).
NAME_PATTERN = re.compile(r'[A-Za-z0-9_.-]{1,100}')
#: ASSUMPTION: limits that catch typing errors, not design choices.
MAX_FRAMES = 100_000_000        # frames in one run
MAX_INERTIA_KGM2 = 1e10         # largest principal moment [kg m^2]
#: WGS-84 a [m]; a TLE must put the satellite 100 km above it at the epoch.
EARTH_RADIUS_M, MIN_ALTITUDE_KM = 6378137.0, 100.0


def _name(text: str) -> str:
    if not NAME_PATTERN.fullmatch(text):
        raise ValueError(f'{short(text)}: use 1 to 100 letters, digits, "_", "." or "-" (it '
                         'names the run directory)')
    return text


def _euler312(items: List[Any]) -> List[Any]:
    from adcs_nodes.core.guidance_profiles import profile_from_dicts
    if not all(isinstance(v, dict) for v in items):
        raise ValueError(f'expected a list of segments, got {short(items)}')
    if items:
        profile_from_dicts(items)     # ValueError with the reason
    return items


_ESTIMATOR = (
    Param('algorithm', 'str', 'magnetic_filter', '-', 'attitude estimator (a registered '
          'estimator; `adcs list`)'),
    Param('period_s', 'float', 2.0, 's', 'estimator period (paper 000: prediction every 2 s)',
          positive=True),
    Param('initial_q_orbit_body_xyzw', 'quat', [0.0, 0.0, 0.0, 1.0], '-', 'initial attitude '
          'estimate (paper 000: identity)'),
    Param('initial_omega_body_orbit_body_deg_s', 'vec3', [0.0, 0.0, 0.0], 'deg/s', 'initial '
          "relative rate estimate (paper 000: omega' = (0, omega0, 0))"),
    replace(ORBIT, name='onboard_orbit', optional=True,
            description="the flight software's orbit model (default: the orbit)"),
    replace(FIELD, name='onboard_field', optional=True,
            description="the flight software's field model (default: the field)"))
_EXTERNAL = Param('external', 'bool', False, '-', 'a real driver publishes this topic: the '
                  'launcher starts no simulated node for it and says so')
_GUIDANCE = Section('guidance', (
    Param('period_s', 'float', None, 's', 'target period (default: controllers.period_s)',
          positive=True),
    Param('frame', 'str', 'orbit', '-', 'frame of the profile attitudes', choices=FRAMES),
    PROFILE,
    Param('euler312_profile', 'list', [], '-', "paper 001's profile instead: list of {type: "
          'maneuver|hold|sine, start_s, end_s, euler_deg | center_deg, amplitude_deg, '
          'period_s, phase_deg} in LVLH 3-1-2 Euler angles [deg] (orbit frame)',
          check=_euler312)), optional=True)
_MANAGER = Section('manager', (
    Param('safe', 'str', 'bdot', '-', 'safe-mode controller (fallback)'),
    Param('fallback', 'str[]', [], '-', 'controllers tried in order before the safe one when '
          "the active command is unusable (e.g. [magnetic]: a failed wheel's controller hands "
          'over to the magnetorquers)'),
    Param('initial', 'str', '', '-', 'controller active at start (default: auto detumble or '
          'safe)'),
    Param('stale_after_s', 'float', 0.0, 's', 'a command older than this is stale (0: the '
          'frame stamp only in lockstep; negative: automatic)', min=-1.0),
    SCHEDULE, AUTO_SEQUENCE), optional=True)
#: ``faults``: the scripted faults of the world (each kind's params: its registry entry).
FAULTS = Param('faults', 'table', [], '-', 'scripted faults of the world; kinds: `adcs list` '
               'and the table below; params.duration_s: how long (0: to the end)', fields=(
                   Param('index', 'int', None, '-', 'position in the list (filled in)'),
                   Param('at_s', 'float', REQUIRED, 's', 'start time'),
                   Param('kind', 'str', REQUIRED, '-', 'a registered fault kind'),
                   Param('target', 'str', REQUIRED, '-', 'what it strikes (a sensor, a wheel, '
                         'a magnetorquer axis x|y|z, a node)'),
                   Param('params', 'dict', {}, '-', "the kind's parameters")),
               check=lambda faults: [{**f, 'index': i} for i, f in enumerate(faults)])


def schema() -> Section:
    """The whole scenario schema, the components' sections from their registry entries."""
    sensors = Section('sensors', tuple(replace(e.section(), params=e.params + (_EXTERNAL,))
                                       for e in registry.entries('sensor').values()))
    estimators = registry.entries('estimator')
    estimator = Section('estimator', _ESTIMATOR, optional=True, selector='algorithm',
                        variants={n: e.params for n, e in estimators.items()},
                        check=lambda v: (estimators[v['algorithm']].check or bool)(v))
    controllers = Section('controllers', (
        Param('period_s', 'float', 2.0, 's', 'control period of every controller (paper 000 '
              'assumption: 2 s, dipole held in between)', positive=True),
    ) + tuple(e.section() for e in registry.entries('controller').values()), optional=True)
    return Section('', (
        Param('name', 'str', REQUIRED, '-', 'scenario name', check=_name),
        Param('description', 'str', '', '-', 'one-paragraph description'),
        Param('paper', 'str', '', '-', 'source paper (file in papers/original) this scenario '
              'reproduces'),
        EPOCH, SEED,
        Param('plugins', 'str[]', [], '-', 'registry plugin modules or .py files (relative to '
              'the scenario) that register more controllers, estimators or sensors'),
        Param('duration_s', 'float', REQUIRED, 's', 'simulated duration', positive=True),
        TIMING, ORBIT, FIELD, registry.section('spacecraft'), registry.section('initial'),
        sensors, estimator, controllers, _GUIDANCE, _MANAGER,
        Section('record', (Param('topics', 'str[]', [], '-', 'topics to record (empty: every '
                                 'topic of the graph)'),)),
        FAULTS))


# ---------------------------------------------------------------------- YAML with lines
#: Largest scenario file [bytes], number of YAML nodes after alias expansion (an alias bomb
#: of a few hundred bytes expands to billions), run of characters without a space echoed in
#: an error message, and message.
MAX_FILE_BYTES, MAX_NODES, MAX_SHOWN, MAX_MESSAGE = 1_000_000, 100_000, 80, 600


class _LineLoader(yaml.SafeLoader):
    """SafeLoader that remembers the line of every mapping key and refuses alias bombs."""

    def construct_document(self, node):
        _check_expansion(node)
        return super().construct_document(node)


class _Map(dict):
    """dict that carries ``lines``: key -> line number in the YAML file."""

    def __init__(self, data, lines):
        super().__init__(data)
        self.lines = lines


def _check_expansion(root) -> None:
    """``ScenarioError`` if the YAML node graph expands to more than ``MAX_NODES`` or loops."""
    size: Dict[int, int] = {}
    inside = set()

    def count(node) -> int:
        if id(node) in size:
            return size[id(node)]
        line = node.start_mark.line + 1
        if id(node) in inside:
            raise ScenarioError(f'line {line}: a value that contains itself (recursive alias)')
        inside.add(id(node))
        kids = [] if isinstance(node, yaml.ScalarNode) else (
            [n for pair in node.value for n in pair] if isinstance(node, yaml.MappingNode)
            else node.value)
        size[id(node)] = total = 1 + sum(count(k) for k in kids)
        inside.discard(id(node))
        if total > MAX_NODES:
            raise ScenarioError(f'line {line}: this value expands to more than {MAX_NODES} '
                                'YAML nodes (aliases of aliases?)')
        return total
    count(root)


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


_LineLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
# YAML 1.1 (PyYAML) reads 1e-5 and 2.0e6 as text; engineers write them: read them as floats
_LineLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(r'^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$'),
    list('-+0123456789.'))


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
    """The YAML data of ``path`` through the guards (``ScenarioError``), nothing validated."""
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


def shorten_message(text: str, max_run: int = MAX_SHOWN, max_len: int = MAX_MESSAGE) -> str:
    """``text`` with long runs of non-space characters and the whole cut in their middle."""
    def cut(match) -> str:
        run = match.group(0)
        return f'{run[:max_run // 2]}...<{len(run)} characters>...{run[-(max_run // 4):]}'

    text = re.sub(r'\S{%d,}' % (max_run + 1), cut, text)
    if len(text) > max_len:
        text = f'{text[:max_len - 80]} ...<{len(text)} characters>... {text[-60:]}'
    return text


# ---------------------------------------------------------------------- loading
def load_scenario(path: str, plugins: Optional[List[str]] = None) -> Dict[str, Any]:
    """A scenario file's values, validated, defaults filled in, plus ``_path``; ``plugins``
    replace the file's own (a bag). ``ScenarioError`` naming the file, line and key."""
    try:
        data = read_yaml(path)
        if isinstance(data, dict) and plugins is not None:
            data['plugins'] = list(plugins)
        out = _validated(data, os.path.dirname(os.path.abspath(path)), str(path))
    except ScenarioError as exc:
        text, name = str(exc), str(path)
        if text.startswith(name):      # the file's path is never cut, only what follows it
            raise ScenarioError(name + shorten_message(text[len(name):])) from None
        raise ScenarioError(shorten_message(text)) from None
    out['_path'] = os.path.abspath(path)
    return out


def check_scenario(sc: Dict[str, Any]) -> Dict[str, Any]:
    """A scenario dict validated as a file is, without file and line; ``_path`` is kept."""
    data = plain({k: v for k, v in sc.items() if not str(k).startswith('_')})
    base = os.path.dirname(sc.get('_path') or os.path.abspath('scenario.yaml'))
    out = _validated(data, base, '')
    out.update({k: v for k, v in sc.items() if str(k).startswith('_')})
    return out


def _validated(data: Any, base: str, path: str) -> Dict[str, Any]:
    """``data`` validated (``ScenarioError``: ``path:line: key: why``)."""
    def fail(line: Optional[int], key: str, why: str) -> None:
        where = f'{path}:{line}' if path and line else path
        raise ScenarioError(f'{where}: {key}: {why}' if where else f'{key}: {why}')

    if not isinstance(data, dict):
        fail(None, '<top>', 'a scenario must be a YAML mapping')
    lines = getattr(data, 'lines', {})
    plugins = data.get('plugins') or []
    if not isinstance(plugins, list) or not all(isinstance(x, str) for x in plugins):
        fail(lines.get('plugins'), 'plugins', 'expected a list of module names or .py paths')
    try:   # plugins register their components before the schema is built from the registry
        registry.load_plugins(plugins, base)
        out = schema().validate(data)
    except SpecError as exc:
        fail(exc.line, exc.key or '<top>', exc.why + (f' ({exc.doc})' if exc.doc else ''))
    except ValueError as exc:
        fail(lines.get('plugins'), 'plugins', str(exc))
    out['plugins'] = [os.path.join(base, x) if x.endswith('.py') and not os.path.isabs(x)
                      else x for x in out['plugins']]   # plugin files: absolute for every node
    if 'estimator' in out:   # the flight software's own models default to the truth's
        out['estimator'].setdefault('onboard_orbit', dict(out['orbit']))
        out['estimator'].setdefault('onboard_field', dict(out['field']))
    for check in (_check_run, _check_flight, _check_spacecraft, _check_faults):
        try:
            check(out)
        except SpecError as exc:
            fail(lines.get(re.split(r'[.[]', exc.key)[0]), exc.key, exc.why)
    return out


# ---------------------------------------------------------------------- cross-field checks
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
    if 'magnetorquer' in entry.actuators and not any(
            craft.get('magnetorquer', {}).get('max_dipole_Am2', [])):
        out.append('commands magnetorquers: needs spacecraft.magnetorquer (a non-zero '
                   'max_dipole_Am2)')
    wheels = craft.get('wheels') or []
    if 'wheels' in entry.actuators and not wheels:
        out.append('commands reaction wheels: needs spacecraft.wheels')
    if 'torque' in entry.actuators and 'ideal_torque' not in craft and not wheels:
        out.append('commands a body torque: needs spacecraft.ideal_torque or '
                   'spacecraft.wheels (torque allocation)')
    if wheels and {'wheels', 'torque'} & set(entry.actuators) and \
            np.linalg.matrix_rank(np.array([w['axis'] for w in wheels], float)) < 3:
        out.append('allocates its torque to the wheels: the axes of spacecraft.wheels must '
                   'span three dimensions')
    for section in entry.requires:
        head, _, tail = section.partition('.')
        if not (sc.get(head, {}).get(tail) if tail else sc.get(head)):
            out.append(f'needs {section}')
    return out


def _check_run(sc: Dict[str, Any]) -> None:
    """Whole frames, periods that are multiples of the frame (in integer nanoseconds, as the
    engines count), the epoch, one initial attitude and rate, a TLE SGP4 propagates."""
    frame, duration = sc['timing']['frame_s'], sc['duration_s']
    if seconds_to_ns(duration) % seconds_to_ns(frame):
        raise SpecError('duration_s', f'{duration} s is not a whole number of {frame} s frames')
    if duration / frame > MAX_FRAMES:
        raise SpecError('duration_s', f'{duration:g} s is more than {MAX_FRAMES:g} frames of '
                        f'{frame:g} s')
    periods = [(f'{k}.period_s', sc.get(k, {}).get('period_s'))
               for k in ('estimator', 'controllers', 'guidance')]
    periods += [(f'sensors.{k}.period_s', v['period_s']) for k, v in sc['sensors'].items()]
    for key, period in periods:
        if period is not None and (seconds_to_ns(period) < seconds_to_ns(frame) or
                                   seconds_to_ns(period) % seconds_to_ns(frame)):
            raise SpecError(key, f'{period} s is not a positive multiple of the frame '
                            f'{frame} s')
    try:
        epoch = epoch_range(sc['epoch'], duration)
    except ValueError as exc:
        raise SpecError('epoch', str(exc)) from None
    for a, b in (('q_orbit_body_wxyz', 'q_orbit_body_xyzw'),
                 ('omega_body_eci_body_deg_s', 'omega_body_orbit_body_deg_s')):
        if a in sc['initial'] and b in sc['initial']:
            raise SpecError('initial', f'give {a} or {b}, not both')
    for key, orbit in (('orbit', sc['orbit']),
                       ('estimator.onboard_orbit', sc.get('estimator', {}).get('onboard_orbit'))):
        if orbit and orbit['type'] == 'tle':
            _check_tle(orbit, key, epoch)


def _check_tle(orbit: Dict[str, Any], key: str, epoch: datetime.datetime) -> None:
    from sgp4.api import Satrec, jday
    try:
        sat = Satrec.twoline2rv(orbit['line1'], orbit['line2'])
        err, r_km, _ = sat.sgp4(*jday(epoch.year, epoch.month, epoch.day, epoch.hour,
                                      epoch.minute, epoch.second + epoch.microsecond * 1e-6))
    except Exception as exc:  # noqa: BLE001 - sgp4 raises several types for bad text
        raise SpecError(key, f'the TLE does not parse: {exc}') from None
    if err != 0 or not np.all(np.isfinite(r_km)):
        raise SpecError(key, f'SGP4 cannot propagate the TLE to the epoch {epoch} (error code '
                        f'{err}: decayed or bad elements)')
    altitude_km = np.linalg.norm(r_km) - EARTH_RADIUS_M / 1e3
    if altitude_km < MIN_ALTITUDE_KM:
        raise SpecError(key, f'the TLE puts the satellite at {altitude_km:.0f} km altitude at '
                        'the epoch')


def _check_flight(sc: Dict[str, Any]) -> None:
    """A sensor for every input, runnable controllers, a consistent manager."""
    sensors = sc['sensors']
    if 'estimator' in sc:
        entry = registry.get('estimator', sc['estimator']['algorithm'])
        for sensor in filter(None, map(SENSOR_OF_INPUT.get, entry.inputs)):
            if sensor not in sensors:
                raise SpecError('estimator.algorithm', f'{entry.name} needs sensors.{sensor}')
    if 'wheel_tachometer' in sensors and not sc['spacecraft'].get('wheels'):
        raise SpecError('sensors.wheel_tachometer', 'needs spacecraft.wheels')
    if 'controllers' not in sc:
        if 'manager' in sc:
            raise SpecError('manager', 'needs a controllers section')
        return
    names = controller_names(sc)
    if not names:
        raise SpecError('controllers', 'no controller configured (registered: '
                        f'{", ".join(registry.names("controller"))})')
    for name in names:
        for why in controller_problems(sc, name):
            raise SpecError(f'controllers.{name}', why)
    man = sc.get('manager', {'safe': default_safe(names), 'initial': '', 'schedule': []})
    named = [('manager.safe', man['safe'])] + [('manager.initial', man['initial'])] * bool(
        man['initial'])
    named += [(f'manager.auto.{k}', v) for k, v in man.get('auto', {}).items()
              if k in ('detumble', 'acquire', 'point')]
    for key, name in named:
        if name not in names:
            raise SpecError(key, f'{name!r} is not a configured controller ({names})')
    fallback = man.get('fallback') or []
    for name in fallback:
        if name not in names or name == man['safe']:
            raise SpecError('manager.fallback', f'{name!r} is not a configured controller '
                            f'other than the safe one ({names})')
    if len(set(fallback)) != len(fallback):
        raise SpecError('manager.fallback', 'names a controller twice')
    if 'auto' in man:
        try:
            AutoSequence.from_dict(man['auto'])
        except ValueError as exc:
            raise SpecError('manager.auto', str(exc)) from None
    allowed = names + (['auto'] if 'auto' in man else [])
    for entry in man.get('schedule', []):
        if entry['controller'] not in allowed:
            raise SpecError('manager.schedule', f'{entry["controller"]!r} is not one of '
                            f'{allowed}')


def _check_spacecraft(sc: Dict[str, Any]) -> None:
    """A rigid body's inertia, wheels with a spin axis and ``h0`` within their capacity,
    unloading pulses inside their period, a momentum error only with wheels."""
    craft, key = sc['spacecraft'], 'spacecraft.inertia_kgm2'
    inertia = np.array(craft['inertia_kgm2'])
    if not np.allclose(inertia, inertia.T, rtol=1e-9, atol=1e-9):
        raise SpecError(key, 'must be symmetric')
    moments = np.linalg.eigvalsh(inertia)
    text = ', '.join(f'{m:.6g}' for m in moments)
    if moments[0] <= 0.0:
        raise SpecError(key, f'not positive definite (principal moments {text} kg m^2)')
    if moments[2] > MAX_INERTIA_KGM2:
        raise SpecError(key, f'principal moment {moments[2]:.6g} kg m^2 is above '
                        f'{MAX_INERTIA_KGM2:g}')
    if moments[2] > (moments[0] + moments[1]) * (1.0 + 1e-9):
        raise SpecError(key, f'principal moments {text} kg m^2 break the triangle inequality '
                        '(largest <= sum of the others): no rigid body has them')
    for i, wheel in enumerate(craft['wheels']):
        if np.linalg.norm(wheel['axis']) < 1e-9:
            raise SpecError(f'spacecraft.wheels[{i}].axis', 'a spin axis of zero length')
        if abs(wheel['h0_Nms']) > wheel['max_momentum_Nms']:
            raise SpecError(f'spacecraft.wheels[{i}].h0_Nms', f'|{wheel["h0_Nms"]:g}| N m s is '
                            f'above max_momentum_Nms {wheel["max_momentum_Nms"]:g}')
    dist = craft['disturbance']
    if dist['unloading_duration_s'] > dist['unloading_period_s']:
        raise SpecError('spacecraft.disturbance.unloading_duration_s',
                        'must be in [0, unloading_period_s]')
    if craft['wheel_error_std_Nms'] > 0 and not craft['wheels']:
        raise SpecError('spacecraft.wheel_error_std_Nms', 'needs spacecraft.wheels')


#: ROS time stamps are int32 seconds since 1970: a run must end by 2038-01-19T03:14:07Z.
_ROS_TIME = (datetime.datetime(1970, 1, 1, tzinfo=datetime.timezone.utc),
             datetime.datetime(2038, 1, 19, 3, 14, 7, tzinfo=datetime.timezone.utc))


def epoch_range(epoch: Any, duration_s: float) -> datetime.datetime:
    """The UTC ``epoch``; ``ValueError`` unless the run fits ROS time stamps (1970-2038)."""
    start = datetime.datetime.fromisoformat(iso_time(epoch).strip().replace('Z', '+00:00'))
    start = (start if start.tzinfo else start.replace(tzinfo=datetime.timezone.utc)
             ).astimezone(datetime.timezone.utc)
    if start < _ROS_TIME[0]:
        raise ValueError(f'{epoch} is before 1970 (ROS time starts in 1970)')
    try:
        end = start + datetime.timedelta(seconds=float(duration_s))
    except OverflowError:
        end = datetime.datetime.max.replace(tzinfo=datetime.timezone.utc)
    if end > _ROS_TIME[1]:
        raise ValueError(f'the run ({epoch} + {duration_s:g} s) ends after '
                         '2038-01-19T03:14:07Z, the last ROS time stamp (int32 seconds)')
    return start


# ---------------------------------------------------------------------- faults
def node_targets(sc: Dict[str, Any]) -> List[str]:
    """The nodes of ``sc`` (validated or raw) a ``node_killed`` fault may strike."""
    out = fault_targets(sc, nodes=False)['sensor'] + ['estimator'] * bool(sc.get('estimator'))
    ctrl = sc.get('controllers')
    if isinstance(ctrl, dict):
        out += ['guidance'] + [f'{k}_controller' for k in ctrl if k != 'period_s']
        out.append('controller_manager')
    return out


def fault_targets(sc: Dict[str, Any], nodes: bool = True) -> Dict[str, List[str]]:
    """What a fault of ``sc`` (validated or raw) may strike, by target kind."""
    craft = sc.get('spacecraft') or {}
    out = {'sensor': [k for k, cfg in (sc.get('sensors') or {}).items()
                      if not (isinstance(cfg, dict) and cfg.get('external'))],
           'wheel': [w.get('name') for w in craft.get('wheels') or [] if isinstance(w, dict)],
           'magnetorquer': ['x', 'y', 'z'] if 'magnetorquer' in craft else []}
    return {**out, 'node': node_targets(sc)} if nodes else out


def check_fault(kind: str, target: str, params: Any, targets: Dict[str, List[str]],
                scripted: bool = True) -> Dict[str, Any]:
    """The validated parameters of fault ``kind`` striking ``target``: the one check of a
    scripted or live fault. ``SpecError`` naming ``kind``, ``target`` or ``params``."""
    try:
        entry = registry.get('fault', kind)
    except ValueError as exc:
        raise SpecError('kind', str(exc)) from None
    if not scripted and 'node' in entry.targets:
        raise SpecError('kind', f"{kind} is a scripted fault only (a scenario's faults:); to "
                        'kill a node of a running graph, kill its process (adcs status shows '
                        'the pids)')
    known = [t for what in entry.targets for t in targets.get(what, [])]
    if target not in known:
        raise SpecError('target', f'{kind} cannot strike {target!r}; it strikes '
                        f'{", ".join(entry.targets)}: '
                        f'{", ".join(known) or "none in this scenario"}')
    try:
        return entry.validate(dict(params or {}))
    except ValueError as exc:
        raise SpecError('params', str(exc)) from None


def _check_faults(sc: Dict[str, Any]) -> None:
    """Each fault: a kind, a target it can strike, its parameters, a time inside the run."""
    targets = fault_targets(sc)
    for f in sc['faults']:
        key = f'faults[{f["index"]}]'
        try:
            f['params'] = check_fault(f['kind'], f['target'], f['params'], targets)
        except SpecError as exc:
            raise exc.within(key) from None
        if not 0.0 <= f['at_s'] <= sc['duration_s']:
            raise SpecError(f'{key}.at_s', f'{f["at_s"]:g} s is outside the run '
                            f'[0, {sc["duration_s"]:g}] s')


# ---------------------------------------------------------------------- listing, docs
def list_scenarios(directory: str) -> List[Tuple[str, str]]:
    """(file name, first line of the description) of every scenario in ``directory``."""
    rows = []
    for fname in sorted(f for f in os.listdir(directory) if f.endswith(('.yaml', '.yml'))):
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
            'Generated by `adcs schema` from the specs (`adcs_nodes/core/spec.py`: the orbit '
            'in `core/orbit.py`, the field in `core/geomag.py`, the spacecraft and initial '
            'state in `sim_node/models/spacecraft_config.py`, ...) and the registry '
            '(`adcs_nodes/entries.py`, `sim_node/entries.py`); do not edit.',
            'Unknown keys are rejected. Angles in degrees only where the key ends in `_deg`. '
            'The nodes take the same values, with the same ranges, as parameters.', '',
            '| key | type | default | meaning |', '|---|---|---|---|']

    def walk(prefix: str, specs) -> None:
        for spec in specs:
            full = prefix + spec.name
            if isinstance(spec, Section):
                walk(full + '.', spec.params)
                for name, keys in spec.variants.items():
                    walk(f'{full}.({spec.selector}={name}).', keys)
                continue
            rows.append(f'| `{full}` | {spec.type} | {spec.default_text()} | {spec.doc()} |')
            walk(full + '[i].', spec.fields)

    walk('', schema().params)
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
    """``--set`` arguments ``['a.b=3', 'wheels.0.x=[1, 2]']`` -> ``{'a.b': 3, ...}`` (YAML
    values; a dict as is). ``ScenarioError`` naming a malformed item."""
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
            out[key] = plain(yaml.load(text, Loader=_LineLoader))  # noqa: S506 - SafeLoader
        except (yaml.YAMLError, ScenarioError, RecursionError) as exc:
            why = getattr(exc, 'problem', None) or str(exc) or type(exc).__name__
            raise ScenarioError(shorten_message(f'--set {key}: the value is not YAML: {why}')) \
                from None
    return out


def apply_overrides(sc: Dict[str, Any], overrides: Any) -> Dict[str, Any]:
    """A copy of the validated ``sc`` with ``overrides`` (``{dotted key: value or None}`` or
    ``KEY=VALUE`` strings), validated again. ``ScenarioError``: ``--set KEY=VALUE: key: why``."""
    changes = parse_overrides(overrides)
    data = copy.deepcopy({k: v for k, v in sc.items() if not str(k).startswith('_')})
    for key, value in changes.items():
        _set_dotted(data, key, copy.deepcopy(value))
    what = ', '.join(f'{k}={v!r}' for k, v in changes.items())
    try:
        return check_scenario({**data, **{k: v for k, v in sc.items() if str(k)[:1] == '_'}})
    except ScenarioError as exc:
        raise ScenarioError(shorten_message(f'--set {what}: {exc}')) from None


def _set_dotted(data: Dict[str, Any], key: str, value: Any) -> None:
    """Set ``key`` (dotted; a list element by its index) to ``value`` (``None``: remove)."""
    node: Any = data
    parts = key.split('.')
    for i, part in enumerate(parts):
        where, last = '.'.join(parts[:i]) or '<top>', i == len(parts) - 1
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise ScenarioError(f'--set {key}: {where} is a list of {len(node)}: '
                                    f'{part!r} is not an index of it')
            if last and value is None:
                raise ScenarioError(f'--set {key}: a list element cannot be removed')
            part = int(part)
        elif not isinstance(node, dict):
            raise ScenarioError(f'--set {key}: {where} is a value ({node!r}), not a section')
        elif last and value is None:
            node.pop(part, None)
            return
        elif not last and node.get(part) is None:
            node[part] = {}            # a new section (the validation names a bad one)
        if last:
            node[part] = value
            return
        node = node[part]
