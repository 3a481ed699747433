"""Flexible spacecraft of paper 001 (sim_node.models.flexible), wheel status and momentum
error (actuators), paper 001 disturbance torques (disturbances).

Truth: the paper's modal frequencies (FFT of free oscillations with the hub held by a huge
inertia); the free-free frequencies from numpy's eigenvalues of ``M^-1 K``; conservation of
energy and inertial angular momentum without damping or torque; the logarithmic decrement of
a damped oscillator; the limits themselves; sample statistics of seeded draws.
"""
import math
import sys

import numpy as np
import pytest

sys.modules.setdefault('rclpy', None)

from reference_dynamics import FlexibleSpacecraft  # noqa: E402
from sim_node.models import flexible as fx  # noqa: E402
from sim_node.models.actuators import WheelCluster, WheelMomentumError  # noqa: E402
from sim_node.models.disturbances import HarmonicTorque, PeriodicPulseTorque  # noqa: E402

W0 = 1.0831e-3


def _simulate(sc, x, t_end, dt, record, substeps=1, **kw):
    out = []
    for k in range(int(round(t_end / dt))):
        out.append(record(x))
        x, _ = sc.step(x, k * dt, dt, substeps=substeps, **kw)
    return np.array(out), x


def _peak_hz(signal, dt, pad=16):
    s = (signal - signal.mean()) * np.hanning(len(signal))
    spec = np.abs(np.fft.rfft(s, n=pad * len(s)))
    freqs = np.fft.rfftfreq(pad * len(s), dt)
    return freqs, spec


def test_paper_modes_data():
    f, freq = fx.paper001_modes('two')
    assert f.shape == (3, 10) and freq.shape == (10,)
    np.testing.assert_allclose(f[:, :5], fx.PAPER001_COUPLING_ONE_WING)
    np.testing.assert_allclose(f[:, 5:], np.diag([-1, -1, 1]) @ fx.PAPER001_COUPLING_ONE_WING)
    # digest CHECK: one wing's sum C_a C_a^T has diagonal ~ [138, 590, 708] kg m^2
    np.testing.assert_allclose(np.diag(f[:, :5] @ f[:, :5].T), [138, 590, 708], rtol=5e-3)
    f1, freq1 = fx.paper001_modes('one')
    assert f1.shape == (3, 5)
    with pytest.raises(ValueError, match='wings'):
        fx.paper001_modes('three')


def test_clamped_hub_oscillates_at_the_paper_frequencies():
    """A hub 1e8 times heavier does not move: each mode rings at its own frequency (FFT)."""
    f, freq = fx.paper001_modes('one')
    sc = FlexibleSpacecraft(fx.PAPER001_INERTIA * 1e8, f, freq, damping=0.0)
    x0 = sc.pack([0, 0, 0, 1], np.zeros(3), eta=np.ones(5))
    dt = 0.02                       # RK4 phase error (w h)^4 / 120 < 1e-4 at 2.55 Hz
    etas, _ = _simulate(sc, x0, 200.0, dt, lambda x: x[7:12].copy())
    for i, f_i in enumerate(fx.PAPER001_FREQUENCIES_HZ):
        freqs, spec = _peak_hz(etas[:, i], dt)
        assert abs(freqs[np.argmax(spec)] - f_i) < 1e-3


def test_free_free_frequencies_fft_and_eigenvalues():
    """Free spacecraft, small motion: the spectrum of the body rate peaks at the
    eigenfrequencies of K v = w^2 M v (numpy eig of M^-1 K), above the clamped ones."""
    f, freq = fx.paper001_modes('one')
    sc = FlexibleSpacecraft(fx.PAPER001_INERTIA, f, freq, damping=0.0)
    m_mat = np.block([[fx.PAPER001_INERTIA, f], [f.T, np.eye(5)]])
    k_mat = np.zeros((8, 8))
    k_mat[3:, 3:] = np.diag((2 * np.pi * freq) ** 2)
    lam = np.sort(np.real(np.linalg.eigvals(np.linalg.solve(m_mat, k_mat))))[3:]
    expected = np.sqrt(lam) / (2 * np.pi)
    np.testing.assert_allclose(sc.free_free_frequencies_hz(), expected, rtol=1e-9)
    assert np.all(expected > freq - 1e-12)
    x0 = sc.pack([0, 0, 0, 1], np.zeros(3), eta=1e-3 * np.ones(5))
    dt = 0.04
    rates, _ = _simulate(sc, x0, 300.0, dt, lambda x: x[4:7].copy())
    freqs, spec = _peak_hz(rates[:, 2], dt)     # z: modes 1, 3, 5 couple about z
    peaks = [freqs[i] for i in range(1, len(spec) - 1)
             if spec[i] > spec[i - 1] and spec[i] > spec[i + 1] and spec[i] > 1e-3 * spec.max()]
    for e in expected[[0, 2]]:                   # the two strongest z-coupled modes
        assert min(abs(p - e) for p in peaks) < 2e-3


