"""Guidance profiles of paper 001 (adcs_nodes.core.guidance_profiles), on the profile and the
initial state of the shipped scenario ``scenarios/paper001_mpi.yaml``.

Truth: the paper's numbers (Sec. 6, digest section 4: peak rates, the reference at 3500 s,
the initial 3-1-2 angles and rates), finite differences of the attitude for the rate and of
the rate for the acceleration.
"""
import math
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

sys.modules.setdefault('rclpy', None)

from adcs_nodes.core import attitude as att  # noqa: E402
from adcs_nodes.core import guidance_profiles as gp  # noqa: E402
from adcs_nodes.core.control import mpi  # noqa: E402

SCENARIO = yaml.safe_load((Path(__file__).resolve().parents[2] / 'scenarios'
                           / 'paper001_mpi.yaml').read_text(encoding='utf-8'))


def _paper_profile():
    return gp.profile_from_dicts(SCENARIO['guidance']['euler312_profile'])


def test_paper_profile_segments_and_time_to_go():
    p = _paper_profile()
    assert p.end_s == 5000.0
    q40 = mpi.q_orbit_body_of_lvlh_euler312(np.radians([40.0, -40.0, 20.0]))
    pt = p.profile_at(50.0)
    assert pt.time_to_go_s == pytest.approx(150.0) and pt.frame == 'orbit'
    assert att.angle_between(pt.q_ref_body, q40) < 1e-12
    np.testing.assert_array_equal(pt.omega_body_ref_body, 0.0)
    assert p.profile_at(200.0).time_to_go_s == 0.0
    assert p.profile_at(3600.0).time_to_go_s == pytest.approx(100.0)
    assert att.angle_between(p.profile_at(4000.0).q_ref_body,
                             mpi.q_orbit_body_of_lvlh_euler312(np.zeros(3))) < 1e-12
    after = p.profile_at(6000.0)                  # past the end: hold the last attitude
    assert after.time_to_go_s == 0.0 and np.all(after.omega_body_ref_body == 0.0)
    first = p.profile_at(float('nan'))
    assert np.all(np.isfinite(first.q_ref_body))


def test_tracking_reference_matches_the_digest_numbers():
    """At 3500 s: [49.92, -32.55, 20.00] deg with Euler rates [-0.048, 0.045, 0.072] deg/s;
    peak Euler rates 0.0960, 0.0901, 0.0720 deg/s (digest section 4)."""
    seg = _paper_profile().segments[2]
    e, de, _ = seg.euler(3500.0)
    np.testing.assert_allclose(np.degrees(e), [49.92, -32.55, 20.00], atol=5e-3)
    np.testing.assert_allclose(np.degrees(de), [-0.048, 0.045, 0.072], atol=1e-3)
    peak = np.degrees(np.radians([11.46, 8.60, 5.73]) * 2 * np.pi / np.array([750, 600, 500]))
    np.testing.assert_allclose(peak, [0.0960, 0.0901, 0.0720], atol=1e-4)


def test_tracking_rate_and_acceleration_are_derivatives_of_the_attitude():
    p = _paper_profile()
    h = 1e-3
    for t in (1000.5, 1700.0, 2950.0):
        pt = p.profile_at(t)
        q_m, q_p = p.profile_at(t - h).q_ref_body, p.profile_at(t + h).q_ref_body
        # body rate w.r.t. orbit: 2 vec(q^* dq/dt)
        w_fd = att.to_rotation_vector(att.multiply(att.conjugate(q_m), q_p)) / (2 * h)
        np.testing.assert_allclose(pt.omega_body_ref_body, w_fd, atol=1e-9)
        wd_fd = (p.profile_at(t + h).omega_body_ref_body
                 - p.profile_at(t - h).omega_body_ref_body) / (2 * h)
        np.testing.assert_allclose(pt.omega_dot_body_ref_body, wd_fd, atol=1e-11)


def test_initial_state_is_the_papers():
    q = np.array(SCENARIO['initial']['q_orbit_body_xyzw'])
    w = np.radians(SCENARIO['initial']['omega_body_orbit_body_deg_s'])
    np.testing.assert_allclose(np.degrees(mpi.lvlh_euler312_of(q)), [3.0, -3.0, 3.0],
                               atol=1e-9)
    e = np.radians([3.0, -3.0, 3.0])
    np.testing.assert_allclose(np.degrees(mpi.euler312_rates_from_body_rate(e, w)),
                               [0.3, -0.3, 0.3], atol=1e-9)


def test_bad_profiles_raise():
    with pytest.raises(ValueError, match='overlap'):
        gp.Profile([gp.Hold(0, 100, [0, 0, 0]), gp.Hold(50, 150, [0, 0, 0])])
    with pytest.raises(ValueError, match='start_s < end_s'):
        gp.Hold(100, 100, [0, 0, 0])
    with pytest.raises(ValueError, match='roll'):
        gp.Maneuver(0, 10, [89.0, 0, 0])
    with pytest.raises(ValueError, match='type'):
        gp.profile_from_dicts([{'type': 'spin', 'start_s': 0, 'end_s': 1}])
    with pytest.raises(ValueError, match='hold segment'):
        gp.profile_from_dicts([{'type': 'hold', 'start_s': 0, 'end_s': 1, 'euler': [0, 0, 0]}])
    with pytest.raises(ValueError, match='period'):
        gp.SineTracking(0, 10, [0, 0, 0], [1, 1, 1], [0, 1, 1])
    with pytest.raises(ValueError):
        gp.Profile([])
    assert math.isfinite(gp.Hold(0, 1, [0, 0, 0]).at(0.5).time_to_go_s)
