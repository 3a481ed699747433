"""Estimator algorithms behind one interface (registry entries; the node only dispatches).

Interface
---------
Every algorithm has ``initialise(q_orbit_body0, omega_body_orbit_body0)`` and::

    step(inputs: EstimatorInputs, t, dt) -> Step

``dt`` is the time since the previous step [s] (0 at the first). ``Step.estimate`` is None
while there is nothing to publish; ``Step.rejections`` lists why samples were refused.

Algorithms here:

* :class:`MagneticFilterEstimator`: paper 000's filter (33)-(39) with its divergence reset
  (a restart from the initial estimate) and its covariance mapped to the published 6x6
  angle/rate one: the small error angle is ``2 phi`` (or ``2 mu``), so ``P_angle = 4 P_phi``,
  ``P_angle,rate = 2 P_phi,w``. An interval longer than ``max_step_s`` is predicted in
  ``n = ceil(dt / max_step_s)`` equal steps. **Sample interval**: theta and tau of (38) are
  given for one sample every ``theta_interval_s`` (10 s in paper 000); a sample ``d`` after
  the last accepted one updates with ``theta / r`` and ``tau * r``, ``r = d /
  theta_interval_s`` in [1e-3, 1] (0: off). **Hypotheses** (``hypotheses`` > 1, beyond the
  paper): a bank of filters turned about the measured field
  (:mod:`~adcs_nodes.core.estimation.hypotheses`); the misalignment states open when it
  decides (without a bank: at the first lock).
* :class:`GeometricEstimator`: TRIAD or paper 004's horizon + magnetometer yaw (formula (3)),
  with the rate as the finite difference of successive attitudes::

      omega_body_orbit_body = rotvec(q_prev^* q) / dt

Rate frames: ``omega_body_eci_body = omega_body_orbit_body + R(q_orbit_body)^T [0, omega0, 0]``
(the orbit frame turns at ``omega0`` about its y axis, the orbit normal).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Optional

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core import attitude as att
from adcs_nodes.core.control import positive
from adcs_nodes.core.estimation.horizon_yaw import (attitude_from_horizon_and_yaw,
                                                    triad_from_horizon_and_field,
                                                    yaw_from_horizon_and_field)
from adcs_nodes.core.estimation.hypotheses import HypothesisBank, locked
from adcs_nodes.core.estimation.magnetic_filter import MagneticFilter
from adcs_nodes.core.estimation.onboard import OnboardState
from adcs_nodes.core.kernels import jit

MAX_STEP_S = 2.0
"""Longest single prediction of :class:`MagneticFilterEstimator` [s] (ASSUMPTION: paper 000's
prediction interval, the one its tests validate)."""
#: Most prediction steps per estimator step (bounds the work after a very long pause).
MAX_PREDICTION_STEPS = 1000
#: Paper 000's sample interval [s], for which its theta and tau of (38) are given.
THETA_INTERVAL_S = 10.0
#: Floor of the interval ratio (two samples at one instant do not make theta infinite).
MIN_INTERVAL_RATIO = 1e-3


@dataclass(frozen=True)
class EstimatorInputs:
    """One frame of estimator input (fresh samples only; None = no new sample): the onboard
    reference at t, the magnetometer sample ``b_body`` (3,) [T] body axes, horizon roll and
    pitch [rad], the dipole applied over the last interval (3,) [A m^2] body axes, the gyro
    ``omega_body_eci_body`` (3,) [rad/s], the star tracker ``q_eci_body`` (4,) and the
    per-axis variances of ``b_body`` (3,) [T^2] from the sample's covariance."""

    ref: OnboardState
    b_body: Optional[np.ndarray] = None
    horizon_roll_pitch: Optional[tuple] = None
    dipole_body: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gyro_rate_body: Optional[np.ndarray] = None
    q_eci_body_meas: Optional[np.ndarray] = None
    b_body_var: Optional[np.ndarray] = None


@dataclass
class Estimate6:
    """Published estimate: attitude to the orbit frame, absolute rate, 6x6 covariance."""

    q_orbit_body: np.ndarray
    omega_body_eci_body: np.ndarray
    covariance: np.ndarray            # (6, 6): [angle (body, rad); rate (body, rad/s)]


