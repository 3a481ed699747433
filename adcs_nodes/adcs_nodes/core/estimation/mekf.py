"""Multiplicative extended Kalman filter: star tracker + gyro with gyro-bias states.

Lefferts, Markley, Shuster, "Kalman filtering for spacecraft attitude estimation", JGCA 5(5),
1982; Markley & Crassidis, "Fundamentals of Spacecraft Attitude Determination and Control",
2014, section 6.2. The estimator that feeds paper 001's MPI controller (its sensors: star
tracker 0.02 deg 3-sigma, gyro drift 0.01 deg/h 3-sigma; digest section 4).

State and error state
---------------------
``q = q_eci_body`` (scalar last), gyro bias ``b`` [rad/s]; the error ``dx = [dtheta, db]`` with
``q_true = q (x) exp(dtheta)`` (body axes). Gyro model ``omega_m = omega + b + v``,
``db/dt = w_u``.

Propagation over ``dt`` with the mean of the previous and the fresh gyro samples (the held
previous sample when no fresh one came; a sample is the rate at its instant, so the mean is
exact for a linearly changing rate, where holding one sample leaves ``alpha dt^2 / 2``)::

    omega_m   = (omega_m,k-1 + omega_m,k) / 2
    omega_hat = omega_m - b
    q <- q (x) exp(omega_hat dt)                                                      (P1)
    Phi = [[R(omega_hat dt)^T, -dt E], [0, E]]                                         (P2)
    Q_d = [[s_v^2 dt^2 + s_u^2 dt^3 / 3, -s_u^2 dt^2 / 2], [., s_u^2 dt]] (x) E3         (P3)
    P <- Phi P Phi^T + Q_d

``s_v`` is the gyro's white noise per sample [rad/s] (held over ``dt``), ``s_u`` the bias
random-walk density [rad/s/sqrt(s)].

Star-tracker update (``H = [E3, 0]``, ``R = s_st^2 E3``)::

    z = rotvec(q^* (x) q_m)                      innovation, body axes [rad]           (U1)
    S = H P H^T + R,   K = P H^T S^-1,   dx = K z
    q <- q (x) exp(dtheta),   b <- b + db,   P <- (E - K H) P (E - K H)^T + K R K^T    (U2)

Output: ``q_orbit_body = q_eci_orbit^* (x) q``; ``omega_body_eci_body = omega_m - b``; the 6x6
covariance ``[[P_tt, -P_tb], [-P_bt, P_bb + s_v^2 E]]`` (angle, rate; body axes).

Assumptions (not in paper 001)
------------------------------
* ASSUMPTION: gyro white noise ``s_v = 1e-6 rad/s`` per sample (the paper gives only the
  drift); bias walk ``s_u = 2.69e-10 rad/s/sqrt(s)`` (0.01 deg/h 3-sigma after 1 h, as the
  simulated gyro).
* The filter starts at the first star-tracker sample (``q = q_m``, ``P_tt = s_st^2``); an
  innovation beyond the gate (NIS) is refused; ``max_rejections`` refusals in a row restart the
  filter from the next sample.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core import attitude as att
from adcs_nodes.core.control import integer, positive
from adcs_nodes.core.estimation.algorithms import Estimate6, EstimatorInputs, Step

#: Star tracker std per axis for paper 001's 0.02 deg (3-sigma) [rad].
STAR_TRACKER_STD_RAD = math.radians(0.02 / 3.0)
#: ASSUMPTION: gyro white noise per sample [rad/s].
GYRO_NOISE_STD_RAD_S = 1e-6
#: Bias random walk reaching 0.01 deg/h (3-sigma) after 1 h [rad/s/sqrt(s)].
GYRO_BIAS_WALK_RAD_S_SQRT_S = math.radians(0.01 / 3.0) / 3600.0 / math.sqrt(3600.0)


def _finite(a) -> bool:
    return a is not None and bool(np.all(np.isfinite(np.asarray(a, dtype=float))))


class MEKF:
    """Star tracker + gyro MEKF with bias states (module docstring): ``s_st`` per axis [rad]
    > 0, ``s_v`` per sample [rad/s] >= 0, ``s_u`` [rad/s/sqrt(s)] >= 0, the initial bias std per
    axis [rad/s] > 0, the largest accepted NIS ``z^T S^-1 z`` (3 dof) and the refusals in a row
    that restart the filter (>= 1). A bad value is a ``ValueError`` naming it.
    """

    def __init__(self, star_tracker_std_rad: float = STAR_TRACKER_STD_RAD,
                 gyro_noise_std_rad_s: float = GYRO_NOISE_STD_RAD_S,
                 gyro_bias_walk_rad_s_sqrt_s: float = GYRO_BIAS_WALK_RAD_S_SQRT_S,
                 p0_bias_rad_s: float = 1e-4, gate_nis: float = 100.0,
                 max_rejections: int = 10) -> None:
        self.s_st = positive(star_tracker_std_rad, 'star_tracker_std_rad', 'rad')
        self.s_v = positive(gyro_noise_std_rad_s, 'gyro_noise_std_rad_s', 'rad/s', zero=True)
        self.s_u = positive(gyro_bias_walk_rad_s_sqrt_s, 'gyro_bias_walk_rad_s_sqrt_s',
                            'rad/s/sqrt(s)', zero=True)
        self.p0_bias = positive(p0_bias_rad_s, 'p0_bias_rad_s', 'rad/s')
        self.gate = positive(gate_nis, 'gate_nis', '-')
        self.max_rejections = integer(max_rejections, 'max_rejections')
        self.reset()

    def reset(self) -> None:
        """Forget everything: the next star-tracker sample starts the filter."""
        self.q: Optional[np.ndarray] = None
        self.b = np.zeros(3)
        self.P = np.zeros((6, 6))
        self.omega_m: Optional[np.ndarray] = None
        self._rejected = 0

    def initialise(self, q_orbit_body0: ArrayLike, omega_body_orbit_body0: ArrayLike) -> None:
        """Estimator interface; the MEKF starts from its first star-tracker sample instead."""
        self.reset()

    # ------------------------------------------------------------------ filter steps
    def propagate(self, dt: float, omega_m: Optional[np.ndarray] = None) -> None:
        """(P1)-(P3) over ``dt`` [s] with the gyro rate ``omega_m`` (default: the held one)."""
        omega_m = self.omega_m if omega_m is None else omega_m
        if self.q is None or omega_m is None or not dt > 0.0:
            return
        w = omega_m - self.b
        self.q = att.normalize(att.multiply(self.q, att.from_rotation_vector(w * dt)))    # (P1)
        phi = np.eye(6)
        phi[:3, :3] = att.to_matrix(att.from_rotation_vector(w * dt)).T
        phi[:3, 3:] = -dt * np.eye(3)                                                     # (P2)
        su2, sv2 = self.s_u ** 2, self.s_v ** 2
        qd = np.zeros((6, 6))
        qd[:3, :3] = (sv2 * dt * dt + su2 * dt ** 3 / 3.0) * np.eye(3)
        qd[:3, 3:] = qd[3:, :3] = -0.5 * su2 * dt * dt * np.eye(3)
        qd[3:, 3:] = su2 * dt * np.eye(3)                                                 # (P3)
        self.P = phi @ self.P @ phi.T + qd
        self.P = 0.5 * (self.P + self.P.T)

    def update(self, q_meas: np.ndarray) -> tuple[bool, np.ndarray, str]:
        """(U1)-(U2) with a star-tracker attitude; returns (accepted, innovation, reason)."""
        if self.q is None:
            self.q = att.normalize(q_meas)
            self.b = np.zeros(3)
            self.P = np.diag([self.s_st ** 2] * 3 + [self.p0_bias ** 2] * 3)
            return True, np.zeros(3), ''
        z = att.to_rotation_vector(att.multiply(att.conjugate(self.q), q_meas))          # (U1)
        r = self.s_st ** 2 * np.eye(3)
        s = self.P[:3, :3] + r
        nis = float(z @ np.linalg.solve(s, z))
        if not math.isfinite(nis) or nis > self.gate:
            self._rejected += 1
            if self._rejected >= self.max_rejections:
                self.reset()
                return False, z, (f'{self.max_rejections} star-tracker samples refused in a '
                                  'row: filter restarted')
            return False, z, f'star-tracker innovation refused (NIS {nis:.3g} > {self.gate:g})'
        self._rejected = 0
        k = np.linalg.solve(s, self.P[:3, :]).T                                   # P H^T S^-1
        dx = k @ z
        self.q = att.normalize(att.multiply(self.q, att.from_rotation_vector(dx[:3])))
        self.b = self.b + dx[3:]
        ikh = np.eye(6)
        ikh[:, :3] -= k
        self.P = ikh @ self.P @ ikh.T + k @ r @ k.T                                       # (U2)
        self.P = 0.5 * (self.P + self.P.T)
        return True, z, ''

    def step(self, inputs: EstimatorInputs, t: float, dt: float) -> Step:
        """Propagate over ``dt`` (mean of the previous and the fresh gyro sample), then
        update with a fresh star-tracker sample."""
        out = Step(None)
        fresh = None
        gyro = inputs.gyro_rate_body
        if gyro is not None:
            g = np.asarray(gyro, dtype=float)
            if g.shape == (3,) and _finite(g):
                fresh = g.copy()
            else:
                out.rejections.append('gyro sample not a finite (3,) vector: refused')
        w_prop = self.omega_m if fresh is None else (
            fresh if self.omega_m is None else 0.5 * (self.omega_m + fresh))
        self.propagate(float(dt) if math.isfinite(dt) else 0.0, w_prop)
        if fresh is not None:
            self.omega_m = fresh
        qm = inputs.q_eci_body_meas
        if qm is not None:
            qm = np.asarray(qm, dtype=float)
            if qm.shape == (4,) and _finite(qm) and float(np.linalg.norm(qm)) > 1e-9:
                ok, z, why = self.update(qm / np.linalg.norm(qm))
                if ok:
                    out.updates = 1
                    out.innovation = [float(v) for v in z]
                else:
                    out.rejections.append(why)
            else:
                out.rejections.append('star-tracker sample not a finite unit quaternion: '
                                      'refused')
        out.covariance_trace = float(np.trace(self.P))
        if self.q is None or self.omega_m is None:
            return out
        if not (_finite(self.q) and _finite(self.b) and _finite(self.P)):
            self.reset()
            out.rejections.append('filter state not finite: restarted')
            return out
        q_orbit_body = att.multiply(att.conjugate(att.normalize(inputs.ref.q_eci_orbit)),
                                    self.q)
        cov = np.zeros((6, 6))
        cov[:3, :3] = self.P[:3, :3]
        cov[:3, 3:] = -self.P[:3, 3:]
        cov[3:, :3] = -self.P[3:, :3]
        cov[3:, 3:] = self.P[3:, 3:] + self.s_v ** 2 * np.eye(3)
        out.estimate = Estimate6(q_orbit_body, self.omega_m - self.b, cov)
        return out
