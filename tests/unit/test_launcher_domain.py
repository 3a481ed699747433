"""``adcs run --domain N`` (issue 23): a driver that already runs on a domain can be joined; the
launcher checks the id and says what a driver needs to join when a sensor is external."""
import os

import pytest

from adcs_nodes.tools.run.launcher import DDS_ENV_KEYS, LaunchError, Launcher, child_env
from adcs_nodes.scenario import load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.mark.parametrize('bad', [-1, 233, 1.5, '7'])
def test_a_domain_outside_0_232_is_refused(bad):
    sc = load_scenario(os.path.join(ROOT, 'scenarios', 'free_tumble.yaml'))
    with pytest.raises(LaunchError, match='--domain'):
        Launcher(sc, duration_s=10.0, progress=False, domain=bad)


def test_the_driver_environment_names_the_domain_and_discovery():
    env = child_env(42)
    line = ' '.join(f'{k}={env[k]}' for k in DDS_ENV_KEYS if env.get(k))
    assert 'ROS_DOMAIN_ID=42' in line and 'FASTDDS_DEFAULT_PROFILES_FILE=' in line
    # the profile binds discovery to loopback; LOCALHOST would make rmw_fastrtps replace its
    # transports with UDP plus shared memory
    assert 'ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT' in line


def test_the_project_profile_keeps_its_discovery_also_when_inherited(monkeypatch):
    """A process that already runs with the project's profile (the launcher after taking its
    run's settings, a test worker) gives its children the same settings; a user's own profile
    keeps LOCALHOST discovery."""
    from adcs_nodes.tools.run.launcher import FASTDDS_PROFILES
    monkeypatch.setenv('FASTDDS_DEFAULT_PROFILES_FILE', FASTDDS_PROFILES)
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    assert child_env(7)['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SYSTEM_DEFAULT'
    monkeypatch.setenv('FASTDDS_DEFAULT_PROFILES_FILE', '/somewhere/mine.xml')
    env = child_env(7)
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert env['FASTDDS_DEFAULT_PROFILES_FILE'] == '/somewhere/mine.xml'