@pytest.mark.parametrize('wings', ['one', 'two'])
def test_energy_and_angular_momentum_conserved_without_damping(wings):
    f, freq = fx.paper001_modes(wings)
    wheels = WheelCluster(np.eye(3), 1.0, 55.0, 0.1)
    sc = FlexibleSpacecraft(fx.PAPER001_INERTIA, f, freq, damping=0.0, wheels=wheels)
    rng = np.random.default_rng(3)
    x = sc.pack(rng.normal(size=4), [0.01, -0.02, 0.015], eta=0.05 * rng.normal(size=f.shape[1]),
                eta_dot=0.05 * rng.normal(size=f.shape[1]), h_wheels=[5.0, -3.0, 10.0])
    e0, h0 = sc.energy(x), sc.angular_momentum_eci(x)
    drift = []
    for substeps in (5, 10):              # h = 0.01 s and 0.005 s over 20 s
        y = x.copy()
        for k in range(400):
            y, _ = sc.step(y, k * 0.05, 0.05, substeps=substeps)
        drift.append(abs(sc.energy(y) - e0) / e0)
        np.testing.assert_allclose(sc.angular_momentum_eci(y), h0,
                                   atol=1e-9 * np.linalg.norm(h0))
    # the model conserves energy: what is left is RK4's dissipation, O(h^5) over a fixed time
    assert drift[1] < 1e-5 and drift[0] / drift[1] > 16.0


def test_modal_damping_log_decrement():
    f, freq = fx.paper001_modes('one')
    zeta = 0.02
    sc = FlexibleSpacecraft(fx.PAPER001_INERTIA * 1e8, f, freq, damping=zeta)
    x = sc.pack([0, 0, 0, 1], np.zeros(3), eta=np.ones(5))
    dt = 0.01
    eta0 = []
    for k in range(int(100 / dt)):
        eta0.append(x[7])
        x, _ = sc.step(x, k * dt, dt)
    eta0 = np.array(eta0)
    w = 2 * np.pi * 0.16
    t = np.arange(len(eta0)) * dt
    env = np.exp(-zeta * w * t)        # envelope of the damped 0.16 Hz oscillator
    peaks = [i for i in range(1, len(eta0) - 1)
             if eta0[i] > eta0[i - 1] and eta0[i] >= eta0[i + 1]]
    np.testing.assert_allclose(eta0[peaks], env[peaks], rtol=2e-3)


def test_wheel_torque_and_momentum_saturation_with_status():
    wheels = WheelCluster(np.eye(3), 1.0, 55.0, 0.1)
    sc = FlexibleSpacecraft(fx.PAPER001_INERTIA, np.zeros((3, 0)), [], wheels=wheels)
    x = sc.pack([0, 0, 0, 1], np.zeros(3), h_wheels=[54.5, 0.0, -10.0])
    x, applied = sc.step(x, 0.0, 0.2, wheel_torque_cmd=[3.0, -0.5, 0.2])
    np.testing.assert_allclose(applied['wheel_torque'], [1.0, -0.5, 0.2])
    np.testing.assert_array_equal(applied['torque_limited'], [True, False, False])
    np.testing.assert_array_equal(applied['momentum_limited'], [False, False, False])
    for k in range(1, 6):                       # 54.7 -> the limit: the torque stops there
        x, applied = sc.step(x, k * 0.2, 0.2, wheel_torque_cmd=[1.0, 0.0, 0.0])
    assert sc.unpack(x)['h_wheels'][0] == pytest.approx(55.0, abs=1e-12)
    assert applied['wheel_torque'][0] == 0.0 and applied['momentum_limited'][0]
    x, applied = sc.step(x, 2.0, 0.2, wheel_torque_cmd=[-1.0, 0.0, 0.0])   # back off: free
    assert applied['wheel_torque'][0] == -1.0 and not applied['momentum_limited'][0]


