"""Scenario overrides (``--set KEY=VALUE``, adcs_nodes.scenario.apply_overrides): a dotted
key set in a copy, validated again as the file is; an unknown key or a bad value is refused
with a message naming the key (exit 2 from ``adcs run``)."""
import os

import pytest

from adcs_nodes.scenario import (ScenarioError, apply_overrides, load_scenario,
                                 parse_overrides)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PAPER003 = os.path.join(ROOT, 'scenarios', 'paper003_slew.yaml')
PAPER001 = os.path.join(ROOT, 'scenarios', 'paper001_mpi.yaml')


@pytest.fixture(scope='module')
def sc():
    return load_scenario(PAPER003)


def test_parse_reads_yaml_values_as_a_scenario_file_does():
    got = parse_overrides(['seed=3', 'a.b=1e-5', 'x=[1, 2.5]', 'flag=false', 'name=abc',
                           'gone=null', 'p=[{t_s: 0, type: hold}]', 'e=a=b'])
    assert got == {'seed': 3, 'a.b': 1e-5, 'x': [1, 2.5], 'flag': False, 'name': 'abc',
                   'gone': None, 'p': [{'t_s': 0, 'type': 'hold'}], 'e': 'a=b'}
    assert type(got['p'][0]) is dict                 # plain dicts (yaml.safe_dump writes them)
    assert parse_overrides({'k': 1}) == {'k': 1}


@pytest.mark.parametrize('item, words', [
    ('seed', 'expected KEY=VALUE'), ('=3', 'expected KEY=VALUE'),
    ('a..b=3', 'expected KEY=VALUE'), ('seed=', 'no value'),
    ('seed=[1', 'not YAML')])
def test_parse_refuses_malformed_items_naming_them(item, words):
    with pytest.raises(ScenarioError, match=words) as err:
        parse_overrides([item])
    assert str(err.value).startswith('--set ')


def test_nested_key_is_set_in_a_validated_copy(sc):
    out = apply_overrides(sc, ['controllers.fuzzy.mk_gain=2.5', 'manager.initial=reference_slew'])
    assert out['controllers']['fuzzy']['mk_gain'] == 2.5
    assert out['manager']['initial'] == 'reference_slew'
    assert sc['controllers']['fuzzy']['mk_gain'] == 3.7 and sc['manager']['initial'] == 'fuzzy'
    assert out['_path'] == sc['_path']
    # the rest is the scenario as loaded (every default filled in once more, nothing lost)
    same = {k: v for k, v in out.items() if k not in ('controllers', 'manager')}
    assert same == {k: v for k, v in sc.items() if k not in ('controllers', 'manager')}


def test_dict_overrides_lists_by_index_and_removal():
    sc = load_scenario(PAPER001)
    out = apply_overrides(sc, {'spacecraft.wheels.1.max_torque_Nm': 0.5,
                               'spacecraft.flexible.wings': 'two',
                               'initial.q_orbit_body_xyzw': None,
                               'initial.q_orbit_body_wxyz': [1.0, 0.0, 0.0, 0.0]})
    assert [w['max_torque_Nm'] for w in out['spacecraft']['wheels']] == [1.0, 0.5, 1.0]
    assert sc['spacecraft']['flexible']['wings'] == 'one'       # the replication model
    assert out['spacecraft']['flexible']['wings'] == 'two'
    assert 'q_orbit_body_xyzw' not in out['initial']
    assert out['initial']['q_orbit_body_wxyz'] == [1.0, 0.0, 0.0, 0.0]


def test_unknown_key_is_refused_with_its_name_and_a_hint(sc):
    with pytest.raises(ScenarioError) as err:
        apply_overrides(sc, ['controllers.fuzzy.mk_gainn=1'])
    text = str(err.value)
    assert text.startswith('--set controllers.fuzzy.mk_gainn=1: ')
    assert 'controllers.fuzzy.mk_gainn: unknown key' in text and "'mk_gain'" in text
    with pytest.raises(ScenarioError, match="controlers: unknown key.*'controllers'"):
        apply_overrides(sc, ['controlers.fuzzy.mk_gain=1'])


@pytest.mark.parametrize('item, words', [
    ('controllers.fuzzy.mk_gain=-1', 'controllers.fuzzy.mk_gain: must be > 0'),
    ('controllers.fuzzy.table1_rows=sideways', 'controllers.fuzzy.table1_rows'),
    ('manager.initial=nope', 'manager.initial:'),
    ('timing.frame_s=abc', 'timing.frame_s'),
    ('seed.x=1', 'seed is a value'),
    ('spacecraft.inertia_kgm2.7=1', 'not an index'),
])
def test_bad_value_is_refused_naming_the_key(sc, item, words):
    with pytest.raises(ScenarioError, match=words) as err:
        apply_overrides(sc, [item])
    assert str(err.value).startswith('--set ') and 'Traceback' not in str(err.value)


def test_adcs_run_refuses_a_bad_override_with_exit_2(capsys):
    from adcs_nodes.tools.cli import main
    code = main(['run', PAPER003, '--engine', 'plain', '--quiet', '--set', 'seed=-1'])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith('adcs run: --set seed=-1: seed:'), err
    code = main(['run', PAPER003, '--engine', 'plain', '--quiet', '--set', 'nokey=1'])
    assert code == 2 and 'nokey: unknown key' in capsys.readouterr().err


def test_adcs_run_applies_the_override_to_the_recorded_scenario(tmp_path, capsys):
    import yaml

    from adcs_nodes.tools.cli import main
    bag = str(tmp_path / 'bag')
    assert main(['run', PAPER003, '--engine', 'plain', '--quiet', '--duration', '1',
                 '--record', bag, '--set', 'manager.initial=reference_slew']) == 0
    with open(os.path.join(bag, 'scenario.yaml')) as fh:
        assert yaml.safe_load(fh)['manager']['initial'] == 'reference_slew'


def test_an_override_keeps_the_scenarios_faults():
    """A scenario with faults (demo_mission) takes an override: its loaded faults, which
    carry their index, validate again (it failed with exit 2 before)."""
    sc = load_scenario(os.path.join(ROOT, 'scenarios', 'demo_mission.yaml'))
    out = apply_overrides(sc, parse_overrides(['seed=3']))
    assert out['seed'] == 3
    assert [(f['index'], f['kind']) for f in out['faults']] == \
        [(f['index'], f['kind']) for f in sc['faults']]
