"""Geomagnetic field models of the simulated world: tilted dipole and IGRF (pure numpy, no ROS).

Equations
---------
Both models are fixed in the Earth (ECEF) and rotate with it (GMST of :mod:`.orbit`)::

    r_ecef = Rz(GMST(t))^T r_eci,   b_eci = Rz(GMST(t)) b_ecef(r_ecef, t)               (G1)

Centred tilted dipole (digest of paper 000, section 5.2; Wertz 1978, appendix H)::

    b_ecef = B0 (R / |r|)^3 [3 (m . r_hat) r_hat - m]                                 (G2)

``m = -p`` is the unit dipole moment, ``p`` the unit vector to the north geomagnetic pole
(colatitude ``theta_p``, east longitude ``phi_p``; ``theta_p = 0``: aligned dipole), so
``b = -2 B0 (R/r)^3 r_hat`` at that pole. From the IGRF degree-1 Gauss coefficients (nT)::

    B0 = sqrt(g10^2 + g11^2 + h11^2),   m = (g11, h11, g10) / B0   (ECEF)               (G3)

IGRF (International Geomagnetic Reference Field; Alken et al. 2021, EPS 73:49; IGRF-14
coefficients: IAGA V-MOD, doi:10.5281/zenodo.14012302), Schmidt
semi-normalised ``P_n^m(cos theta)``, reference radius ``a = 6371.2 km``::

    V = a sum_n (a/r)^(n+1) sum_m P_n^m (g_nm cos m phi + h_nm sin m phi)               (G4)
    B_r = -dV/dr,  B_theta = -(1/r) dV/dtheta,  B_phi = -(1/(r sin theta)) dV/dphi

with ``g, h`` linear in the decimal year ``y`` between the 5-year model epochs ``Y_k``, and
the secular variation ``sv`` after the last one (as the reference ``igrf14syn``)::

    g(y) = g(Y_k) + (y - Y_k) / 5 [g(Y_k+1) - g(Y_k)],   Y_k <= y < Y_k+1               (G4a)
    g(y) = g(2025) + (y - 2025) sv,                      y >= 2025

(``ppigrf``'s 2030 column is ``g(2025) + 5 sv``: one formula). ``y = Y + (instant -
Y-01-01) / length of year Y``; ``b = B_r r_hat + B_theta theta_hat + B_phi phi_hat``
(``theta_hat`` points south).

Rate along the trajectory (motion + Earth rotation + secular variation), central difference::

    b_dot_eci(t) = [b_eci(r(t+h), t+h) - b_eci(r(t-h), t-h)] / (2 h),   h = 0.5 s       (G5)

(relative truncation error ``(2 n h)^2 / 6 ~ 2e-7`` in LEO). The coefficients are read once
from ``ppigrf``'s ``IGRF14.shc`` (1900-2030; extrapolated with the secular variation up to
2035); the sum (G4) is checked against ``ppigrf.igrf_gc`` (< 0.001 nT) and ``igrf14syn``
(< 0.1 nT). The rotations (G1) and the dipole (G2) are numba kernels (same bits uncompiled).
ASSUMPTION: the default dipole (``B0 = 3.0e-5 T``, pole at 79 deg N, 71 deg W) is the digest's
proposal (section 5.2), not the paper's.
"""
from __future__ import annotations

import abc
import functools
import importlib.util
import math
import os
from datetime import datetime, timedelta, timezone
from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core.kernels import jit
from adcs_nodes.core.control import finite
from adcs_nodes.core.orbit import OrbitModel, _utc, gmst
from adcs_nodes.core.spec import Param, Section

R_REF_M = 6371200.0
"""Geomagnetic reference radius [m] (IGRF)."""
B0_DEFAULT_T = 3.0e-5
"""Default dipole strength [T] (digest of paper 000, section 5.2; assumption)."""
POLE_COLATITUDE_DEFAULT_RAD = math.radians(11.0)
"""Default north geomagnetic pole colatitude [rad] (79 deg N, digest 5.2; assumption)."""
POLE_LONGITUDE_DEFAULT_RAD = math.radians(-71.0)
"""Default north geomagnetic pole east longitude [rad] (71 deg W, digest 5.2; assumption)."""
IGRF_YEARS = (1900.0, 2035.0)
"""Range of decimal years accepted for the IGRF epoch."""

