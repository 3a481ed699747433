"""Flexible appendages in the world integrator (sim_node.models.dynamics + kernels, issue 9).

Truth used here:
* ``reference_dynamics.FlexibleSpacecraft`` (tests/unit): an independent implementation of the same
  hybrid equations (numpy, its own RK4 loop) must give the same trajectory to round-off;
* conservation laws: without damping and torques the energy
  ``1/2 [w; eta_dot]^T M [w; eta_dot] + 1/2 eta^T Lambda^2 eta`` and the inertial angular
  momentum ``R(q) (I w + F eta_dot + A h_w)``, written here from the equations;
* with zero coupling a mode is a damped harmonic oscillator (closed form) and the body moves
  as the rigid model does;
* the wheel limits: the torque stops at the momentum limit even with the momentum error.
"""
import math

import numpy as np
import pytest

from adcs_nodes.core import attitude
from sim_node.models.actuators import WheelCluster, WheelMomentumError
from sim_node.models.disturbances import ConstantTorque, HarmonicTorque
from sim_node.models.dynamics import (ActuatorCommand, FlexibleModes, FrameEnvironment,
                                      Spacecraft, SpacecraftState)
from reference_dynamics import FlexibleSpacecraft, pack_state, unpack_state
from sim_node.models.flexible import PAPER001_INERTIA, paper001_modes
from sim_node.models.spacecraft_config import SPACECRAFT, spacecraft_from_config

Q0 = attitude.normalize([0.1, -0.2, 0.3, 0.9])
W0 = np.radians([0.3, -0.3, 0.3])
ENV = FrameEnvironment(np.array([6978.137e3, 0.0, 0.0]), np.array([0.0, 1035.0, 7486.0]))


def _disturbances():
    return [HarmonicTorque([1e-3, 2e-3, 5e-4], 0.01, seed=3),
            ConstantTorque([1e-4, -2e-4, 3e-4])]


@pytest.mark.parametrize('wings', ['one', 'two'])
def test_kernel_with_modes_agrees_with_the_independent_flexible_model(wings):
    """Same equations, two implementations (compiled kernel vs flexible.py's numpy RK4):
    200 frames of 0.2 s with varying wheel commands (torque limit hit), disturbances, the
    momentum error, 4 substeps; agreement to round-off."""
    f, freq = paper001_modes(wings)
    wheels = WheelCluster(np.eye(3), 1.0, 55.0, 0.1)
    ref = FlexibleSpacecraft(PAPER001_INERTIA, f, freq, 0.005, wheels, _disturbances(),
                             wheel_error=WheelMomentumError(0.01, 0.2, 3, 5))
    sc = Spacecraft(PAPER001_INERTIA, wheels=wheels, disturbances=_disturbances(),
                    gravity_gradient=False, flexible=FlexibleModes(f, freq, 0.005),
                    wheel_error=WheelMomentumError(0.01, 0.2, 3, 5))
    eta0 = np.linspace(-1e-3, 1e-3, f.shape[1])
    x = ref.pack(Q0, W0, eta=eta0, h_wheels=[1.0, -2.0, 3.0])
    st = SpacecraftState(Q0, W0, [1.0, -2.0, 3.0], eta0, np.zeros(f.shape[1]))
    for k in range(200):
        t = 0.2 * k
        cmd = np.array([0.8 * np.sin(0.3 * t), -1.5 * np.cos(0.2 * t), 0.5])
        x, ap_ref = ref.step(x, t, 0.2, cmd, substeps=4)
        st, ap = sc.step(st, t, 0.2, ENV, ActuatorCommand(wheel_torque=cmd), 4)
        np.testing.assert_array_equal(ap['torque_limited'], ap_ref['torque_limited'])
        np.testing.assert_allclose(ap['wheel_torque'], ap_ref['wheel_torque'], rtol=0,
                                   atol=1e-15)
    u = ref.unpack(x)
    assert np.max(np.abs(u['eta'])) > 1e-4                   # the modes are excited
    for key, value in (('q_eci_body', st.q_eci_body), ('omega_body_eci_body',
                                                       st.omega_body_eci_body),
                       ('eta', st.eta), ('eta_dot', st.eta_dot), ('h_wheels', st.h_wheels)):
        scale = np.max(np.abs(u[key]))
        np.testing.assert_allclose(value, u[key], rtol=0, atol=1e-11 * scale, err_msg=key)


