"""One spec, one answer (issue 34, item 1): values drawn in and out of range for every spec'd
scenario key are accepted, or refused naming the key, alike by

* ``adcs validate`` (:func:`adcs_nodes.scenario.apply_overrides`, the file's validation);
* the plain engine's build: :meth:`sim_node.engine.FrameLoop.from_scenario`, and its own build
  from the graph (``FrameLoop(build_graph(...))``, without the scenario's validation);
* the declaration of every node that receives the value: the flat parameters
  :func:`adcs_nodes.graph.build_graph` gives, validated as each node declares them
  (``Param.from_ros`` through :func:`adcs_nodes.components.base.param_value`,
  ``Section.read`` for its sections), without rclpy.

The value goes into a validated shipped scenario; what the validator refuses only by a
cross-field rule (a period that is not a multiple of the frame, a safe controller that is not
configured, ...) is the validator's alone and skipped here. A key no node receives must be
one of :data:`VALIDATOR_ONLY`.
"""
import copy
import math
import os

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from adcs_nodes import registry
from adcs_nodes.components import controller as ccomp
from adcs_nodes.components import estimator as ecomp
from adcs_nodes.components.base import param_value, parse_epoch
from adcs_nodes.components.guidance import PARAMS as GUIDANCE_PARAMS
from adcs_nodes.components.manager import MANAGER_PARAMS
from adcs_nodes.core.geomag import FIELD
from adcs_nodes.core.manager import AUTO_SEQUENCE
from adcs_nodes.core.orbit import ORBIT
from adcs_nodes.graph import build_graph
from adcs_nodes.scenario import (ScenarioError, apply_overrides, load_scenario, schema,
                                 shorten_message)
from adcs_nodes.spec import COMMON, Param, Section, SpecError
from sim_node.engine import FrameLoop
from sim_node.entries import DYNAMICS_PARAMS
from sim_node.faults import FAULTS_PARAM
from sim_node.models.spacecraft_config import INITIAL, SPACECRAFT

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
#: Shipped scenarios that together hold every section (wheels, flexible modes, a TLE, IGRF,
#: a guidance profile, the automatic sequence, every sensor and controller kind).
BASES = ('demo_mission', 'paper001_mpi_two_wings', 'iss_tle_tumble', 'dawn_dusk_igrf',
         'paper003_slew', 'paper004_yaw')
#: Keys (their last part) that configure the run, not a node parameter: the launcher, the
#: recorder, the validator (``external``: which nodes the graph has).
VALIDATOR_ONLY = {'name', 'description', 'paper', 'plugins', 'topics', 'external'}
#: The values of a node started alone for keys a section needs (a node validates only what it
#: is given, with these where it is given nothing).
DURATION_S = 10.0


def _load(name):
    sc = load_scenario(os.path.join(ROOT, 'scenarios', f'{name}.yaml'))
    return apply_overrides(sc, {'duration_s': DURATION_S, 'faults': []})


BASE = {name: _load(name) for name in BASES}


def _leaves(section, data, prefix=''):
    """``(dotted key, Param)`` of every value of the validated ``data`` (a table: its first
    record's fields; free lists and mappings, checked by their ``check``, are left out)."""
    for key, spec in section.keys(data).items():
        if key not in data:
            continue
        if isinstance(spec, Section):
            yield from _leaves(spec, data[key], f'{prefix}{key}.')
        elif spec.type == 'table':
            if data[key] and key != 'faults':
                yield from ((f'{prefix}{key}.0.{f.name}', f) for f in spec.fields)
        elif spec.type not in ('list', 'dict'):
            yield f'{prefix}{key}', spec


KEYS = sorted({key: (base, spec) for base in BASES for key, spec in
               _leaves(schema(), BASE[base])}.items())


# ---------------------------------------------------------------------- draws
def _number(spec, integer=False):
    lo = spec.min if spec.min is not None else (0.0 if spec.positive else -1e6)
    hi = spec.max if spec.max is not None else lo + 2e6
    make = (lambda a, b: st.integers(int(math.ceil(a)), int(b))) if integer else (
        lambda a, b: st.floats(a, b, allow_nan=False))
    good = make(lo + (1e-9 if spec.positive else 0.0), hi)
    bad = [st.sampled_from([math.nan, math.inf, -math.inf, 'x', True])]
    if spec.min is not None or spec.positive:
        bad.append(make(lo - 1e6, lo - (0 if spec.positive else 1e-6 if not integer else 1)))
    if spec.max is not None:
        bad.append(make(hi + (1 if integer else 1e-6), hi + 1e6))
    return good, st.one_of(bad)


