"""report.html (adcs_nodes/tools/analyse/report_html.py) of short plain-engine bags (written in
process by
the FrameLoop's BagSink: no ROS, no process): one self-contained page (inline PNGs, no
network, no script) with the timeline, the switches and fallbacks with their reasons, the
faults, the wheels, the dipole, the estimator against the truth with its 3-sigma bound, and
the paper table when the report's metrics.json has one; the interpolation of the truth.
"""
import base64
import json
import math
import re

import numpy as np
import pytest

from adcs_nodes.core import attitude as att
from adcs_nodes.tools.analyse.metrics import slerp_at
from adcs_nodes.tools.analyse.report_html import write_report_html
from frameloop_run import raw, validated
from adcs_nodes.tools.run.plain import run_plain

PNG = b'\x89PNG\r\n\x1a\n'


def _mission_variant():
    """The demo mission cut to 90 s: MPI from the start on a slowly turning body, its node
    killed at 5 s (stale: fallback to B-dot), the star tracker NaN 20-30 s, a scheduled fuzzy
    slew at 40 s and MPI again at 70 s."""
    sc = raw('demo_mission')
    sc['duration_s'] = 90.0
    sc['initial'] = {'q_orbit_body_xyzw': [0.0, 0.0, 0.0, 1.0],
                     'omega_body_orbit_body_deg_s': [0.3, -0.2, 0.25]}
    sc['manager'] = {'safe': 'bdot', 'initial': 'mpi',
                     'schedule': [{'t_s': 40.0, 'controller': 'fuzzy'},
                                  {'t_s': 70.0, 'controller': 'mpi'}]}
    q10 = att.from_axis_angle([1.0, 0.0, 0.0], math.radians(10.0)).tolist()
    sc['guidance']['profile'] = [{'t_s': 0.0, 'type': 'hold'},
                                 {'t_s': 40.0, 'type': 'hold', 'q_xyzw': q10}]
    sc['faults'] = [{'at_s': 5.0, 'kind': 'node_killed', 'target': 'mpi_controller'},
                    {'at_s': 20.0, 'kind': 'nan', 'target': 'star_tracker',
                     'params': {'duration_s': 10.0}}]
    return sc


@pytest.fixture(scope='module')
def mission_bag(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('html')
    bag = str(tmp / 'bag')
    result = run_plain(validated(tmp, _mission_variant(), 'variant'), record=bag,
                       progress=False)
    assert result.exit_code == 3             # degraded: the fallback, as the demo
    return bag


def _images(page):
    return [base64.b64decode(m) for m in re.findall(r'src="data:image/png;base64,([^"]+)"',
                                                    page)]


def test_the_page_is_self_contained_with_every_section(mission_bag, tmp_path):
    path = write_report_html(mission_bag, tmp_path / 'out')
    page = open(path, encoding='utf-8').read()
    assert page.startswith('<!DOCTYPE html>') and page.rstrip().endswith('</html>')
    for forbidden in ('http://', 'https://', '<script', '<link', 'src="/', "src='"):
        assert forbidden not in page                 # nothing to fetch, nothing to run
    images = _images(page)
    assert len(images) == 4 and all(img.startswith(PNG) for img in images)
    for title in ('Timeline', 'Switches and fallbacks', 'Faults', 'Reaction wheels',
                  'Magnetorquer dipole', 'Estimator against the truth', 'Paper comparison'):
        assert f'<h2>{title}</h2>' in page
    assert 'Not shown' not in page
    overview = (tmp_path / 'out' / 'overview.png').read_bytes()
    assert overview.startswith(PNG) and overview == images[0]


def test_switches_fallbacks_and_faults_with_their_reasons(mission_bag, tmp_path):
    page = open(write_report_html(mission_bag, tmp_path), encoding='utf-8').read()
    rows = re.findall(r'<tr><td>([^<]*)</td><td>([^<]*)</td><td>([^<]*)</td></tr>', page)
    by_what = {what: (t, why) for t, what, why in rows}
    assert by_what['start: mpi'][1] == 'initial controller'
    assert by_what['switch mpi -&gt; fuzzy'] == ('40 s', 'scheduled (manager.schedule)')
    assert by_what['switch fuzzy -&gt; mpi'] == ('70 s', 'scheduled (manager.schedule)')
    t_fb, why = next((t, why) for t, what, why in rows if what == 'fallback from mpi')
    assert 5.0 <= float(t_fb.split()[0]) < 20.0
    assert why.startswith('mpi: stale') and 'fallback to bdot' in why
    assert any(w.startswith('commands from bdot (not the active mpi)') for w in by_what)
    faults = [(t, f, st) for t, f, st in rows if st in ('active', 'cleared')]
    assert faults == [('5 s', 'node_killed mpi_controller', 'active'),
                      ('20 s', 'nan star_tracker', 'active'),
                      ('30 s', 'nan star_tracker', 'cleared')]
    assert 'rejected samples: 10' in page
    assert 'no paper table for this run' in page


def test_the_paper_table_comes_from_the_reports_metrics(mission_bag, tmp_path):
    rows = [{'name': 'settling time', 'paper': '25.73 s', 'measured': '26.8 s', 'pass': True,
             'verdict': 'PASS'},
            {'name': 'ratio', 'paper': '1.5x', 'measured': '0.65x', 'pass': None,
             'verdict': 'not comparable: <why>'}]
    (tmp_path / 'metrics.json').write_text(json.dumps({'expectations': rows}))
    page = open(write_report_html(mission_bag, tmp_path), encoding='utf-8').read()
    assert ('<tr><td>settling time</td><td>25.73 s</td><td>26.8 s</td>'
            '<td><span class="pass">PASS</span></td></tr>') in page
    assert 'not comparable: &lt;why&gt;' in page       # escaped


def test_a_bag_with_the_truth_only_says_what_is_not_shown(tmp_path):
    sc = raw('free_tumble')
    bag = str(tmp_path / 'bag')
    run_plain(validated(tmp_path, sc, 'tumble'), duration_s=20.0, record=bag, progress=False)
    page = open(write_report_html(bag, tmp_path / 'out'), encoding='utf-8').read()
    assert len(_images(page)) == 1                     # the timeline (rates) only
    shown = page[page.index('<h2>Not shown</h2>'):]
    for what in ('reaction wheels', 'magnetorquer dipole', 'estimator'):
        assert what in shown
    assert 'no fault announced' in page


def test_slerp_interpolates_the_truth_at_a_stamp_between_samples():
    axis = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    t_src = np.array([0.0, 1.0, 2.0])
    q_src = np.array([att.from_axis_angle(axis, 0.1 * k) for k in range(3)])
    q_src[2] *= -1.0                                   # the same attitude, other sign
    got = slerp_at(t_src, q_src, np.array([0.25, 1.5, 2.0, 5.0, -1.0]))
    for q, angle in zip(got, (0.025, 0.15, 0.2, 0.2, 0.0)):
        want = att.from_axis_angle(axis, angle)
        assert att.angle_between(q, want) < 1e-12
