"""Paper 000's closed-loop rows (adcs_nodes.tools.analyse.papers.paper000, printed by `adcs
report` and
`make reproduce` through adcs_nodes.tools.analyse.reproductions): verdicts only where the paper
has a
number; the metrics come from adcs_nodes.tools.analyse.metrics on a synthetic angle signal."""
import numpy as np

from adcs_nodes.tools.analyse import metrics
from adcs_nodes.tools.analyse.paper000_sensitivity import sensitivity_markdown
from adcs_nodes.tools.analyse.papers import NotComparable, table_lines
from adcs_nodes.tools.analyse.papers.paper000 import INFO, control_rows
from adcs_nodes.tools.analyse.reproductions import failed, table_text

PERIOD = 6000.0


def _rows(e, claim=True):
    t = np.arange(0.0, 6 * PERIOD + 1, 10.0)
    return control_rows(metrics.run_metrics(t, e(t), PERIOD), 0.5, '3.0 A m^2, 1 %', claim)


def test_capture_and_hold_rows_pass_or_fail_on_the_paper_claim_only():
    good = _rows(lambda t: 120.0 * np.exp(-t / 2000.0) + 0.8)        # in 5 deg at ~1.06 T
    verdicts = {name: ok for name, _, _, ok in good}
    assert verdicts['capture: enters 5 deg, then stays within 10 deg'] is True
    assert verdicts['hold accuracy, angle to orbit frame from 4 orbits to the end'] is True
    info = [r for r in good if r[3] is INFO]
    assert {r[0] for r in info} == {'last exit from 5 deg', 'first entry below 5 deg',
                                    'final angle to orbit frame',
                                    'estimation error, median over the hold',
                                    'dipole use: mean |m|, frames with a saturated coil'}
    assert all(r[1] == '(not given)' for r in info)
    late = _rows(lambda t: 120.0 * np.exp(-t / 8000.0) + 0.8)       # in 5 deg at ~4.5 T
    v = {name: ok for name, _, _, ok in late}
    assert v['capture: enters 5 deg, then stays within 10 deg'] is False
    noisy = _rows(lambda t: np.where(t > 3 * PERIOD, 3.0, 90.0))     # captured, held at 3 deg
    v = {name: ok for name, _, _, ok in noisy}
    assert v['capture: enters 5 deg, then stays within 10 deg'] is True
    assert v['hold accuracy, angle to orbit frame from 4 orbits to the end'] is False


def test_stress_rows_are_information_only():
    rows = _rows(lambda t: 120.0 * np.exp(-t / 8000.0) + 0.8, claim=False)
    assert all(ok is INFO for _, _, _, ok in rows)


def test_sensitivity_table_has_one_line_per_case():
    case = {'capture_orbits': 2.5, 'last_exit_orbits': None, 'hold_rms_deg': 1.0,
            'hold_median_deg': 0.8, 'hold_p95_deg': 1.9, 'est_err_median_deg': 0.4,
            'hold_only': {'rms_deg': 0.9, 'median_deg': 0.7, 'p95_deg': 1.5,
                          'est_err_median_deg': 0.3}}
    data = {'scenario': 'paper000_control', 'seed': 21, 'duration_s': 35484.0,
            'hold_only_orbits': 3.0, 'hold_only_from_orbits': 1.0,
            'baseline': {'random_period_s': 0.1, 'misalignment_deg': 0.0},
            'cases': [{'parameter': 'random_period_s', 'value': 0.5, **case},
                      {'parameter': 'misalignment_deg', 'value': 2.0, **case}]}
    text = sensitivity_markdown(data)
    assert '| random torque correlation [s] | 0.5 | 2.50 | never | 1.00 / 0.80 / 1.90 | ' \
        '0.90 / 0.70 / 1.50 | 0.30 |' in text
    assert '| magnetometer misalignment [deg] | 2 |' in text


def test_reproduction_prints_the_report_table_and_fails_only_on_fail_rows():
    rows = [('a', '1', 1.0, True), ('b', '2', 3.0, False), ('c', '(not given)', 4.0, INFO),
            ('d', '1.5x', '0.66x', NotComparable('undescribed reference'))]
    text = table_text('paper003_slew', rows)
    assert text.startswith('paper003_slew: paper vs measured\n')
    for line in table_lines(rows):
        assert line in text
    assert '| d | 1.5x | 0.66x | not comparable: undescribed reference |' in text
    assert '1 of 2 comparisons with the paper pass; 1 rows are information (no paper value); ' \
        '1 not comparable' in text
    assert failed(rows) == [rows[1]]