_POLE_EPS = 1e-9  # [rad] colatitude kept this far from the poles (B_phi has 1/sin(theta))


@jit
def to_ecef(c, s, v_eci):
    """``Rz(GMST)^T v`` (G1), ``c, s = cos, sin GMST``; shape (3,)."""
    return np.array([c * v_eci[0] + s * v_eci[1], c * v_eci[1] - s * v_eci[0], v_eci[2]])


@jit
def to_eci(c, s, v_ecef):
    """``Rz(GMST) v`` (G1), ``c, s = cos, sin GMST``; shape (3,)."""
    return np.array([c * v_ecef[0] - s * v_ecef[1], s * v_ecef[0] + c * v_ecef[1], v_ecef[2]])


@jit
def dipole_ecef(r_ecef, m_ecef, k):
    """Tilted dipole (G2) (3,) [T], ECEF, at ``r_ecef`` (3,) [m]; ``k = B0 R^3`` [T m^3]."""
    r2 = r_ecef[0] * r_ecef[0] + r_ecef[1] * r_ecef[1] + r_ecef[2] * r_ecef[2]
    r = math.sqrt(r2)
    f = k / (r2 * r)
    a = 3.0 * (m_ecef[0] * r_ecef[0] + m_ecef[1] * r_ecef[1] + m_ecef[2] * r_ecef[2]) / r2
    return np.array([f * (a * r_ecef[0] - m_ecef[0]), f * (a * r_ecef[1] - m_ecef[1]),
                     f * (a * r_ecef[2] - m_ecef[2])])                                # (G2)


@jit
def dipole_eci(r_eci, theta, m_ecef, k):
    """Tilted dipole (G1), (G2) (3,) [T], ECI, at ``r_eci`` (3,) [m], ``theta`` = GMST [rad]."""
    c, s = math.cos(theta), math.sin(theta)
    return to_eci(c, s, dipole_ecef(to_ecef(c, s, r_eci), m_ecef, k))


@jit
def dipole_eci_and_rate(r, r_plus, r_minus, theta, theta_plus, theta_minus, m_ecef, k, h):
    """:func:`dipole_eci` at ``r`` (GMST ``theta``) and its central difference (G5) between
    ``r_plus`` (``theta_plus``) and ``r_minus`` (``theta_minus``) over ``2 h`` [s]: ``(b_eci
    (3,) [T], b_dot_eci (3,) [T/s])``."""
    b_plus = dipole_eci(r_plus, theta_plus, m_ecef, k)
    b_minus = dipole_eci(r_minus, theta_minus, m_ecef, k)
    return dipole_eci(r, theta, m_ecef, k), (b_plus - b_minus) / (2.0 * h)


@functools.cache
def warm_up() -> None:
    """Compile (or load from the numba cache) the kernels once per process, from the model
    constructors: the first compilation never falls inside a frame."""
    v = np.array([7e6, 0.0, 0.0])
    dipole_eci(v, 0.1, v, 1.0)
    dipole_eci_and_rate(v, v, v, 0.1, 0.1, 0.1, v, 1.0, 0.5)
    to_eci(1.0, 0.0, dipole_ecef(to_ecef(1.0, 0.0, v), v, 1.0))


def _position(r_eci: ArrayLike) -> np.ndarray:
    r = np.asarray(r_eci, dtype=float)
    v = r.tolist() if r.shape == (3,) else None      # a finite sum: all finite (hot path)
    if v is None or not (math.isfinite(sum(v)) or np.isfinite(r).all()):
        raise ValueError(f'r_eci must be a finite array of shape (3,), got {r_eci!r}')
    if not any(v):
        raise ValueError('r_eci must be non-zero')
    return r


