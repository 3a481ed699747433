"""Independent truth for paper 000's example: the rigid-body equations in ECI, for scipy.

Used by the filter tests (``tests/unit/test_magnetic_filter_bias.py``,
``tests/unit/test_live_gaps.py``) with ``solve_ivp`` (DOP853), independent of the project's
dynamics and of the filter's (33).
"""
import numpy as np
from scipy.spatial.transform import Rotation

from adcs_nodes.core.orbit import MU_EARTH


def rigid_body_rhs(orbit, inertia, accel_dist):
    """``rhs(t, x)`` of ``x = [q_eci_body (4, scalar-last), omega_body_eci_body (3) rad/s]``:
    kinematics ``dq/dt = 1/2 Omega(omega) q``, Euler's equation with the gravity-gradient
    torque ``3 mu / r^3 r_b x (I r_b)`` at the orbit's position, plus a constant angular
    acceleration ``accel_dist`` (3,) [rad/s^2] (paper 000's ``I^-1 M_r``)."""
    inertia = np.asarray(inertia, dtype=float)
    i_inv, accel_dist = np.linalg.inv(inertia), np.asarray(accel_dist, dtype=float)

    def rhs(t, x):
        q, w = x[:4], x[4:]
        r = orbit.state(t).r_eci
        r_b = Rotation.from_quat(q).inv().apply(r) / np.linalg.norm(r)
        torque = 3 * MU_EARTH / np.linalg.norm(r) ** 3 * np.cross(r_b, inertia @ r_b)
        big_omega = np.array([[0, w[2], -w[1], w[0]], [-w[2], 0, w[0], w[1]],
                              [w[1], -w[0], 0, w[2]], [-w[0], -w[1], -w[2], 0]])
        return np.r_[0.5 * big_omega @ q,
                     i_inv @ (torque - np.cross(w, inertia @ w)) + accel_dist]
    return rhs