def _draws(spec):
    """Values in (the spec accepts them) and out of its range or type."""
    t = spec.type
    if t in ('float', 'int'):
        good, bad = _number(spec, t == 'int')
    elif t == 'bool':
        good, bad = st.booleans(), st.sampled_from([0, 1, 'yes'])
    elif t in ('str', 'time'):
        good = st.sampled_from(spec.choices) if spec.choices else (
            st.datetimes().map(lambda d: d.isoformat() + 'Z') if t == 'time' else st.text())
        bad = st.one_of(st.integers(), st.sampled_from(['not one of them'] if spec.choices or
                                                       t == 'time' else [1.5]))
    elif t in ('vec3', 'quat', 'float[]', 'matrix3'):
        n = {'vec3': 3, 'quat': 4, 'matrix3': 3}.get(t, spec.length or 3)
        elem_good, elem_bad = _number(spec)
        good = st.lists(elem_good, min_size=n, max_size=n)
        if t == 'quat':
            good = good.filter(lambda q: sum(c * c for c in q) > 1e-6).map(
                lambda q: [c / math.sqrt(sum(c * c for c in q)) for c in q])
        bad = st.one_of(st.lists(elem_good, min_size=n + 1, max_size=n + 1),
                        st.lists(elem_bad, min_size=n, max_size=n), st.just('x'))
    elif t == 'str[]':
        good = st.lists(st.sampled_from(spec.choices) if spec.choices else st.text(),
                        max_size=3)
        bad = st.one_of(st.just('x'), st.lists(st.integers(), min_size=1, max_size=2))
    else:
        raise AssertionError(f'no draws for type {t}')
    return st.one_of(good, bad)


# ---------------------------------------------------------------------- the three paths
def _edited(sc, key, value):
    """``sc`` with ``key`` (dotted, list indices as numbers) set to ``value``, unvalidated."""
    out = copy.deepcopy(sc)
    node, *path, leaf = [out] + key.split('.')
    for part in path:
        node = node[int(part)] if isinstance(node, list) else node[part]
    node[int(leaf) if isinstance(node, list) else leaf] = value
    return out


def _canon(key):
    """A key without list indices (``wheels[0].axis`` and ``wheels.0.axis``: ``wheels.axis``)."""
    return '.'.join(p for p in key.replace('[', '.').replace(']', '').split('.')
                    if not p.isdigit())


def _node_specs(node):
    """``(params, sections)`` a node declares (the pure view of the node classes)."""
    p = node.params
    sensor = registry.entries('sensor').get(node.name)
    if node.module == 'sim_node.nodes.environment':
        return (), (('orbit', ORBIT), ('field', FIELD))
    if node.module == 'sim_node.nodes.dynamics':
        return DYNAMICS_PARAMS + (FAULTS_PARAM,), (('spacecraft', SPACECRAFT),
                                                   ('initial', INITIAL))
    if sensor is not None:
        return sensor.params + (Param('frame_id', 'str', node.name), FAULTS_PARAM), ()
    onboard = (('onboard_orbit', ORBIT), ('onboard_field', FIELD))
    if node.module == 'adcs_nodes.nodes.estimator':
        return ecomp.CONTEXT_PARAMS + registry.get('estimator', p['algorithm']).params, onboard
    if node.module == 'adcs_nodes.nodes.controller':
        return ccomp.CONTEXT_PARAMS + registry.get('controller', p['controller']).params, \
            onboard
    if node.module == 'adcs_nodes.nodes.guidance':
        return GUIDANCE_PARAMS, ()
    if node.module == 'adcs_nodes.nodes.controller_manager':
        return MANAGER_PARAMS, (('auto', AUTO_SEQUENCE),)
    raise AssertionError(f'unknown node {node.module}')


def _declare(node):
    """The refusals (``[(key, message)]``) of ``node`` declaring its flat parameters."""
    params, sections = _node_specs(node)
    known = {s.name for s in params + tuple(COMMON.values())}
    unknown = [k for k in node.params if k not in known
               and not any(k.startswith(f'{prefix}.') for prefix, _ in sections)]
    assert unknown == [], f'{node.name} is given parameters it does not declare: {unknown}'
    out = []
    for spec in params + tuple(COMMON.values()):
        try:
            param_value(spec, node.params)
        except ValueError as exc:
            out.append((getattr(exc, 'key', spec.name), str(exc)))
    for prefix, section in sections:
        try:
            section.read(node.params, prefix)
        except SpecError as exc:
            out.append((exc.key, str(exc)))
    if node.module == 'adcs_nodes.nodes.controller' and not out:
        try:      # the context a controller node builds its core with (no magnetorquer, ...)
            ccomp.controller_context(registry.get('controller', node.params['controller']),
                                     {s.name: param_value(s, node.params) for s in params},
                                     parse_epoch(node.params['epoch']), 0,
                                     ORBIT.read(node.params, 'onboard_orbit'),
                                     FIELD.read(node.params, 'onboard_field'))
        except ValueError as exc:
            out.append((next((k for k in node.params if k in str(exc)), str(exc)), str(exc)))
    return out


def _flat(sc):
    return {n.name: n for n in build_graph(sc, sc['duration_s']) if n.name != 'recorder'}


FLAT = {name: _flat(sc) for name, sc in BASE.items()}


