"""Paper 001's figures from a series (adcs_nodes.tools.analyse.papers.paper001.plots): one PNG per
panel,
a real image each (PNG signature), from a synthetic two-frame series."""
import numpy as np

from adcs_nodes.tools.analyse.papers.paper001 import plots


def test_plots_write_one_png_per_panel(tmp_path):
    t = np.array([0.0, 0.2, 0.4])
    three = np.zeros((3, 3))
    r = {'t': t, 'e': three + 0.01, 'e_d': three, 'de': three, 'de_d': three, 'tau': three,
         'h': three, 'eta': np.zeros((3, 10))}
    paths = plots(r, str(tmp_path / 'figs'))
    assert [p.rsplit('/', 1)[1] for p in paths] == [
        'attitude_error.png', 'rate_error.png', 'wheel_torque.png', 'wheel_momentum.png',
        'modal_amplitudes.png']
    for p in paths:
        with open(p, 'rb') as fh:
            assert fh.read(8) == b'\x89PNG\r\n\x1a\n'
