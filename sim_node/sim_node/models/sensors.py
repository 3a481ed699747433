"""Seeded attitude-sensor models of the simulated world: magnetometer, horizon, star tracker, gyro.

Every model takes truth (numpy arrays, SI units, radians) and returns one measurement per
call. Randomness: one ``SeedSequence(seed).spawn`` child stream per error source, drawn on
every call whatever the outcome (dropout, invalid output), so the streams never shift. Every
constructor raises ``ValueError`` on a malformed, non-finite or out-of-range parameter.

Magnetometer (paper 000, digest sections 5.1-5.2: bias up to 120 nT, misalignment up to
10 deg, LSB 20 nT, noise std 375/25/65 nT). Effects in this order::

    b_nom  = R(q_body_sensor)^T b_body          nominal mounting (sensor axes, no error)   (M1)
    b_mis  = R(exp(delta))^T b_nom              misalignment: the real sensor axes are the
                                                nominal ones rotated by the rotation vector
                                                delta (small, |delta| <= pi/2)             (M2)
    b_sf   = (1 + s_i) b_mis,i                  scale-factor error per sensor axis          (M3)
    b_bias = b_sf + bias                        constant bias, sensor axes                 (M4)
    b_n    = b_bias + sigma_i n_i,  n ~ N(0,I)  white Gaussian noise                       (M5)
    b_sat  = clip(b_n,i, -S_i, S_i)             saturation, per axis (S_i = 0: none)       (M6)
    b_out  = L round(b_sat / L)                 quantisation to the LSB L (0: none)        (M7)

and with probability ``p`` the sample is lost (dropout: ``None``). (M1)-(M3) are one constant
matrix ``M = diag(1 + s) R(exp(delta))^T R(q_body_sensor)^T``.

Horizon (Earth) sensor (paper 004, digest section 3). Roll and pitch are the 3-2-1 angles of
the body w.r.t. the orbit frame (x along-track, y orbit normal, z zenith)::

    C = R(q_orbit_body)^T = R1(phi) R2(theta) R3(psi)                          (orbit -> body)
    z_b = C z0 = (-s theta, c theta s phi, c theta c phi),   z0 = (0, 0, 1)    (zenith, body)
    theta = -asin(z_b,x),   phi = atan2(z_b,y, z_b,z)                                     (H1)
    phi_m = (1 + s_r) phi + b_r + sigma_r n_r,  theta_m = (1 + s_p) theta + b_p + sigma_p n_p
                                                                                          (H2)

Yaw does not enter ``z_b``. The sensor looks along body ``-z`` (its boresight is nadir when
the body is aligned with the orbit frame). The output is valid when the Earth is inside the
field of view: ``z_b,z > 0`` (nadir less than 90 deg off the boresight) and the TRUE
``|phi| <= fov_roll``, ``|theta| <= fov_pitch``. An invalid sample carries NaN angles.

Star tracker (paper 001: 0.02 deg 3-sigma per axis -> sigma = 0.00667 deg)::

    delta = sigma * n,  n ~ N(0, I3)            small error rotation, body axes
    q_eci_body_m = q_eci_body (x) exp(delta)                                              (S1)

Gyro (rate-integrating model with a random-walk bias)::

    beta_k = beta_{k-1} + sigma_w sqrt(dt_k) w_k,   w_k ~ N(0, I3),   beta_0 = bias_initial
    omega_m = omega_body_eci_body + beta_k + sigma_v v_k,   v_k ~ N(0, I3)                (G1)

so ``Var(beta_k - beta_0) = sigma_w^2 t_k`` per axis. Paper 001's "random drift" of
0.01 deg/h (3-sigma, digest section 4) is reached after one hour by
``sigma_w = (0.01 / 3 deg/h) / sqrt(3600 s) = 2.69e-10 rad/s/sqrt(s)``.

Wheel tachometer: ``w_meas,i = q round((w_i + n_i) / q)``, ``n_i ~ N(0, sigma^2)``     (T1)
"""
from __future__ import annotations

import math
from typing import NamedTuple, Optional

import numpy as np

from adcs_nodes.core import attitude as att
from adcs_nodes.core.control import integer, positive
from adcs_nodes.core.kernels import finite_vector

#: Gyro rate random walk [rad/s/sqrt(s)] whose bias reaches 0.01 deg/h (3-sigma) after 1 h.
GYRO_DRIFT_WALK_RAD_S_SQRT_S = math.radians(0.01 / 3.0) / 3600.0 / math.sqrt(3600.0)
#: Star tracker noise [rad] per body axis for paper 001's 0.02 deg (3-sigma).
STAR_TRACKER_STD_RAD = math.radians(0.02 / 3.0)