class GeomagneticField(abc.ABC):
    """Earth-fixed field model (``epoch``: aware UTC instant of ``t = 0``); subclasses give
    :meth:`field_ecef`."""

    rate_step_s = 0.5
    """Half step ``h`` [s] of the central difference (G5)."""

    def __init__(self, epoch: datetime) -> None:
        self.epoch = _utc(epoch)
        warm_up()

    @abc.abstractmethod
    def field_ecef(self, r_ecef: np.ndarray, t: float) -> np.ndarray:
        """Field (3,) [T] in ECEF at the ECEF position ``r_ecef`` (3,) [m], ``t`` s after epoch."""

    def field_eci(self, r_eci: ArrayLike, t: float) -> np.ndarray:
        """Field ``b_eci`` (3,) [T], ECI, at the finite non-zero ``r_eci`` (3,) [m], ECI, time
        ``t`` [s] (G1)."""
        r = _position(r_eci)
        theta = gmst(self.epoch, t)
        c, s = math.cos(theta), math.sin(theta)
        return to_eci(c, s, self.field_ecef(to_ecef(c, s, r), t))                     # (G1)

    def field_and_rate(self, orbit: OrbitModel, t: float,
                       r_eci: ArrayLike = None) -> tuple[np.ndarray, np.ndarray]:
        """``(b_eci (3,) [T], b_dot_eci (3,) [T/s])``, ECI, at ``orbit.state(t).r_eci`` (or the
        given ``r_eci`` [m]), ``t`` [s]; the rate (G5) includes the satellite's motion, the
        Earth's rotation and the secular variation. ``ValueError`` if the orbit's epoch
        differs from this model's."""
        if getattr(orbit, 'epoch', self.epoch) != self.epoch:
            raise ValueError(f'orbit epoch {orbit.epoch} differs from field epoch {self.epoch}')
        t = float(t)
        h = self.rate_step_s
        position = getattr(orbit, 'position', None) or (lambda s: orbit.state(s).r_eci)
        return self._field_and_difference(
            _position(position(t) if r_eci is None else r_eci), _position(position(t + h)),
            _position(position(t - h)), t, h)

    def _field_and_difference(self, r: np.ndarray, r_plus: np.ndarray, r_minus: np.ndarray,
                              t: float, h: float) -> tuple[np.ndarray, np.ndarray]:
        """``b(r, t)`` and (G5) ``(b(r_plus, t + h) - b(r_minus, t - h)) / 2 h`` (ECI)."""
        b_plus, b_minus = self.field_eci(r_plus, t + h), self.field_eci(r_minus, t - h)
        return self.field_eci(r, t), (b_plus - b_minus) / (2.0 * h)


class DipoleField(GeomagneticField):
    """Centred tilted dipole (G2), fixed in ECEF: equatorial field ``b0_T`` [T] > 0 at
    ``r_ref_m`` [m] > 0, north geomagnetic pole at ``pole_colatitude_rad`` in [0, pi] and east
    ``pole_longitude_rad`` [rad]. ``ValueError`` on a bad argument or a naive ``epoch``."""

    def __init__(self, epoch: datetime, *, b0_T: float = B0_DEFAULT_T,
                 r_ref_m: float = R_REF_M,
                 pole_colatitude_rad: float = POLE_COLATITUDE_DEFAULT_RAD,
                 pole_longitude_rad: float = POLE_LONGITUDE_DEFAULT_RAD) -> None:
        super().__init__(epoch)
        self.b0 = finite(b0_T, 'b0_T')
        self.r_ref = finite(r_ref_m, 'r_ref_m')
        if self.b0 <= 0.0 or self.r_ref <= 0.0:
            raise ValueError(f'b0_T and r_ref_m must be > 0, got {self.b0}, {self.r_ref}')
        colat = finite(pole_colatitude_rad, 'pole_colatitude_rad')
        if not 0.0 <= colat <= math.pi:
            raise ValueError(f'pole_colatitude_rad must be in [0, pi], got {colat}')
        lon = finite(pole_longitude_rad, 'pole_longitude_rad')
        self.pole_colatitude, self.pole_longitude = colat, lon
        # Unit dipole moment (3,), ECEF: minus the direction to the north geomagnetic pole.
        self.m_ecef = -np.array([math.sin(colat) * math.cos(lon),
                                 math.sin(colat) * math.sin(lon), math.cos(colat)])
        self._k = self.b0 * self.r_ref ** 3

    @classmethod
    def from_igrf(cls, epoch: datetime, coefficient_date: datetime | None = None) -> DipoleField:
        """Dipole of the IGRF-14 degree-1 coefficients (G3) at the aware ``coefficient_date``
        (1900-2035; default ``epoch``), fixed in ECEF for the run (23 % RMS from the full IGRF
        at 700 km in 2025, a test measures it)."""
        date = _utc(epoch if coefficient_date is None else coefficient_date, 'coefficient_date')
        year = _decimal_year(date)
        if not IGRF_YEARS[0] <= year <= IGRF_YEARS[1]:
            raise ValueError(f'IGRF date must be in {IGRF_YEARS}, got decimal year {year}')
        g, h = _igrf_table(1).coefficients(year)
        g10, g11, h11 = g[0], g[1], h[1]  # keys (1, 0), (1, 1)
        b0_nt = math.sqrt(g10 * g10 + g11 * g11 + h11 * h11)
        return cls(epoch, b0_T=b0_nt * 1e-9, r_ref_m=R_REF_M,
                   pole_colatitude_rad=math.acos(-g10 / b0_nt),
                   pole_longitude_rad=math.atan2(-h11, -g11))

    def field_ecef(self, r_ecef: np.ndarray, t: float) -> np.ndarray:
        """Field (3,) [T], ECEF, at ``r_ecef`` (3,) [m] (G2); independent of ``t``."""
        return dipole_ecef(np.asarray(r_ecef, dtype=float), self.m_ecef, self._k)

    def field_eci(self, r_eci: ArrayLike, t: float) -> np.ndarray:
        """Field ``b_eci`` (3,) [T], ECI, (G1) and (G2) in one compiled call (see the base)."""
        return dipole_eci(_position(r_eci), gmst(self.epoch, t), self.m_ecef, self._k)

    def _field_and_difference(self, r: np.ndarray, r_plus: np.ndarray, r_minus: np.ndarray,
                              t: float, h: float) -> tuple[np.ndarray, np.ndarray]:
        """The base's three fields (G1), (G2) and (G5) in one compiled call."""
        return dipole_eci_and_rate(r, r_plus, r_minus, gmst(self.epoch, t),
                                   gmst(self.epoch, t + h), gmst(self.epoch, t - h),
                                   self.m_ecef, self._k, h)


