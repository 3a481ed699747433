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

Mamdani inference (the paper names Mamdani [6] and triangular functions; the rest is the
standard choice, ASSUMPTION): triangular terms with feet on the neighbouring peaks (shoulders
at both ends, input clipped), so memberships sum to 1; ``w_r = min(mu_1, mu_2)``; ``min``
implication, ``max`` aggregation; centroid of the piecewise-linear set on a grid (the formula
of scikit-fuzzy's ``centroid``), vectorised over rules, terms, grid and inputs.

Table 1 is read with its rows reversed (Н, ОМ, М, С, Б top to bottom, the text's order of the
φ terms; ``table1_rows='reversed'``, the default): read as printed, (Н, Н) -> О makes the end
state (3) no equilibrium. ``'as_printed'`` keeps the literal reading (docs/decisions.md).

Assumptions (the breakpoints are only in Figs. 4, 5):
* Breakpoints and output half-widths: :data:`DEFAULTS` (fitted to the paper's settling time
  and energy) and :data:`SMOOTH` (no overshoot).
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

from adcs_nodes.core.control import (finite_vector, inertia_matrix, limits_vector, positive,
                                     scale_to_limits)
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
    """Memberships ``mu[j, i]`` (k, n) of the inputs ``x`` (k,) (clipped to the end peaks) in
    the triangular partition of the increasing ``peaks`` (n,); every row sums to 1."""
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
    """Centroids (k,) of the piecewise-linear sets ``mu`` (k, N) on the increasing grid ``x``
    (N,) (exact per segment, as ``skfuzzy.defuzz(..., 'centroid')``); 0 for an empty set."""
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
    """Two-input, one-output Mamdani controller with triangular terms: increasing term peaks
    ``peaks1`` (n1,), ``peaks2`` (n2,), ``out_peaks`` (m,); ``out_half_width`` > 0 of every
    output triangle; ``table`` (n1, n2) of output term indices; ``n_points`` on the output
    universe ``[out_peaks[0] - w, out_peaks[-1] + w]``. ``ValueError`` if not."""

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
        w = positive(out_half_width, 'output half width')
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
        """Firing strength (k, m) of each output term: ``max`` over its rules of
        ``min(mu1, mu2)``."""
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
#: Default breakpoints (ASSUMPTION, fitted from the digest's set S1 to the paper's settling
#: time and energy; docs/decisions.md). Units: deg, deg/s, deg/s^2, N m.
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
#: A smoother set (ASSUMPTION): no overshoot, ~40 % less energy than :data:`DEFAULTS`.
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

    ``inertia_kgm2`` (3, 3) or (3,) [kg m^2] body axes; ``max_torque_Nm`` per-axis limit
    [N m] (paper: 1); ``table1_rows`` ``'reversed'`` or ``'as_printed'``; ``compensation``:
    run Table 2; ``saturation`` ``'scale'`` or ``'clip'``; the breakpoints of :data:`DEFAULTS`
    as keywords; ``n_points`` per centroid grid; ``wheel_axes_body`` (n, 3) and
    ``wheel_max_torque_Nm`` (n,) [N m] to allocate to wheels; ``hysteresis_deg`` of the axis
    sign below 180 deg. ``ValueError`` on a bad configuration.
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
        self.mk_gain = positive(bp['mk_gain'], 'mk_gain')
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
        """One step on the error quaternion ``q_target_body`` (4,) and the relative rate
        ``omega_rel_body`` (3,) [rad/s], body axes, period ``dt`` [s] (``tau`` of (15)).

        Returns a dict: ``torque_body`` (3,) [N m] after the limit, and ``torque_unlimited``,
        ``phi``, ``phi_dot``, ``g``, ``g_dot``, ``M_k``, ``M_gk``, ``e_phi``, ``sigma``.
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
