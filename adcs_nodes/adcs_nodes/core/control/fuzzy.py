"""Fuzzy-logic eigenaxis slew controller (paper 003; pure numpy).

Alekseev, Malyavin, Shadyan, "Extensive attitude control of a near-Earth satellite based on
fuzzy logic" (seed paper 003; digest ``papers/fuzzy-eigenaxis-slew.md``, sections 4-8).
Geometry (1), (4)-(9), (15) is in :mod:`adcs_nodes.core.control.eigenaxis`.

Law
---
Two Mamdani controllers run in parallel (Fig. 3)::

    M_k  = FLC1(phi, phi_dot)              Table 1: 5 x 9 terms -> 9 terms
    M_gk = FLC2(|phidot_g|, |phiddot_g|)    Table 2: 5 x 5 terms -> 5 terms
    M    = M_k e_k + M_gk e_gk             (unnumbered equation before (4))
    |M_i| <= 1 N m per body axis

Negative ``M_k`` accelerates along ``-e_phi`` (toward the target); negative ``M_gk`` brakes the
parasitic rate.

Mamdani inference (the paper names Mamdani [6] and triangular membership functions; the
rest is the standard choice, ASSUMPTION): fuzzification with triangular functions whose feet
sit on the neighbouring peaks (the two outer terms are shoulders; the input is clipped to
[first peak, last peak]), so the memberships of each input sum to 1; rule strength
``w_r = min(mu_1, mu_2)``; implication by clipping (``min``); aggregation by ``max``;
defuzzification by the centroid of the piecewise-linear aggregated set on a grid of the
output universe (the formula of scikit-fuzzy's ``centroid``). The inference is vectorised
over rules, terms and the grid (and over a batch of inputs).

Table 1 row order (interpretation)
----------------------------------
Read with its printed row labels (top to bottom Б, С, М, ОМ, Н), Table 1 gives the rule
(φ = Н, φ̇ = Н) -> О: at the target and at rest (and only that rule fires there) the output is
the centroid of О, a non-zero torque, so the end state (3) of the paper (at the target, at
rest) is not an equilibrium, whatever the breakpoints; and the rule (Б, Н) -> Н leaves a
spacecraft at rest at a big angle where it is. With the rows taken in the order in which the
text lists the φ terms (Н, ОМ, М, С, Б top to bottom, i.e. the printed labels reversed), the
table is a conventional rate-profile controller: (Н, Н) -> Н, rate damping at φ = Н, full
acceleration from rest at ОМ/М and braking when faster than a cruise rate that grows with φ.
So the paper means the reversed reading (``table1_rows='reversed'``, the default); the
literal one is kept as ``'as_printed'``. Table 2 is symmetric, so its order does not matter.
On the paper's case (:mod:`adcs_nodes.tools.analyse.papers.paper003`, default breakpoints) the
reversed
reading settles (5 % band) in 26.7 s with 40.2 N m s (paper: 25.73 s, 42.91 N m s); the printed
one swings +-14 deg through the target and has not settled after 80 s.

Assumptions (not in the paper: breakpoints are only in Figs. 4, 5)
-------------------------------------------------------------------
* Breakpoints (term peaks) and output half-widths: :data:`DEFAULTS`, fitted from the digest's
  set S1 to the paper's settling time and energy (ASSUMPTION; see the comment there), and
  :data:`SMOOTH`, a set without overshoot.
* ``mk_gain``: a gain on the defuzzified ``M_k`` before the limit (ASSUMPTION; 1 = none).
* Limit: uniform scaling ``M <- M / max(1, max_i |M_i| / l_i)`` (keeps the direction and so
  the eigenaxis; ASSUMPTION), or per-axis clipping (``saturation='clip'``).
* ``tau`` of (15) is the controller period ``dt``.
* Inertia: ``J e / |J e|`` with the full matrix (the paper's principal ``J_i`` when diagonal).
* Axis undefined (``phi = 0``): the previous axis; without one, the direction of the rate
  (then ``phi_dot = |omega|``, the true growth of ``phi``), else x.
* Target in the orbital frame: the relative rate ``omega - omega0 R(q_orbit_body)^T y_orbit``;
  then minus the target's feed-forward rate ``omega_body_ref_body`` (body axes).
* Reaction wheels (when configured): motor torques ``tau_w = -pinv(A) (M + omega x A h_w)``
  (``A`` the (3, n) axes; the gyroscopic term of the wheel momentum is cancelled so that the
  body sees ``M``), scaled by one factor onto the wheel torque limits: (A1), (A2) of
  :mod:`adcs_nodes.core.control.wheel_allocation`, through
  :func:`adcs_nodes.core.control.eigenaxis.realise`.
"""
from __future__ import annotations