class IgrfField(GeomagneticField):
    """IGRF-14 main field (G4) up to ``max_degree`` (1..13), ``epoch`` an aware instant in
    1900-2035 (``ValueError`` if not)."""

    def __init__(self, epoch: datetime, max_degree: int = 13) -> None:
        super().__init__(epoch)
        if isinstance(max_degree, bool) or not isinstance(max_degree, (int, np.integer)) \
                or not 1 <= max_degree <= 13:
            raise ValueError(f'max_degree must be an integer in 1..13, got {max_degree!r}')
        self.max_degree = int(max_degree)
        self.year0 = _decimal_year(self.epoch)
        if not IGRF_YEARS[0] <= self.year0 <= IGRF_YEARS[1]:
            raise ValueError(f'IGRF epoch must be in {IGRF_YEARS}, got decimal year {self.year0}')
        self._table = _igrf_table(self.max_degree)

    def decimal_year(self, t: float) -> float:
        """Decimal year of ``t`` s after the epoch, as of the epoch itself (G4a)."""
        if t == 0.0:
            return self.year0
        return _decimal_year(self.epoch + timedelta(seconds=float(t)))

    def field_ecef(self, r_ecef: np.ndarray, t: float) -> np.ndarray:
        """Field (3,) [T], ECEF, at ``r_ecef`` (3,) [m], ``t`` s after the epoch (G4)."""
        tab = self._table
        g, h = tab.coefficients(self.decimal_year(t))                                 # (G4a)
        r = math.sqrt(r_ecef @ r_ecef)
        theta = min(max(math.acos(r_ecef[2] / r), _POLE_EPS), math.pi - _POLE_EPS)
        phi = math.atan2(r_ecef[1], r_ecef[0])
        ct, st = math.cos(theta), math.sin(theta)
        p, dp = tab.legendre(ct, st)
        cm, sm = np.cos(tab.m * phi), np.sin(tab.m * phi)
        ar = (R_REF_M / r) ** (tab.n + 2)
        a_nm = g * cm + h * sm
        b_r = np.dot(ar * (tab.n + 1), p * a_nm)
        b_theta = -np.dot(ar * dp, a_nm)
        b_phi = -np.dot(ar * p, tab.m * (h * cm - g * sm)) / st
        cp, sp = math.cos(phi), math.sin(phi)
        r_hat = np.array([st * cp, st * sp, ct])
        theta_hat = np.array([ct * cp, ct * sp, -st])
        phi_hat = np.array([-sp, cp, 0.0])
        return 1e-9 * (b_r * r_hat + b_theta * theta_hat + b_phi * phi_hat)


