"""Sensor models (sim_node.models.sensors) against independent truth.

Truth used here: hand-computed fields for a bias, a scale factor and rotations about one axis;
scipy's ``Rotation`` for attitudes and error rotations; the 3-2-1 angles an attitude was built
from; sampling statistics (std, binomial rate, random-walk variance slope) with tolerances of
at least 5 standard errors of the estimator (the seeds are fixed, so the tests are exact
repeats, but the tolerances would also hold for other seeds).
"""
import importlib
import math
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from adcs_nodes.core import attitude as att
from sim_node.models.sensors import (GYRO_DRIFT_WALK_RAD_S_SQRT_S, STAR_TRACKER_STD_RAD, Gyro,
                                     HorizonSensor, Magnetometer, StarTracker)

NT = 1e-9
B = np.array([21e-6, -7e-6, 38e-6])      # a LEO field in body axes [T]
DEG = math.pi / 180.0


def test_imports_without_ros(monkeypatch):
    for name in ('rclpy', 'sensor_msgs', 'adcs_msgs', 'geometry_msgs'):
        monkeypatch.setitem(sys.modules, name, None)
    monkeypatch.delitem(sys.modules, 'sim_node.models.sensors')
    importlib.import_module('sim_node.models.sensors')


# ---------------------------------------------------------------------- magnetometer
def test_magnetometer_without_errors_returns_the_true_field():
    m = Magnetometer(seed=1)
    for _ in range(3):
        assert np.array_equal(m.measure(B), B)
    q = Magnetometer(lsb_T=20 * NT, seed=1).measure(B)
    assert np.all(np.abs(q - B) <= 10 * NT + 1e-21)


def test_magnetometer_bias_and_scale_factor_by_hand():
    bias = np.array([120.0, -80.0, 50.0]) * NT
    assert np.allclose(Magnetometer(bias_T=bias).measure(B), B + bias, rtol=0, atol=1e-20)
    out = Magnetometer(scale_factor_error=[0.05, -0.02, 0.1]).measure(B)
    assert np.allclose(out, [1.05 * 21e-6, 0.98 * -7e-6, 1.1 * 38e-6], rtol=1e-14, atol=0)


def test_magnetometer_misalignment_by_hand():
    a = 10 * DEG
    # sensor axes = body axes turned by a about z: x_s = (c, s, 0), y_s = (-s, c, 0)
    out = Magnetometer(misalignment_rad=[0.0, 0.0, a]).measure([30e-6, 0.0, 0.0])
    assert np.allclose(out, [30e-6 * math.cos(a), -30e-6 * math.sin(a), 0.0], atol=1e-20)
    # turned by a about x: y_s = (0, c, s), z_s = (0, -s, c)
    out = Magnetometer(misalignment_rad=[a, 0.0, 0.0]).measure([0.0, 0.0, 30e-6])
    assert np.allclose(out, [0.0, 30e-6 * math.sin(a), 30e-6 * math.cos(a)], atol=1e-20)


def test_magnetometer_mounting_and_misalignment_compose_like_scipy():
    q_mount = att.from_axis_angle([0.0, 0.0, 1.0], math.pi / 2)   # sensor x along body y
    assert np.allclose(Magnetometer(q_body_sensor=q_mount).measure([0.0, 40e-6, 0.0]),
                       [40e-6, 0.0, 0.0], atol=1e-20)
    delta = np.array([0.05, -0.1, 0.08])
    q_mount = Rotation.from_euler('zyx', [30, -20, 70], degrees=True)
    m = Magnetometer(misalignment_rad=delta, q_body_sensor=q_mount.as_quat(),
                     scale_factor_error=[0.01, 0.0, -0.03])
    r_body_sensor = q_mount * Rotation.from_rotvec(delta)
    expect = np.array([1.01, 1.0, 0.97]) * r_body_sensor.inv().apply(B)
    assert np.allclose(m.measure(B), expect, rtol=0, atol=1e-18)