def _energy(inertia, f, lam, w, eta, eta_dot):
    """Kinetic + strain energy written from (E2f), (E9): 1/2 v^T M v + 1/2 sum lam^2 eta^2."""
    kin = 0.5 * w @ inertia @ w + w @ f @ eta_dot + 0.5 * eta_dot @ eta_dot
    return kin + 0.5 * np.sum((lam * eta) ** 2)


def test_energy_and_angular_momentum_are_conserved_without_damping_and_torque():
    f, freq = paper001_modes('two')
    lam = 2 * math.pi * freq
    axes = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]])
    sc = Spacecraft(PAPER001_INERTIA, wheels=WheelCluster(axes, 1.0, 55.0, 0.1),
                    gravity_gradient=False, flexible=FlexibleModes(f, freq, 0.0))
    h_w = np.array([5.0, -3.0, 2.0, 1.0])
    st = SpacecraftState(Q0, np.radians([2.0, -1.5, 1.0]), h_w,
                         np.linspace(-2e-2, 3e-2, 10), np.linspace(1e-2, -1e-2, 10))
    unit = axes / np.linalg.norm(axes, axis=1, keepdims=True)

    def h_eci(s):
        return attitude.to_matrix(s.q_eci_body) @ (PAPER001_INERTIA @ s.omega_body_eci_body
                                                   + f @ s.eta_dot + unit.T @ s.h_wheels)

    e0 = _energy(PAPER001_INERTIA, f, lam, st.omega_body_eci_body, st.eta, st.eta_dot)
    h0 = h_eci(st)
    for k in range(200):                       # 20 s in 0.005 s RK4 steps
        st, _ = sc.step(st, 0.1 * k, 0.1, ENV, sc.zero_command(), 20)
    e1 = _energy(PAPER001_INERTIA, f, lam, st.omega_body_eci_body, st.eta, st.eta_dot)
    assert e0 > 0 and abs(e1 - e0) / e0 < 1e-6, (e0, e1)
    assert np.linalg.norm(h_eci(st) - h0) / np.linalg.norm(h0) < 1e-9
    np.testing.assert_array_equal(st.h_wheels, h_w)          # no motor torque
    assert np.max(np.abs(st.eta)) > 1e-3                      # still oscillating


def test_damping_dissipates_energy():
    f, freq = paper001_modes('one')
    sc = Spacecraft(PAPER001_INERTIA, gravity_gradient=False,
                    flexible=FlexibleModes(f, freq, 0.05))
    st = SpacecraftState(Q0, np.zeros(3), [], np.full(5, 1e-2), np.zeros(5))
    energies = []
    for k in range(50):
        st, _ = sc.step(st, 0.2 * k, 0.2, ENV, sc.zero_command(), 20)
        energies.append(_energy(PAPER001_INERTIA, f, 2 * math.pi * freq,
                                st.omega_body_eci_body, st.eta, st.eta_dot))
    assert np.all(np.diff(energies) < 0.0) and energies[-1] < 0.5 * energies[0]


def test_uncoupled_modes_are_damped_oscillators_and_the_body_stays_rigid():
    """F = 0: each mode follows the closed-form damped oscillation; the body moves exactly as
    the rigid model (same arithmetic in the kernel)."""
    inertia = np.array([[118.0, 3.0, -2.0], [3.0, 100.0, 4.0], [-2.0, 4.0, 19.6]])
    freq = np.array([0.16, 0.85, 2.55])
    zeta = np.array([0.0, 0.02, 0.005])
    flex = Spacecraft(inertia, flexible=FlexibleModes(np.zeros((3, 3)), freq, zeta))
    rigid = Spacecraft(inertia)
    eta0 = np.array([1e-2, -2e-2, 5e-3])
    s_f = SpacecraftState(Q0, W0, [], eta0, np.zeros(3))
    s_r = SpacecraftState(Q0, W0)
    dt, n = 0.1, 100
    for k in range(n):
        s_f, _ = flex.step(s_f, k * dt, dt, ENV, flex.zero_command(), 10)
        s_r, _ = rigid.step(s_r, k * dt, dt, ENV, rigid.zero_command(), 10)
    np.testing.assert_array_equal(s_f.q_eci_body, s_r.q_eci_body)
    np.testing.assert_array_equal(s_f.omega_body_eci_body, s_r.omega_body_eci_body)
    t = n * dt
    wn = 2 * math.pi * freq
    wd = wn * np.sqrt(1 - zeta ** 2)
    exact = eta0 * np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta * wn / wd * np.sin(wd * t))
    # RK4's phase error (w h)^5 / 120 per step bounds the difference (steps h = 0.01 s)
    bound = 2.0 * (n * 10) * (wn * 0.01) ** 5 / 120.0 * np.abs(eta0) + 1e-15
    assert np.all(np.abs(s_f.eta - exact) <= bound), (s_f.eta - exact, bound)


