"""Studies on the FrameLoop (adcs_nodes.tools.analyse.study): a short run's series and paper
table, a
sweep through overrides, and the command line's exit codes."""
import json
import math
import os

import numpy as np
import pytest

from adcs_nodes.tools.analyse import study
from adcs_nodes.scenario import load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PAPER000 = os.path.join(ROOT, 'scenarios', 'paper000_control.yaml')
PAPER003 = os.path.join(ROOT, 'scenarios', 'paper003_slew.yaml')


def test_short_run_starts_at_the_papers_initial_attitude():
    from adcs_nodes.tools.campaigns.worker import run_series
    from sim_node.engine import FrameLoop
    series = run_series(FrameLoop.from_scenario(load_scenario(PAPER000), 20.0))
    assert series['t_s'].tolist() == [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 18.0,
                                      20.0]
    # Lambda(0) = (0.36, 0.48, -0.48, 0.64): rotation angle 2 acos(0.36)
    assert series['angle_deg'][0] == pytest.approx(math.degrees(2 * math.acos(0.36)), abs=1e-9)
    # omega(0) = (-3, 3, 3) deg/s absolute
    rate = np.degrees(np.linalg.norm(series['w_eci'][0]))
    assert rate == pytest.approx(3 * math.sqrt(3), abs=1e-9)
    # N(t0) = identity, then the t = 0 sample updates it: it moves away from 138 deg
    assert 0.0 < series['est_err_deg'][0] < series['angle_deg'][0]
    assert np.all(np.isfinite(series['angle_deg'])) and set(series['active']) == {'magnetic'}


def test_run_rows_gives_the_report_rows_and_a_summary():
    sc, rows, summary = study.run_rows(load_scenario(PAPER003), 5.0,
                                       {'manager.initial': 'reference_slew'})
    assert sc['manager']['initial'] == 'reference_slew'
    names = [r[0] for r in rows]
    assert names[:2] == ['settling time (5 % band of phi0)',
                         'energy (integral of sum |M_i| to settling)']
    assert 'reference_slew' in rows[0][3].reason         # flown by the reference: no verdict
    assert summary['duration_s'] == 5.0 and summary['final_deg'] > 0.0


def test_ideal_estimate_is_the_truth():
    sc, _, summary = study.run_rows(load_scenario(PAPER000), 10.0, ideal=True)
    assert summary['est_err_median_deg'] is None or summary['est_err_median_deg'] == 0.0
    topics = study.run_topics(sc, ('sim/state', 'adcs/attitude_estimate'), 10.0, ideal=True)
    for stamp, est in topics['adcs/attitude_estimate'].items():
        assert est.q_orbit_body == topics['sim/state'][stamp].q_orbit_body


def test_command_line_sweep_prints_one_column_per_value(tmp_path, capsys):
    out = tmp_path / 'sweep.json'
    code = study.main(['sweep', PAPER003, 'controllers.reference_slew.accel_fraction', '0.9',
                       '0.5', '--set', 'manager.initial=reference_slew', '--duration', '3',
                       '--out', str(out)])
    text = capsys.readouterr().out
    assert code == 0
    assert '| quantity | paper | controllers.reference_slew.accel_fraction=0.9 | ' \
        'controllers.reference_slew.accel_fraction=0.5 |' in text
    data = json.loads(out.read_text())
    assert [r['value'] for r in data['runs']] == [0.9, 0.5]
    assert data['runs'][0]['rows'][0]['verdict'].startswith('not comparable')


def test_command_line_run_prints_the_paper_table(capsys):
    assert study.main(['run', PAPER003, '--duration', '2', '--set',
                       'manager.initial=reference_slew']) == 0
    text = capsys.readouterr().out
    assert text.startswith('paper003_slew on the FrameLoop, --set manager.initial=')
    assert '| quantity | paper | measured | verdict |' in text


@pytest.mark.parametrize('argv', [
    ['run', PAPER003, '--set', 'controllers.fuzzy.mk_gainn=1'],
    ['sweep', PAPER003, 'controllers.fuzzy.nope', '1'],
    ['run', PAPER003, '--duration', '0.15'],              # not a multiple of the frame
])
def test_bad_overrides_and_durations_exit_2(argv, capsys):
    assert study.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith('study: ') and 'Traceback' not in err


def test_help_names_every_study(capsys):
    with pytest.raises(SystemExit):
        study.main(['--help'])
    text = capsys.readouterr().out
    for name in ('run', 'sweep', 'wings', 'hold-horizon', 'table1', 'sensitivity'):
        assert name in text
