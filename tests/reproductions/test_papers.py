"""Full paper reproductions (``make reproduce``): run each paper scenario through the node graph,
print its table (the rows ``adcs report`` prints for the same bag:
:mod:`adcs_nodes.tools.reproductions`), fail on a row that compares with a paper value and
misses. Information rows and claims the run cannot check ("not comparable", with the reason)
are printed and never fail. The paper-like figures of papers 001 and 003 go to
``out/<scenario>/``. Long: excluded from ``make test``.

Tolerances are the papers' own bounds, stated in each paper module
(:mod:`adcs_nodes.tools.papers`); paper 003's settling time and energy within 15 % and 20 %,
fixed before any tuning.
"""
import os

import pytest

from adcs_nodes.tools.reproductions import failed, reproduce

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
pytest.importorskip('rclpy')

SCENARIOS = ['paper000_estimation', 'paper004_yaw', 'paper000_control',
             'paper000_control_misaligned', 'paper001_mpi', 'paper003_slew']


@pytest.mark.slow
@pytest.mark.timeout(3600)
@pytest.mark.parametrize('name', SCENARIOS)
def test_reproduction(name, tmp_path):
    figures = os.path.join(ROOT, 'out', name) if name in ('paper001_mpi', 'paper003_slew') \
        else None
    got, rows = reproduce(os.path.join(ROOT, 'scenarios', f'{name}.yaml'),
                          str(tmp_path / name), engine='graph', figures=figures, cwd=ROOT)
    assert got == name and rows
    missed = failed(rows)
    assert not missed, f'{name}: rows not reproduced: {missed}'
