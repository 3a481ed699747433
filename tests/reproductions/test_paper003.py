"""Paper 003's study on the FrameLoop (``make reproduce``; marker ``slow``): both readings of
Table 1, the smooth set, no compensation and the reference slew, from
``scenarios/paper003_slew.yaml`` with overrides (``python -m adcs_nodes.tools.analyse.study
table1``).

Tolerances (relative to the paper's values), fixed before any tuning and not changed after:
settling time 15 %, energy 20 % (:data:`adcs_nodes.tools.analyse.papers.paper003.TOLERANCE`). Each
paper number is its own test. The paper's ratios to its reference slew are not comparable (the
paper does not describe that controller): the test checks that the row says so and shows the
ratios against ours. The structural claims (which Table 1 reading settles, the torque limit)
are a separate test. The PNG equivalents of the paper's Figs. 6-9 go to ``out/paper003/``.
"""
import math
import os

import pytest

from adcs_nodes.tools.analyse.papers import NotComparable, paper003
from adcs_nodes.scenario import load_scenario
from adcs_nodes.tools.analyse.study import table1

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_RESULT = {}


def _result():
    if not _RESULT:
        sc = load_scenario(os.path.join(ROOT, 'scenarios', 'paper003_slew.yaml'))
        runs, series = table1(sc)
        rows = paper003.rows(runs['fuzzy (Table 1 reversed)'], runs['reference slew'])
        _RESULT.update(runs=runs, rows={r[0]: r for r in rows})
        print('\n' + paper003.format_runs(runs))
        for path in paper003.figures(series, os.path.join(ROOT, 'out', 'paper003')):
            print(f'  figure: {os.path.relpath(path, ROOT)}')
    return _RESULT


@pytest.mark.slow
def test_paper003_structure():
    runs = _result()['runs']
    rev, lit = runs['fuzzy (Table 1 reversed)'], runs['fuzzy (Table 1 as printed)']
    ref = runs['reference slew']
    assert math.isfinite(rev['settling_s'])          # the reversed reading settles
    assert math.isnan(lit['settling_s'])             # the printed reading does not (80 s)
    # The paper's motivation: without the compensation controller the slew does not settle.
    assert math.isnan(runs['fuzzy (no compensation)']['settling_s'])
    for m in runs.values():
        assert m['max_abs_torque_Nm'] <= 1.0 + 1e-12  # |M_i| <= 1 N m
    assert rev['final_deg'] < 0.1 and ref['final_deg'] < 0.1


@pytest.mark.slow
@pytest.mark.parametrize('quantity', ['settling time (5 % band of phi0)',
                                      'energy (integral of sum |M_i| to settling)'])
def test_paper003_number(quantity):
    _, paper, measured, verdict = _result()['rows'][quantity]
    assert verdict is True, f'{quantity}: ours {measured}, paper {paper}'


@pytest.mark.slow
@pytest.mark.parametrize('quantity', ['faster than the reference slew (T_s ratio)',
                                      'less energy than the reference slew (E ratio)'])
def test_paper003_ratio_is_not_comparable(quantity):
    _, paper, measured, verdict = _result()['rows'][quantity]
    assert isinstance(verdict, NotComparable) and 'not described' in verdict.reason
    assert 'x (reference' in measured, measured