@dataclass
class Step:
    """Result of one step: the estimate (or None) and the bookkeeping of the step."""

    estimate: Optional[Estimate6]
    updates: int = 0
    rejections: List[str] = field(default_factory=list)
    innovation: List[float] = field(default_factory=list)
    covariance_trace: float = 0.0


def _orbit_rate_body(q_orbit_body: ArrayLike, omega0: float) -> np.ndarray:
    """``R(q)^T [0, omega0, 0]`` (3,) [rad/s]: ``omega0`` times the second row of ``R(q)`` (the
    zero terms of the product drop out exactly), in Python floats as :func:`att.to_matrix`."""
    x, y, z, w = att.normalize(q_orbit_body).tolist()
    return np.array([omega0 * (2 * (x * y + z * w)), omega0 * (1 - 2 * (x * x + z * z)),
                     omega0 * (2 * (y * z - x * w))])


def omega_eci_from_orbit(q_orbit_body: ArrayLike, omega_body_orbit_body: ArrayLike,
                         omega0: float) -> np.ndarray:
    """``omega_body_eci_body = omega_body_orbit_body + R(q)^T [0, omega0, 0]`` [rad/s]."""
    return np.asarray(omega_body_orbit_body, float) + _orbit_rate_body(q_orbit_body, omega0)


def omega_orbit_from_eci(q_orbit_body: ArrayLike, omega_body_eci_body: ArrayLike,
                         omega0: float) -> np.ndarray:
    """Inverse of :func:`omega_eci_from_orbit`."""
    return np.asarray(omega_body_eci_body, float) - _orbit_rate_body(q_orbit_body, omega0)


def _finite(*arrays) -> bool:
    # math.isfinite on Python floats: np.all(np.isfinite(a)) without the numpy dispatch
    isfinite = math.isfinite
    return all(all(map(isfinite, np.asarray(a, dtype=float).ravel().tolist())) for a in arrays)