_UNIT_TOL = 1e-6   # accepted deviation of a configured quaternion from unit norm


def _vector(value, n: int, name: str, nonneg: bool = False,
            scalar_ok: bool = True) -> np.ndarray:
    """Validate a finite (n,) vector (or a scalar broadcast to it); ValueError if bad."""
    a = np.array(value, dtype=float)
    if a.shape == () and scalar_ok:
        a = np.full(n, float(a))
    if a.shape != (n,):
        raise ValueError(f'{name} must have shape ({n},)'
                         + (' or be a scalar' if scalar_ok else '') + f', got {a.tolist()}')
    if not np.all(np.isfinite(a)):
        raise ValueError(f'{name} must be finite, got {a.tolist()}')
    if nonneg and np.any(a < 0.0):
        raise ValueError(f'{name} must be >= 0, got {a.tolist()}')
    return a


def _scale_factor(value, n: int, name: str = 'scale_factor_error') -> np.ndarray:
    s = _vector(value, n, name)
    if np.any(s <= -1.0):
        raise ValueError(f'{name} must be > -1 (measured = (1 + s) true), got {s.tolist()}')
    return s


def _unit_quaternion(value, name: str) -> np.ndarray:
    q = np.array(value, dtype=float)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise ValueError(f'{name} must be a finite (4,) quaternion [x, y, z, w], got {value!r}')
    if abs(np.linalg.norm(q) - 1.0) > _UNIT_TOL:
        raise ValueError(f'{name} must have unit norm, got |q| = {np.linalg.norm(q)}')
    return q / np.linalg.norm(q)


def _streams(seed, n: int):
    """``n`` independent generators from a non-negative integer seed."""
    seeds = np.random.SeedSequence(integer(seed, 'seed', 0)).spawn(n)
    return [np.random.default_rng(s) for s in seeds]


class Magnetometer:
    """Three-axis magnetometer, (M1)-(M7).

    Parameters (float or (3,), sensor axes): ``noise_std_T`` [T] >= 0, ``bias_T`` [T],
    ``misalignment_rad`` rotation vector ``delta`` (3,) [rad], ``|delta| <= pi/2`` (large
    rotations belong in ``q_body_sensor``), ``scale_factor_error`` ``s_i > -1``, ``lsb_T`` [T]
    (0: none), ``saturation_T`` [T] (0: none), ``dropout_probability`` in [0, 1],
    ``q_body_sensor`` (4,) unit, ``v_body = R(q_body_sensor) v_sensor``, ``seed`` >= 0.
    """

    def __init__(self, noise_std_T=0.0, bias_T=0.0, misalignment_rad=(0.0, 0.0, 0.0),
                 scale_factor_error=0.0, lsb_T: float = 0.0, saturation_T=0.0,
                 dropout_probability: float = 0.0, q_body_sensor=(0.0, 0.0, 0.0, 1.0),
                 seed: int = 0) -> None:
        self.noise_std_T = _vector(noise_std_T, 3, 'noise_std_T', nonneg=True)
        self.bias_T = _vector(bias_T, 3, 'bias_T')
        self.misalignment_rad = _vector(misalignment_rad, 3, 'misalignment_rad',
                                        scalar_ok=False)
        if np.linalg.norm(self.misalignment_rad) > math.pi / 2:
            raise ValueError('misalignment_rad is a small rotation (|delta| <= pi/2 rad); put a '
                             'large mounting rotation in q_body_sensor')
        self.scale_factor_error = _scale_factor(scale_factor_error, 3)
        self.lsb_T = positive(lsb_T, 'lsb_T', zero=True)
        self.saturation_T = _vector(saturation_T, 3, 'saturation_T', nonneg=True)
        p = positive(dropout_probability, 'dropout_probability', zero=True)
        if p > 1.0:
            raise ValueError(f'dropout_probability must be in [0, 1], got {p}')
        self.dropout_probability = p
        self.q_body_sensor = _unit_quaternion(q_body_sensor, 'q_body_sensor')
        r_nom_mis = att.to_matrix(att.from_rotation_vector(self.misalignment_rad))
        #: (3, 3) constant map body -> sensor including scale factor, (M1)-(M3).
        self.matrix = (np.diag(1.0 + self.scale_factor_error) @ r_nom_mis.T
                       @ att.to_matrix(self.q_body_sensor).T)
        self._noise_rng, self._drop_rng = _streams(seed, 2)

    @property
    def covariance(self) -> np.ndarray:
        """White-noise covariance ``diag(noise_std_T^2)`` [T^2], sensor axes, shape (3, 3)."""
        return np.diag(self.noise_std_T ** 2)

    def measure(self, b_body) -> Optional[np.ndarray]:
        """Measured field (3,) [T], sensor axes, of the true ``b_body`` (3,) [T], body axes;
        ``None`` when the sample dropped out."""
        b = self.matrix @ finite_vector(b_body, 'b_body', (3,)) + self.bias_T
        b = b + self.noise_std_T * self._noise_rng.standard_normal(3)
        lost = self._drop_rng.random() < self.dropout_probability
        sat = self.saturation_T
        b = np.where(sat > 0.0, np.clip(b, -sat, sat), b)
        if self.lsb_T > 0.0:
            b = self.lsb_T * np.round(b / self.lsb_T)
        return None if lost else b


