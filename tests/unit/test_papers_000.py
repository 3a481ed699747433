"""Paper 000's table (adcs_nodes.tools.analyse.papers.paper000): metrics on synthetic series whose
answers are computed by hand, the not-comparable rows of a short run, and ``adcs report`` of a
short plain-engine bag printing the table (the rows ``make reproduce`` prints)."""
import math
import os

import numpy as np
import pytest

from adcs_nodes.tools.analyse import metrics
from adcs_nodes.tools.analyse.papers import INFO, NotComparable, paper000, table_lines

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
T = 6000.0          # orbit period of the synthetic runs [s]


def _verdicts(rows):
    return {name: ok for name, _, _, ok in rows}


def test_estimation_converges_at_the_first_sample_below_2_deg_for_good():
    t = np.arange(0.0, T + 1.0, 100.0)                  # 0, 100, ..., 6000 s
    e = np.where(t < 1250.0, 40.0, 1.0)                 # below 2 deg from t = 1300 s
    e[t == 4000.0] = 1.9                                 # still inside: no exit
    rate = np.full(t.shape, 0.01)
    m = paper000.estimation_metrics(t, e, rate, T)
    assert m['converged_s'] == 1300.0
    # T/2..T: samples 3000..6000 (31), all 1.0 but one 1.9: median 1.0
    assert m['window_samples'] == 31 and m['median_deg'] == 1.0
    assert m['rate_median_deg_s'] == pytest.approx(0.01)
    v = _verdicts(paper000.estimation_rows(m))
    assert v['time to converge (attitude error < 2 deg for good)'] is True   # 0.22 T <= T/2
    assert v['attitude error, median over T/2..T'] is True
    late = paper000.estimation_metrics(t, np.where(t < 3500.0, 40.0, 1.0), rate, T)
    assert late['converged_s'] == 3500.0
    assert _verdicts(paper000.estimation_rows(late))[
        'time to converge (attitude error < 2 deg for good)'] is False


def test_a_short_estimation_run_is_not_comparable():
    t = np.arange(0.0, 2001.0, 100.0)                    # ends at T/3
    m = paper000.estimation_metrics(t, np.full(t.shape, 40.0), np.zeros(t.shape), T)
    rows = paper000.estimation_rows(m)
    assert all(isinstance(ok, NotComparable) for _, _, _, ok in rows[:2])
    assert 'before T/2' in rows[0][3].reason and not rows[0][3]     # never a pass
    assert [ok for *_, ok in rows[2:]] == [INFO, INFO]


def test_control_metrics_dipole_use_and_hold_estimate_by_hand():
    t = np.arange(0.0, 6 * T + 1.0, 100.0)
    angle = np.where(t < 2 * T, 90.0, 1.0)               # captured at 2 T, held at 1 deg
    dip = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [60.0, 0.0, 0.0]])
    est_t = np.array([0.0, 4 * T, 5 * T, 6 * T])
    est_e = np.array([50.0, 0.2, 0.4, 0.9])
    m = paper000.control_metrics(t, angle, T, dip, [60.0, 60.0, 60.0], est_t, est_e)
    assert m['dipole_mean_Am2'] == pytest.approx((0.0 + 5.0 + 60.0) / 3)
    assert m['dipole_saturated_fraction'] == pytest.approx(1 / 3)
    assert m['est_median_deg'] == pytest.approx(0.4)     # median of 0.2, 0.4, 0.9 (t >= 4 T)
    assert m['capture_orbits'] == pytest.approx(2.0) and m['hold_rms_deg'] == 1.0
    assert paper000.dipole_text(m) == '21.7 A m^2, 33 %'
    v = _verdicts(paper000.control_rows(m, m['est_median_deg'], paper000.dipole_text(m)))
    assert v['capture: enters 5 deg, then stays within 10 deg'] is True
    assert v['hold accuracy, angle to orbit frame from 4 orbits to the end'] is True


def test_a_control_run_shorter_than_4_orbits():
    t = np.arange(0.0, 1.5 * T, 100.0)
    tumbling = metrics.run_metrics(t, np.full(t.shape, 90.0), T)
    tumbling['t_end_s'] = float(t[-1])
    rows = paper000.control_rows(tumbling, None, '-')
    cap, hold = rows[0][3], rows[1][3]
    assert isinstance(cap, NotComparable) and 'before the 4-orbit deadline' in cap.reason
    assert isinstance(hold, NotComparable) and 'no sample after 4 orbits' in hold.reason
    captured = metrics.run_metrics(t, np.where(t < T, 90.0, 1.0), T)
    assert paper000.control_rows(captured, None, '-')[0][3] is True     # in 1 orbit: a pass
    stress = paper000.control_rows(tumbling, None, '-', claim=False)
    assert all(ok is INFO for *_, ok in stress)


def test_misalignment_vector_has_the_asked_magnitude():
    for deg in (0.0, 0.5, 2.0):
        assert np.linalg.norm(paper000.misalignment_vector(deg)) == pytest.approx(deg)
    d = np.array(paper000.misalignment_vector(1.0))
    assert d @ np.array([0.6, -0.6, 0.5]) == pytest.approx(math.sqrt(0.97))  # same direction


def _report(tmp_path, name, duration_s, capsys):
    """``adcs report`` of a short plain-engine bag: (printed text, rows)."""
    from adcs_nodes.tools.cli import main
    from adcs_nodes.tools.analyse.reproductions import expectations_for
    from adcs_nodes.scenario import load_scenario
    from adcs_nodes.tools.run.plain import run_plain
    bag = str(tmp_path / name)
    sc = load_scenario(os.path.join(ROOT, 'scenarios', f'{name}.yaml'))
    assert run_plain(sc, duration_s, bag, progress=False).exit_code == 0
    capsys.readouterr()
    assert main(['report', bag, '--out', str(tmp_path / 'report')]) == 0
    text = capsys.readouterr().out
    got, rows = expectations_for(bag)
    assert got == name and rows
    for line in table_lines(rows):                       # what make reproduce prints
        assert line in text, line
    return text, rows


def test_adcs_report_prints_paper000_control_table(tmp_path, capsys):
    text, rows = _report(tmp_path, 'paper000_control', 200.0, capsys)
    assert '## Paper comparison' in text
    assert '| capture: enters 5 deg, then stays within 10 deg | 3-4 orbits | never | ' \
        'not comparable: the run ends at 0.03 orbits' in text
    assert '0 of 0 comparisons with the paper pass; 5 rows are information' in text
    assert '## Sensitivity of the hold accuracy' in text


def test_adcs_report_prints_paper000_estimation_table(tmp_path, capsys):
    text, rows = _report(tmp_path, 'paper000_estimation', 200.0, capsys)
    assert '| time to converge (attitude error < 2 deg for good) | <= 0.5 orbit |' in text
    assert [r[0] for r in rows] == ['time to converge (attitude error < 2 deg for good)',
                                    'attitude error, median over T/2..T',
                                    'attitude error, 95th percentile over T/2..T',
                                    'rate error, median over T/2..T']
