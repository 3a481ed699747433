"""Bad scenario input: a clear message and exit code 2, never a traceback, a hang or a flood.

``adcs validate`` is called in process (``adcs_nodes.tools.cli.main``). The truth is the
input's defect: each case names a physical or format fact (a body's principal moments obey
the triangle inequality, an orbit lies above the surface, a name cannot hold a path, ...).
The property tests mutate the shipped scenarios and random bytes: either the validator exits
2 with a one-paragraph message, or the accepted scenario builds its node graph.
"""
import copy
import os
import random
import time

import pytest
import yaml

from adcs_nodes.tools.cli import main as adcs_main

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENARIOS = os.path.join(ROOT, 'scenarios')
FREE_TUMBLE = os.path.join(SCENARIOS, 'free_tumble.yaml')
SHIPPED = sorted(os.path.join(SCENARIOS, f) for f in os.listdir(SCENARIOS)
                 if f.endswith('.yaml'))
#: An error message is one short paragraph, whatever the input.
MAX_MESSAGE_CHARS = 800


def validate(path, capsys, seconds=10.0):
    """``adcs validate path`` in process: (exit code, stderr); fails on a traceback or hang."""
    t0 = time.monotonic()
    code = adcs_main(['validate', str(path)])
    elapsed = time.monotonic() - t0
    err = capsys.readouterr().err
    assert elapsed < seconds, f'validate took {elapsed:.1f} s'
    return code, err


def text_of(path=FREE_TUMBLE):
    with open(path, encoding='utf-8') as fh:
        return fh.read()


def replaced(old, new, path=FREE_TUMBLE):
    text = text_of(path)
    assert old in text, old
    return text.replace(old, new, 1)


BOMB = ''.join(f'{c}: &{c} [' + ','.join([f'*{p}'] * 9) + ']\n'
               for p, c in zip('abcdefgh', 'bcdefghi'))
BOMB = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n' + BOMB

CASES = {
    # format
    'alias bomb as the description': (
        lambda: BOMB.replace('i: &i', 'description: &i') + replaced(
            'description: >-', 'paper_note: >-').split('\n', 3)[3].replace(
            'paper: ', 'paper: ', 1), 'expands to more than'),
    'non-UTF-8 bytes': (lambda: text_of().encode()[:200] + b'\xff\xfe\x80'
                        + text_of().encode()[200:], 'not UTF-8'),
    'complex mapping key': (lambda: replaced('seed: 1', '? [a, b]\n: 1\nseed: 1'),
                            'mapping key must be plain text'),
    'list as the field model': (lambda: replaced('model: igrf_dipole', 'model: [1, 2]'),
                                'field.model'),
    'mapping as the orbit type': (lambda: replaced('type: circular', 'type: {}'),
                                  'orbit.type'),
    'recursive alias': (lambda: text_of() + 'zz: &r [1, *r]\n', 'contains itself'),
    'deep nesting': (lambda: text_of() + 'zz: ' + '[' * 50000 + ']' * 50000 + '\n',
                     'nested too deeply'),
    'a 50 MB file': (lambda: text_of() + '#' * 50_000_000 + '\n', 'larger than'),
    # physics
    'altitude below the surface': (lambda: replaced('altitude_km: 690.0', 'altitude_km: -100.0'),
                                   'orbit.altitude_km: must be >= 100 km'),
    'zero inertia': (lambda: replaced('[118.0, 118.0, 19.6]', '[0, 0, 0]'),
                     'not positive definite'),
    'negative principal moment': (
        lambda: replaced('[118.0, 118.0, 19.6]',
                         '[[10, 0, 0], [0, 10, 20], [0, 20, 10]]'), 'not positive definite'),
    'triangle inequality broken': (lambda: replaced('[118.0, 118.0, 19.6]', '[1, 1, 3]'),
                                   'triangle inequality'),
    'initial rate 1e6 deg/s': (lambda: replaced('[-3.0, 3.0, 3.0]', '[1.0e6, 0, 0]'),
                               'above 100 deg/s'),
    'epoch not a date': (lambda: replaced('"2026-01-01T00:00:00Z"', 'not-a-date'), 'ISO-8601'),
    'epoch after ROS time': (lambda: replaced('"2026-01-01T00:00:00Z"',
                                              '"2040-01-01T00:00:00Z"'), '2038'),
    'frame of 1e300 s': (lambda: replaced('frame_s: 1.0', 'frame_s: 1.0e300'),
                         'timing.frame_s'),
    'frame of 1e-9 s': (lambda: replaced('frame_s: 1.0', 'frame_s: 1.0e-9'),
                        'timing.frame_s'),
    'substeps 1e9': (lambda: replaced('substeps: 10', 'substeps: 1000000000'),
                     'timing.substeps'),
    'negative disturbance std': (lambda: replaced('random_std_Nm: 1.0e-5',
                                                  'random_std_Nm: -1.0e-5'),
                                 'random_std_Nm: must be >= 0'),
    'negative seed': (lambda: replaced('seed: 1', 'seed: -1'), 'seed'),
    'path in the name': (lambda: replaced('name: free_tumble', 'name: ../../outside'),
                         'names the run directory'),
    'a 100 kB name': (lambda: replaced('name: free_tumble', 'name: ' + 'x' * 100_000),
                      'characters>'),
}


