"""``adcs compare`` without processes: bad input exits 2 before any run; how each controller is
made the one that flies (or why it cannot); the table of hand-made runs; and a short compare
of three controllers on the demo's spacecraft run in this process (the runs' process replaced
by the plain worker's body, as in ``test_sweep.py``), interrupted and resumed: the same draws
for every controller, and the table's metrics against a computation of them from each run's
``series.npz`` written here (scipy for the angles, numpy for the integrals)."""
import json
import math
import os

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from adcs_nodes.scenario import load_scenario
from adcs_nodes.tools import cli
from adcs_nodes.tools.campaigns import campaign as campaign_mod
from adcs_nodes.tools.campaigns import compare
from adcs_nodes.tools.campaigns.files import SERIES_FILE, load_result, run_dir_of
from frameloop_run import SCENARIOS, raw
from test_sweep import _InProcessBackend

PAPER000 = os.path.join(SCENARIOS, 'paper000_control.yaml')
PAPER001 = os.path.join(SCENARIOS, 'paper001_mpi.yaml')
DEMO = os.path.join(SCENARIOS, 'demo_mission.yaml')


# ---------------------------------------------------------------------- bad input: exit 2
@pytest.mark.parametrize('argv, message', [
    (['--controllers', 'magnetic,mpii'], "unknown controller 'mpii' (did you mean 'mpi'?)"),
    (['--controllers', ''], "--controllers '': give each name once"),
    (['--controllers', 'mpi,,fuzzy'], 'give each name once'),
    (['--controllers', 'mpi,mpi'], 'give each name once'),
    (['--controllers', 'mpi', '--runs', '0'], '--runs must be in [1, 100000], got 0'),
    (['--controllers', 'mpi', '--duration', '0.3'], 'whole number'),
    (['--controllers', 'mpi', '--jobs', '0'], '--jobs must be in'),
])
def test_bad_input_exits_2_before_any_run(argv, message, tmp_path, capsys):
    out = tmp_path / 'cmp'
    assert cli.main(['compare', PAPER001, '--out', str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith('adcs compare: ') and message in err, err
    assert not (out / 'controllers').exists()


def test_a_scenario_that_does_not_validate_exits_2(tmp_path, capsys):
    sc = raw('paper000_control')
    sc['controllers']['magnetic']['gain'] = 1.0
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(sc))
    assert cli.main(['compare', str(path), '--controllers', 'magnetic']) == 2
    err = capsys.readouterr().err
    assert err.startswith('adcs compare: ') and 'controllers.magnetic' in err \
        and 'gain' in err, err


def test_no_controller_that_can_fly_exits_2_with_the_reasons(tmp_path, capsys):
    out = tmp_path / 'cmp'
    code = cli.main(['compare', PAPER000, '--controllers', 'mpi,fuzzy', '--out', str(out)])
    assert code == 2
    text = capsys.readouterr()
    assert 'mpi cannot fly paper000_control: needs sensors.wheel_tachometer (input ' \
        'wheel_speeds); commands reaction wheels: needs spacecraft.wheels' in text.out
    assert 'fuzzy cannot fly paper000_control: commands a body torque' in text.out
    assert 'no controller of mpi,fuzzy can fly paper000_control' in text.err
    assert not (out / 'controllers').exists()


# ---------------------------------------------------------------------- who flies, how
def test_each_controller_holds_the_pointing_phase_or_says_why_not():
    demo = load_scenario(DEMO)
    for name in ('magnetic', 'mpi', 'fuzzy'):
        sc, how = compare.flying(demo, name)
        auto = sc['manager']['auto']
        assert auto['acquire'] == auto['point'] == name and auto['detumble'] == 'bdot'
        assert sc['manager']['schedule'] == []
        assert how == 'manager.auto.acquire, manager.auto.point, scripted switches removed'
        # the rest of the scenario, its draws' inputs included, is the demo's
        assert {k: v for k, v in sc.items() if k not in ('manager', '_path')} == \
            {k: v for k, v in demo.items() if k not in ('manager', '_path')}
    p001 = load_scenario(PAPER001)
    sc, how = compare.flying(p001, 'fuzzy')     # not in the scenario: the registry defaults
    assert sc['manager']['initial'] == 'fuzzy' and sc['manager']['safe'] == 'mpi'
    assert sc['controllers']['fuzzy']['max_torque_Nm'] == 1.0
    assert how == 'manager.initial, registry defaults (not in the scenario)'
    sc, why = compare.flying(p001, 'magnetic')
    assert sc is None and why.startswith('needs sensors.magnetometer')
    assert 'needs spacecraft.magnetorquer' in why
    p000 = load_scenario(PAPER000)
    assert compare.flying(p000, 'magnetic')[0]['manager']['initial'] == 'magnetic'
    assert compare.flying(p000, 'mpi') == (None, 'needs sensors.wheel_tachometer (input '
                                           'wheel_speeds); commands reaction wheels: needs '
                                           'spacecraft.wheels')


# ---------------------------------------------------------------------- the table, by hand
def _run(settle, effort, peak, sat, flown, lost, pointing):
    return {'pointing_deg': np.array(pointing, float), 'settle_s': settle,
            'effort_Nms': effort, 'peak_h_Nms': peak, 'saturated_s': sat, 'flown_s': flown,
            'lost': lost}


def test_the_row_of_hand_made_runs():
    runs = [_run(100.0, 2.0, 0.1, 10.0, 900.0, False, [1.0, 2.0, 3.0]),
            _run(300.0, 4.0, 0.3, 30.0, 1000.0, True, [4.0, 5.0, 6.0]),
            _run(None, 9.0, 0.2, 20.0, 500.0, False, [7.0, 8.0, 9.0, 10.0, np.nan])]
    r = compare.summarise('mpi', runs, n_runs=4, errors=1, duration_s=1000.0)
    # pooled 1..10: median 5.5, p95 (linear) 9.55
    assert r['pointing_median_deg'] == 5.5 and math.isclose(r['pointing_p95_deg'], 9.55)
    assert (r['done'], r['errors'], r['settled'], r['lost']) == (3, 1, 2, 1)
    assert (r['settle_median_s'], r['settle_max_s']) == (200.0, 300.0)
    assert (r['effort_median_Nms'], r['peak_h_max_Nms'], r['saturated_median_s']) == \
        (4.0, 0.3, 20.0)
    assert r['flown_median_pct'] == 90.0
    line = compare.table_markdown([r, {'controller': 'magnetic', 'reason': 'no coils'}])
    lines = line.splitlines()
    assert lines[2] == ('| mpi | 3/4 | 5.5 / 9.55 | 2/3 | 200 / 300 | 4 | 0.3 | 20 | 90 | '
                        '1 error(s), 1 lost the command |')
    assert lines[3].startswith('| magnetic | cannot fly this scenario: no coils |')
    assert lines[3].count('|') == lines[2].count('|')
    none = compare.summarise('mpi', [], n_runs=2, errors=2, duration_s=10.0)
    assert none['pointing_median_deg'] is None and none['settle_median_s'] is None


# ---------------------------------------------------------------------- a compare, in process
def _short_demo(tmp_path):
    """The demo's spacecraft for 20 s: no automatic sequence (the compared controller flies
    from t = 0), no faults (they come later), no wheel tachometer and so no MPI."""
    sc = raw('demo_mission')
    sc['duration_s'] = 20.0
    del sc['manager']['auto'], sc['faults'], sc['sensors']['wheel_tachometer']
    del sc['controllers']['mpi']
    sc['manager']['initial'] = 'fuzzy'
    sc['manager']['schedule'] = []
    path = tmp_path / 'demo_short.yaml'
    path.write_text(yaml.safe_dump(sc))
    return str(path)


def _compare(path, out, backends, monkeypatch, capsys):
    made = iter(backends)
    monkeypatch.setattr(campaign_mod, 'LocalBackend', lambda jobs: next(made))
    code = cli.main(['compare', path, '--controllers', 'magnetic,mpi,fuzzy,reference_slew',
                     '--runs', '2', '--out', str(out)])
    return code, capsys.readouterr().out


def _independent(run_dir, name, sc):
    """The run's metrics from its saved series, computed here."""
    with np.load(os.path.join(run_dir, SERIES_FILE)) as s:
        s = dict(s)
    t = s['t_s']
    angle = np.degrees((Rotation.from_quat(s['q_orbit_target']).inv()
                        * Rotation.from_quat(s['q_orbit_body'])).magnitude())
    second_half = (t >= (t[0] + t[-1]) / 2.0) & s['target_judged']
    effort = sat = flown = 0.0
    craft = sc['spacecraft']
    for k in range(t.size - 1):
        dt = t[k + 1] - t[k]
        m, b = s['dipole_body_Am2'][k], s['b_body_T'][k]
        tau_mag = [m[1] * b[2] - m[2] * b[1], m[2] * b[0] - m[0] * b[2],
                   m[0] * b[1] - m[1] * b[0]]
        effort += dt * (sum(abs(x) for x in s['wheel_torque_Nm'][k])
                        + sum(abs(x) for x in tau_mag))
        at_limit = any(abs(m[i]) >= 0.999 * craft['magnetorquer']['max_dipole_Am2'][i]
                       for i in range(3)) or any(
            abs(s['wheel_torque_Nm'][k][i]) >= 0.999 * w['max_torque_Nm']
            or abs(s['wheel_momentum_Nms'][k][i]) >= 0.999 * w['max_momentum_Nms']
            for i, w in enumerate(craft['wheels']))
        sat += dt * at_limit
        flown += dt * (s['active'][k] == name)
    mine = [i for i, a in enumerate(s['active']) if a == name]
    return {'pointing': angle[second_half], 'effort': effort, 'saturated': sat,
            'flown': flown, 'peak_h': np.abs(s['wheel_momentum_Nms']).max(),
            'lost': bool(mine) and any(a != name for a in s['active'][mine[0]:])}


def test_an_interrupted_compare_resumes_on_the_same_draws_and_its_table_is_the_series(
        tmp_path, monkeypatch, capsys):
    path, out = _short_demo(tmp_path), tmp_path / 'cmp'
    # Ctrl-C after the first run of the first controller: exit 130, the others never start
    cut = _InProcessBackend(interrupt_after=1)
    code, text = _compare(path, out, [cut], monkeypatch, capsys)
    assert code == 130 and 'interrupted' in text and len(cut.ran) == 1, text
    assert '| magnetic | 1/2 |' in text and '| fuzzy | 0/2 |' in text
    assert '| mpi | cannot fly this scenario: needs sensors.wheel_tachometer (input ' \
        'wheel_speeds) |' in text
    # the same command again: only the missing runs run
    rest = [_InProcessBackend() for _ in range(3)]
    code, text = _compare(path, out, rest, monkeypatch, capsys)
    assert code == 0, text
    assert [len(b.ran) for b in rest] == [1, 2, 2]
    assert not (out / 'controllers' / 'mpi').exists()
    assert 'resuming: 1 of 2 runs already done, 1 to run' in text
    with open(out / 'compare.json') as fh:
        rows = {r['controller']: r for r in json.load(fh)['rows']}
    assert (out / 'compare.png').is_file() and (out / 'compare.md').is_file()
    sc = load_scenario(path)
    assert rows['mpi'] == {'controller': 'mpi', 'reason': 'needs sensors.wheel_tachometer '
                           '(input wheel_speeds)'}
    for name in ('magnetic', 'fuzzy', 'reference_slew'):
        row, pooled, ind = rows[name], [], []
        assert (row['done'], row['errors']) == (2, 0)
        for i in range(2):
            run_dir = run_dir_of(str(out / 'controllers' / name), i)
            with open(os.path.join(run_dir, 'scenario.yaml')) as fh:
                run_sc = yaml.safe_load(fh)
            with open(os.path.join(run_dir_of(str(out / 'controllers' / 'magnetic'), i),
                                   'scenario.yaml')) as fh:
                first = yaml.safe_load(fh)
            # the same draws for every controller: initial state and noise seeds
            assert run_sc['initial'] == first['initial'] and run_sc['seed'] == first['seed']
            assert run_sc['manager']['initial'] == name
            ind.append(_independent(run_dir, name, sc))
            pooled.append(ind[-1]['pointing'])
            assert load_result(run_dir)['capture_time_s'] is None    # 20 s: none settles
        pooled = np.concatenate(pooled)
        assert pooled.size == 2 * 11                   # 10..20 s, judged
        assert math.isclose(row['pointing_median_deg'], np.median(pooled), rel_tol=1e-9)
        assert math.isclose(row['pointing_p95_deg'], np.percentile(pooled, 95),
                            rel_tol=1e-9)
        assert math.isclose(row['effort_median_Nms'], np.median([r['effort'] for r in ind]),
                            rel_tol=1e-9)
        assert row['saturated_median_s'] == np.median([r['saturated'] for r in ind])
        assert row['peak_h_max_Nms'] == max(r['peak_h'] for r in ind)
        assert row['flown_median_pct'] == 100.0 * np.median([r['flown'] for r in ind]) / 20.0
        assert row['lost'] == sum(r['lost'] for r in ind) and row['settled'] == 0
    # the runs differ by controller: coils only for the magnetic law, wheels for the others
    assert rows['magnetic']['peak_h_max_Nms'] == 0.0 < rows['fuzzy']['peak_h_max_Nms']
    # manager.initial: each flies from frame 0 to the end
    assert {r['flown_median_pct'] for r in rows.values() if r['reason'] is None} == {100.0}