class MagneticFilterEstimator:
    """Paper 000's filter with a divergence reset and the 6x6 covariance (module docstring).

    :class:`~adcs_nodes.core.estimation.magnetic_filter.MagneticFilter`'s parameters plus
    ``max_rate_rad_s`` (beyond it: a divergence), ``use_sensor_covariance`` (theta per axis
    from the sample's covariance, never below ``theta``) and ``max_step_s`` [s].
    """

    def __init__(self, inertia: ArrayLike, max_rate_rad_s: float = 1.0,
                 use_sensor_covariance: bool = True, max_step_s: float = MAX_STEP_S,
                 theta_interval_s: float = THETA_INTERVAL_S, hypotheses: int = 1,
                 hypothesis_window_s: float = 2000.0, **filter_args) -> None:
        self.filter = MagneticFilter(inertia, max_rate_rad_s=max_rate_rad_s, **filter_args)
        angle_rate_covariance(np.eye(9))        # compiled (or loaded) before the first frame
        self.use_sensor_covariance = bool(use_sensor_covariance)
        self.max_rate = float(max_rate_rad_s)
        self.max_step = positive(max_step_s, 'max_step_s', 's')
        self.theta_interval = positive(theta_interval_s, 'theta_interval_s', 's', zero=True)
        self.bank = (HypothesisBank(hypotheses, hypothesis_window_s)
                     if int(hypotheses) > 1 else None)
        self._t_sample: Optional[float] = None     # time of the last accepted sample [s]
        self.q0 = att.identity()
        self.omega_rel0 = np.zeros(3)
        self.resets = 0
        self._started = False

    def initialise(self, q_orbit_body0: ArrayLike, omega_body_orbit_body0: ArrayLike) -> None:
        """Initial estimate (applied at the first step, when omega0 is known)."""
        self.q0 = att.normalize(q_orbit_body0)
        self.omega_rel0 = np.asarray(omega_body_orbit_body0, dtype=float)
        self._started = False

    def interval_ratio(self, t: float) -> float:
        """``r = min(1, d / theta_interval_s)``, ``d`` the time [s] from the last accepted
        sample to ``t`` (1 for the first sample or with ``theta_interval_s = 0``), floored at
        :data:`MIN_INTERVAL_RATIO`."""
        if self.theta_interval <= 0.0 or self._t_sample is None:
            return 1.0
        return min(1.0, max(MIN_INTERVAL_RATIO, (t - self._t_sample) / self.theta_interval))

    def _filters(self) -> list:
        """The filters stepped this frame: the bank's hypotheses while it runs, else one."""
        return self.bank.members if self.bank is not None and self.bank.active else [self.filter]

    def _reset(self, ref: OnboardState) -> None:
        self.filter.reset(self.q0, omega_eci_from_orbit(self.q0, self.omega_rel0, ref.omega0))
        if self.bank is not None:
            self.bank.clear()

    def _predict(self, f: MagneticFilter, inputs: EstimatorInputs, dt: float) -> bool:
        """Predict ``f`` over ``dt`` in steps of at most ``max_step_s``; False: diverged."""
        dipole = inputs.dipole_body if _finite(inputs.dipole_body) else np.zeros(3)
        # steps of at most max_step_s (a long live-mode interval in one step diverged)
        n = min(MAX_PREDICTION_STEPS, max(1, math.ceil(dt / self.max_step * (1.0 - 1e-9))))
        for _ in range(n):
            if not f.predict(dt / n, inputs.ref.omega0, dipole,
                             b_orbit_for_torque=inputs.ref.b_orbit):
                return False
        w = f.omega_body_eci_body        # finite after a True predict
        return math.sqrt(float(w @ w)) <= self.max_rate

    def _predict_all(self, inputs: EstimatorInputs, dt: float, out: Step) -> None:
        filters = self._filters()
        for k in reversed(range(len(filters))):
            if self._predict(filters[k], inputs, dt):
                continue
            if len(filters) > 1:        # a diverged hypothesis leaves the bank
                self.bank.drop(k)
                self.filter = self.bank.best()
                continue
            self.resets += 1
            out.rejections.append(
                f"filter diverged (|omega'| beyond {self.max_rate:g} rad/s or not finite): "
                f'reset to the initial estimate ({self.resets})')
            self._reset(inputs.ref)

    def _theta(self, inputs: EstimatorInputs, t: float) -> tuple:
        """``(theta (3,) [T^2] or None for the filter's own, r)`` of this reading: the
        sample's variances when given (never below theta), over the interval ratio ``r``."""
        f = self.filter
        # ASSUMPTION: theta also covers what a covariance does not (bias, misalignment, models)
        var = inputs.b_body_var if self.use_sensor_covariance else None
        theta = None if var is None else np.maximum(f.theta, var)
        r = self.interval_ratio(t)
        if r < 1.0:         # samples closer than the paper's interval (module docstring)
            theta = (np.full(3, f.theta) if theta is None else theta) / r
        return theta, r

    @staticmethod
    def _update(f: MagneticFilter, inputs: EstimatorInputs, theta, r: float) -> dict:
        tau = f.tau
        f.tau = tau * r
        try:
            return f.update(inputs.b_body, inputs.ref.b_orbit, theta_axes=theta)
        finally:
            f.tau = tau

    def step(self, inputs: EstimatorInputs, t: float, dt: float) -> Step:
        """Predict over ``dt`` with the applied dipole, then update with a fresh sample."""
        out = Step(None)
        if not self._started:
            self._reset(inputs.ref)
            self._started = True
        elif dt > 0:
            self._predict_all(inputs, dt, out)
        if inputs.b_body is None:
            return self._publish(out)
        theta, r = self._theta(inputs, t)
        if self.bank is not None:
            self.bank.score(inputs.b_body, inputs.ref.b_orbit,
                            np.full(3, self.filter.theta) if theta is None else theta, t)
        res = [self._update(f, inputs, theta, r) for f in self._filters()][0]
        if not res.get('accepted', False):
            out.rejections.append(str(res.get('reason', 'update refused')))
            return self._publish(out)
        self._t_sample = t
        out.updates = 1
        out.innovation = [float(v) for v in res['innovation']]
        if self.bank is None:
            if locked(self.filter):
                self.filter.open_misalignment()
        else:
            won = self.bank.decide(t)
            if won is not None:
                self.filter = won
                won.open_misalignment()
            self.bank.maybe_start(self.filter, inputs.b_body, t)
            if self.bank.active:
                self.filter = self.bank.best()
        return self._publish(out)

    def _publish(self, out: Step) -> Step:
        f = self.filter
        q, omega, p = f.q_orbit_body, f.omega_body_eci_body, f.P
        out.covariance_trace = float(np.trace(p))
        if not _finite(q, omega):
            out.rejections.append('filter state not finite: not published')
            return out
        out.estimate = Estimate6(q, omega, angle_rate_covariance(p))
        return out


