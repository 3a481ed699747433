"""report.html as a person sees it: opened in headless Chromium (Debian package ``chromium``;
``.ci/run`` installs it on CI), the page loads with no console error, the plots are there in
the DOM and on the screenshot.

The bag is a short plain-engine run of the demo mission (written in process); Chromium is
started with a fresh profile, no network services (``--disable-background-networking``,
``--disable-component-update``, ``--disable-sync``), on a ``file://`` URL. Console messages
come from ``--enable-logging=stderr --v=0`` (``INFO:CONSOLE`` lines); a control page with a
script error proves that they are caught.

It starts processes (Chromium), no ROS graph: graph tier, marked ``parallel``.
"""
import os
import re
import shutil
import subprocess

import numpy as np
import pytest
import yaml

from adcs_nodes.tools.analyse.report_html import KNOWN_COLOURS, write_report_html
from adcs_nodes.scenario import load_scenario
from adcs_nodes.tools.run.plain import run_plain

pytestmark = pytest.mark.parallel

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CHROMIUM = shutil.which('chromium')
WINDOW = (1200, 2400)
FLAGS = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
         '--disable-component-update', '--disable-sync', '--no-first-run',
         '--enable-logging=stderr', '--v=0', f'--window-size={WINDOW[0]},{WINDOW[1]}']


@pytest.fixture(scope='module')
def chromium():
    if CHROMIUM is None:
        if os.environ.get('CI'):
            pytest.fail('chromium is not installed on CI (.ci/run installs the Debian package '
                        'chromium before make test)')
        pytest.skip('chromium is not installed (Debian package chromium: apt-get install -y '
                    'chromium; .ci/run installs it on CI)')
    return CHROMIUM


def _browser(exe, tmp_path, url, *extra, timeout_s=90.0):
    """Run headless Chromium on ``url`` with a fresh profile: (stdout, stderr)."""
    profile = tmp_path / f'profile-{len(list(tmp_path.iterdir()))}'
    proc = subprocess.run([exe, *FLAGS, f'--user-data-dir={profile}', *extra, url],
                          capture_output=True, text=True, timeout=timeout_s)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout, proc.stderr


def _console(stderr):
    """The page's console messages and load failures in Chromium's log."""
    return [line for line in stderr.splitlines()
            if 'CONSOLE' in line or 'Uncaught' in line or 'Failed to load resource' in line]


@pytest.fixture(scope='module')
def report(tmp_path_factory):
    """report.html of a 90 s plain run of the demo mission (MPI, a scheduled fuzzy slew, the
    star tracker NaN for 10 s, wheel_x stuck (MPI flies on), MPI killed at 75 s: a fallback)."""
    tmp = tmp_path_factory.mktemp('page')
    with open(os.path.join(ROOT, 'scenarios', 'demo_mission.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['duration_s'] = 90.0
    sc['initial'] = {'q_orbit_body_xyzw': [0.0, 0.0, 0.0, 1.0],
                     'omega_body_orbit_body_deg_s': [0.3, -0.2, 0.25]}
    sc['manager'] = {'safe': 'bdot', 'initial': 'mpi',
                     'schedule': [{'t_s': 40.0, 'controller': 'fuzzy'},
                                  {'t_s': 70.0, 'controller': 'mpi'}]}
    sc['guidance']['profile'] = [{'t_s': 0.0, 'type': 'hold'},
                                 {'t_s': 40.0, 'type': 'hold',
                                  'q_xyzw': [0.0871557, 0.0, 0.0, 0.9961947]}]
    sc['faults'] = [{'at_s': 5.0, 'kind': 'wheel_stuck', 'target': 'wheel_x'},
                    {'at_s': 20.0, 'kind': 'nan', 'target': 'star_tracker',
                     'params': {'duration_s': 10.0}},
                    {'at_s': 75.0, 'kind': 'node_killed', 'target': 'mpi_controller'}]
    path = tmp / 'variant.yaml'
    path.write_text(yaml.safe_dump(sc))
    bag = str(tmp / 'bag')
    run_plain(load_scenario(str(path)), record=bag, progress=False)
    return write_report_html(bag, tmp / 'report')


def test_the_console_check_catches_a_script_error(chromium, tmp_path):
    bad = tmp_path / 'bad.html'
    bad.write_text('<!DOCTYPE html><html><body><script>console.error("boom"); '
                   'undefinedFunction();</script></body></html>')
    _, err = _browser(chromium, tmp_path, bad.as_uri(), '--dump-dom')
    found = ' '.join(_console(err))
    assert 'boom' in found and 'undefinedFunction' in found


def test_the_page_loads_without_console_errors_with_its_plots(chromium, report, tmp_path):
    dom, err = _browser(chromium, tmp_path, 'file://' + os.path.abspath(report), '--dump-dom')
    assert _console(err) == []
    assert '<h1>ADCS run: demo_mission</h1>' in dom
    images = re.findall(r'<img class="plot" alt="([^"]+)" src="data:image/png;base64,', dom)
    assert len(images) == 4, images
    assert 'timeline' in images[0] and 'estimator' in images[3]
    assert 'fallback from mpi' in dom and 'wheel_stuck wheel_x' in dom


def test_the_screenshot_shows_the_plots(chromium, report, tmp_path):
    from matplotlib.image import imread
    shot = tmp_path / 'shot.png'
    _, err = _browser(chromium, tmp_path, 'file://' + os.path.abspath(report),
                      f'--screenshot={shot}')
    assert _console(err) == []
    img = imread(str(shot))
    assert img.shape[:2] == (WINDOW[1], WINDOW[0])
    rgb = np.round(img[:, :, :3] * 255).astype(int)

    def pixels(hex_colour):
        want = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)])
        return int(np.sum(np.all(np.abs(rgb - want) <= 3, axis=2)))
    # the timeline's bands, drawn in the controllers' colours, are on the screen
    assert pixels(KNOWN_COLOURS['mpi']) > 2000
    assert pixels(KNOWN_COLOURS['fuzzy']) > 500
    assert pixels(KNOWN_COLOURS['bdot']) > 500
    # and the page is more than text: a good share of the window is drawn, not white
    assert np.mean(np.any(rgb < 240, axis=2)) > 0.05