def test_wheel_torque_stops_at_the_momentum_limit_and_the_status_says_so():
    wheels = WheelCluster(np.eye(3), 1.0, 55.0, 0.1)
    f, freq = paper001_modes('two')
    sc = Spacecraft(PAPER001_INERTIA, wheels=wheels, gravity_gradient=False,
                    flexible=FlexibleModes(f, freq, 0.005),
                    wheel_error=WheelMomentumError(0.01, 0.2, 3, 1))
    st = sc.zero_state(Q0, np.zeros(3), [54.95, 0.0, -10.0])
    cmd = ActuatorCommand(wheel_torque=np.array([1.0, 2.0, -0.3]))
    hx = []
    for k in range(10):
        st, ap = sc.step(st, 0.2 * k, 0.2, ENV, cmd, 4)
        hx.append(st.h_wheels[0])
        np.testing.assert_array_equal(ap['torque_limited'], [False, True, False])
        assert ap['momentum_limited'][0] and not ap['momentum_limited'][2]
        assert np.all(np.abs(ap['wheel_torque']) <= 1.0)
    # the error (0.01 N m s 1-sigma here) moves the wheel about, never past the limit
    assert max(hx) <= 55.0 + 1e-9 and min(hx) > 54.9
    exact = Spacecraft(PAPER001_INERTIA, wheels=wheels, gravity_gradient=False,
                       flexible=FlexibleModes(f, freq, 0.005))
    st = exact.zero_state(Q0, np.zeros(3), [54.95, 0.0, -10.0])
    torque_x = []
    for k in range(3):
        st, ap = exact.step(st, 0.2 * k, 0.2, ENV, cmd, 4)
        torque_x.append(ap['wheel_torque'][0])
        assert ap['momentum_limited'][0]
    assert torque_x == pytest.approx([0.25, 0.0, 0.0], abs=1e-12)   # stops at the limit
    assert st.h_wheels[0] == pytest.approx(55.0, abs=1e-12)


def test_state_packing_and_bad_modal_state_are_refused():
    f, freq = paper001_modes('one')
    sc = Spacecraft(PAPER001_INERTIA, flexible=FlexibleModes(f, freq, 0.005))
    st = SpacecraftState(Q0, W0, [], np.arange(5.0), -np.arange(5.0))
    back = unpack_state(pack_state(st), n_modes=5)
    np.testing.assert_array_equal(back.eta, st.eta)
    np.testing.assert_array_equal(back.eta_dot, st.eta_dot)
    with pytest.raises(ValueError, match='eta'):
        sc.step(SpacecraftState(Q0, W0), 0.0, 0.2, ENV, sc.zero_command())
    bad = SpacecraftState(Q0, W0, [], np.full(5, np.nan), np.zeros(5))
    with pytest.raises(ValueError, match='eta'):
        sc.step(bad, 0.0, 0.2, ENV, sc.zero_command())
    with pytest.raises(ValueError, match='hub inertia'):
        Spacecraft(np.diag([100.0, 100.0, 100.0]), flexible=FlexibleModes(f, freq))
    with pytest.raises(ValueError, match='damping'):
        FlexibleModes(f, freq, 1.5)
    FlexibleModes(f, freq, 1.0)        # critical damping: the spec's [0, 1] range
    with pytest.raises(ValueError, match='frequencies'):
        FlexibleModes(f, freq[:4])


