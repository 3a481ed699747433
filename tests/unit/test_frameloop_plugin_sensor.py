"""A new sensor feeding a new input kind, in four places (issue 34): ``tests/plugins/
zenith_sensor.py`` holds the input record (with its converter), the sensor model, its entry and
the controller that reads it; nothing in the product names it. On the FrameLoop (paper 003's
spacecraft, ideal torque, 0.1 s frames): the sensor publishes every 0.2 s, each sample is the
true zenith (from ``sim/state`` and ``sim/environment``, rotated here with scipy) within its
noise, and the controller's torque is ``k e_z x z`` of the true zenith within the noise on
frames with a fresh sample, zero between them.
"""
import os
import re

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from adcs_nodes.scenario import load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PLUGIN = os.path.join(ROOT, 'tests', 'plugins', 'zenith_sensor.py')
GAIN, NOISE = 0.5, 1e-3


@pytest.fixture(autouse=True)
def _forget_the_plugin():
    """The plugin registers into the process's registry and input records: remove it after
    each test, so other tests of this worker see the built-ins only."""
    from adcs_nodes import inputs, registry
    yield
    registry._ENTRIES['sensor'].pop('zenith_sensor', None)
    registry._ENTRIES['controller'].pop('zenith_pointer', None)
    inputs.BY_NAME.pop('zenith', None)
    if PLUGIN in registry._LOADED:
        registry._LOADED.remove(PLUGIN)


def zenith_scenario(tmp_path):
    """paper003_slew with the zenith sensor (0.2 s) and its controller active from t = 0."""
    with open(os.path.join(ROOT, 'scenarios', 'paper003_slew.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['plugins'] = [PLUGIN]
    sc['sensors']['zenith_sensor'] = {'period_s': 0.2, 'noise_std': NOISE}
    sc['controllers']['zenith_pointer'] = {'gain_Nm': GAIN}
    sc['manager']['initial'] = 'zenith_pointer'
    path = tmp_path / 'zenith.yaml'
    path.write_text(yaml.safe_dump(sc))
    return load_scenario(str(path))


def test_the_plugin_is_the_only_place_that_names_the_sensor():
    names = re.compile(r'zenith_(sensor|pointer|period_s)')
    found = [os.path.join(d, f) for pkg in ('adcs_nodes', 'sim_node')
             for d, _, files in os.walk(os.path.join(ROOT, pkg)) for f in files
             if f.endswith('.py') and names.search(open(os.path.join(d, f)).read())]
    assert found == []


def test_a_plugin_sensor_feeds_its_plugin_controller_on_the_frameloop(tmp_path):
    from sim_node.engine import FrameLoop
    loop = FrameLoop.from_scenario(zenith_scenario(tmp_path), duration_s=6.0)
    truth, zenith, torque, sources = {}, {}, {}, set()
    for frame in loop.run():
        got = dict(frame.outputs)
        r, q = got['sim/environment'].r_eci_m, got['sim/state'].q_eci_body
        truth[frame.t_ns] = Rotation.from_quat(q).inv().apply(r / np.linalg.norm(r))
        if 'sensors/zenith' in got:
            zenith[frame.t_ns] = got['sensors/zenith'].zenith_body
        cmd = got['adcs/actuator_command']
        torque[frame.t_ns] = cmd.torque_body_Nm
        sources.add(cmd.source)
    assert sorted(zenith) == [k * 2 * 10**8 for k in range(31)]          # every 0.2 s
    for t, z in zenith.items():
        assert np.linalg.norm(z - truth[t]) < 6 * NOISE, t
    assert sources == {'zenith_pointer'}
    for t, tau in torque.items():
        if t in zenith:                    # k e_z x z of the true zenith, within the noise
            want = GAIN * np.cross([0.0, 0.0, 1.0], truth[t])
            assert np.linalg.norm(tau - want) < GAIN * 6 * NOISE and np.any(tau), t
        else:
            assert not np.any(tau), t      # no fresh sample: nothing commanded
