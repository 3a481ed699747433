"""Reference eigenaxis slew (paper 003's comparison): limit, equilibrium, rest-to-rest slew.

The slew runs on the FrameLoop (``scenarios/paper003_slew.yaml`` with the reference slew
active, the controllers fed the true state: ``ideal_estimate``)."""
import math
import os

import numpy as np
import pytest

from adcs_nodes.core import attitude
from adcs_nodes.core.control import ControlInputs, Estimate, Target
from adcs_nodes.core.control.reference_slew import ReferenceSlewController
from adcs_nodes.tools.analyse.papers import paper003
from adcs_nodes.scenario import load_scenario
from adcs_nodes.tools.analyse.study import run_topics

J = np.diag([250.0, 200.0, 180.0])
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _slew(overrides, duration_s):
    """paper003_slew on the FrameLoop with ``overrides``: :func:`paper003.series`."""
    sc = load_scenario(os.path.join(ROOT, 'scenarios', 'paper003_slew.yaml'))
    topics = run_topics(sc, paper003.TOPICS, duration_s, overrides, ideal=True)
    return paper003.series(topics, sc)


def _inputs(q, w):
    return ControlInputs(Estimate(q, np.asarray(w, float), 0.0, q_eci_body=q),
                         Target(frame='eci'))


def test_torque_within_limit_and_zero_at_rest_on_target():
    c = ReferenceSlewController(J, 1.0)
    rng = np.random.default_rng(2)
    for _ in range(300):
        q = attitude.normalize(rng.normal(size=4))
        cmd = c.update(_inputs(q, rng.normal(scale=0.05, size=3)), 0.0, 0.1)
        assert np.all(np.abs(cmd.torque_body) <= 1.0 + 1e-12)
    c.reset()
    np.testing.assert_allclose(
        c.update(_inputs(attitude.identity(), np.zeros(3)), 0.0, 0.1).torque_body, 0.0)


def test_rest_to_rest_slew_is_an_eigenaxis_slew_near_the_bang_bang_time():
    run = _slew({'manager.initial': 'reference_slew'}, 45.0)
    assert set(run['source'][1:]) == {'reference_slew'}
    phi0 = run['phi'][0]
    # Rest-to-rest bang-bang about the fixed eigenaxis with the largest acceleration the box
    # allows (closed form): T = 2 sqrt(phi0 / a); the 5 % band is entered sqrt(0.1 phi0 / a)
    # before T (the braking parabola phi = a tau^2 / 2).
    e0 = run['e_phi'][0]
    a_max = min(1.0 / abs(v) for v in J @ e0)
    t_band = 2.0 * math.sqrt(phi0 / a_max) - math.sqrt(0.1 * phi0 / a_max)
    m = paper003.metrics(run['t'], run['phi'], run['torque'])
    assert 0.9 * t_band <= m['settling_s'] <= 1.2 * t_band
    assert math.degrees(run['phi'][-1]) < 0.05
    assert np.abs(run['omega'][-1]).max() < math.radians(0.01)     # w.r.t. the target frame
    slewing = run['phi'] > 0.05 * phi0
    ang = np.degrees(np.arccos(np.clip(run['e_phi'][slewing] @ e0, -1.0, 1.0)))
    assert ang.max() < 3.0                   # the axis stays put: a plane (eigenaxis) slew
    assert m['max_abs_torque_Nm'] <= 1.0 + 1e-12


def test_bad_configuration_raises():
    with pytest.raises(ValueError):
        ReferenceSlewController(J, accel_fraction=1.5)
    with pytest.raises(ValueError):
        ReferenceSlewController(J, rate_gain_per_s=0.0)
    with pytest.raises(ValueError):
        ReferenceSlewController(J, max_torque_Nm=math.inf)
