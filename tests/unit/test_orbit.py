"""Unit tests of adcs_nodes.core.orbit against independent truth (no ROS)."""
import math
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from adcs_nodes.core import attitude
from adcs_nodes.core import orbit
from adcs_nodes.core.orbit import (MU_EARTH, R_EARTH, CircularOrbit, Sgp4Orbit, make_orbit)

UTC = timezone.utc
EPOCH = datetime(2025, 3, 20, 6, 0, 0, tzinfo=UTC)

# ISS TLE of 2008-09-20, the example of the "Two-line element set" article (Wikipedia) and of
# CelesTrak's format documentation; checksums 7 and 7.
ISS_L1 = '1 25544U 98067A   08264.51782528 -.00002182  00000-0 -11606-4 0  2927'
ISS_L2 = '2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.72125391563537'


def _with_checksum(line68):
    """Append the TLE checksum: digits summed, '-' counts 1, modulo 10."""
    total = sum(int(c) if c.isdigit() else c == '-' for c in line68)
    return line68 + str(total % 10)


def _paper_orbit(**kw):
    """Paper 000 scenario: 690 km circular, i = 98 deg (digest section 5.1)."""
    args = dict(altitude_m=690e3, inclination_rad=math.radians(98.0),
                raan_rad=math.radians(30.0), arg_latitude0_rad=0.3, epoch=EPOCH)
    args.update(kw)
    return CircularOrbit(**args)


# ------------------------------------------------------------------------ circular orbit
def test_period_matches_kepler_and_digest():
    orb = _paper_orbit()
    a = R_EARTH + 690e3
    assert orb.period == pytest.approx(2 * math.pi * math.sqrt(a ** 3 / MU_EARTH), rel=1e-12)
    assert abs(orb.period - 5913.8) < 1.0          # digest 5.1: T = 5913.8 s
    assert orb.mean_motion == pytest.approx(1.0625e-3, rel=1e-4)  # digest: w0 = 1.0625e-3


def test_circular_orbit_closes_after_one_period():
    orb = _paper_orbit()
    for t0 in (0.0, 1234.5):
        s0, s1 = orb.state(t0), orb.state(t0 + orb.period)
        assert np.linalg.norm(s1.r_eci - s0.r_eci) < 1e-6 * np.linalg.norm(s0.r_eci)
        assert np.linalg.norm(s1.v_eci - s0.v_eci) < 1e-6 * np.linalg.norm(s0.v_eci)


def test_circular_orbit_radius_speed_and_geometry():
    inc, raan = math.radians(98.0), math.radians(30.0)
    orb = _paper_orbit(arg_latitude0_rad=0.0)
    a = R_EARTH + 690e3
    for t in np.linspace(0.0, 7000.0, 15):
        s = orb.state(t)
        assert np.linalg.norm(s.r_eci) == pytest.approx(a, rel=1e-12)
        assert np.linalg.norm(s.v_eci) == pytest.approx(math.sqrt(MU_EARTH / a), rel=1e-12)
        assert abs(s.r_eci @ s.v_eci) < 1e-9 * a * np.linalg.norm(s.v_eci)
        h = np.cross(s.r_eci, s.v_eci)
        assert math.acos(h[2] / np.linalg.norm(h)) == pytest.approx(inc, abs=1e-12)
    s0 = orb.state(0.0)  # u = 0: at the ascending node, moving north
    assert np.allclose(s0.r_eci / a, [math.cos(raan), math.sin(raan), 0.0], atol=1e-12)
    assert s0.v_eci[2] > 0.0


def test_circular_orbit_matches_two_body_integration():
    orb = _paper_orbit()
    s0 = orb.state(0.0)

    def rhs(_t, y):
        return np.concatenate([y[3:], -MU_EARTH * y[:3] / np.linalg.norm(y[:3]) ** 3])

    t_end = 0.37 * orb.period
    sol = solve_ivp(rhs, (0.0, t_end), np.concatenate([s0.r_eci, s0.v_eci]),
                    method='DOP853', rtol=1e-11, atol=1e-6)
    s1 = orb.state(t_end)
    assert np.linalg.norm(sol.y[:3, -1] - s1.r_eci) < 1e-3      # m
    assert np.linalg.norm(sol.y[3:, -1] - s1.v_eci) < 1e-6      # m/s


