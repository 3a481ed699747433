"""Scenario validation: every shipped scenario loads; bad files fail naming key and line."""
import os
import re
import textwrap

import pytest

from adcs_nodes.graph import build_graph, topic_type, params_file_text
from adcs_nodes.scenario import ScenarioError, load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCEN = os.path.join(ROOT, 'scenarios')

GOOD = textwrap.dedent("""\
    name: t  # name
    duration_s: 10.0  # s
    orbit:  # orbit
      altitude_km: 690.0  # km
      inclination_deg: 98.0  # deg
    field:  # field
      model: dipole  # model
    spacecraft:  # sc
      inertia_kgm2: [1.0, 2.0, 3.0]  # kg m2
    """)


def write(tmp_path, text):
    p = tmp_path / 's.yaml'
    p.write_text(text)
    return str(p)


@pytest.mark.parametrize('fname', sorted(f for f in os.listdir(SCEN) if f.endswith('.yaml')))
def test_shipped_scenarios_are_valid_and_every_key_is_commented(fname):
    path = os.path.join(SCEN, fname)
    sc = load_scenario(path)
    assert sc['name']
    key = re.compile(r'^\s*(- )?[A-Za-z_][A-Za-z0-9_]*:')
    with open(path) as fh:
        for i, line in enumerate(fh, 1):
            if key.match(line):
                assert '#' in line, f'{fname}:{i}: key without a comment: {line.strip()}'


def test_defaults_are_filled(tmp_path):
    sc = load_scenario(write(tmp_path, GOOD))
    assert sc['timing'] == {'frame_s': 1.0, 'substeps': 10, 'timeout_s': 5.0}
    assert sc['spacecraft']['inertia_kgm2'] == [[1, 0, 0], [0, 2, 0], [0, 0, 3]]
    assert sc['orbit']['raan_deg'] == 0.0
    assert 'magnetorquer' not in sc['spacecraft']


def test_unknown_key_names_key_line_and_suggestion(tmp_path):
    bad = GOOD.replace('  inclination_deg: 98.0', '  inclinaton_deg: 98.0')
    with pytest.raises(ScenarioError) as exc:
        load_scenario(write(tmp_path, bad))
    msg = str(exc.value)
    assert ':5: orbit.inclinaton_deg: unknown key' in msg
    assert "did you mean 'inclination_deg'" in msg


@pytest.mark.parametrize('old,new,expect', [
    ('duration_s: 10.0', 'duration_s: ten', 'duration_s: expected a number'),
    ('duration_s: 10.0', 'duration_s: .nan', 'finite'),
    ('duration_s: 10.0', 'duration_s: -1.0', 'duration_s: must be > 0 s'),
    ('duration_s: 10.0', 'duration_s: 10.5', 'whole number'),
    ('model: dipole', 'model: wmm', "unknown model 'wmm'"),
    ('[1.0, 2.0, 3.0]', '[1.0, 2.0]', 'expected 3 numbers or a 3x3'),
    ('name: t  # name\n', '', 'name: missing required key'),
    ('altitude_km: 690.0', 'altitude_km: [1]', 'expected a number'),
])
def test_bad_values_are_named(tmp_path, old, new, expect):
    with pytest.raises(ScenarioError, match=expect.replace('[', r'\[')):
        load_scenario(write(tmp_path, GOOD.replace(old, new)))


def test_yaml_syntax_error_has_a_line(tmp_path):
    with pytest.raises(ScenarioError, match=r's.yaml:\d+: YAML syntax error'):
        load_scenario(write(tmp_path, GOOD + 'orbit: [unclosed\n'))


def test_missing_file_and_non_mapping(tmp_path):
    with pytest.raises(ScenarioError, match='no such scenario file'):
        load_scenario(str(tmp_path / 'nope.yaml'))
    with pytest.raises(ScenarioError, match='mapping'):
        load_scenario(write(tmp_path, '- 1\n- 2\n'))


