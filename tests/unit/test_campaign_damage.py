"""A damaged campaign directory and absurd arguments are refused up front in one line, exit 2
(issue 38 items 6 and 7); a run's damaged ``result.json`` makes that run run again; each
attempt writes its own temporary files. The run processes' ownership (one worker per run) is
``tests/graph/test_montecarlo_ownership.py``."""
import json
import os
import time

import pytest

from adcs_nodes.tools import cli

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENARIO = os.path.join(ROOT, 'scenarios', 'paper000_control.yaml')


def _mc(capsys, out, *extra):
    t0 = time.monotonic()
    code = cli.main(['montecarlo', SCENARIO, '--runs', '1', '--duration', '2', '--engine',
                     'plain', '--out', str(out), *extra])
    got = capsys.readouterr()
    return code, got.out, got.err, time.monotonic() - t0


def _write(path, text):
    with open(path, 'w', encoding='utf-8') as fh:
        fh.write(text)


DAMAGE = {
    'empty campaign.json': (lambda out: _write(out / 'campaign.json', ''), 'not JSON'),
    'garbage campaign.json': (lambda out: _write(out / 'campaign.json', '{"runs": 1,,'),
                              'not JSON'),
    'list campaign.json': (lambda out: _write(out / 'campaign.json', '[1, 2]'),
                           'a JSON list, not a campaign'),
    'runs is a file': (lambda out: _write(out / 'runs', 'x'), 'runs is not a directory'),
    '.lock is a directory': (lambda out: os.mkdir(out / '.lock'), '.lock is a directory'),
    'campaign.csv is a directory': (lambda out: os.mkdir(out / 'campaign.csv'),
                                    'campaign.csv is a directory'),
}


@pytest.mark.parametrize('case', sorted(DAMAGE))
def test_a_damaged_campaign_is_refused_in_one_line(tmp_path, capsys, case):
    damage, reason = DAMAGE[case]
    out = tmp_path / 'mc'
    out.mkdir()
    damage(out)
    code, _, err, wall = _mc(capsys, out)
    assert code == 2, err
    assert err.startswith('adcs montecarlo: ') and err.count('\n') == 1, err
    assert reason in err and 'Traceback' not in err and wall < 10.0, err
    assert not (out / 'runs').is_dir()                  # nothing was run


@pytest.mark.parametrize('extra, reason', [
    (('--max-rate-deg-s', '1e9'), 'rate 1.73205e+09 deg/s is above'),
    (('--mag-bias-nT', '1e8'), 'sensors.magnetometer.bias_T'),
    (('--runs', '99999999999'), '--runs must be in [1, 100000]'),
    (('--jobs', '100000'), '--jobs must be in [1, 256]'),
])
def test_arguments_no_run_could_take_are_refused_up_front(tmp_path, capsys, extra, reason):
    code, _, err, wall = _mc(capsys, tmp_path / 'mc', *extra)
    assert code == 2 and reason in err and err.count('\n') == 1, err
    assert wall < 10.0 and not (tmp_path / 'mc').exists()
    code = cli.main(['sweep', SCENARIO, '--set', 'controllers.magnetic.alpha_per_s=2e-3',
                     '--runs', '1', '--duration', '2', '--out', str(tmp_path / 'sw'), *extra])
    assert code == 2 and reason in capsys.readouterr().err


def test_a_list_result_json_runs_the_run_again(tmp_path, capsys):
    out = tmp_path / 'mc'
    assert _mc(capsys, out)[0] == 0
    result = out / 'runs' / 'run_0000' / 'result.json'
    first = json.loads(result.read_text())
    result.write_text('[]')
    code, text, err, _ = _mc(capsys, out)
    assert code == 0, err
    assert 'executed 1 run(s)' in text and 'Traceback' not in err
    again = json.loads(result.read_text())
    assert again['status'] == first['status'] and again['final_angle_deg'] == \
        first['final_angle_deg']                        # the same seeded run, bit for bit


def test_each_attempt_writes_its_own_temporary_series(tmp_path, monkeypatch):
    import numpy as np

    from adcs_nodes.tools.campaigns import worker
    code = cli.main(['montecarlo', SCENARIO, '--runs', '1', '--duration', '2', '--engine',
                     'plain', '--out', str(tmp_path / 'mc')])
    assert code == 0
    run_dir = str(tmp_path / 'mc' / 'runs' / 'run_0000')
    names = []
    save = np.savez
    monkeypatch.setattr(np, 'savez', lambda path, **kw: (names.append(path), save(path, **kw)))
    assert worker.mc_worker(run_dir) == 0 and worker.mc_worker(run_dir) == 0
    assert len(set(names)) == 2 and all(os.path.dirname(n) == run_dir for n in names)
    assert not [n for n in os.listdir(run_dir) if 'tmp' in n]