# ----------------------------------------------------------------------- IGRF internals

def _decimal_year(t_utc: datetime) -> float:
    """Decimal year of an aware datetime: ``year + elapsed / length of that year``."""
    start = datetime(t_utc.year, 1, 1, tzinfo=timezone.utc)
    end = datetime(t_utc.year + 1, 1, 1, tzinfo=timezone.utc)
    return t_utc.year + (t_utc - start) / (end - start)


class _IgrfTable:
    """IGRF-14 Gauss coefficients (nT) up to ``max_degree`` and Legendre recursion constants."""

    def __init__(self, max_degree: int) -> None:
        keys = [(n, m) for n in range(1, max_degree + 1) for m in range(n + 1)]
        self.n = np.array([k[0] for k in keys], dtype=float)
        self.m = np.array([k[1] for k in keys], dtype=float)
        self.years, self.g, self.h = _read_igrf14(keys)
        # Recursion (Langel 1987): slot 0 is P_0^0 = 1, slot K + 1 stays 0 (absent P_{n-2}^m).
        slot = {k: i + 1 for i, k in enumerate(keys)}
        slot[0, 0] = 0
        self._size = len(keys) + 2
        self._steps = []
        for n, m in keys:
            if n == m:
                a = 1.0 if n == 1 else math.sqrt((2 * n - 1) / (2 * n))
                self._steps.append((True, slot[n, m], slot[n - 1, m - 1], 0, a, 0.0))
            else:
                den = math.sqrt(n * n - m * m)
                self._steps.append((False, slot[n, m], slot[n - 1, m],
                                    slot.get((n - 2, m), len(keys) + 1), (2 * n - 1) / den,
                                    math.sqrt(max((n - 1) ** 2 - m * m, 0)) / den))

    def coefficients(self, year: float) -> tuple[np.ndarray, np.ndarray]:
        """``(g, h)`` (K,) [nT] at a decimal year, (G4a); extrapolated past the ends."""
        i = min(max(int(np.searchsorted(self.years, year)) - 1, 0), len(self.years) - 2)
        w = (year - self.years[i]) / (self.years[i + 1] - self.years[i])
        return (self.g[i] + w * (self.g[i + 1] - self.g[i]),
                self.h[i] + w * (self.h[i + 1] - self.h[i]))

    def legendre(self, ct: float, st: float) -> tuple[np.ndarray, np.ndarray]:
        """Schmidt semi-normalised ``P_n^m(cos theta)`` and ``dP/dtheta`` (K,) in key order::

            P_n^n = a_n sin P_{n-1}^{n-1},  a_1 = 1,  a_n = sqrt((2n - 1) / 2n)
            P_n^m = [(2n - 1) cos P_{n-1}^m - sqrt((n-1)^2 - m^2) P_{n-2}^m] / sqrt(n^2 - m^2)
        """
        p = [1.0] + [0.0] * (self._size - 1)
        dp = [0.0] * self._size
        for diag, i, j, k, a, b in self._steps:
            if diag:
                p[i] = a * st * p[j]
                dp[i] = a * (st * dp[j] + ct * p[j])
            else:
                p[i] = a * ct * p[j] - b * p[k]
                dp[i] = a * (ct * dp[j] - st * p[j]) - b * dp[k]
        return np.array(p[1:-1]), np.array(dp[1:-1])


def _shc_path() -> str:
    """``IGRF14.shc`` of the installed ``ppigrf`` package (found without importing it)."""
    spec = importlib.util.find_spec('ppigrf')
    if spec is None or not spec.submodule_search_locations:
        raise ValueError('the IGRF coefficients need the ppigrf package (pip install ppigrf)')
    return os.path.join(list(spec.submodule_search_locations)[0], 'IGRF14.shc')