class HorizonMeasurement(NamedTuple):
    """Output of :meth:`HorizonSensor.measure`: angles [rad] (NaN when not valid) and validity."""

    roll: float
    pitch: float
    valid: bool


def roll_pitch_of_zenith(zenith_body) -> tuple:
    """True ``(roll in (-pi, pi], pitch in [-pi/2, pi/2])`` [rad], (H1), of the zenith
    (orbit-frame z) ``zenith_body`` (3,) in body components, any non-zero length."""
    z = finite_vector(zenith_body, 'zenith_body', (3,))
    n = np.linalg.norm(z)
    if n == 0.0:
        raise ValueError('zenith_body must not be zero')
    z = z / n
    pitch = -math.asin(min(1.0, max(-1.0, float(z[0]))))
    roll = math.atan2(float(z[1]), float(z[2]))
    return roll, pitch


class HorizonSensor:
    """Earth horizon sensor giving roll and pitch, (H1)-(H2).

    Parameters (float or (2,) for (roll, pitch)): ``noise_std_rad`` [rad] >= 0, ``bias_rad``
    [rad], ``scale_factor_error`` ``s > -1``, ``fov_rad`` largest true angle with a valid
    output, in (0, pi/2] [rad], ``seed`` >= 0.
    """

    def __init__(self, noise_std_rad=0.0, bias_rad=0.0, scale_factor_error=0.0,
                 fov_rad=math.radians(30.0), seed: int = 0) -> None:
        self.noise_std_rad = _vector(noise_std_rad, 2, 'noise_std_rad', nonneg=True)
        self.bias_rad = _vector(bias_rad, 2, 'bias_rad')
        self.scale_factor_error = _scale_factor(scale_factor_error, 2)
        self.fov_rad = _vector(fov_rad, 2, 'fov_rad')
        if np.any(self.fov_rad <= 0.0) or np.any(self.fov_rad > math.pi / 2):
            raise ValueError(f'fov_rad must be in (0, pi/2], got {self.fov_rad.tolist()}')
        (self._noise_rng,) = _streams(seed, 1)

    @property
    def variance(self) -> np.ndarray:
        """Noise variance of (roll, pitch) [rad^2], shape (2,)."""
        return self.noise_std_rad ** 2

    def measure_zenith(self, zenith_body) -> HorizonMeasurement:
        """Measured roll and pitch [rad] (NaN when not valid) of the zenith ``zenith_body``
        (3,) in body components (``R(q_eci_body)^T r_eci``), any non-zero length."""
        z = finite_vector(zenith_body, 'zenith_body', (3,))
        roll, pitch = roll_pitch_of_zenith(z)
        noise = self.noise_std_rad * self._noise_rng.standard_normal(2)
        valid = bool(z[2] > 0.0 and abs(roll) <= self.fov_rad[0]
                     and abs(pitch) <= self.fov_rad[1])
        if not valid:
            return HorizonMeasurement(math.nan, math.nan, False)
        true = np.array([roll, pitch])
        out = (1.0 + self.scale_factor_error) * true + self.bias_rad + noise
        return HorizonMeasurement(float(out[0]), float(out[1]), True)

    def measure(self, q_orbit_body) -> HorizonMeasurement:
        """Measured roll and pitch of the true attitude ``q_orbit_body`` (4,)."""
        return self.measure_zenith(att.to_matrix(q_orbit_body)[2, :])


