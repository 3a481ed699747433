"""Paper 004's table (adcs_nodes.tools.analyse.papers.paper004): formula (3) against TRIAD on
synthetic
errors computed by hand, a run that covers one region only, and ``adcs report`` of a short
plain-engine bag printing the table."""
import math
import os

import numpy as np
import pytest

from adcs_nodes.tools.analyse.papers import NotComparable, paper004, table_lines

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
U = np.array([0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0])
EQ3 = np.array([0.1, -0.2, 3.0, 0.5, 0.1, 0.2, -2.0, 0.3])
TRIAD = np.array([0.1, -0.2, 2.8, 0.5, 0.1, 0.2, -1.9, 0.3])


def test_metrics_by_hand():
    m = paper004.metrics(U, EQ3, TRIAD)
    assert m['eq3_max_deg'] == 3.0 and m['triad_max_deg'] == 2.8
    # RMS: sqrt((0.01 + 0.04 + 9 + 0.25 + 0.01 + 0.04 + 4 + 0.09) / 8) = sqrt(13.44 / 8)
    assert m['eq3_rms_deg'] == pytest.approx(math.sqrt(13.44 / 8))
    assert m['triad_rms_deg'] == pytest.approx(math.sqrt((13.44 - 9 - 4 + 7.84 + 3.61) / 8))
    assert m['peak_u_deg'] == 90.0
    assert m['near_max_deg'] == 3.0 and m['far_max_deg'] == 0.5   # near: u = 90 and 270
    rows = {name: (measured, ok) for name, _, measured, ok in paper004.rows(m)}
    assert rows['formula (3) and TRIAD errors close'][1] is True    # 1.296 - 1.219 = 0.077
    assert rows['formula (3) and TRIAD errors close'][0] == 'RMS differ by 0.08 deg'
    assert rows['largest error near u = 90 or 270 deg'][1] is True
    assert rows['yaw error of formula (3): max / RMS'] == ('3.00 / 1.30 deg', None)


def test_far_from_close_and_degrading_elsewhere_fail():
    m = paper004.metrics(U, np.where(U == 0.0, 5.0, 0.1), np.full(U.shape, 0.1))
    rows = {name: ok for name, _, _, ok in paper004.rows(m)}
    assert rows['formula (3) and TRIAD errors close'] is False   # RMS 1.78 vs 0.1
    assert rows['largest error near u = 90 or 270 deg'] is False  # the peak is at u = 0


def test_one_region_only_is_not_comparable():
    u = np.array([0.0, 10.0, 20.0, 30.0])
    m = paper004.metrics(u, np.full(4, 0.2), np.full(4, 0.2))
    assert math.isnan(m['near_max_deg'])
    ok = paper004.rows(m)[3][3]
    assert isinstance(ok, NotComparable) and 'only one of the two regions' in ok.reason


def test_adcs_report_prints_paper004_table(tmp_path, capsys):
    """2000 s: the argument of latitude runs from 0 to about 122 deg, both regions."""
    from adcs_nodes.tools.cli import main
    from adcs_nodes.tools.analyse.reproductions import expectations_for
    from adcs_nodes.scenario import load_scenario
    from adcs_nodes.tools.run.plain import run_plain
    bag = str(tmp_path / 'paper004_yaw')
    sc = load_scenario(os.path.join(ROOT, 'scenarios', 'paper004_yaw.yaml'))
    assert run_plain(sc, 2000.0, bag, progress=False).exit_code == 0
    capsys.readouterr()
    assert main(['report', bag, '--out', str(tmp_path / 'report')]) == 0
    text = capsys.readouterr().out
    name, rows = expectations_for(bag)
    assert name == 'paper004_yaw' and [r[0] for r in rows] == [
        'yaw error of formula (3): max / RMS', 'yaw error of TRIAD: max / RMS',
        'formula (3) and TRIAD errors close', 'largest error near u = 90 or 270 deg']
    for line in table_lines(rows):
        assert line in text, line
    assert rows[2][3] is True and rows[3][3] is True
