"""``adcs montecarlo --engine auto`` (the default): plain for every scenario without an external
sensor, graph with one (a driver publishes it), an explicit engine wins, a resumed campaign
keeps its recorded engine."""
import json
import os

import pytest

from adcs_nodes.tools.campaigns.cli import main
from adcs_nodes.tools.campaigns.config import plain_engine_problem, resolve_engine
from adcs_nodes.scenario import load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def scenario(name):
    return load_scenario(os.path.join(ROOT, 'scenarios', f'{name}.yaml'))


SHIPPED = sorted(f[:-5] for f in os.listdir(os.path.join(ROOT, 'scenarios'))
                 if f.endswith('.yaml'))


@pytest.mark.parametrize('name', SHIPPED)
def test_auto_is_plain_for_every_shipped_scenario(name, tmp_path):
    assert plain_engine_problem(scenario(name)) is None
    assert resolve_engine('auto', scenario(name), str(tmp_path))[0] == 'plain'
    assert resolve_engine(None, scenario(name), str(tmp_path))[0] == 'plain'


def test_auto_is_graph_with_an_external_sensor(tmp_path):
    sc = scenario('paper000_control')
    sc['sensors']['magnetometer']['external'] = True
    engine, reason = resolve_engine('auto', sc, str(tmp_path))
    assert engine == 'graph' and 'magnetometer' in reason and 'driver' in reason, reason


def test_explicit_engine_wins(tmp_path):
    sc = scenario('paper000_control')
    assert resolve_engine('graph', sc, str(tmp_path)) == ('graph', '--engine')
    assert resolve_engine('plain', scenario('paper003_slew'), str(tmp_path))[0] == 'plain'
    with pytest.raises(ValueError, match='--engine'):
        resolve_engine('fast', sc, str(tmp_path))


@pytest.mark.parametrize('recorded, expected', [
    ({'engine': 'graph'}, 'graph'), ({'engine': 'plain'}, 'plain'),
    ({}, 'graph')])   # a campaign.json from before the engines
def test_a_resumed_campaign_keeps_its_recorded_engine(recorded, expected, tmp_path):
    with open(tmp_path / 'campaign.json', 'w', encoding='utf-8') as fh:
        json.dump({'seed': 1, **recorded}, fh)
    engine, reason = resolve_engine('auto', scenario('paper000_control'), str(tmp_path))
    assert engine == expected and 'resumed' in reason


def test_first_line_names_the_chosen_engine(tmp_path, capsys):
    """A 2 s plain run (one run process): the first output line names the engine and why."""
    out = tmp_path / 'mc'
    code = main([os.path.join(ROOT, 'scenarios', 'paper000_control.yaml'), '--runs', '1',
                 '--duration', '2', '--out', str(out)])
    lines = capsys.readouterr().out.splitlines()
    assert code == 0, lines
    assert 'engine plain [auto: the plain engine runs this scenario]' in lines[0], lines[0]
    with open(out / 'campaign.json', encoding='utf-8') as fh:
        assert json.load(fh)['engine'] == 'plain'


def test_resume_keeps_the_engine_and_refuses_another(tmp_path, capsys):
    """A plain campaign resumed without --engine stays plain (nothing to run); naming the graph
    engine for it is refused like any other changed argument; a campaign.json from before the
    engines (no engine key) resumes as a graph campaign."""
    out = tmp_path / 'mc'
    args = [os.path.join(ROOT, 'scenarios', 'paper000_control.yaml'), '--runs', '1',
            '--duration', '2', '--out', str(out)]
    assert main(args + ['--engine', 'plain']) == 0
    capsys.readouterr()
    assert main(args) == 0
    text = capsys.readouterr().out
    assert 'engine plain [auto: the engine of the campaign being resumed]' in text
    assert 'executed 0 run(s)' in text
    assert main(args + ['--engine', 'graph']) == 2
    err = capsys.readouterr().err
    assert "engine: 'plain' in campaign.json, 'graph' now" in err, err
    # before the engines: no engine key; auto resumes it as graph, with nothing left to run
    with open(out / 'campaign.json', encoding='utf-8') as fh:
        data = json.load(fh)
    del data['engine']
    with open(out / 'campaign.json', 'w', encoding='utf-8') as fh:
        json.dump(data, fh)
    assert main(args) == 0
    text = capsys.readouterr().out
    assert 'engine graph [auto: the engine of the campaign being resumed]' in text, text
    assert 'executed 0 run(s)' in text