def test_magnetometer_noise_std_per_axis():
    std = np.array([375.0, 25.0, 65.0]) * NT
    m = Magnetometer(noise_std_T=std, seed=7)
    n = 20000
    err = np.array([m.measure(B) for _ in range(n)]) - B
    assert np.all(np.abs(err.mean(axis=0)) < 5 * std / math.sqrt(n))
    assert np.allclose(err.std(axis=0), std, rtol=5 / math.sqrt(2 * n))
    assert np.allclose(m.covariance, np.diag(std ** 2), rtol=1e-15)
    assert abs(np.corrcoef(err.T)[0, 1]) < 5 / math.sqrt(n)


def test_magnetometer_quantisation_is_rounding_to_the_lsb():
    lsb = 20 * NT
    raw = Magnetometer(noise_std_T=375 * NT, bias_T=120 * NT, seed=3)
    quant = Magnetometer(noise_std_T=375 * NT, bias_T=120 * NT, lsb_T=lsb, seed=3)
    for _ in range(500):
        a, b = raw.measure(B), quant.measure(B)
        k = b / lsb
        assert np.allclose(k, np.round(k), rtol=0, atol=1e-9)
        assert np.all(np.abs(b - a) <= lsb / 2 * (1 + 1e-9))


def test_magnetometer_saturation_per_axis():
    b = [1e-4, -1e-4, 1e-5]
    assert np.array_equal(Magnetometer(saturation_T=5e-5).measure(b), [5e-5, -5e-5, 1e-5])
    assert np.array_equal(Magnetometer(saturation_T=[5e-5, 0.0, 0.0]).measure(b),
                          [5e-5, -1e-4, 1e-5])
    out = Magnetometer(saturation_T=5e-5, lsb_T=20 * NT).measure(b)      # clip, then quantise
    assert np.allclose(out, [5e-5, -5e-5, 1e-5], rtol=1e-12)


def test_magnetometer_dropout_rate_and_noise_stream_unchanged():
    p, n = 0.3, 20000
    m = Magnetometer(noise_std_T=100 * NT, dropout_probability=p, seed=11)
    ref = Magnetometer(noise_std_T=100 * NT, seed=11)
    lost = 0
    for _ in range(n):
        a, r = m.measure(B), ref.measure(B)
        if a is None:
            lost += 1
        else:
            assert np.array_equal(a, r)           # a dropout never shifts the noise stream
    assert abs(lost / n - p) < 5 * math.sqrt(p * (1 - p) / n)
    assert all(Magnetometer(dropout_probability=1.0).measure(B) is None for _ in range(50))


def test_magnetometer_deterministic_per_seed():
    kw = dict(noise_std_T=[375 * NT, 25 * NT, 65 * NT], lsb_T=20 * NT, dropout_probability=0.2)
    a, b, c = (Magnetometer(seed=s, **kw) for s in (5, 5, 6))
    out_a, out_b, out_c = ([m.measure(B) for _ in range(50)] for m in (a, b, c))
    same = [(x is None and y is None) or (x is not None and y is not None
                                          and np.array_equal(x, y))
            for x, y in zip(out_a, out_b)]
    assert all(same)
    differ = [x is None or y is None or not np.array_equal(x, y) for x, y in zip(out_a, out_c)]
    assert sum(differ) > 40


def test_magnetometer_paper_000_case_mean_is_the_deterministic_part():
    """Bias 120 nT, misalignment 10 deg, LSB 20 nT, noise 375/25/65 nT (paper 000 sec. 4)."""
    delta = 10 * DEG * np.array([1.0, 1.0, 1.0]) / math.sqrt(3.0)
    bias = np.array([120.0, -120.0, 60.0]) * NT
    m = Magnetometer(noise_std_T=np.array([375.0, 25.0, 65.0]) * NT, bias_T=bias,
                     misalignment_rad=delta, lsb_T=20 * NT, seed=2)
    n = 5000
    mean = np.mean([m.measure(B) for _ in range(n)], axis=0)
    expect = Rotation.from_rotvec(delta).inv().apply(B) + bias
    assert np.all(np.abs(mean - expect) < 5 * np.array([375.0, 25.0, 65.0]) * NT / math.sqrt(n)
                  + 2 * NT)