@pytest.mark.parametrize('case', sorted(CASES))
def test_bad_input_is_refused_with_a_short_clear_message(case, tmp_path, capsys):
    make, expected = CASES[case]
    content = make()
    path = tmp_path / 'bad.yaml'
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding='utf-8')
    code, err = validate(path, capsys)
    assert code == 2, err
    assert expected in err, err
    assert 'Traceback' not in err
    assert len(err) < MAX_MESSAGE_CHARS, err[:2000]
    assert str(path) in err


def test_sensor_noise_and_probability_ranges(tmp_path, capsys):
    """A probability of 5 and a negative noise std are refused (by the registry's parameter
    ranges, which follow the naming conventions: test_registry)."""
    text = text_of(os.path.join(SCENARIOS, 'paper000_estimation.yaml'))
    data = yaml.safe_load(text)
    for mutate, expected in [
            (lambda d: d['sensors']['magnetometer'].__setitem__('dropout_probability', 5.0),
             'dropout_probability'),
            (lambda d: d['sensors']['magnetometer'].__setitem__('noise_std_T',
                                                                [-1e-7, 1e-7, 1e-7]),
             'noise_std_T')]:
        bad = copy.deepcopy(data)
        mutate(bad)
        path = tmp_path / 'bad.yaml'
        path.write_text(yaml.safe_dump(bad))
        code, err = validate(path, capsys)
        assert code == 2 and expected in err, err


def test_shipped_scenarios_pass(capsys):
    for path in SHIPPED:
        code, err = validate(path, capsys)
        assert code == 0, err


# ---------------------------------------------------------------------- property tests
hypothesis = pytest.importorskip('hypothesis')
from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402

from adcs_nodes.graph import build_graph  # noqa: E402
from adcs_nodes.scenario import ScenarioError, load_scenario  # noqa: E402

PROPERTY = settings(max_examples=100, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])