def test_argument_of_latitude_increases_at_mean_motion():
    orb = _paper_orbit()
    for t in (0.0, 100.0, 2500.0, 5000.0, 9000.0):
        s = orb.state(t)
        expected = (0.3 + orb.mean_motion * t) % (2 * math.pi)
        assert s.argument_of_latitude == pytest.approx(expected, abs=1e-9)
        assert 0.0 <= s.argument_of_latitude < 2 * math.pi
        # the general r, v formula (used for SGP4) gives the same angle
        assert orbit.state_from_rv(s.r_eci, s.v_eci).argument_of_latitude == \
            pytest.approx(expected, abs=1e-9)


# --------------------------------------------------------------------------- frames
def _check_orbit_axes(rot, r, v):
    assert np.allclose(rot.T @ rot, np.eye(3), atol=1e-12)
    assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-12)
    h = np.cross(r, v)
    assert np.allclose(rot[:, 2], r / np.linalg.norm(r), atol=1e-12)   # z zenith
    assert np.allclose(rot[:, 1], h / np.linalg.norm(h), atol=1e-12)   # y orbit normal
    assert np.allclose(rot[:, 0], np.cross(rot[:, 1], rot[:, 2]), atol=1e-12)
    assert rot[:, 0] @ v > 0.0                                          # x along-track


def test_orbit_frame_of_circular_state():
    orb = _paper_orbit()
    for t in (0.0, 800.0, 3000.0, 5500.0):
        s = orb.state(t)
        rot = attitude.to_matrix(s.q_eci_orbit)
        _check_orbit_axes(rot, s.r_eci, s.v_eci)
        assert np.allclose(rot[:, 0], s.v_eci / np.linalg.norm(s.v_eci), atol=1e-12)
        assert np.allclose(orbit.orbit_frame_dcm(s.r_eci, s.v_eci), rot, atol=1e-12)


def test_orbit_frame_functions_on_eccentric_state():
    r = np.array([7.0e6, -1.0e6, 2.0e6])
    v = np.array([1.0e3, 7.2e3, 1.5e3])   # not perpendicular to r
    rot = orbit.orbit_frame_dcm(r, v)
    _check_orbit_axes(rot, r, v)
    assert np.allclose(attitude.to_matrix(orbit.q_eci_orbit(r, v)), rot, atol=1e-12)
    lvlh = attitude.to_matrix(orbit.q_eci_lvlh(r, v))
    assert np.allclose(lvlh, rot @ np.diag([1.0, -1.0, -1.0]), atol=1e-12)
    assert np.allclose(lvlh[:, 2], -r / np.linalg.norm(r), atol=1e-12)   # LVLH z nadir
    assert np.allclose(attitude.to_matrix(orbit.Q_ORBIT_LVLH), np.diag([1.0, -1.0, -1.0]))


def test_orbit_frame_rate_is_finite_difference_of_attitude():
    orb = _paper_orbit()
    t, dt = 1000.0, 0.01
    r_minus = attitude.to_matrix(orb.state(t - dt).q_eci_orbit)
    r_plus = attitude.to_matrix(orb.state(t + dt).q_eci_orbit)
    w_skew = (r_plus - r_minus) / (2 * dt) @ attitude.to_matrix(orb.state(t).q_eci_orbit).T
    omega = np.array([w_skew[2, 1], w_skew[0, 2], w_skew[1, 0]])    # ECI axes
    s = orb.state(t)
    assert np.allclose(omega, s.omega_orbit_eci_eci, atol=1e-9)
    assert s.orbit_rate == pytest.approx(orb.mean_motion, rel=1e-12)


def test_fast_quaternion_equals_attitude_from_matrix():
    rng = np.random.default_rng(7)
    quats = list(rng.normal(size=(200, 4)))
    quats += [[1, 0, 0, 1e-3], [0, 1, 0, 1e-3], [0, 0, 1, 1e-3], [0, 0, 0, 1]]  # all branches
    for q in quats:
        m = attitude.to_matrix(q)
        fast = orbit._quat_from_axes(m[:, 0], m[:, 1], m[:, 2])
        assert np.allclose(fast, attitude.from_matrix(m), atol=1e-12)