import math
from typing import Dict, Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core.control import finite_vector, inertia_matrix, limits_vector, scale_to_limits
from adcs_nodes.core.control import eigenaxis as ea

__all__ = ['PHI_TERMS', 'DPHI_TERMS', 'MK_TERMS', 'TABLE1_ROWS_PRINTED', 'TABLE1', 'G_TERMS',
           'TABLE2', 'table1_indices', 'table2_indices', 'triangular_memberships',
           'centroid', 'Mamdani', 'FuzzyEigenaxisController', 'DEFAULTS',
           'SMOOTH']

# ---------------------------------------------------------------------- rule tables
#: φ terms in increasing order: zero, very small, small, medium, big.
PHI_TERMS = ('Н', 'ОМ', 'М', 'С', 'Б')
#: φ̇ terms in increasing order (Table 1 header order): neg. big .. pos. big.
DPHI_TERMS = ('ОБ', 'ОС', 'ОМ', 'ООМ', 'Н', 'ПОМ', 'ПМ', 'ПС', 'ПБ')
#: M_k terms in increasing order (the paper's listing).
MK_TERMS = ('ОБ', 'ОС', 'О', 'ОМ', 'Н', 'ПМ', 'П', 'ПС', 'ПБ')
#: Table 1 exactly as printed: (row label, cells over DPHI_TERMS), top to bottom.
TABLE1_ROWS_PRINTED = (
    ('Б', ('П', 'ПБ', 'ПС', 'ПМ', 'Н', 'ОМ', 'ОС', 'ОБ', 'О')),
    ('С', ('П', 'П', 'ПБ', 'Н', 'ОБ', 'О', 'О', 'О', 'О')),
    ('М', ('ПБ', 'ПС', 'Н', 'ОС', 'ОБ', 'О', 'О', 'О', 'О')),
    ('ОМ', ('ПС', 'ОМ', 'ОС', 'О', 'О', 'О', 'О', 'О', 'О')),
    ('Н', ('ПБ', 'О', 'О', 'О', 'О', 'О', 'О', 'О', 'О')),
)
#: TABLE1[phi_term][dphi_term] -> M_k term, with the printed labels.
TABLE1: Dict[str, Dict[str, str]] = {
    row: dict(zip(DPHI_TERMS, cells)) for row, cells in TABLE1_ROWS_PRINTED}
#: Terms of |φ̇_g|, |φ̈_g| and M_gk: neg. big, neg. medium, zero, pos. medium, pos. big.
G_TERMS = ('ОБ', 'ОС', 'Н', 'ПС', 'ПБ')
#: TABLE2[abs_rate_term][rate_derivative_term] -> M_gk term, exactly as printed.
TABLE2: Dict[str, Dict[str, str]] = {
    'ОБ': dict(zip(G_TERMS, ('ПБ', 'ПБ', 'ПБ', 'ПС', 'Н'))),
    'ОС': dict(zip(G_TERMS, ('ПБ', 'ПБ', 'ПС', 'Н', 'ОС'))),
    'Н': dict(zip(G_TERMS, ('ПБ', 'ПС', 'Н', 'ОС', 'ОБ'))),
    'ПС': dict(zip(G_TERMS, ('ПС', 'Н', 'ОС', 'ОБ', 'ОБ'))),
    'ПБ': dict(zip(G_TERMS, ('Н', 'ОС', 'ОБ', 'ОБ', 'ОБ'))),
}
TABLE1_READINGS = ('reversed', 'as_printed')


