"""A plugin controller may read any input kind (issue 19): ``tests/plugins/gyro_damper.py``
declares the gyro and the star tracker, which no built-in controller reads. On the FrameLoop,
paper 003's spacecraft (ideal body torque) with a gyro and a star tracker added and an initial
tumble: the damper gets both inputs and the kinetic energy decays at least as fast as the
analytic bound of pure damping.

Independent truth: with ``tau = -k omega`` (unsaturated), ``dE/dt = omega . tau = -k |omega|^2
<= -(2 k / I_max) E``, so ``E(T) <= E(0) exp(-2 k T / I_max)``; gravity gradient adds at most
a few 1e-6 N m here, far below the damping torque.
"""
import math
import os

import numpy as np
import pytest
import yaml

from adcs_nodes.msgs.fields import vec3
from frameloop_run import messages
from adcs_nodes.scenario import load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PLUGIN = os.path.join(ROOT, 'tests', 'plugins', 'gyro_damper.py')
INERTIA = np.diag([250.0, 200.0, 180.0])
GAIN = 20.0


@pytest.fixture(autouse=True)
def _forget_the_plugin():
    """The plugin registers into the process's registry: remove it after each test, so the
    schema (docs/scenarios.md) other tests of this worker generate has the built-ins only."""
    from adcs_nodes import registry
    yield
    registry._ENTRIES['controller'].pop('gyro_damper', None)
    if PLUGIN in registry._LOADED:
        registry._LOADED.remove(PLUGIN)


def damper_scenario(tmp_path):
    """paper003_slew with a gyro, a star tracker and the damper active from t = 0."""
    with open(os.path.join(ROOT, 'scenarios', 'paper003_slew.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['plugins'] = [PLUGIN]
    sc['sensors']['gyro'] = {'period_s': 0.1}
    sc['sensors']['star_tracker'] = {'period_s': 0.1}
    sc['initial']['omega_body_orbit_body_deg_s'] = [2.0, -1.5, 1.0]
    sc['controllers']['gyro_damper'] = {'gain_Nms': GAIN, 'max_torque_Nm': 1.0}
    sc['manager']['initial'] = 'gyro_damper'
    path = tmp_path / 'damper.yaml'
    path.write_text(yaml.safe_dump(sc))
    return load_scenario(str(path))


def energy(omega):
    return 0.5 * float(omega @ INERTIA @ omega)


def test_a_gyro_and_star_tracker_plugin_controller_runs_on_the_frameloop(tmp_path):
    from sim_node.engine import FrameLoop
    loop = FrameLoop.from_scenario(damper_scenario(tmp_path), duration_s=30.0)
    omegas, sources = [], set()
    for frame in loop.run():
        for topic, msg in messages(frame, loop):
            if topic == 'sim/state':
                omegas.append(vec3(msg.omega_body_eci_body))
            elif topic == 'adcs/actuator_command':
                sources.add(msg.source)
    assert sources == {'gyro_damper'}
    e0, e_end = energy(omegas[0]), energy(omegas[-1])
    # |tau| = k |omega| <= 20 * 0.045 = 0.9 N m: never saturated, the bound holds
    assert GAIN * np.abs(omegas[0]).max() < 1.0
    bound = e0 * math.exp(-2.0 * GAIN * 30.0 / 250.0)
    assert e_end <= bound * 1.01, (e0, e_end, bound)
    assert e_end > 0.0
    # a damper that never got the star tracker would command nothing: E would not move
    assert e_end < 0.2 * e0


def test_without_the_star_tracker_the_plugin_commands_nothing(tmp_path):
    """The same run with the star tracker's input removed from the graph is refused at
    validation (the plugin needs sensors.star_tracker): the wiring comes from the records."""
    from adcs_nodes.scenario import ScenarioError
    sc = damper_scenario(tmp_path)
    raw = {k: v for k, v in sc.items() if not k.startswith('_')}
    del raw['sensors']['star_tracker']
    path = tmp_path / 'no_star.yaml'
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(ScenarioError, match='star_tracker'):
        load_scenario(str(path))