def test_config_builds_the_paper001_world():
    wheels = [{'name': f'w{i}', 'axis': list(axis), 'max_torque_Nm': 1.0,
               'max_momentum_Nms': 55.0, 'inertia_kgm2': 0.1} for i, axis in enumerate(np.eye(3))]
    cfg = {'inertia_kgm2': PAPER001_INERTIA.tolist(), 'gravity_gradient': True,
           'wheels': wheels, 'flexible': {'model': 'paper001', 'wings': 'two', 'damping': 0.01},
           'disturbance': {'aerodynamic_Nm': [1e-6] * 3, 'solar_pressure_Nm': [1e-5] * 3,
                           'residual_magnetic_Nm': [1e-8] * 3, 'unloading_Nm': [1e-3] * 3,
                           'harmonic_period_s': 5801.0, 'unloading_period_s': 600.0,
                           'unloading_duration_s': 60.0},
           'wheel_error_std_Nms': 0.01 / 3, 'wheel_error_period_s': 0.2}
    sc = spacecraft_from_config(cfg, seed=7)
    assert sc.n_modes == 10 and sc.flexible.damping[0] == 0.01
    assert sc.wheel_error is not None and sc.wheel_error.period_s == 0.2
    torques = np.array([sum(d.torque(t) for d in sc.disturbances) for t in (10.0, 100.0)])
    assert np.all(np.abs(torques[0]) > 9e-4) and np.all(np.abs(torques[0]) < 1.1e-3)  # pulse
    assert np.all(np.abs(torques[1]) < 2.5e-5)           # between pulses: aero + solar only
    again = spacecraft_from_config(cfg, seed=7)
    np.testing.assert_array_equal(sum(d.torque(10.0) for d in again.disturbances),
                                  torques[0])                               # seeded
    other = spacecraft_from_config(cfg, seed=8)
    assert not np.array_equal(sum(d.torque(10.0) for d in other.disturbances), torques[0])
    with pytest.raises(ValueError, match='flexible.model'):
        spacecraft_from_config({**cfg, 'flexible': {'model': 'nope'}}, seed=1)
    with pytest.raises(ValueError, match='harmonic_period_s'):
        spacecraft_from_config({**cfg, 'disturbance': {**cfg['disturbance'],
                                                       'harmonic_period_s': 0.0}}, seed=1)


def test_graph_gives_the_dynamics_node_the_flexible_world():
    import os
    from adcs_nodes.graph import build_graph, orbital_period_s, topic_type
    from adcs_nodes.scenario import load_scenario
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    sc = load_scenario(os.path.join(root, 'scenarios', 'paper001_mpi_two_wings.yaml'))
    nodes = build_graph(sc, 10.0, record=True)
    dyn = next(n for n in nodes if n.name == 'dynamics')
    p = dyn.params
    assert p['spacecraft.flexible.model'] == 'paper001'
    assert p['spacecraft.disturbance.unloading_Nm'] == [1e-3] * 3
    # 600 km circular orbit: T = 2 pi sqrt(a^3 / mu) = 5801 s
    assert p['spacecraft.disturbance.harmonic_period_s'] == pytest.approx(5801.0, abs=1.0)
    assert orbital_period_s(sc['orbit']) == pytest.approx(5801.0, abs=1.0)
    assert 'sim/appendages' in dyn.publishes
    assert topic_type('sim/appendages') == 'adcs_msgs/msg/AppendageState'
    rec = next(n for n in nodes if n.name == 'recorder')
    assert 'sim/appendages=adcs_msgs/msg/AppendageState' in rec.params['topics']
    assert spacecraft_from_config(SPACECRAFT.read(p, 'spacecraft'), seed=1).n_modes == 10
    # (two wings, 5 each)
    # the replication scenario: the 5 modes of (32) only (F = C_a, digest option R)
    one = build_graph(load_scenario(os.path.join(root, 'scenarios', 'paper001_mpi.yaml')),
                      10.0, record=True)
    p1 = next(n for n in one if n.name == 'dynamics').params
    assert spacecraft_from_config(SPACECRAFT.read(p1, 'spacecraft'), seed=1).n_modes == 5
