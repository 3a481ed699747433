"""Paper 001's table (adcs_nodes.tools.papers.paper001): metrics of a synthetic 5000 s series
whose answers are computed by hand, the not-comparable rows of a short run, and ``adcs report``
of a short plain-engine bag printing the table."""
import math
import os

import numpy as np
import pytest

from adcs_nodes.tools.papers import NotComparable, paper001, table_lines

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DT = 0.2


def _series(t_end=5000.0):
    """Errors in degrees laid out so that each metric has a hand-computed value:

    * stabilisation windows (500-1000, 4200-5000 s): x error alternating +-0.001 deg
      (3-sigma 0.003 deg), x rate error alternating +-0.002 deg/s (3-sigma 0.006 deg/s);
    * tracking (1100-3500 s): y error alternating +-0.01 deg (3-sigma 0.03 deg);
    * 0.15 deg on y from 100 s until 240 s (last sample 239.8 s: back within 0.1 deg
      239.8 - 200 + 0.2 = 40 s after the 200 s maneuver end), then 0 until the windows;
    * 3700 s: z error 0.25 deg at that sample only (back 0.2 s after).
    """
    t = np.round(np.arange(0.0, t_end + DT / 2, DT), 6)
    n = t.size
    err = np.zeros((n, 3))
    derr = np.zeros((n, 3))
    alt = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    stab = ((t >= 500) & (t < 1000)) | ((t >= 4200) & (t < 5000))
    trk = (t >= 1100) & (t < 3500)
    err[stab, 0] = 0.001 * alt[stab]
    derr[stab, 0] = 0.002 * alt[stab]
    err[trk, 1] = 0.01 * alt[trk]
    err[(t >= 100) & (t < 240), 1] = 0.15
    err[t == 3700.0, 2] = 0.25
    tau_cmd = np.zeros((n, 3))
    tau_cmd[np.arange(n) % 10 == 0, 0] = 1.0            # 10 % of the frames at the limit
    h = np.tile([10.0, -37.8, 5.0], (n, 1))
    eta = np.zeros((n, 10))
    eta[5, 3] = -0.02
    e_d = np.tile(np.radians([40.0, -40.0, 20.0]), (n, 1))
    de_d = np.zeros((n, 3))
    return {'t': t, 'e': e_d + np.radians(err), 'e_d': e_d, 'de': np.radians(derr),
            'de_d': de_d, 'tau_cmd': tau_cmd, 'tau': np.clip(tau_cmd, -1.0, 1.0), 'h': h,
            'eta': eta, 'est_err_deg': np.full(n, 0.002), 'w_bo': np.zeros((n, 3))}


def test_metrics_by_hand():
    m = paper001.metrics(_series())
    assert m['stab_angle_3sigma_deg'] == pytest.approx([0.003, 0.0, 0.0], abs=1e-9)
    assert m['stab_rate_3sigma_deg_s'] == pytest.approx([0.006, 0.0, 0.0], abs=1e-9)
    assert m['track_angle_3sigma_deg'] == pytest.approx([0.0, 0.03, 0.0], abs=1e-9)
    assert m['error_at_200s_deg'] == pytest.approx([0.0, 0.15, 0.0], abs=1e-9)
    assert m['back_within_0.1deg_after_200s_s'] == pytest.approx(40.0)
    assert m['error_at_3700s_deg'] == pytest.approx([0.0, 0.0, 0.25], abs=1e-9)
    assert m['back_within_0.1deg_after_3700s_s'] == pytest.approx(0.2)
    assert m['max_abs_h_Nms'] == [10.0, 37.8, 5.0]
    assert m['max_abs_wheel_torque_Nm'] == [1.0, 0.0, 0.0]
    assert m['torque_at_limit_fraction'] == pytest.approx(0.1, abs=1e-4)   # 2501 of 25001
    assert m['max_abs_eta'] == 0.02 and m['estimate_error_median_deg'] == 0.002
    assert m['torque_limit_episodes_start_s'][:2] == [0.0, 2.0]
    rows = {name: (measured, ok) for name, _, measured, ok in paper001.rows(m)}
    assert rows['stabilisation angle 3-sigma, x/y/z'] == ('0.0030 / 0.0000 / 0.0000 deg', True)
    assert rows['stabilisation rate 3-sigma, x/y/z'][1] is False          # 0.006 > 0.004
    assert rows['tracking error 3-sigma, x/y/z'][1] is False              # 0.03 > 0.02
    assert rows['error at the end of the first maneuver (200 s)'][1] is True    # 0.15 < 0.2
    assert rows['error at the end of the second maneuver (3700 s)'][1] is False  # 0.25
    assert rows['back within 0.1 deg after 200 s'] == ('40.0 s', True)   # <= 50 s
    assert rows['wheel momentum, max |h|'] == ('10.00 / 37.80 / 5.00 N m s', True)
    assert rows['wheel torque, max |tau|'][1] is True
    assert rows['commanded wheel torque at the limit'] == ('10 % of frames', None)


def test_never_back_within_the_band():
    r = _series()
    r['e'][(r['t'] >= 3700.0), 2] += math.radians(0.5)       # 0.5 deg to the end
    m = paper001.metrics(r)
    assert m['back_within_0.1deg_after_3700s_s'] is None
    rows = {name: (measured, ok) for name, _, measured, ok in paper001.rows(m)}
    assert rows['back within 0.1 deg after 3700 s'] == ('never', False)


def test_a_short_run_cannot_check_the_windows():
    m = paper001.metrics(_series(150.0))
    assert 'stab_angle_3sigma_deg' not in m and 'error_at_200s_deg' not in m
    rows = paper001.rows(m)
    nc = [r for r in rows if isinstance(r[3], NotComparable)]
    assert len(nc) == 7 and all('the run ends at 150 s' in r[3].reason for r in nc)
    assert not any(r[3] for r in nc)


def _report(tmp_path, name, duration_s, capsys):
    from adcs_nodes.tools.cli import main
    from adcs_nodes.tools.reproductions import expectations_for
    from adcs_nodes.tools.scenario import load_scenario
    from sim_node.engine import run_plain
    bag = str(tmp_path / name)
    sc = load_scenario(os.path.join(ROOT, 'scenarios', f'{name}.yaml'))
    assert run_plain(sc, duration_s, bag, progress=False).exit_code == 0
    capsys.readouterr()
    assert main(['report', bag, '--out', str(tmp_path / 'report')]) == 0
    text = capsys.readouterr().out
    got, rows = expectations_for(bag)
    assert got == name and rows
    for line in table_lines(rows):
        assert line in text, line
    return text, rows


def test_adcs_report_prints_paper001_table(tmp_path, capsys):
    text, rows = _report(tmp_path, 'paper001_mpi', 20.0, capsys)
    assert '| stabilisation angle 3-sigma, x/y/z | 0.005 deg | - | not comparable: the run ' \
        'ends at 20 s, before 500-1000 s |' in text
    verdicts = {name: ok for name, _, _, ok in rows}
    assert verdicts['wheel momentum, max |h|'] is True
    assert verdicts['wheel torque, max |tau|'] is True
    for png in ('attitude_error.png', 'wheel_momentum.png', 'modal_amplitudes.png'):
        assert os.path.getsize(tmp_path / 'report' / png) > 0      # the paper's figures