def _read_igrf14(keys: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(years (T,), g (T, K), h (T, K))`` [nT] of the ``keys`` ``(n, m)`` from IGRF14.shc:
    ``#`` comments, a line of sizes, a line of model years, then ``n m c_1 .. c_T`` per
    coefficient (``m < 0``: ``h_n^|m|``). Plain Python (``ppigrf.read_shc`` imports pandas);
    a file whose years are not whole goes through ``ppigrf``."""
    rows: dict = {}
    with open(_shc_path(), encoding='utf-8') as fh:
        lines = [line.split() for line in fh if line.strip() and not line.startswith('#')]
    years = [float(x) for x in lines[1]] if len(lines) > 2 else []   # lines[0]: sizes
    for parts in lines[2:]:
        rows[int(parts[0]), int(parts[1])] = [float(x) for x in parts[2:]]
    if not years or any(y != math.floor(y) for y in years):
        return _read_igrf14_ppigrf(keys)
    g = np.array([rows[n, m] for n, m in keys], dtype=float).T
    h = np.array([rows[n, -m] if m > 0 else [0.0] * len(years) for n, m in keys],
                 dtype=float).T
    return np.array(years), g, h


def _read_igrf14_ppigrf(keys: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """As :func:`_read_igrf14`, through ``ppigrf.read_shc`` (pandas)."""
    from ppigrf import ppigrf

    g_df, h_df = ppigrf.read_shc(ppigrf.shc_fn_igrf14)
    years = np.array([_decimal_year(d.to_pydatetime().replace(tzinfo=timezone.utc))
                      for d in g_df.index])
    return years, g_df[keys].to_numpy(dtype=float), h_df[keys].to_numpy(dtype=float)


@functools.lru_cache(maxsize=None)
def _igrf_table(max_degree: int) -> _IgrfTable:
    return _IgrfTable(max_degree)


# ----------------------------------------------------------------------------- factory
#: The ``field`` section (a scenario's, a node's ``field.*`` and ``onboard_field.*``).
FIELD = Section('field', (
    Param('model', 'str', 'dipole', '-', 'geomagnetic model',
          choices=('dipole', 'igrf_dipole', 'igrf')),
), 'the geomagnetic field', selector='model', variants={
    'dipole': (
        Param('b0_T', 'float', None, 'T', 'dipole strength at the reference radius',
              positive=True, max=1e-3),
        Param('r_ref_m', 'float', None, 'm', 'reference radius of b0_T', positive=True,
              max=1e9),
        Param('pole_colatitude_deg', 'float', None, 'deg', 'geographic colatitude of the '
              'dipole axis', min=0.0, max=180.0),
        Param('pole_longitude_deg', 'float', None, 'deg', 'geographic east longitude of the '
              'axis', min=-360.0, max=360.0)),
    'igrf_dipole': (Param('coefficient_date', 'time', None, '-', 'date of the IGRF degree-1 '
                          'coefficients (ISO 8601; default: the epoch)'),),
    'igrf': (Param('max_degree', 'int', None, '-', 'truncation degree of the IGRF expansion',
                   min=1, max=13),)})


def make_field(cfg: Mapping, epoch: datetime) -> GeomagneticField:
    """The field model of a :data:`FIELD` mapping at the aware scenario ``epoch``
    (``ValueError`` naming a missing or unknown model or key, or a bad value)."""
    if not isinstance(cfg, Mapping) or 'model' not in cfg:
        raise ValueError("field config must be a mapping with a 'model' key")
    cfg = FIELD.validate(cfg)
    model = cfg['model']
    if model == 'igrf':
        return IgrfField(epoch, max_degree=cfg.get('max_degree', 13))
    if model == 'igrf_dipole':
        date = cfg.get('coefficient_date')
        if isinstance(date, str):
            try:
                date = datetime.fromisoformat(date)
            except ValueError:
                raise ValueError(f'coefficient_date is not an ISO date: {date!r}') from None
        return DipoleField.from_igrf(epoch, date)
    kwargs = {k: cfg[k] for k in ('b0_T', 'r_ref_m') if k in cfg}
    for key in ('pole_colatitude_deg', 'pole_longitude_deg'):
        if key in cfg:
            kwargs[key.replace('_deg', '_rad')] = math.radians(cfg[key])
    return DipoleField(epoch, **kwargs)