@pytest.mark.parametrize('kw', [
    dict(noise_std_T=[-1e-9, 0, 0]), dict(noise_std_T=[1e-9, 1e-9]), dict(bias_T=[np.nan, 0, 0]),
    dict(misalignment_rad=0.1), dict(misalignment_rad=[2.0, 0.0, 0.0]),
    dict(scale_factor_error=[-1.0, 0, 0]), dict(lsb_T=-1e-9), dict(lsb_T='x'),
    dict(saturation_T=[-1.0, 0, 0]), dict(dropout_probability=1.5),
    dict(dropout_probability=-0.1), dict(q_body_sensor=[0, 0, 0, 2.0]),
    dict(q_body_sensor=[0, 0, 1.0]), dict(seed=-1), dict(seed=1.5), dict(seed=True),
])
def test_magnetometer_bad_config(kw):
    with pytest.raises(ValueError):
        Magnetometer(**kw)


def test_magnetometer_bad_input():
    with pytest.raises(ValueError):
        Magnetometer().measure([np.nan, 0.0, 0.0])
    with pytest.raises(ValueError):
        Magnetometer().measure([1.0, 0.0])


# ---------------------------------------------------------------------- horizon sensor
def test_horizon_recovers_roll_pitch_for_any_yaw():
    rng = np.random.default_rng(0)
    h = HorizonSensor(fov_rad=math.pi / 2)
    for _ in range(200):
        roll, pitch = rng.uniform(-80, 80, 2) * DEG
        yaw = rng.uniform(-math.pi, math.pi)
        for q in (att.from_euler_321(roll, pitch, yaw),
                  Rotation.from_euler('ZYX', [yaw, pitch, roll]).as_quat()):
            m = h.measure(q)
            assert m.valid
            assert m.roll == pytest.approx(roll, abs=1e-12)
            assert m.pitch == pytest.approx(pitch, abs=1e-12)


def test_horizon_zenith_form_matches_paper_004_column():
    """z_b = (-s theta, c theta s phi, c theta c phi), eq. (1) of paper 004, column 3 of C."""
    h = HorizonSensor()
    phi, theta = 4 * DEG, 3 * DEG
    z_b = [-math.sin(theta), math.cos(theta) * math.sin(phi), math.cos(theta) * math.cos(phi)]
    m = h.measure_zenith(7e6 * np.array(z_b))
    assert (m.roll, m.pitch) == (pytest.approx(phi, abs=1e-15), pytest.approx(theta, abs=1e-15))


def test_horizon_scale_factor_and_bias():
    roll, pitch, yaw = 4 * DEG, 3 * DEG, 5 * DEG          # paper 004's test attitude
    q = att.from_euler_321(roll, pitch, yaw)
    m = HorizonSensor(scale_factor_error=[0.05, 0.0]).measure(q)
    assert m.roll == pytest.approx(1.05 * roll, rel=1e-12)
    assert m.pitch == pytest.approx(pitch, rel=1e-12)
    m = HorizonSensor(scale_factor_error=[0.0, 0.05]).measure(q)
    assert (m.roll, m.pitch) == (pytest.approx(roll, rel=1e-12),
                                 pytest.approx(1.05 * pitch, rel=1e-12))
    m = HorizonSensor(bias_rad=[0.01, -0.02]).measure(q)
    assert (m.roll, m.pitch) == (pytest.approx(roll + 0.01, abs=1e-15),
                                 pytest.approx(pitch - 0.02, abs=1e-15))


def test_horizon_field_of_view():
    h = HorizonSensor(fov_rad=[30 * DEG, 20 * DEG])
    assert h.measure(att.from_euler_321(29 * DEG, 19 * DEG, 1.0)).valid
    for roll, pitch in ((31, 0), (-31, 0), (0, 21), (0, -21), (180, 0)):
        m = h.measure(att.from_euler_321(roll * DEG, pitch * DEG, 0.3))
        assert not m.valid and math.isnan(m.roll) and math.isnan(m.pitch)
    wide = HorizonSensor(fov_rad=math.pi / 2)
    assert not wide.measure(att.from_euler_321(math.pi, 0.0, 0.0)).valid     # looking up
    assert not wide.measure([0.0, 1.0, 0.0, 0.0]).valid                    # upside down
    assert wide.measure(att.from_euler_321(89 * DEG, 0.0, 0.0)).valid