# ---------------------------------------------------------------------------- SGP4
def test_sgp4_state_is_library_output_in_si_units():
    from sgp4.api import Satrec

    orb = Sgp4Orbit(ISS_L1, ISS_L2)
    sat = Satrec.twoline2rv(ISS_L1, ISS_L2)
    # TLE epoch 08264.51782528 = 2008-09-20 + 0.51782528 d = 12:25:40.104 UTC
    assert abs((orb.epoch - datetime(2008, 9, 20, 12, 25, 40, 104000, tzinfo=UTC))
               .total_seconds()) < 1e-3
    t = 1800.0
    err, r_km, v_kms = sat.sgp4(sat.jdsatepoch, sat.jdsatepochF + t / 86400.0)
    assert err == 0
    s = orb.state(t)
    assert np.allclose(s.r_eci, np.array(r_km) * 1e3, atol=1e-2)
    assert np.allclose(s.v_eci, np.array(v_kms) * 1e3, atol=1e-5)
    assert 6.6e6 < np.linalg.norm(s.r_eci) < 6.8e6
    assert 7.5e3 < np.linalg.norm(s.v_eci) < 7.9e3
    _check_orbit_axes(attitude.to_matrix(s.q_eci_orbit), s.r_eci, s.v_eci)


def test_sgp4_epoch_shift_and_elements():
    orb = Sgp4Orbit(ISS_L1, ISS_L2)
    later = Sgp4Orbit(ISS_L1, ISS_L2, epoch=orb.epoch + timedelta(minutes=90))
    assert np.allclose(later.state(30.0).r_eci, orb.state(5430.0).r_eci, atol=1e-3)
    assert orb.period == pytest.approx(86400.0 / 15.72125391, rel=1e-9)  # mean motion rev/day
    s = orb.state(0.0)
    assert s.orbit_rate == pytest.approx(orb.mean_motion, rel=0.02)
    h = np.cross(s.r_eci, s.v_eci)
    assert math.degrees(math.acos(h[2] / np.linalg.norm(h))) == pytest.approx(51.6416, abs=0.1)
    raan = math.degrees(math.atan2(h[0], -h[1])) % 360.0
    assert raan == pytest.approx(247.4627, abs=0.1)
    # u = argument of perigee + true anomaly ~ 130.536 + 325.029 (e = 0.00067) - 360 deg
    assert math.degrees(s.argument_of_latitude) == pytest.approx(95.565, abs=0.3)


# --------------------------------------------------------------------- Earth rotation
@pytest.mark.parametrize('when, gmst_deg', [
    # Vallado, Fundamentals of Astrodynamics, Example 3-5 (UT1).
    (datetime(1992, 8, 20, 12, 14, tzinfo=UTC), 152.578787810),
    # Meeus, Astronomical Algorithms, Example 12.a: 13h10m46.3668s.
    (datetime(1987, 4, 10, tzinfo=UTC), (13 + 10 / 60 + 46.3668 / 3600) * 15),
    # Meeus, Example 12.b: 8h34m57.0896s.
    (datetime(1987, 4, 10, 19, 21, tzinfo=UTC), (8 + 34 / 60 + 57.0896 / 3600) * 15),
])
def test_gmst_published_values(when, gmst_deg):
    assert math.degrees(orbit.gmst(when)) == pytest.approx(gmst_deg, abs=1e-6)


def test_gmst_offsets_time_zones_and_rate():
    base = datetime(2025, 6, 1, 3, 0, tzinfo=UTC)
    assert orbit.gmst(base, 4000.5) == pytest.approx(
        orbit.gmst(base + timedelta(seconds=4000.5)), abs=1e-9)
    tz = timezone(timedelta(hours=-5))
    assert orbit.gmst(base.astimezone(tz)) == pytest.approx(orbit.gmst(base), abs=1e-12)
    dtheta = (orbit.gmst(base, 1000.0) - orbit.gmst(base)) % (2 * math.pi)
    # IAU 1982: 1.00273790935 sidereal turns per UT1 day (Aoki et al. 1982)
    assert dtheta / 1000.0 == pytest.approx(1.00273790935 * 2 * math.pi / 86400, rel=1e-9)
    assert dtheta / 1000.0 == pytest.approx(orbit.OMEGA_EARTH, rel=1e-6)