def test_free_tumble_graph_converts_paper_conventions():
    sc = load_scenario(os.path.join(SCEN, 'free_tumble.yaml'))
    nodes = {n.name: n for n in build_graph(sc, 60.0, record=True)}
    dyn = nodes['dynamics'].params
    # the dynamics reads the scenario's initial section (the same spec): paper 000's Lambda(0)
    # scalar first -> scalar last, deg/s -> rad/s, with the orbit frame at the identity
    from sim_node.models.spacecraft_config import INITIAL, SPACECRAFT, initial_state
    from sim_node.models.spacecraft_config import spacecraft_from_config
    assert dyn['initial.q_orbit_body_wxyz'] == pytest.approx([0.36, 0.48, -0.48, 0.64])
    craft = spacecraft_from_config(SPACECRAFT.read(dyn, 'spacecraft'), seed=0)
    state = initial_state(INITIAL.read(dyn, 'initial'), [0.0, 0.0, 0.0, 1.0], [0.0] * 3, craft)
    assert state.q_eci_body == pytest.approx([0.48, -0.48, 0.64, 0.36])
    assert state.omega_body_eci_body[0] == pytest.approx(-3.0 * 3.141592653589793 / 180)
    assert dyn['wait_for_nodes'] == ['environment', 'recorder']
    assert 'pub:/clock=2' in dyn['expected_matches']        # environment + recorder
    assert 'sub:sim/environment=1' in dyn['expected_matches']
    text = params_file_text(list(nodes.values()))
    assert '/dynamics:' in text and 'ros__parameters' in text


def test_docs_scenarios_md_is_generated_from_the_schema():
    from adcs_nodes.scenario import schema_markdown
    with open(os.path.join(ROOT, 'docs', 'scenarios.md')) as fh:
        assert fh.read() == schema_markdown(), \
            'regenerate: ros2_ws/run.sh adcs schema > docs/scenarios.md'


def test_exponent_floats_without_a_sign_or_dot_are_numbers(tmp_path):
    sc = load_scenario(write(tmp_path, GOOD.replace('duration_s: 10.0', 'duration_s: 1e1')
                             .replace('[1.0, 2.0, 3.0]', '[2.0e-1, 1E-1, 1.5e-1]')))
    assert sc['duration_s'] == 10.0   # (a rigid body's moments obey the triangle inequality)
    assert sc['spacecraft']['inertia_kgm2'][0][0] == 0.2
    assert sc['spacecraft']['inertia_kgm2'][1][1] == 0.1
    assert sc['spacecraft']['inertia_kgm2'][2][2] == 0.15


@pytest.mark.parametrize('fname', sorted(f for f in os.listdir(SCEN) if f.endswith('.yaml')))
def test_flight_software_never_subscribes_to_the_simulator(fname):
    sc = load_scenario(os.path.join(SCEN, fname))
    for node in build_graph(sc, sc['duration_s'], record=False):
        if node.package == 'adcs_nodes':
            assert not [t for t in node.subscribes if t.startswith('sim/')], node.name
        # every published topic has a message type for the recorder
        for topic in node.publishes:
            assert topic_type(topic), topic


def test_an_epoch_written_as_a_yaml_timestamp_is_the_iso_text(tmp_path):
    """``epoch: 2026-01-01T00:00:00Z`` unquoted is a YAML timestamp (a ``ros2 param dump``
    style value): it loads as the same ISO text the quoted form gives (issue 37, 6)."""
    sc = load_scenario(write(tmp_path, GOOD + 'epoch: 2026-03-04T05:06:07Z  # t0\n'))
    assert sc['epoch'] == '2026-03-04T05:06:07Z'
    with pytest.raises(ScenarioError, match='epoch: expected ISO-8601 text, got date'):
        load_scenario(write(tmp_path, GOOD + 'epoch: 2026-03-04  # a date, no time\n'))