def test_horizon_noise_statistics_and_variance():
    std = np.array([0.1, 0.05]) * DEG
    h = HorizonSensor(noise_std_rad=std, seed=4)
    q = att.from_euler_321(2 * DEG, -3 * DEG, 1.0)
    n = 20000
    out = np.array([h.measure(q)[:2] for _ in range(n)]) - [2 * DEG, -3 * DEG]
    assert np.allclose(out.std(axis=0), std, rtol=5 / math.sqrt(2 * n))
    assert np.all(np.abs(out.mean(axis=0)) < 5 * std / math.sqrt(n))
    assert np.allclose(h.variance, std ** 2, rtol=1e-15)


def test_horizon_deterministic_per_seed_even_across_invalid_samples():
    qs = [att.from_euler_321(r * DEG, 0.0, 0.0) for r in (1, 50, 2, 3)]
    a = HorizonSensor(noise_std_rad=1e-3, seed=9)
    b = HorizonSensor(noise_std_rad=1e-3, seed=9)
    c = HorizonSensor(noise_std_rad=1e-3, seed=9)
    out_a = [a.measure(q) for q in qs]
    out_b = [b.measure(q) for q in qs]
    assert str(out_a) == str(out_b)
    # the invalid sample at 50 deg consumed its draw: sample 3 equals c's third draw
    out_c = [c.measure(qs[0]) for _ in range(2)] + [c.measure(qs[2])]
    assert out_a[2] == out_c[2]


@pytest.mark.parametrize('kw', [
    dict(fov_rad=0.0), dict(fov_rad=2.0), dict(fov_rad=[0.5, 0.5, 0.5]),
    dict(noise_std_rad=-1.0), dict(bias_rad=[np.inf, 0.0]), dict(scale_factor_error=-1.5),
    dict(seed=-3),
])
def test_horizon_bad_config(kw):
    with pytest.raises(ValueError):
        HorizonSensor(**kw)


# ---------------------------------------------------------------------- star tracker
def test_star_tracker_without_noise_is_exact():
    q = Rotation.from_euler('zyx', [10, 20, 30], degrees=True).as_quat()
    assert np.allclose(StarTracker(noise_std_rad=0.0).measure(q), q, atol=1e-15)
    assert np.allclose(StarTracker(noise_std_rad=0.0).measure(-q), -q, atol=1e-15)


def test_star_tracker_error_angle_statistics():
    std = np.array([1.0, 2.0, 3.0]) * 1e-4
    st = StarTracker(noise_std_rad=std, seed=12)
    q_true = Rotation.from_euler('zyx', [-100, 40, 170], degrees=True)
    n = 20000
    err = np.empty((n, 3))
    for k in range(n):
        q_m = st.measure(-q_true.as_quat())                   # either sign of the input
        assert abs(np.linalg.norm(q_m) - 1.0) < 1e-12
        assert np.dot(q_m, -q_true.as_quat()) > 0              # same hemisphere
        err[k] = (q_true.inv() * Rotation.from_quat(q_m)).as_rotvec()   # body axes
    assert np.allclose(err.std(axis=0), std, rtol=5 / math.sqrt(2 * n))
    assert np.all(np.abs(err.mean(axis=0)) < 5 * std / math.sqrt(n))
    angle2 = np.sum(err ** 2, axis=1)
    assert np.mean(angle2) == pytest.approx(np.sum(std ** 2), rel=0.05)
    assert np.allclose(st.covariance, np.diag(std ** 2))


