"""Compiled world kernels (sim_node.models.kernels): one implementation, compiled or not.

Truth: the kernel's saturation against the actuator models' own ``apply`` (numpy ``clip``).
The same functions run as plain Python (``NUMBA_DISABLE_JIT=1``, a fresh interpreter) give the
compiled results of :func:`scenario` (identical, or within 1e-12 relative), and the compile
cache serves a second process without compiling: ``tests/graph/test_fresh_interpreters.py``
(processes).
"""
import numpy as np
import pytest

from adcs_nodes.core import attitude
from sim_node.models import kernels
from sim_node.models.actuators import Magnetorquer, WheelCluster, WheelMomentumError
from sim_node.models.disturbances import ConstantTorque, RandomTorque
from sim_node.models.dynamics import (ActuatorCommand, FlexibleModes, FrameEnvironment,
                                      Spacecraft, SpacecraftState)
from sim_node.models.flexible import PAPER001_INERTIA, paper001_modes

PYRAMID = np.array([[1.0, 1.0, 1.0], [-1.0, 1.0, 1.0], [-1.0, -1.0, 1.0], [1.0, -1.0, 1.0]])


def scenario():
    """Every kernel path in a few frames: gravity gradient, magnetorquers clipping, wheels
    hitting torque and momentum limits, constant + random disturbances, the field cubic; then
    the same with flexible modes (paper 001's two wings) and the wheel momentum error.
    Returns the trajectory as a list of float.hex strings (exact comparison)."""
    inertia = np.array([[118.0, 3.0, -2.0], [3.0, 100.0, 4.0], [-2.0, 4.0, 19.6]])
    wheels = WheelCluster(PYRAMID, max_torque=0.02, max_momentum=[0.5, 0.5, 0.5, np.inf],
                          inertia=0.01)
    sc = Spacecraft(inertia, magnetorquer=Magnetorquer([1.0, 2.0, 0.5]), wheels=wheels,
                    disturbances=[ConstantTorque([1e-5, 0.0, -2e-5]),
                                  RandomTorque(1e-5, 0.7, seed=3)])
    state = SpacecraftState(attitude.normalize([0.36, 0.48, -0.48, 0.64]),
                            np.radians([-3.0, 3.0, 3.0]), np.array([0.49, -0.3, 0.0, 2.0]))
    out = []
    f, freq = paper001_modes('two')
    flex = Spacecraft(PAPER001_INERTIA, magnetorquer=Magnetorquer([1.0, 2.0, 0.5]),
                      wheels=wheels, disturbances=[ConstantTorque([1e-5, 0.0, -2e-5])],
                      flexible=FlexibleModes(f, freq, 0.005),
                      wheel_error=WheelMomentumError(0.01, 1.0, 4, 2))
    out += _frames(sc, state, 6)
    out += _frames(flex, flex.zero_state(state.q_eci_body, state.omega_body_eci_body,
                                         state.h_wheels), 6)
    return out


def _frames(sc, state, n):
    out = []
    for k in range(n):
        t = 1.0 * k
        u = 0.2 + 1.06e-3 * t
        env = FrameEnvironment(7068.137e3 * np.array([np.cos(u), 0.0, np.sin(u)]),
                               7509.6 * np.array([-np.sin(u), 0.0, np.cos(u)]),
                               3e-5 * np.array([np.cos(2 * u), 0.3, np.sin(2 * u)]),
                               6.4e-8 * np.array([-np.sin(2 * u), 0.0, np.cos(2 * u)]))
        cmd = ActuatorCommand(np.array([3.0, -0.5, -2.0]), np.array([0.05, -0.01, 0.0, 0.03]),
                              np.array([0.0, 1e-4, 0.0]))
        state, applied = sc.step(state, t, 1.0, env, cmd, 10)
        values = [state.q_eci_body, state.omega_body_eci_body, state.h_wheels, state.eta,
                  state.eta_dot]
        values += [applied[key] for key in sorted(applied)]
        out.extend(float(v).hex() for arr in values for v in np.ravel(arr))
    return out


def test_saturation_matches_the_actuator_models():
    rng = np.random.default_rng(7)
    mtq = Magnetorquer([1.0, 0.0, 2.5])
    wheels = WheelCluster(PYRAMID, max_torque=[0.1, 0.2, 0.0, 0.05],
                          max_momentum=[1.0, np.inf, 2.0, 0.5], inertia=0.01)
    for dt in (0.1, 1.0, 10.0):
        for _ in range(200):
            m_cmd = rng.normal(0.0, 2.0, 3)
            t_cmd = rng.normal(0.0, 0.2, 4)
            h = rng.uniform(-1.2, 1.2, 4) * np.array([1.0, 5.0, 2.0, 0.5])
            dipole, tau = kernels.saturate(dt, m_cmd, mtq.max_dipole_Am2, t_cmd,
                                           wheels.max_torque, wheels.max_momentum, h)
            np.testing.assert_array_equal(dipole, mtq.apply(m_cmd))
            np.testing.assert_array_equal(tau, wheels.apply(t_cmd, h, dt))


@pytest.mark.parametrize('m', [0, 10])
def test_state_layout_is_named_and_contiguous(m):
    """The named slices cover the kernel state once, in order; wheels follow at H0, then the
    modal coordinates and their rates."""
    n = 4
    size = kernels.state_size(n, m)
    covered = np.zeros(size, dtype=int)
    eta, eta_dot = kernels.modal_slices(n, m)
    for sl in (kernels.Q, kernels.W, kernels.R, kernels.V, slice(kernels.H0, kernels.H0 + n),
               eta, eta_dot):
        covered[sl] += 1
    np.testing.assert_array_equal(covered, np.ones(size, dtype=int))
    assert eta.start == kernels.H0 + n and eta_dot.stop == size


@pytest.mark.parametrize('bad', [0.0, -1.0])
def test_zero_position_without_gravity_gradient_is_not_a_division_by_zero(bad):
    """r = 0 is allowed when gravity gradient is off (a free body): the orbit term is 0."""
    sc = Spacecraft(np.diag([2.0, 3.0, 4.0]), gravity_gradient=False)
    s, _ = sc.step(SpacecraftState([0.0, 0.0, 0.0, 1.0], [0.1, bad, 0.0]), 0.0, 1.0,
                   FrameEnvironment(np.zeros(3)), sc.zero_command(), 10)
    assert np.all(np.isfinite(s.omega_body_eci_body))
