"""Orbit models and Earth rotation of the simulated world (pure numpy, no ROS).

Equations
---------
Circular Keplerian orbit, radius ``a = R_EARTH + altitude``, node unit vector ``p1``, in-plane
unit vector ``p2`` (90 deg ahead of the node) and orbit normal ``p3``
(columns of ``Rz(raan) Rx(i)``)::

    n = sqrt(MU_EARTH / a^3),  T = 2 pi / n,  u(t) = u0 + n t                     (O1)
    r_eci = a (cos u p1 + sin u p2),  v_eci = a n (-sin u p1 + cos u p2)        (O2)

Orbit frame (papers 000/004; DESIGN section 4), columns of ``R_eci_orbit``::

    z = r / |r| (zenith),  y = h / |h| with h = r x v (orbit normal),  x = y x z   (O3)

``x`` is along-track; the frame rotates with ``omega_orbit_eci_eci = h / |r|^2`` (exact for
a Keplerian orbit). LVLH (paper 001: x along-track, y = -normal, z nadir) is a half turn about
the orbit x axis, ``q_orbit_lvlh = [1, 0, 0, 0]``.

Argument of latitude: angle from the ascending node ``N = e_z x h`` to ``r``, positive about
``h``; for an equatorial orbit (``N = 0``) it is measured from the ECI x axis::

    u = atan2(h_hat . (N_hat x r), N_hat . r)  in [0, 2 pi)                       (O4)

Earth rotation (IAU 1982 GMST, Aoki et al. 1982, A&A 105:359; as in Vallado, *Fundamentals of
Astrodynamics and Applications*, 4th ed., Example 3-5), ``T`` in Julian centuries of UT1 from
J2000::

    GMST [s] = 67310.54841 + (876600 h + 8640184.812866) T + 0.093104 T^2 - 6.2e-6 T^3  (E1)
    R_eci_ecef = Rz(GMST),  q_eci_ecef = [0, 0, sin(GMST/2), cos(GMST/2)]          (E2)

Approximations: UT1 = UTC (< 0.004 deg of Earth rotation), no polar motion. :class:`Sgp4Orbit`
gives TEME, used as "eci" (TEME -> Earth-fixed is exactly Rz(-GMST82), Vallado et al. 2006;
TEME is not J2000: ~0.35 deg of precession in 2025, which matters only against external J2000
data). For :class:`CircularOrbit` "eci" has z along the Earth's axis, x at the GMST origin.

References: Vallado (2013) ch. 2-3; Vallado, Crawford, Hujsak, Kelso, "Revisiting Spacetrack
Report #3" (2006); paper 000 (Lebedev et al.) and its digest section 1.2 for the orbit frame.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from typing import Mapping, Protocol

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core import attitude
from adcs_nodes.core.control import finite
from adcs_nodes.core.kernels import finite_vector
from adcs_nodes.core.spec import REQUIRED, Param, Section

MU_EARTH = 3.986004418e14
"""Earth gravitational parameter [m^3/s^2] (WGS 84 / EGM96)."""
R_EARTH = 6378137.0
"""Earth equatorial radius [m] (WGS 84); altitudes are measured from it."""
OMEGA_EARTH = 7.2921150e-5
"""Earth rotation rate [rad/s] (WGS 84 nominal)."""

Q_ORBIT_LVLH = np.array([1.0, 0.0, 0.0, 0.0])
"""``q_orbit_lvlh`` (4,), scalar last: half turn about the orbit x axis."""
Q_ORBIT_LVLH.setflags(write=False)

_J2000 = datetime(2000, 1, 1, 12, 0, 0, tzinfo=timezone.utc)
_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class OrbitState:
    """Orbit state at one instant: ``r_eci`` (3,) [m], ``v_eci`` (3,) [m/s], ``q_eci_orbit``
    (4,) scalar last (``v_eci = R(q) v_orbit``), ``omega_orbit_eci_eci`` (3,) [rad/s] ECI
    axes, ``orbit_rate`` its norm [rad/s], ``argument_of_latitude`` in [0, 2 pi) [rad]."""

    r_eci: np.ndarray
    v_eci: np.ndarray
    q_eci_orbit: np.ndarray
    omega_orbit_eci_eci: np.ndarray
    orbit_rate: float
    argument_of_latitude: float


class OrbitModel(Protocol):
    """What the rest of the simulator needs from an orbit model."""

    epoch: datetime

    def state(self, t: float) -> OrbitState:
        """State at ``t`` seconds after :attr:`epoch`."""


# ---------------------------------------------------------------------------- validation
def _utc(t_utc: datetime, name: str = 'epoch') -> datetime:
    if not isinstance(t_utc, datetime):
        raise ValueError(f'{name} must be a datetime, got {t_utc!r}')
    if t_utc.tzinfo is None or t_utc.utcoffset() is None:
        raise ValueError(f'{name} must be timezone-aware (UTC), got naive {t_utc}')
    return t_utc.astimezone(timezone.utc)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    # np.cross costs ~10x more for single 3-vectors; this is called every frame.
    return np.array([a[1] * b[2] - a[2] * b[1],
                     a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


# ------------------------------------------------------------------------ Earth rotation
def gmst(t_utc: datetime, t: float = 0.0) -> float:
    """GMST [rad] in [0, 2 pi) (E1), UT1 = UTC, at the aware instant ``t_utc`` plus ``t`` [s]
    (added here for full precision): the angle from the ECI to the ECEF x axis about z."""
    days = (_seconds_since_j2000(t_utc) + float(t)) / 86400.0
    cent = days / 36525.0
    # 876600 h T = 86400 s * days, kept apart from the small terms for precision.
    sec = (67310.54841 + 86400.0 * math.fmod(days, 1.0)
           + cent * (8640184.812866 + cent * (0.093104 - 6.2e-6 * cent)))
    return (math.fmod(sec, 86400.0) / 86400.0 * _TWO_PI) % _TWO_PI


@functools.lru_cache(maxsize=64)
def _seconds_since_j2000(t_utc: datetime) -> float:
    """``t_utc - J2000`` [s] (an epoch's, once: GMST is evaluated several times a frame)."""
    return (_utc(t_utc, 't_utc') - _J2000).total_seconds()


def q_eci_ecef(t_utc: datetime, t: float = 0.0) -> np.ndarray:
    """``q_eci_ecef`` (4,), scalar last: rotation by GMST about z (E2), ``t`` s after ``t_utc``."""
    half = 0.5 * gmst(t_utc, t)
    return np.array([0.0, 0.0, math.sin(half), math.cos(half)])


def _rz(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def ecef_from_eci(r_eci: ArrayLike, t_utc: datetime, t: float = 0.0) -> np.ndarray:
    """Earth-fixed components (3,) of the ECI vector ``r_eci`` (3,), any unit, at ``t_utc + t``."""
    return _rz(gmst(t_utc, t)).T @ finite_vector(r_eci, 'r_eci', (3,))


def eci_from_ecef(r_ecef: ArrayLike, t_utc: datetime, t: float = 0.0) -> np.ndarray:
    """ECI components (3,) of the Earth-fixed vector ``r_ecef`` (3,) at ``t_utc + t``."""
    return _rz(gmst(t_utc, t)) @ finite_vector(r_ecef, 'r_ecef', (3,))


# ------------------------------------------------------------------------- orbit frames
def _frame_axes(r: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    h = _cross(r, v)
    nh, nr = math.sqrt(h @ h), math.sqrt(r @ r)
    if nr == 0.0 or nh <= 1e-12 * nr * math.sqrt(v @ v):
        raise ValueError('r and v must be non-zero and not parallel to define the orbit frame')
    z = r / nr
    y = h / nh
    return _cross(y, z), y, z


def orbit_frame_dcm(r_eci: ArrayLike, v_eci: ArrayLike) -> np.ndarray:
    """``R_eci_orbit`` (3, 3), columns the orbit x, y, z (O3), of ``r_eci`` [m] and ``v_eci``
    [m/s] (3,), ECI (``ValueError`` if not finite, zero or parallel)."""
    x, y, z = _frame_axes(finite_vector(r_eci, 'r_eci', (3,)), finite_vector(v_eci, 'v_eci', (3,)))
    return np.column_stack((x, y, z))


def q_eci_orbit(r_eci: ArrayLike, v_eci: ArrayLike) -> np.ndarray:
    """``q_eci_orbit`` (4,), scalar last, ``w >= 0``, of the orbit frame (O3)."""
    return attitude.from_matrix(orbit_frame_dcm(r_eci, v_eci))


def q_eci_lvlh(r_eci: ArrayLike, v_eci: ArrayLike) -> np.ndarray:
    """``q_eci_lvlh`` (4,), scalar last: LVLH (x along-track, y -normal, z nadir) in ECI."""
    return attitude.multiply(q_eci_orbit(r_eci, v_eci), Q_ORBIT_LVLH)


def _argument_of_latitude(r: np.ndarray, h_hat: np.ndarray) -> float:
    node = np.array([-h_hat[1], h_hat[0], 0.0])  # e_z x h_hat
    nn = math.sqrt(node @ node)
    node = node / nn if nn > 1e-12 else np.array([1.0, 0.0, 0.0])
    u = math.atan2(h_hat @ _cross(node, r), node @ r)
    return u % _TWO_PI


def state_from_rv(r_eci: ArrayLike, v_eci: ArrayLike) -> OrbitState:
    """:class:`OrbitState` of a position (3,) [m] and velocity (3,) [m/s] in ECI (O3, O4)."""
    r, v = finite_vector(r_eci, 'r_eci', (3,)), finite_vector(v_eci, 'v_eci', (3,))
    x, y, z = _frame_axes(r, v)
    omega = _cross(r, v) / (r @ r)
    return OrbitState(r, v, _quat_from_axes(x, y, z), omega, float(math.sqrt(omega @ omega)),
                      _argument_of_latitude(r, y))


def _quat_from_axes(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    # Shepperd's method on R = [x y z], as attitude.from_matrix without its checks.
    m00, m11, m22 = x[0], y[1], z[2]
    tr = m00 + m11 + m22
    diag = (m00, m11, m22, tr)
    i = diag.index(max(diag))       # the first largest, as np.argmax
    if i == 3:
        w = 0.5 * math.sqrt(1.0 + tr)
        q = np.array([y[2] - z[1], z[0] - x[2], x[1] - y[0], 4.0 * w * w]) / (4.0 * w)
    elif i == 0:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = np.array([0.25 * s * s, x[1] + y[0], z[0] + x[2], y[2] - z[1]]) / s
    elif i == 1:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        q = np.array([x[1] + y[0], 0.25 * s * s, y[2] + z[1], z[0] - x[2]]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = np.array([z[0] + x[2], y[2] + z[1], 0.25 * s * s, x[1] - y[0]]) / s
    return -q if q[3] < 0.0 else q


# ------------------------------------------------------------------------------ orbits
class CircularOrbit:
    """Keplerian circular orbit (O1, O2) around a point-mass Earth: ``altitude_m`` > 0 above
    ``R_EARTH``, ``inclination_rad`` in [0, pi], ``raan_rad`` (from the ECI x axis),
    ``arg_latitude0_rad`` at ``t = 0``, ``epoch`` the aware UTC instant of ``t = 0``.
    ``ValueError`` on a bad argument."""

    def __init__(self, altitude_m: float, inclination_rad: float, raan_rad: float = 0.0,
                 arg_latitude0_rad: float = 0.0, *, epoch: datetime) -> None:
        altitude_m = finite(altitude_m, 'altitude_m')
        if altitude_m <= 0.0:
            raise ValueError(f'altitude_m must be > 0, got {altitude_m}')
        inc = finite(inclination_rad, 'inclination_rad')
        if not 0.0 <= inc <= math.pi:
            raise ValueError(f'inclination_rad must be in [0, pi], got {inc}')
        self.raan = finite(raan_rad, 'raan_rad')
        self.arg_latitude0 = finite(arg_latitude0_rad, 'arg_latitude0_rad')
        self.epoch = _utc(epoch)
        self.inclination = inc
        self.radius = R_EARTH + altitude_m
        self._n = math.sqrt(MU_EARTH / self.radius ** 3)
        # Columns p1 (node), p2 (in-plane, 90 deg ahead), p3 (orbit normal) of Rz(raan) Rx(i).
        self._p = attitude.to_matrix(attitude.multiply(
            attitude.from_axis_angle([0.0, 0.0, 1.0], self.raan),
            attitude.from_axis_angle([1.0, 0.0, 0.0], inc)))
        self._omega = self._n * self._p[:, 2]
        self._p_cols = self._p.T.tolist()          # Python floats: the same IEEE operations

    @property
    def mean_motion(self) -> float:
        """Orbital rate ``n = sqrt(mu / a^3)`` [rad/s]."""
        return self._n

    @property
    def period(self) -> float:
        """Orbital period ``2 pi / n`` [s]."""
        return _TWO_PI / self._n

    def state(self, t: float) -> OrbitState:
        """:class:`OrbitState` at ``t`` seconds after :attr:`epoch`."""
        u = (self.arg_latitude0 + self._n * float(t)) % _TWO_PI
        c, s = math.cos(u), math.sin(u)
        p1, p2, normal = self._p_cols
        zen = [c * a + s * b for a, b in zip(p1, p2)]
        along = [c * b - s * a for a, b in zip(p1, p2)]
        r, rn = self.radius, self.radius * self._n
        return OrbitState(np.array([r * v for v in zen]), np.array([rn * v for v in along]),
                          _quat_from_axes(along, normal, zen), self._omega.copy(), self._n, u)

    def position(self, t: float) -> np.ndarray:
        """``state(t).r_eci`` [m] alone (the same operations)."""
        u = (self.arg_latitude0 + self._n * float(t)) % _TWO_PI
        c, s, r = math.cos(u), math.sin(u), self.radius
        return np.array([r * (c * a + s * b) for a, b in zip(*self._p_cols[:2])])


class Sgp4Orbit:
    """SGP4/SDP4 propagation (``sgp4`` library, WGS 72 constants) of the TLE ``line1``,
    ``line2``; TEME used as "eci", in m and m/s. ``epoch``: aware instant of ``t = 0``
    (``None``: the TLE epoch). ``ValueError`` on a malformed TLE (length, line numbers,
    checksum, satellite number), elements SGP4 rejects at the epoch, or a naive ``epoch``."""

    def __init__(self, line1: str, line2: str, epoch: datetime | None = None) -> None:
        from sgp4.api import WGS72, Satrec
        from sgp4.conveniences import sat_epoch_datetime

        line1, line2 = _check_tle_line(line1, 1), _check_tle_line(line2, 2)
        if line1[2:7] != line2[2:7]:
            raise ValueError(f'TLE satellite numbers differ: {line1[2:7]!r} vs {line2[2:7]!r}')
        try:
            self._sat = Satrec.twoline2rv(line1, line2, WGS72)
        except Exception as exc:  # the parser raises assorted types on bad fields
            raise ValueError(f'malformed TLE: {exc}') from None
        if self._sat.error:
            raise ValueError(f'malformed TLE (sgp4 error {self._sat.error})')
        self.tle_epoch = sat_epoch_datetime(self._sat).astimezone(timezone.utc)
        self.epoch = self.tle_epoch if epoch is None else _utc(epoch)
        self._t0_min = (self.epoch - self.tle_epoch) / timedelta(minutes=1)
        try:
            self.state(0.0)
        except RuntimeError as exc:
            raise ValueError(f'TLE cannot be propagated to the epoch: {exc}') from None

    @property
    def mean_motion(self) -> float:
        """TLE (Kozai) mean motion [rad/s]."""
        return self._sat.no_kozai / 60.0

    @property
    def period(self) -> float:
        """Period from the TLE mean motion, ``2 pi / n`` [s]."""
        return _TWO_PI / self.mean_motion

    def state(self, t: float) -> OrbitState:
        """:class:`OrbitState` at ``t`` s after :attr:`epoch` (TEME as ECI); ``RuntimeError``
        if SGP4 fails (e.g. the satellite has decayed)."""
        r_km, v_kms = self._propagate(t)
        return state_from_rv(np.multiply(r_km, 1e3), np.multiply(v_kms, 1e3))

    def position(self, t: float) -> np.ndarray:
        """``state(t).r_eci`` [m] alone."""
        return np.multiply(self._propagate(t)[0], 1e3)

    def _propagate(self, t: float) -> tuple:
        err, r_km, v_kms = self._sat.sgp4_tsince(self._t0_min + float(t) / 60.0)
        if err or not math.isfinite(r_km[0] + v_kms[0]):
            from sgp4.api import SGP4_ERRORS

            raise RuntimeError(f'SGP4 error {err}: {SGP4_ERRORS.get(err, "non-finite state")}')
        return r_km, v_kms


def _check_tle_line(line: str, number: int) -> str:
    if not isinstance(line, str):
        raise ValueError(f'TLE line{number} must be a string, got {line!r}')
    line = line.strip()
    if len(line) != 69 or not line.startswith(f'{number} '):
        raise ValueError(f'TLE line{number} must be 69 characters starting with "{number} ", '
                         f'got {line!r}')
    total = sum(int(c) if c.isdigit() else (1 if c == '-' else 0) for c in line[:68])
    if not line[68].isdigit() or int(line[68]) != total % 10:
        raise ValueError(f'TLE line{number} checksum is {line[68]!r}, expected {total % 10}')
    return line


# ----------------------------------------------------------------------------- factory
#: The ``orbit`` section (a scenario's, a node's ``orbit.*`` and ``onboard_orbit.*``).
ORBIT = Section('orbit', (
    Param('type', 'str', 'circular', '-', 'orbit model', choices=('circular', 'tle')),
), 'the orbit', selector='type', variants={
    'circular': (
        Param('altitude_km', 'float', REQUIRED, 'km', 'altitude above the reference radius '
              '(100 km: the Karman line; 400,000 km: about the Moon)', min=100.0,
              max=400_000.0),
        Param('inclination_deg', 'float', REQUIRED, 'deg', 'inclination', min=0.0, max=180.0),
        Param('raan_deg', 'float', 0.0, 'deg', 'right ascension of the ascending node',
              min=-360.0, max=360.0),
        Param('arg_latitude0_deg', 'float', 0.0, 'deg', 'argument of latitude at the epoch',
              min=-360.0, max=360.0)),
    'tle': (Param('line1', 'str', REQUIRED, '-', 'TLE line 1'),
            Param('line2', 'str', REQUIRED, '-', 'TLE line 2'))},
    standalone={'altitude_km': 690.0, 'inclination_deg': 98.0})   # paper 000's orbit


def make_orbit(cfg: Mapping, epoch: datetime) -> CircularOrbit | Sgp4Orbit:
    """The orbit model of an :data:`ORBIT` mapping at the aware scenario ``epoch`` (also a
    TLE's ``t = 0``); ``ValueError`` naming an unknown type or key or a value out of range."""
    if not isinstance(cfg, Mapping) or 'type' not in cfg:
        raise ValueError("orbit config must be a mapping with a 'type' key")
    cfg = ORBIT.validate(cfg)
    if cfg['type'] == 'tle':
        return Sgp4Orbit(cfg['line1'], cfg['line2'], epoch=epoch)
    return CircularOrbit(cfg['altitude_km'] * 1e3, math.radians(cfg['inclination_deg']),
                         math.radians(cfg['raan_deg']), math.radians(cfg['arg_latitude0_deg']),
                         epoch=epoch)
