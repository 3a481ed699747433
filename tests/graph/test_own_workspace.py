"""Your own colcon workspace, as a ROS 2 user builds it (issue 37, item 4; README, ROS 2).

The packages are copied out of the repository into a new workspace and built with plain
``colcon build`` in a clean environment that has only the README's set-up
(``source ros2_ws/setup.bash``): no ``run.sh``, no ``AMENT_PREFIX_PATH`` of ours. Truth: the
repository's own files (which scenarios exist) and what a user sees (exit codes, messages).
"""
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SETUP = ROOT / 'ros2_ws' / 'setup.bash'
PACKAGES = ('adcs_msgs', 'adcs_nodes', 'sim_node')


def _bash(script: str, cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    """``script`` after the documented set-up, in an environment with nothing else of ROS."""
    env = {'HOME': os.environ.get('HOME', '/root'), 'PATH': '/usr/bin:/bin',
           'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'MPLBACKEND': 'Agg'}
    return subprocess.run(['bash', '-c', f'source {SETUP} && {script}'], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def _copy(ws: Path, packages, follow_links: bool) -> None:
    for pkg in packages:
        shutil.copytree(ROOT / pkg, ws / 'src' / pkg, symlinks=not follow_links,
                        ignore=shutil.ignore_patterns('__pycache__', '*.nb[ic]'))


@pytest.mark.parallel
def test_a_plain_copy_says_the_scenarios_link_broke(tmp_path):
    """``cp -r`` keeps ``adcs_nodes/scenarios`` a link to ``../scenarios``: the build stops and
    says so (it installed 0 scenarios without a word before)."""
    _copy(tmp_path, ['adcs_nodes'], follow_links=False)
    assert (tmp_path / 'src' / 'adcs_nodes' / 'scenarios').is_symlink()
    out = _bash('colcon build', tmp_path, timeout=120)
    assert out.returncode != 0
    assert 'no scenarios in' in out.stdout + out.stderr
    assert 'cp -rL' in out.stdout + out.stderr


@pytest.mark.long   # builds adcs_msgs (about 45 s, 35 s of CPU); the link test above is fast
def test_a_copied_workspace_builds_installs_the_scenarios_and_runs(tmp_path):
    _copy(tmp_path, PACKAGES, follow_links=True)
    built = _bash('colcon build', tmp_path)
    assert built.returncode == 0, built.stdout[-3000:] + built.stderr[-3000:]
    share = tmp_path / 'install' / 'adcs_nodes' / 'share' / 'adcs_nodes'
    assert sorted(p.name for p in (share / 'scenarios').glob('*.yaml')) == sorted(
        p.name for p in (ROOT / 'scenarios').glob('*.yaml'))
    assert (share / 'launch' / 'adcs.launch.py').is_file()
    # the copy's own modules and interfaces, and its `adcs` on a bag of its own
    bag = tmp_path / 'bag'
    ran = _bash('source install/local_setup.bash && python -c "import adcs_nodes, sim_node, '
                'adcs_msgs.msg as m; print(adcs_nodes.__file__, sim_node.__file__, m.__file__)"'
                ' && install/adcs_nodes/lib/adcs_nodes/adcs run '
                f'{share}/scenarios/free_tumble.yaml --engine plain --duration 20 '
                f'--record {bag} --quiet', tmp_path, timeout=300)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    paths = ran.stdout.split()[:3]
    assert all(p.startswith(str(tmp_path)) for p in paths), paths
    assert (bag / 'metadata.yaml').is_file()
    # colcon test here: stops and says why (the tests need the repository), not "0 tests"
    tested = _bash('colcon test --packages-select adcs_nodes', tmp_path, timeout=300)
    log = (tmp_path / 'log' / 'latest_test' / 'adcs_nodes' / 'stdout_stderr.log').read_text()
    assert tested.returncode != 0 and "the project's tests are the repository's" in log


@pytest.mark.long   # collects every test of the repository (about 10 s)
def test_colcon_test_in_ros2_ws_runs_the_projects_tests(tmp_path):
    ws = ROOT / 'ros2_ws'
    tested = _bash(
        f'colcon --log-base {tmp_path}/log test --base-paths src --packages-select adcs_nodes '
        f'--test-result-base {tmp_path}/results --pytest-args -p no:cacheprovider '
        '-k test_distro_from_environment', ws, timeout=300)
    assert tested.returncode == 0, tested.stdout + tested.stderr
    result = (tmp_path / 'results' / 'adcs_nodes' / 'pytest.xml').read_text()
    assert 'tests="0"' not in result and 'failures="0"' in result and 'errors="0"' in result