def test_star_tracker_default_and_determinism():
    assert STAR_TRACKER_STD_RAD == pytest.approx(math.radians(0.02) / 3)
    q = att.from_euler_321(0.1, 0.2, 0.3)
    a = [StarTracker(seed=3).measure(q) for _ in range(2)]
    assert np.array_equal(a[0], a[1])
    assert not np.array_equal(a[0], StarTracker(seed=4).measure(q))
    with pytest.raises(ValueError):
        StarTracker(noise_std_rad=[-1.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        StarTracker(noise_std_rad=[1.0, 0.0])
    with pytest.raises(ValueError):
        StarTracker().measure([0.0, 0.0, 0.0, 0.0])


# ---------------------------------------------------------------------- gyro
def test_gyro_without_noise_adds_the_initial_bias():
    w = np.array([0.01, -0.02, 0.03])
    g = Gyro(bias_initial_rad_s=[1e-5, 2e-5, -3e-5])
    for dt in (0.0, 1.0, 10.0):
        assert np.allclose(g.measure(w, dt), w + [1e-5, 2e-5, -3e-5], rtol=0, atol=1e-20)
    assert np.array_equal(g.bias, [1e-5, 2e-5, -3e-5])


def test_gyro_white_noise_std():
    std = np.array([1e-4, 2e-4, 5e-5])
    g = Gyro(noise_std_rad_s=std, seed=8)
    n = 20000
    err = np.array([g.measure([0.0, 0.0, 0.0], 1.0) for _ in range(n)])
    assert np.allclose(err.std(axis=0), std, rtol=5 / math.sqrt(2 * n))
    assert np.allclose(g.covariance, np.diag(std ** 2))


def test_gyro_bias_random_walk_variance_grows_linearly():
    """Var(beta(t) - beta0) = sigma_w^2 t: slope from an ensemble of independent gyros."""
    sigma_w = np.array([1e-6, 2e-6, 4e-6])
    dts = [0.0] + [1.0, 3.0, 0.5, 2.5] * 10          # uneven steps: sqrt(dt) scaling matters
    t = np.cumsum(dts)
    n_gyros = 1500
    drift = np.empty((n_gyros, len(dts), 3))
    for i in range(n_gyros):
        g = Gyro(bias_initial_rad_s=[1e-3, 0.0, 0.0], bias_walk_std_rad_s_sqrt_s=sigma_w, seed=i)
        drift[i] = [g.measure([0.0, 0.0, 0.0], dt) - [1e-3, 0.0, 0.0] for dt in dts]
    var = drift.var(axis=0) / sigma_w ** 2             # (len, 3), should be t
    assert np.all(var[0] == 0.0)
    slope = (var * t[:, None]).sum(axis=0) / (t ** 2).sum()   # least squares through 0
    # the slope is dominated by the late variances: relative std ~ sqrt(2 / n_gyros) = 3.7 %
    assert np.allclose(slope, 1.0, atol=5 * math.sqrt(2 / n_gyros))
    # linear, not a function of the number of steps: half-time variance is half
    half = len(t) // 2
    ratio = var[-1] / var[half] * t[half] / t[-1]
    assert np.allclose(ratio, 1.0, atol=0.25)


def test_gyro_default_drift_constant():
    """3 sigma of the bias walk after one hour = 0.01 deg/h (paper 001's random drift)."""
    assert 3 * GYRO_DRIFT_WALK_RAD_S_SQRT_S * math.sqrt(3600.0) == pytest.approx(
        math.radians(0.01) / 3600.0, rel=1e-12)


def test_gyro_determinism_and_bad_input():
    kw = dict(noise_std_rad_s=1e-4, bias_walk_std_rad_s_sqrt_s=1e-5)
    a, b = Gyro(seed=2, **kw), Gyro(seed=2, **kw)
    for dt in (0.0, 1.0, 2.0):
        assert np.array_equal(a.measure([0.1, 0.0, 0.0], dt), b.measure([0.1, 0.0, 0.0], dt))
    with pytest.raises(ValueError):
        a.measure([0.0, 0.0, 0.0], -1.0)
    with pytest.raises(ValueError):
        a.measure([0.0, np.nan, 0.0], 1.0)
    for bad in (dict(noise_std_rad_s=-1.0), dict(bias_walk_std_rad_s_sqrt_s=[1.0, 1.0]),
                dict(bias_initial_rad_s=[np.nan, 0, 0]), dict(seed='1')):
        with pytest.raises(ValueError):
            Gyro(**bad)