def check(base, key, spec, value):
    """The three paths agree on ``value`` for ``key`` of scenario ``base``."""
    sc = BASE[base]
    try:
        checked = spec.validate(value)
        in_range = True
    except ValueError:
        checked, in_range = None, False
    try:
        apply_overrides(sc, {key: value})
        valid = True
    except ScenarioError as exc:
        valid, why = False, str(exc)
    assert not (valid and not in_range), f'{key}={value!r}: the validator accepts it'
    if in_range and not valid:
        return                                 # a cross-field rule: the validator's alone
    edited = _edited(sc, key, checked if valid else value)
    if key.split('.')[-1] in VALIDATOR_ONLY and valid:
        return                       # (external: the plain engine has no drivers, by design)
    try:      # the plain engine's public build: the scenario's validation, its message
        FrameLoop.from_scenario(edited, DURATION_S)
        assert valid, f'{key}={value!r}: FrameLoop.from_scenario accepts it'
    except ValueError as exc:
        # (the validator's one-line message shortens long runs of characters alike, and a
        # long one in its middle: the last 60 characters are kept in both)
        assert not valid and why.endswith(shorten_message(str(exc))[-60:]), (why, str(exc))
        assert _canon(str(exc).split(': ', 1)[0]) == _canon(key), why
    if key.split('.')[-1] in VALIDATOR_ONLY:
        return
    try:
        nodes = _flat(edited)
    except (ValueError, TypeError):   # the graph has no parameters for it (an unknown model)
        assert not valid, f'{key}={value!r}: the graph refuses it'
        return
    changed = {name: {k for k in set(n.params) | set(FLAT[base].get(name, n).params)
                      if repr(n.params.get(k)) != repr(FLAT[base].get(name, n).params.get(k))}
               for name, n in nodes.items()}
    try:      # the engine's own build, from the graph without the scenario's validation
        FrameLoop(list(nodes.values()), edited['duration_s'])
        engine = None
    except ValueError as exc:
        engine = getattr(exc, 'key', str(exc))
    refusals = {name: _declare(n) for name, n in nodes.items()}
    if valid:
        assert engine is None and not any(refusals.values()), (key, value, engine, refusals)
        return
    receivers = {name for name, keys in changed.items() if keys}
    assert receivers, f'{key}: no node receives it'
    assert engine is not None, f'{key}={value!r}: the engine builds it'
    assert any(_canon(engine) in {_canon(k) for k in changed[n]} for n in receivers), engine
    for name in receivers:
        names = {_canon(k) for k in changed[name]}
        assert refusals[name], f'{key}={value!r}: node {name} accepts {changed[name]}'
        assert all(_canon(k) in names for k, _ in refusals[name]), (key, name, refusals[name])


@pytest.mark.parametrize('key', [k for k, _ in KEYS])
@settings(max_examples=4, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_validator_engine_and_nodes_agree(key, data):
    base, spec = dict(KEYS)[key]
    check(base, key, spec, data.draw(_draws(spec)))


@pytest.mark.long
@pytest.mark.parametrize('key', [k for k, _ in KEYS])
@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_validator_engine_and_nodes_agree_long(key, data):
    base, spec = dict(KEYS)[key]
    check(base, key, spec, data.draw(_draws(spec)))


def test_a_raan_of_400_deg_is_refused_alike():
    """The named case: ``orbit.raan_deg`` was accepted to +-3600 deg by the validator and to
    +-360 by the environment node."""
    sc = BASE['demo_mission']
    with pytest.raises(ScenarioError, match=r'orbit.raan_deg: must be <= 360 deg, got 400'):
        apply_overrides(sc, {'orbit.raan_deg': 400.0})
    edited = _edited(sc, 'orbit.raan_deg', 400.0)
    with pytest.raises(ScenarioError, match=r'orbit.raan_deg: must be <= 360 deg'):
        FrameLoop.from_scenario(edited, DURATION_S)
    env = _flat(edited)['environment']
    assert _declare(env) == [('orbit.raan_deg', 'orbit.raan_deg: must be <= 360 deg, got 400')]
    check('demo_mission', 'orbit.raan_deg', ORBIT.variants['circular'][2], 400.0)
    check('demo_mission', 'orbit.raan_deg', ORBIT.variants['circular'][2], 359.0)


def test_every_section_is_drawn():
    """The keys drawn cover every section of the schema the bases hold."""
    heads = {k.split('.')[0] for k, _ in KEYS}
    assert {'timing', 'orbit', 'field', 'spacecraft', 'initial', 'sensors', 'estimator',
            'controllers', 'guidance', 'manager', 'epoch', 'seed', 'duration_s'} <= heads
    assert any(k.startswith('spacecraft.wheels.0.') for k, _ in KEYS)
    assert any(k.startswith('spacecraft.flexible.') for k, _ in KEYS)
    assert any(k.startswith('manager.auto.') for k, _ in KEYS)
    assert any(k.startswith('guidance.profile.0.') for k, _ in KEYS)
    assert 'orbit.line1' in dict(KEYS) and 'field.max_degree' in dict(KEYS) or \
        'field.coefficient_date' in dict(KEYS)
