"""Guidance profiles (core/guidance.py) against independent truth.

The slew's rate and acceleration are checked by numerical differentiation of the attitude
(scipy Rotation), the end state against the target, and the track against (G4) evaluated
with scipy; bad profiles raise ValueError.
"""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from adcs_nodes.core import attitude as att
from adcs_nodes.core.guidance import Guidance, Segment, guidance_from_params


def _slew():
    q_end = Rotation.from_euler('zyx', [30, -10, 20], degrees=True).as_quat()
    return Guidance([Segment(0.0, 'hold', att.identity()),
                     Segment(10.0, 'slew', q_end, duration_s=40.0)]), q_end


def test_slew_starts_and_ends_at_rest_on_its_attitudes():
    g, q_end = _slew()
    start, mid, end = g.at(10.0), g.at(30.0), g.at(50.0)
    assert att.angle_between(start.q_ref_body, att.identity()) < 1e-12
    assert np.allclose(start.omega_body_ref_body, 0.0, atol=1e-15)
    assert att.angle_between(end.q_ref_body, q_end) < 1e-12
    assert np.allclose(end.omega_body_ref_body, 0.0) and end.profile == 'hold'
    assert mid.profile == 'slew' and mid.time_to_go_s == pytest.approx(20.0)
    theta = np.linalg.norm(Rotation.from_quat(q_end).as_rotvec())
    assert np.linalg.norm(mid.omega_body_ref_body) == pytest.approx(2 * theta / 40.0)  # peak


def test_slew_rate_and_acceleration_are_the_derivatives_of_the_attitude():
    g, _ = _slew()
    h = 1e-4
    for t in (12.0, 25.0, 33.3, 47.0):
        r0 = Rotation.from_quat(g.at(t - h).q_ref_body)
        r1 = Rotation.from_quat(g.at(t + h).q_ref_body)
        w_num = (r0.inv() * r1).as_rotvec() / (2 * h)       # body-axes rate
        assert np.allclose(g.at(t).omega_body_ref_body, w_num, atol=1e-7)
        a_num = (g.at(t + h).omega_body_ref_body - g.at(t - h).omega_body_ref_body) / (2 * h)
        assert np.allclose(g.at(t).omega_dot_body_ref_body, a_num, atol=1e-7)


def test_track_segment_is_a_sine_about_its_axis():
    q0 = Rotation.from_euler('x', 5, degrees=True).as_quat()
    g = guidance_from_params([0.0], ['track'], list(q0), [0.0], [0.0, 1.0, 0.0], [2.0],
                             [100.0], 'eci')
    for t in (0.0, 13.0, 60.0):
        s = g.at(t)
        theta = math.radians(2.0) * math.sin(2 * math.pi * t / 100.0)
        want = Rotation.from_quat(q0) * Rotation.from_rotvec([0.0, theta, 0.0])
        assert att.angle_between(s.q_ref_body, want.as_quat()) < 1e-12
        assert s.frame == 'eci' and s.time_to_go_s == 0.0


@pytest.mark.parametrize('kwargs, match', [
    (dict(frame='lvlh'), 'frame'),
    (dict(seg=Segment(0.0, 'spin', att.identity())), 'type'),
    (dict(seg=Segment(0.0, 'slew', att.identity(), duration_s=0.0)), 'duration_s'),
    (dict(seg=Segment(0.0, 'hold', np.array([0.0, 0.0, 0.0, 2.0]))), 'unit quaternion'),
])
def test_bad_profiles_are_refused(kwargs, match):
    seg = kwargs.get('seg', Segment(0.0, 'hold', att.identity()))
    with pytest.raises(ValueError, match=match):
        Guidance([seg], kwargs.get('frame', 'orbit'))
