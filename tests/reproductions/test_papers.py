"""Full paper reproductions (``make reproduce``): run each paper scenario through the node graph,
print its table (the rows ``adcs report`` prints for the same bag:
:mod:`adcs_nodes.tools.analyse.reproductions`), fail on a row that compares with a paper value and
misses. Information rows and claims the run cannot check ("not comparable", with the reason)
are printed and never fail. The paper-like figures of papers 001 and 003 go to
``out/<scenario>/``. Long: excluded from ``make test``.

Tolerances are the papers' own bounds, stated in each paper module
(:mod:`adcs_nodes.tools.analyse.papers`); paper 003's settling time and energy within 15 % and 20
%,
fixed before any tuning.
"""
import os

import pytest

from adcs_nodes.tools.analyse.reproductions import failed, reproduce

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
pytest.importorskip('rclpy')

SCENARIOS = ['paper000_estimation', 'paper004_yaw', 'paper000_control',
             'paper000_control_misaligned', 'paper001_mpi', 'paper001_mpi_two_wings',
             'paper003_slew']
#: Paper 001 beyond the paper: the MPI variant (a departure, docs/paper001.md) on the two-wing
#: robustness case; its rows are information (the paper claims nothing for it).
PAPER001_VARIANT = ('controllers.mpi.hold_horizon_s=0.4',
                    'controllers.mpi.reference_time=t0_plus_tau')
FIGURES = ('paper001_mpi', 'paper001_mpi_two_wings', 'paper003_slew')


@pytest.mark.slow
@pytest.mark.timeout(3600)
@pytest.mark.parametrize('name', SCENARIOS)
def test_reproduction(name, tmp_path):
    figures = os.path.join(ROOT, 'out', name) if name in FIGURES else None
    got, rows = reproduce(os.path.join(ROOT, 'scenarios', f'{name}.yaml'),
                          str(tmp_path / name), engine='graph', figures=figures, cwd=ROOT)
    assert got == name and rows
    missed = failed(rows)
    assert not missed, f'{name}: rows not reproduced: {missed}'


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_paper001_variant_on_two_wings(tmp_path):
    """The variant's table: information rows, each saying whether the paper's bound is met;
    the variant is named in a row. Our claim for it (not the paper's): the stabilisation rows
    hold with two wings."""
    name = 'paper001_mpi_two_wings'
    got, rows = reproduce(os.path.join(ROOT, 'scenarios', f'{name}.yaml'),
                          str(tmp_path / name), engine='graph',
                          figures=os.path.join(ROOT, 'out', f'{name}_variant'), cwd=ROOT,
                          sets=PAPER001_VARIANT)
    assert got == name and rows and not failed(rows)
    by = {quantity: measured for quantity, _, measured, _ in rows}
    assert 'horizon 0.4 s' in by['MPI departures from the paper (beyond the paper)']
    for row in ('stabilisation angle 3-sigma, x/y/z', 'stabilisation rate 3-sigma, x/y/z'):
        assert by[row].endswith("within the paper's bound"), (row, by[row])
