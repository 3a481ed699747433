"""Paper 000's free tumble on the FrameLoop (the plain engine: no ROS, no process): the
initial state is the paper's, and the trajectory is an independent scipy integration's.

These were launched-graph tests (``tests/integration/test_free_tumble.py``); the assertions
are theirs, with the same numbers and tolerances. That the graph gives the FrameLoop's series
is ``tests/graph/test_engine_parity.py``; recording, rates, determinism under load, Ctrl-C and
killed nodes stay graph tests (``tests/graph/test_free_tumble.py``).
"""
import math

import numpy as np
from scipy.integrate import solve_ivp

from adcs_nodes.core import attitude as att
from frameloop_run import q, raw, run, v, validated

MU = 3.986004418e14


def test_initial_state_is_the_papers(tmp_path):
    out, _ = run(validated(tmp_path, raw('free_tumble')), 10.0)
    first = out['sim/state'][0]
    # paper 000: Lambda(0) = (0.36, 0.48, -0.48, 0.64), scalar first, maps body to orbit
    assert att.angle_between(q(first.q_orbit_body), [0.48, -0.48, 0.64, 0.36]) < 1e-9
    assert np.allclose(v(first.omega_body_eci_body), np.radians([-3.0, 3.0, 3.0]), atol=1e-15)


def test_trajectory_matches_an_independent_integration(tmp_path):
    """Gravity gradient + constant torque, integrated by scipy from the engine's orbit."""
    sc = raw('free_tumble')
    sc['spacecraft']['disturbance']['random_std_Nm'] = 0.0
    sc['duration_s'] = 300.0
    out, _ = run(validated(tmp_path, sc))
    states, envs = out['sim/state'], out['sim/environment']
    inertia = np.diag(sc['spacecraft']['inertia_kgm2'])
    tau_c = np.array(sc['spacecraft']['disturbance']['constant_torque_Nm'])
    r0, v0 = v(envs[0].r_eci), v(envs[0].v_eci)
    n = math.sqrt(MU / np.linalg.norm(r0)**3)

    def r_eci(t):  # circular orbit: rotation of r0 in the (r0, v0) plane
        return r0 * math.cos(n * t) + v0 / n * math.sin(n * t)

    def rhs(t, x):
        qq, w = x[:4] / np.linalg.norm(x[:4]), x[4:]
        c_body_eci = att.to_matrix(qq).T
        rb = c_body_eci @ r_eci(t)
        rn = np.linalg.norm(rb)
        tau = 3 * MU / rn**5 * np.cross(rb, inertia @ rb) + tau_c
        wdot = np.linalg.solve(inertia, tau - np.cross(w, inertia @ w))
        qdot = 0.5 * att.multiply(qq, np.r_[w, 0.0])
        return np.r_[qdot, wdot]

    x0 = np.r_[q(states[0].q_eci_body), v(states[0].omega_body_eci_body)]
    sol = solve_ivp(rhs, (0.0, 300.0), x0, method='DOP853', rtol=1e-11, atol=1e-13,
                    t_eval=[100.0, 200.0, 300.0])
    for j, k in enumerate([100, 200, 300]):
        s = states[k]
        assert att.angle_between(q(s.q_eci_body), sol.y[:4, j]) < 1e-7, f't={k} s attitude'
        assert np.allclose(v(s.omega_body_eci_body), sol.y[4:, j], atol=1e-9), \
            f't={k} s rate'