class StarTracker:
    """Star tracker, (S1): ``noise_std_rad`` (float or (3,)) [rad] >= 0 about each body axis
    (default paper 001's 0.02 deg 3-sigma), ``seed`` >= 0."""

    def __init__(self, noise_std_rad=STAR_TRACKER_STD_RAD, seed: int = 0) -> None:
        self.noise_std_rad = _vector(noise_std_rad, 3, 'noise_std_rad', nonneg=True)
        (self._noise_rng,) = _streams(seed, 1)

    @property
    def covariance(self) -> np.ndarray:
        """Small-angle attitude error covariance [rad^2], body axes, shape (3, 3)."""
        return np.diag(self.noise_std_rad ** 2)

    def measure(self, q_eci_body) -> np.ndarray:
        """Measured ``q_eci_body`` (4,), unit norm, of the true one (normalised here)."""
        q = att.normalize(q_eci_body)
        delta = self.noise_std_rad * self._noise_rng.standard_normal(3)
        return att.normalize(att.multiply(q, att.from_rotation_vector(delta)))


class Gyro:
    """Three-axis rate gyro with white noise and a random-walk bias, (G1).

    Parameters (float or (3,), body axes): ``noise_std_rad_s`` [rad/s] >= 0 per sample,
    ``bias_initial_rad_s`` [rad/s], ``bias_walk_std_rad_s_sqrt_s`` ``sigma_w``
    [rad/s/sqrt(s)] >= 0, ``seed`` >= 0.
    """

    def __init__(self, noise_std_rad_s=0.0, bias_initial_rad_s=0.0,
                 bias_walk_std_rad_s_sqrt_s=0.0, seed: int = 0) -> None:
        self.noise_std_rad_s = _vector(noise_std_rad_s, 3, 'noise_std_rad_s', nonneg=True)
        self.bias_initial_rad_s = _vector(bias_initial_rad_s, 3, 'bias_initial_rad_s')
        self.bias_walk_std_rad_s_sqrt_s = _vector(
            bias_walk_std_rad_s_sqrt_s, 3, 'bias_walk_std_rad_s_sqrt_s', nonneg=True)
        self._bias = self.bias_initial_rad_s.copy()
        self._walk_rng, self._noise_rng = _streams(seed, 2)

    @property
    def bias(self) -> np.ndarray:
        """Current bias [rad/s], body axes, shape (3,) (a copy)."""
        return self._bias.copy()

    @property
    def covariance(self) -> np.ndarray:
        """White-noise covariance ``diag(noise_std_rad_s^2)`` [(rad/s)^2], shape (3, 3)."""
        return np.diag(self.noise_std_rad_s ** 2)

    def measure(self, omega_body_eci_body, dt: float) -> np.ndarray:
        """Measured rate (3,) [rad/s], body axes, of the true ``omega_body_eci_body``, after
        advancing the bias by ``dt`` >= 0 [s] (0 for the first sample)."""
        w = finite_vector(omega_body_eci_body, 'omega_body_eci_body', (3,))
        dt = positive(dt, 'dt', zero=True)
        walk = self._walk_rng.standard_normal(3)
        self._bias = self._bias + self.bias_walk_std_rad_s_sqrt_s * math.sqrt(dt) * walk
        return w + self._bias + self.noise_std_rad_s * self._noise_rng.standard_normal(3)


class WheelTachometer:
    """Reaction-wheel tachometer, (T1): ``noise_std_rad_s`` [rad/s] >= 0, speed resolution
    ``quantization_rad_s`` ``q`` [rad/s] >= 0 (0: none), ``seed`` >= 0."""

    def __init__(self, noise_std_rad_s: float = 0.0, quantization_rad_s: float = 0.0,
                 seed: int = 0) -> None:
        self.noise_std_rad_s = positive(noise_std_rad_s, 'noise_std_rad_s', zero=True)
        self.quantization_rad_s = positive(quantization_rad_s, 'quantization_rad_s', zero=True)
        (self._rng,) = _streams(seed, 1)

    def measure(self, speed_rad_s) -> np.ndarray:
        """Measured speeds [rad/s] of the true speeds ``speed_rad_s`` (shape (n,)), (T1)."""
        w = np.asarray(speed_rad_s, dtype=float)
        if w.ndim != 1 or not np.all(np.isfinite(w)):
            raise ValueError(f'speed_rad_s must be a finite 1-D array, got {w}')
        meas = w + self.noise_std_rad_s * self._rng.standard_normal(w.size)
        q = self.quantization_rad_s
        return q * np.round(meas / q) if q > 0 else meas