LEAVES = st.one_of(
    st.none(), st.booleans(), st.integers(min_value=-2**70, max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
    st.sampled_from(['circular', 'tle', 'dipole', 'igrf', 'bdot', 'magnetic', '1e400',
                     '2026-13-45T00:00:00Z', '../x', '', '{', '&a', '*a']),
    st.lists(st.floats(min_value=-1e12, max_value=1e12), max_size=4),
    st.lists(st.integers(min_value=-3, max_value=3), min_size=3, max_size=3))
VALUES = st.recursive(LEAVES, lambda inner: st.one_of(
    st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=6)


def _paths(node, prefix=()):
    """Every key path of a nested YAML structure (mappings and lists)."""
    yield prefix
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _paths(value, prefix + (key,))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _paths(value, prefix + (i,))


def _set(node, path, value, delete=False):
    for key in path[:-1]:
        node = node[key]
    if delete and isinstance(node, dict):
        del node[path[-1]]
    elif delete:
        node.pop(path[-1])
    else:
        node[path[-1]] = value


def _check_outcome(path, capsys):
    """The property: exit 2 with a short message, or accepted and the graph builds."""
    code, err = validate(path, capsys)
    assert code in (0, 2), err
    if code == 2:
        assert err.startswith('adcs validate: ') and 'Traceback' not in err
        assert len(err) < MAX_MESSAGE_CHARS, err[:2000]
        return
    sc = load_scenario(str(path))
    nodes = build_graph(sc, sc['duration_s'], False, 1.0, record=True)
    assert nodes, 'an accepted scenario has nodes'


_PARSED = {p: yaml.safe_load(text_of(p)) for p in SHIPPED}


@PROPERTY
@given(data=st.data())
def test_mutated_shipped_scenarios_are_refused_or_build(data, tmp_path, capsys):
    source = data.draw(st.sampled_from(SHIPPED))
    doc = copy.deepcopy(_PARSED[source])
    for _ in range(data.draw(st.integers(1, 3))):
        paths = [p for p in _paths(doc) if p]
        if not paths:
            break
        where = data.draw(st.sampled_from(paths))
        action = data.draw(st.sampled_from(['replace', 'replace', 'delete', 'add']))
        if action == 'add' and isinstance(doc, dict):
            doc[data.draw(st.text(min_size=1, max_size=8))] = data.draw(VALUES)
        else:
            _set(doc, where, data.draw(VALUES), delete=action == 'delete')
    path = tmp_path / 'mutated.yaml'
    try:
        path.write_text(yaml.safe_dump(doc, allow_unicode=False), encoding='utf-8')
    except (yaml.YAMLError, ValueError, UnicodeEncodeError):
        return  # not representable as YAML: nothing to validate
    _check_outcome(path, capsys)


@PROPERTY
@given(data=st.data())
def test_cut_and_shuffled_scenario_text_is_refused_or_builds(data, tmp_path, capsys):
    text = text_of(data.draw(st.sampled_from(SHIPPED)))
    lines = text.splitlines(keepends=True)
    rng = random.Random(data.draw(st.integers(0, 2**32 - 1)))
    kind = data.draw(st.sampled_from(['cut', 'drop', 'swap', 'indent', 'bytes']))
    if kind == 'cut':
        text = text[:rng.randrange(len(text))]
    elif kind == 'drop':
        del lines[rng.randrange(len(lines))]
        text = ''.join(lines)
    elif kind == 'swap':
        i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
        lines[i], lines[j] = lines[j], lines[i]
        text = ''.join(lines)
    elif kind == 'indent':
        i = rng.randrange(len(lines))
        lines[i] = ' ' * rng.randrange(1, 5) + lines[i]
        text = ''.join(lines)
    raw = text.encode('utf-8')
    if kind == 'bytes':
        pos = rng.randrange(len(raw))
        raw = raw[:pos] + data.draw(st.binary(min_size=1, max_size=8)) + raw[pos:]
    path = tmp_path / 'cut.yaml'
    path.write_bytes(raw)
    _check_outcome(path, capsys)


@PROPERTY
@given(raw=st.binary(max_size=400))
def test_random_bytes_are_refused(raw, tmp_path, capsys):
    path = tmp_path / 'random.yaml'
    path.write_bytes(raw)
    code, err = validate(path, capsys)
    assert code == 2, err
    assert 'Traceback' not in err and len(err) < MAX_MESSAGE_CHARS


def test_scenario_error_is_a_value_error():
    assert issubclass(ScenarioError, ValueError)