def test_q_eci_ecef_consistency():
    when = datetime(2025, 1, 1, tzinfo=UTC)
    r_eci = np.array([5.0e6, 3.0e6, 2.0e6])
    q = orbit.q_eci_ecef(when, 10.0)
    r_ecef = orbit.ecef_from_eci(r_eci, when, 10.0)
    assert np.allclose(attitude.to_matrix(q) @ r_ecef, r_eci, atol=1e-6)
    assert np.allclose(orbit.eci_from_ecef(r_ecef, when, 10.0), r_eci, atol=1e-6)
    theta = orbit.gmst(when, 10.0)   # ECEF x axis seen in ECI at angle GMST from ECI x
    assert np.allclose(orbit.eci_from_ecef([1.0, 0.0, 0.0], when, 10.0),
                       [math.cos(theta), math.sin(theta), 0.0], atol=1e-12)
    assert r_ecef[2] == r_eci[2]


# ----------------------------------------------------------------- factory and errors
def test_make_orbit():
    orb = make_orbit({'type': 'circular', 'altitude_km': 690, 'inclination_deg': 98}, EPOCH)
    assert isinstance(orb, CircularOrbit) and abs(orb.period - 5913.8) < 1.0
    assert orb.epoch == EPOCH
    tle = make_orbit({'type': 'tle', 'line1': ISS_L1, 'line2': ISS_L2}, EPOCH)
    assert isinstance(tle, Sgp4Orbit) and tle.epoch == EPOCH


@pytest.mark.parametrize('cfg, word', [
    ({'type': 'keplerian'}, 'keplerian'),
    ({'altitude_km': 690}, 'type'),
    ({'type': 'circular', 'altitude_km': 690}, 'inclination_deg'),
    ({'type': 'circular', 'altitude_km': 690, 'inclination_deg': 98, 'raan': 0}, 'raan'),
    ({'type': 'tle', 'line1': ISS_L1}, 'line2'),
    ({'type': 'tle', 'line1': ISS_L1, 'line2': ISS_L1}, 'line2'),
    ({'type': 'circular', 'altitude_km': 'high', 'inclination_deg': 98}, 'altitude_km'),
])
def test_make_orbit_errors_name_the_key(cfg, word):
    with pytest.raises(ValueError, match=word):
        make_orbit(cfg, EPOCH)


@pytest.mark.parametrize('kwargs', [
    {'altitude_m': -10.0}, {'altitude_m': float('nan')}, {'inclination_rad': 4.0},
    {'inclination_rad': -0.1}, {'raan_rad': float('inf')},
    {'epoch': datetime(2025, 1, 1)}, {'epoch': '2025-01-01'},
])
def test_circular_orbit_rejects_bad_arguments(kwargs):
    with pytest.raises(ValueError):
        _paper_orbit(**kwargs)


@pytest.mark.parametrize('line1, line2', [
    (ISS_L1[:-1] + '8', ISS_L2),                     # checksum
    (ISS_L1, ISS_L2[:-1]),                           # length
    (ISS_L2, ISS_L1),                                # swapped lines
    (ISS_L1, _with_checksum('2 25545' + ISS_L2[7:-1])),  # satellite numbers differ
    (None, ISS_L2),
    (ISS_L1, _with_checksum(ISS_L2[:52] + '-5.7212539156353')),        # negative mean motion
    (ISS_L1, _with_checksum(ISS_L2[:26] + '9906703' + ISS_L2[33:68])),  # eccentricity 0.99
])
def test_sgp4_rejects_malformed_tle(line1, line2):
    with pytest.raises(ValueError):
        Sgp4Orbit(line1, line2)


def test_frame_functions_reject_bad_vectors():
    with pytest.raises(ValueError):
        orbit.orbit_frame_dcm([7e6, 0, 0], [1e3, 0, 0])        # r parallel to v
    with pytest.raises(ValueError):
        orbit.q_eci_orbit([7e6, 0, float('nan')], [0, 7e3, 0])
    with pytest.raises(ValueError):
        orbit.q_eci_lvlh([7e6, 0], [0, 7e3, 0])
    with pytest.raises(ValueError):
        orbit.gmst(datetime(2025, 1, 1))                       # naive datetime