def table1_indices(rows: str = 'reversed') -> np.ndarray:
    """Table 1 as output-term indices, ``out[i_phi, i_dphi]`` (orders of the term tuples).

    ``rows='as_printed'`` uses the printed row labels; ``'reversed'`` assigns the printed rows,
    top to bottom, to Н, ОМ, М, С, Б (the text's order of the φ terms; see the module
    docstring). ``ValueError`` for another value.
    """
    if rows not in TABLE1_READINGS:
        raise ValueError(f'table1_rows must be one of {TABLE1_READINGS}, got {rows!r}')
    out = np.empty((len(PHI_TERMS), len(DPHI_TERMS)), dtype=int)
    for k, (label, cells) in enumerate(TABLE1_ROWS_PRINTED):
        i = PHI_TERMS.index(label) if rows == 'as_printed' else k
        out[i] = [MK_TERMS.index(c) for c in cells]
    return out


def table2_indices() -> np.ndarray:
    """Table 2 as output-term indices, ``out[i_rate, i_rate_derivative]``."""
    return np.array([[G_TERMS.index(TABLE2[r][c]) for c in G_TERMS] for r in G_TERMS])


# ---------------------------------------------------------------------- Mamdani engine
def _check_peaks(peaks: ArrayLike, name: str, n: int) -> np.ndarray:
    p = finite_vector(peaks, name, (n,))
    if np.any(np.diff(p) <= 0.0):
        raise ValueError(f'{name} must be strictly increasing, got {p.tolist()}')
    return p


def triangular_memberships(x: ArrayLike, peaks: np.ndarray) -> np.ndarray:
    """Memberships of a triangular partition (shoulders at both ends).

    Parameters
    ----------
    x : array_like, shape (k,) or scalar
        Crisp inputs, clipped to ``[peaks[0], peaks[-1]]``.
    peaks : ndarray, shape (n,)
        Strictly increasing term peaks; each triangle's feet are the neighbouring peaks.

    Returns
    -------
    ndarray, shape (k, n)
        ``mu[j, i]`` of input ``j`` in term ``i``; every row sums to 1 (at most two non-zero).
    """
    return _memberships(x, peaks, *_inverse_widths(peaks))


def _inverse_widths(peaks: np.ndarray) -> tuple:
    """``1 / (left foot distance)``, ``1 / (right foot distance)`` per term (0: shoulder)."""
    inv = 1.0 / np.diff(peaks)
    return np.concatenate(([0.0], inv)), np.concatenate((inv, [0.0]))


def _memberships(x: ArrayLike, peaks: np.ndarray, inv_left: np.ndarray,
                 inv_right: np.ndarray) -> np.ndarray:
    xs = np.minimum(np.maximum(np.asarray(x, dtype=float).reshape(-1), peaks[0]), peaks[-1])
    d = xs[:, None] - peaks[None, :]
    mu = 1.0 - np.abs(d) * np.where(d >= 0.0, inv_right, inv_left)
    return np.maximum(mu, 0.0)