@jit
def angle_rate_covariance(p):
    """The published (6, 6) covariance of the filter's ``P`` (9, 9) or (12, 12): small angle,
    error angle ~ ``2 phi`` (or ``2 mu``): ``[[4 P_phi, 2 P_phi,w], [2 P_w,phi, P_w]]``."""
    cov = np.empty((6, 6))
    for i in range(3):
        for j in range(3):
            cov[i, j] = 4.0 * p[i, j]
            cov[3 + i, 3 + j] = p[3 + i, 3 + j]
            cov[i, 3 + j] = 2.0 * p[i, 3 + j]
            cov[3 + j, i] = cov[i, 3 + j]
    return cov


class GeometricEstimator:
    """TRIAD or horizon + magnetometer yaw (``method``), with a finite-difference rate."""

    METHODS = ('triad', 'horizon_mag_yaw')

    def __init__(self, method: str) -> None:
        if method not in self.METHODS:
            raise ValueError(f'method must be one of {self.METHODS}, got {method!r}')
        self.method = method
        self._q_prev: Optional[np.ndarray] = None
        self._omega_rel = np.zeros(3)
        self._q = att.identity()

    def initialise(self, q_orbit_body0: ArrayLike, omega_body_orbit_body0: ArrayLike) -> None:
        """Only the initial relative rate is used (until two attitudes exist)."""
        self._q_prev = None
        self._omega_rel = np.asarray(omega_body_orbit_body0, dtype=float)

    def step(self, inputs: EstimatorInputs, t: float, dt: float) -> Step:
        """A new attitude from a fresh (horizon, field) pair, else hold the last one."""
        out = Step(None)
        held = self._held(inputs)
        if inputs.horizon_roll_pitch is None or inputs.b_body is None:
            out.estimate = held
            return out
        roll, pitch = inputs.horizon_roll_pitch
        try:
            if self.method == 'triad':
                q = triad_from_horizon_and_field(roll, pitch, inputs.b_body, inputs.ref.b_orbit)
            else:
                yaw = yaw_from_horizon_and_field(roll, pitch, inputs.b_body, inputs.ref.b_orbit)
                q = attitude_from_horizon_and_yaw(roll, pitch, yaw)
        except ValueError as exc:
            out.rejections.append(f'{self.method}: {exc}')
            out.estimate = held
            return out
        if self._q_prev is not None and dt > 0:
            dq = att.multiply(att.conjugate(self._q_prev), q)
            self._omega_rel = att.to_rotation_vector(dq) / dt
            if float(q @ self._q_prev) < 0:
                q = -q
        self._q_prev = self._q = q
        out.updates = 1
        out.estimate = self._held(inputs)
        return out

    def _held(self, inputs: EstimatorInputs) -> Optional[Estimate6]:
        if self._q_prev is None:
            return None
        omega = omega_eci_from_orbit(self._q, self._omega_rel, inputs.ref.omega0)
        return Estimate6(self._q, omega, _UNKNOWN.copy())


#: Covariance of an estimator that has none: -1 in element 0 ("unknown", AttitudeState.msg).
_UNKNOWN = np.zeros((6, 6))
_UNKNOWN[0, 0] = -1.0