def test_momentum_error_is_seeded_bounded_and_sized():
    err = WheelMomentumError(0.01 / 3, 0.2, 3, seed=7)
    wheels = WheelCluster(np.eye(3), 1.0, 55.0, 0.1)
    sc = FlexibleSpacecraft(fx.PAPER001_INERTIA, np.zeros((3, 0)), [], wheels=wheels,
                            wheel_error=err)
    x = sc.pack([0, 0, 0, 1], np.zeros(3))
    hs = []
    for k in range(3000):
        x, _ = sc.step(x, k * 0.2, 0.2, wheel_torque_cmd=[0.01, 0.0, 0.0])
        hs.append(sc.unpack(x)['h_wheels'] - [0.01 * (k + 1) * 0.2, 0.0, 0.0])
    dev = np.array(hs)
    np.testing.assert_allclose(dev[-1], err.error(2999), atol=1e-12)   # (W5) exactly
    assert np.all(np.abs(dev.std(axis=0) / (0.01 / 3) - 1.0) < 0.1)      # 3000 samples
    np.testing.assert_array_equal(WheelMomentumError(0.01 / 3, 0.2, 3, 7).torque(12.3),
                                  err.torque(12.3))
    with pytest.raises(ValueError):
        WheelMomentumError(-1.0, 0.2, 3, 0)


def test_disturbance_models():
    h = HarmonicTorque([1e-5, 2e-5, 0.0], W0, seed=3)
    t = np.linspace(0, 2 * np.pi / W0, 4001)
    tau = np.array([h.torque(s) for s in t])
    np.testing.assert_allclose(np.abs(tau).max(axis=0), [1e-5, 2e-5, 0.0], rtol=1e-5)
    np.testing.assert_allclose(tau.mean(axis=0), 0.0, atol=1e-8)
    np.testing.assert_array_equal(HarmonicTorque(1e-5, W0, seed=3).phase_rad, h.phase_rad)
    assert not np.array_equal(HarmonicTorque(1e-5, W0, seed=4).phase_rad, h.phase_rad)
    p = PeriodicPulseTorque(1e-3, 600.0, 60.0, start_s=100.0, signs=[1, -1, 1])
    np.testing.assert_array_equal(p.torque(50.0), 0.0)
    np.testing.assert_array_equal(p.torque(130.0), [1e-3, -1e-3, 1e-3])
    np.testing.assert_array_equal(p.torque(200.0), 0.0)
    np.testing.assert_array_equal(p.torque(705.0), [1e-3, -1e-3, 1e-3])
    with pytest.raises(ValueError):
        PeriodicPulseTorque(1e-3, 10.0, 20.0)
    with pytest.raises(ValueError):
        HarmonicTorque(-1.0, W0)


def test_bad_configuration():
    f, freq = fx.paper001_modes('one')
    with pytest.raises(ValueError, match='hub'):
        FlexibleSpacecraft(np.eye(3) * 100.0, f, freq)
    with pytest.raises(ValueError, match='frequencies'):
        FlexibleSpacecraft(fx.PAPER001_INERTIA, f, freq[:4])
    with pytest.raises(ValueError, match='damping'):
        FlexibleSpacecraft(fx.PAPER001_INERTIA, f, freq, damping=1.5)
    sc = FlexibleSpacecraft(fx.PAPER001_INERTIA, f, freq)
    with pytest.raises(ValueError):
        sc.step(np.full(sc.size, np.nan), 0.0, 0.1)
    with pytest.raises(ValueError):
        sc.step(sc.pack([0, 0, 0, 1], np.zeros(3)), 0.0, 0.0)
    assert math.isfinite(sc.energy(sc.pack([0, 0, 0, 1], np.zeros(3))))