def centroid(x: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Centroid of the piecewise-linear set sampled as ``mu`` on the grid ``x``.

    Parameters
    ----------
    x : ndarray, shape (N,)
        Increasing grid of the output universe.
    mu : ndarray, shape (k, N)
        Aggregated memberships of ``k`` sets.

    Returns
    -------
    ndarray, shape (k,)
        Centroids (segment-wise exact for linear interpolation between grid points, the
        formula of ``skfuzzy.defuzz(..., 'centroid')``); 0 for an empty set.
    """
    dx = np.diff(x)
    return _centroid(mu, x[:-1], dx, dx * dx / 6.0)


def _centroid(mu: np.ndarray, x0: np.ndarray, dx: np.ndarray, dx2_6: np.ndarray) -> np.ndarray:
    y1, y2 = mu[:, :-1], mu[:, 1:]
    area = 0.5 * dx * (y1 + y2)
    total = area.sum(axis=1)
    moment = (x0 * area + dx2_6 * (y1 + 2.0 * y2)).sum(axis=1)
    out = np.zeros(mu.shape[0])
    ok = total > 0.0
    out[ok] = moment[ok] / total[ok]
    return out


class Mamdani:
    """Two-input, one-output Mamdani controller with triangular terms.

    Parameters
    ----------
    peaks1 : array_like, shape (n1,)
        Term peaks of input 1 (increasing; partition with shoulders).
    peaks2 : array_like, shape (n2,)
        Term peaks of input 2.
    out_peaks : array_like, shape (m,)
        Output term peaks (increasing).
    out_half_width : float
        Half base width of every output triangle (> 0), output units.
    table : array_like of int, shape (n1, n2)
        Rule base: output term index of the rule (term i of input 1 AND term j of input 2).
    n_points : int
        Grid points on the output universe ``[out_peaks[0] - w, out_peaks[-1] + w]``.

    Raises
    ------
    ValueError
        On non-increasing peaks, a bad table, a non-positive width or too few points.
    """

    def __init__(self, peaks1: ArrayLike, peaks2: ArrayLike, out_peaks: ArrayLike,
                 out_half_width: float, table: ArrayLike, n_points: int = 501) -> None:
        table = np.asarray(table)
        if table.ndim != 2:
            raise ValueError(f'rule table must be 2-D, got shape {table.shape}')
        n1, n2 = table.shape
        self.peaks1 = _check_peaks(peaks1, 'input 1 peaks', n1)
        self.peaks2 = _check_peaks(peaks2, 'input 2 peaks', n2)
        m = len(np.atleast_1d(out_peaks))
        self.out_peaks = _check_peaks(out_peaks, 'output peaks', m)
        if not (np.issubdtype(table.dtype, np.integer) and table.min() >= 0
                and table.max() < m):
            raise ValueError(f'rule table must hold output term indices 0..{m - 1}')
        w = float(out_half_width)
        if not (math.isfinite(w) and w > 0.0):
            raise ValueError(f'output half width must be finite and > 0, got {out_half_width}')
        if int(n_points) < 3:
            raise ValueError(f'n_points must be >= 3, got {n_points}')
        self.table = table.astype(int)
        self.half_width = w
        self.x = np.linspace(self.out_peaks[0] - w, self.out_peaks[-1] + w, int(n_points))
        # Output membership functions on the grid, shape (m, N).
        self.out_mf = np.clip(1.0 - np.abs(self.x[None, :] - self.out_peaks[:, None]) / w,
                              0.0, None)
        self._w1 = _inverse_widths(self.peaks1)
        self._w2 = _inverse_widths(self.peaks2)
        dx = np.diff(self.x)
        self._grid = (self.x[:-1], dx, dx * dx / 6.0)
        # Rules sorted by output term, for a max-reduction per term.
        flat = self.table.reshape(-1)
        self._order = np.argsort(flat, kind='stable')
        counts = np.bincount(flat, minlength=m)
        self._starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
        self._used = counts > 0

    @property
    def universe(self) -> tuple:
        """``(lo, hi)`` of the output universe."""
        return float(self.x[0]), float(self.x[-1])

    def strengths(self, x1: ArrayLike, x2: ArrayLike) -> np.ndarray:
        """Firing strength of each output term, ``max`` over its rules of ``min(mu1, mu2)``.

        Returns
        -------
        ndarray, shape (k, m)
        """
        mu1 = _memberships(x1, self.peaks1, *self._w1)                     # (k, n1)
        mu2 = _memberships(x2, self.peaks2, *self._w2)                     # (k, n2)
        w = np.minimum(mu1[:, :, None], mu2[:, None, :]).reshape(mu1.shape[0], -1)
        # A zero sentinel column keeps every start a valid index (unused trailing terms).
        ws = np.concatenate((w[:, self._order], np.zeros((w.shape[0], 1))), axis=1)
        s = np.maximum.reduceat(ws, self._starts, axis=1)
        return np.where(self._used, s, 0.0)                # a term without rules never fires

    def __call__(self, x1: ArrayLike, x2: ArrayLike) -> np.ndarray:
        """Crisp outputs for crisp inputs (scalars or equal-length arrays), shape (k,)."""
        s = self.strengths(x1, x2)                                          # (k, m)
        agg = np.max(np.minimum(s[:, :, None], self.out_mf[None]), axis=1)  # (k, N)
        return _centroid(agg, *self._grid)


# ---------------------------------------------------------------------- the controller
#: Default breakpoints (ASSUMPTION: the paper gives them only in Figs. 4, 5). Units: deg,
#: deg/s, deg/s^2, N m. Fitted on the paper's scenario
#: (:mod:`adcs_nodes.tools.analyse.papers.paper003`):
#: starting from the digest's set S1, a random search over scalings of the phi and phi_dot
#: peaks, ``mk_gain`` and the compensation output, rounded, picked the clean set (no residual
#: torque after settling) closest to the paper's 25.73 s and 42.91 N m s. It accelerates to
#: ~3.5 deg/s, brakes late and overshoots the target by ~4.5 deg before settling; +-10 % on
#: any of the four scalings keeps it within 24-29 s and 37-44 N m s. The compensation output
#: is x4 S1's (with S1's +-0.1 N m the body circled the target at ~1 deg; without compensation
#: it did not settle at all).
DEFAULTS = dict(
    phi_peaks_deg=(0.0, 2.5, 10.0, 30.0, 90.0),
    dphi_peaks_deg_s=(-6.4, -4.8, -2.4, -0.8, 0.0, 0.8, 2.4, 4.8, 6.4),
    mk_peaks_Nm=(-1.0, -0.75, -0.5, -0.25, 0.0, 0.25, 0.5, 0.75, 1.0),
    mk_half_width_Nm=0.25,
    mk_gain=3.7,
    g_peaks_deg_s=(-0.2, -0.1, 0.0, 0.1, 0.2),
    dg_peaks_deg_s2=(-0.2, -0.1, 0.0, 0.1, 0.2),
    mgk_peaks_Nm=(-0.4, -0.2, 0.0, 0.2, 0.4),
    mgk_half_width_Nm=0.2,
)
#: A smoother set (ASSUMPTION; the first tuning): no overshoot, about the same settling time
#: and ~40 % less energy than :data:`DEFAULTS`, i.e. far from the paper's energy.
SMOOTH = dict(
    DEFAULTS,
    phi_peaks_deg=(0.0, 3.0, 12.0, 35.0, 90.0),
    dphi_peaks_deg_s=(-4.0, -3.0, -1.5, -0.5, 0.0, 0.5, 1.5, 3.0, 4.0),
    mk_gain=3.0,
    mgk_peaks_Nm=(-0.5, -0.25, 0.0, 0.25, 0.5),
    mgk_half_width_Nm=0.25,
)


class FuzzyEigenaxisController(ea.EigenaxisTorqueLaw):
    """Paper 003's fuzzy eigenaxis slew controller (interface of :mod:`..control`).

    Parameters
    ----------
    inertia_kgm2 : array_like, shape (3, 3) or (3,)
        Onboard inertia (or principal inertias) [kg m^2], body axes.
    max_torque_Nm : float or array_like, shape (3,)
        Per-axis torque limit ``|M_i| <= l_i`` [N m] (paper: 1).
    table1_rows : str
        ``'reversed'`` (default; the reading that works, see the module docstring) or
        ``'as_printed'``.
    compensation : bool
        Run the gyroscopic-compensation controller (Table 2).
    saturation : str
        ``'scale'`` (keep the direction) or ``'clip'`` (per axis).
    phi_peaks_deg, dphi_peaks_deg_s, mk_peaks_Nm, mk_half_width_Nm, mk_gain,
    g_peaks_deg_s, dg_peaks_deg_s2, mgk_peaks_Nm, mgk_half_width_Nm :
        Breakpoints of Figs. 4, 5 (ASSUMPTION; defaults :data:`DEFAULTS`).
    n_points : int
        Output grid points of each centroid.
    wheel_axes_body : array_like, shape (n, 3), optional
        Reaction-wheel spin axes; with them the torque is allocated to the wheels.
    wheel_max_torque_Nm : array_like, shape (n,), optional
        Wheel motor torque limits [N m].
    hysteresis_deg : float
        Axis-sign hysteresis below 180 deg [deg].

    Raises
    ------
    ValueError
        On bad configuration (shapes, non-increasing breakpoints, unknown options).
    """

    def __init__(self, inertia_kgm2: ArrayLike, max_torque_Nm: ArrayLike = 1.0,
                 table1_rows: str = 'reversed', compensation: bool = True,
                 saturation: str = 'scale', n_points: int = 501,
                 wheel_axes_body: Optional[ArrayLike] = None,
                 wheel_max_torque_Nm: Optional[ArrayLike] = None,
                 hysteresis_deg: float = 1.0, **breakpoints: Sequence[float]) -> None:
        self.J = inertia_matrix(inertia_kgm2)
        self.limit = limits_vector(max_torque_Nm, 'max_torque_Nm', 3, allow_zero=False)
        if saturation not in ('scale', 'clip'):
            raise ValueError(f"saturation must be 'scale' or 'clip', got {saturation!r}")
        self.saturation = saturation
        self.table1_rows = table1_rows
        self.compensation = bool(compensation)
        self.hysteresis = math.radians(float(hysteresis_deg))
        unknown = set(breakpoints) - set(DEFAULTS)
        if unknown:
            raise ValueError(f'unknown fuzzy parameters {sorted(unknown)}; known: '
                             f'{", ".join(DEFAULTS)}')
        bp = dict(DEFAULTS, **breakpoints)
        self.mk_gain = float(bp['mk_gain'])
        if not (math.isfinite(self.mk_gain) and self.mk_gain > 0.0):
            raise ValueError(f'mk_gain must be finite and > 0, got {bp["mk_gain"]}')
        self.flc1 = Mamdani(bp['phi_peaks_deg'], bp['dphi_peaks_deg_s'], bp['mk_peaks_Nm'],
                            bp['mk_half_width_Nm'], table1_indices(table1_rows), n_points)
        self.flc2 = Mamdani(bp['g_peaks_deg_s'], bp['dg_peaks_deg_s2'], bp['mgk_peaks_Nm'],
                            bp['mgk_half_width_Nm'], table2_indices(), n_points)
        self._set_wheels(wheel_axes_body, wheel_max_torque_Nm)
        self._d_g = ea.RateModulusDerivative()
        self._axis: Optional[np.ndarray] = None

    def reset(self) -> None:
        """Forget the previous axis and the previous parasitic rate."""
        self._d_g.reset()
        self._axis = None

    # ------------------------------------------------------------------ law
    def law(self, q_target_body: ArrayLike, omega_rel_body: ArrayLike, dt: float) -> dict:
        """One step of the law on the attitude error.

        Parameters
        ----------
        q_target_body : array_like, shape (4,)
            Error quaternion (body -> target axes), scalar last.
        omega_rel_body : array_like, shape (3,)
            Body rate relative to the target, body axes [rad/s].
        dt : float
            Period [s] (``tau`` of (15)).

        Returns
        -------
        dict
            ``torque_body`` (3,) [N m] after the limit, and the diagnostics
            ``torque_unlimited`` (before the limit), ``phi``, ``phi_dot``, ``g``, ``g_dot``,
            ``M_k``, ``M_gk``, ``e_phi``, ``sigma``.
        """
        w = np.asarray(omega_rel_body, dtype=float)
        phi, e_phi = ea.eigen_from_quaternion(q_target_body, self._axis, self.hysteresis)
        if not np.any(e_phi):                      # phi = 0 and no previous axis
            nw = float(np.linalg.norm(w))
            e_phi = w / nw if nw > 0.0 else np.array([1.0, 0.0, 0.0])
        self._axis = e_phi
        e_k, _ = ea.torque_direction(self.J, e_phi)                                   # (4)
        phi_dot, wg, g = ea.gyroscopic_rate(w, e_phi)                                 # (9)
        g_dot = self._d_g.update(g, dt)                                              # (15)
        m_k = self.mk_gain * float(self.flc1(math.degrees(phi), math.degrees(phi_dot))[0])
        m = m_k * e_k
        m_gk = 0.0
        if self.compensation and g > 1e-12:                              # pitfall 4
            e_gk, _ = ea.torque_direction(self.J, wg / g)                            # (5)
            m_gk = float(self.flc2(math.degrees(g), math.degrees(g_dot))[0])
            m = m + m_gk * e_gk
        if self.saturation == 'scale':
            m_out, sigma = scale_to_limits(m, self.limit)
        else:
            m_out = np.clip(m, -self.limit, self.limit)
            sigma = 1.0
        return dict(torque_body=m_out, torque_unlimited=m, phi=phi, phi_dot=phi_dot, g=g,
                    g_dot=g_dot, M_k=m_k, M_gk=m_gk, e_phi=e_phi, sigma=sigma)

    def _torque_law(self, q_err: np.ndarray, w_rel: np.ndarray, w_abs: np.ndarray,
                    dt: float) -> dict:
        return self.law(q_err, w_rel, dt)
