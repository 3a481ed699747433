"""Run metrics (adcs_nodes.tools.analyse.metrics) on synthetic signals whose answers are known by
hand."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from adcs_nodes.tools.analyse import metrics as m


def test_capture_is_entry_into_the_band_then_staying_in_the_hold_band():
    t = np.arange(10.0)
    #           0     1    2    3    4    5    6    7    8    9
    e = [90.0, 40.0, 12., 4.0, 7.0, 3.0, 6.0, 2.0, 1.0, 1.0]
    # last sample >= 10 deg is index 2; first sample < 5 after it is index 3
    assert m.capture_index(e, 5.0, 10.0) == 3
    assert m.capture_time(t, e, 5.0, 10.0) == 3.0
    # the last exit from 5 deg is at index 6 -> final stay starts at index 7
    assert m.last_exit_time(t, e, 5.0) == 7.0
    assert m.first_entry_time(t, e, 5.0) == 3.0


def test_never_captured_and_edge_cases():
    t = np.arange(4.0)
    assert m.capture_time(t, [1.0, 2.0, 3.0, 11.0]) is None      # leaves the hold band at the end
    assert m.capture_time(t, [1.0, 2.0, 3.0, 4.0]) == 0.0        # captured from the start
    assert m.capture_time(t, [20.0, 9.0, 8.0, 7.0]) is None      # in the hold band, never < 5
    assert m.last_exit_time(t, [1.0, 6.0, 1.0, 6.0]) is None
    assert m.capture_time([], []) is None
    # NaN counts as outside every band
    assert m.capture_time(t, [1.0, np.nan, 1.0, 1.0]) == 2.0
    with pytest.raises(ValueError):
        m.capture_index([1.0], 5.0, 4.0)
    with pytest.raises(ValueError):
        m.capture_time([0.0, 1.0], [1.0])


def test_hold_stats_of_a_sine_have_the_analytic_values():
    # e(t) = 2 |sin(t)| sampled densely over whole periods: RMS = 2/sqrt(2), median = 2 sin(pi/4)
    # (half the samples of |sin| lie above sin(pi/4)), p95 = 2 sin(0.95 pi/2), max = 2
    t = np.linspace(0.0, 100.0 * math.pi, 2_000_001)
    e = 2.0 * np.abs(np.sin(t))
    s = m.hold_stats(t, e, 0.0)
    assert s.rms == pytest.approx(math.sqrt(2.0), rel=1e-5)
    assert s.median == pytest.approx(2.0 * math.sin(math.pi / 4), rel=1e-4)
    assert s.p95 == pytest.approx(2.0 * math.sin(0.95 * math.pi / 2), rel=1e-4)
    assert s.max == pytest.approx(2.0, rel=1e-9)
    empty = m.hold_stats(t, e, 1e9)
    assert empty.samples == 0 and math.isnan(empty.rms)


def test_run_metrics_of_an_exponential_capture_with_a_late_spike():
    # e = 120 exp(-t / tau) + 0.5 with a 6 deg spike at 4.5 orbits: the capture (entry into
    # 5 deg, staying below 10) is at tau ln(120 / 4.5); the last exit is after the spike
    period = 6000.0
    tau = period / 2.0
    t = np.arange(0.0, 6 * period + 1, 10.0)
    e = 120.0 * np.exp(-t / tau) + 0.5
    spike = (t >= 4.5 * period) & (t < 4.5 * period + 100.0)
    e[spike] = 6.0
    out = m.run_metrics(t, e, period)
    t_enter = tau * math.log(120.0 / 4.5)
    assert out['capture_time_s'] == pytest.approx(t_enter, abs=10.0)
    assert out['capture_orbits'] == pytest.approx(t_enter / period, abs=10.0 / period)
    assert out['captured_in_time'] is True
    assert out['last_exit_s'] == pytest.approx(4.5 * period + 100.0)
    assert out['first_entry_s'] == out['capture_time_s']
    hold = e[t >= 4 * period]
    assert out['hold_rms_deg'] == pytest.approx(math.sqrt(np.mean(hold ** 2)))
    assert out['hold_max_deg'] == 6.0
    assert out['hold_from_s'] == 4 * period and out['hold_complete']
    late = m.run_metrics(t, 400.0 * np.exp(-t / period) + 0.1, period)
    assert late['captured_in_time'] is False and late['capture_orbits'] == pytest.approx(
        math.log(400.0 / 4.9), abs=0.01)


def test_quaternion_angles_match_scipy():
    rng = np.random.default_rng(3)
    a = Rotation.random(50, random_state=rng)
    b = Rotation.random(50, random_state=rng)
    expected = np.degrees((a.inv() * b).magnitude())
    assert np.allclose(m.angle_between_deg(a.as_quat(), b.as_quat()), expected, atol=1e-9)
    assert np.allclose(m.angle_to_identity_deg(-a.as_quat()), np.degrees(a.magnitude()),
                       atol=1e-9)
    tiny = Rotation.from_rotvec([1e-9, 0.0, 0.0]).as_quat()
    assert m.angle_to_identity_deg(tiny)[0] == pytest.approx(math.degrees(1e-9), rel=1e-6)
