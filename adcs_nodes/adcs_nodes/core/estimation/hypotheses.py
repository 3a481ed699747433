"""Hypotheses about the rotation about the measured field: a filter bank beyond paper 000.

DEPARTURE from paper 000 (whose filter is one hypothesis): one reading ``n = C B*`` fixes the
attitude up to a rotation about ``n``; every ``N' = N . R(n_hat, psi)`` predicts the same
``n*``, and only the turn of the inertial field and the gravity gradient separate them, so the
filter can lock onto a wrong ``psi`` (``docs/decisions.md``, "The filter's blind axis").

Remedy: multiple-model adaptive estimation (D. T. Magill, "Optimal adaptive estimation of
sampled stochastic processes", IEEE TAC 10(4), 1965; P. S. Maybeck, "Stochastic Models,
Estimation and Control" vol. 2, 1982, ch. 10). When the filter first locks (attitude ellipsoid
``2 sqrt(trace P_phi)`` below :data:`LOCK_DEG`), ``K`` hypotheses are started on the
unobservable circle::

    N_k = N . R(n_hat_body, 2 pi k / K),  omega'_k = omega',  m'_k = m',  P_k = P,  k = 0..K-1

and run side by side, each with its own prediction (33)-(34) and update (36)-(39). Each scores
its readings by the prediction error before its update::

    J_k = sum_i z_i^T Theta_i^-1 z_i,   z_i = n_i - C(N_k) B*_i                            (H1)

from ``window_s / 2`` after the start (the hypotheses first settle onto their branch) to
``window_s``; meanwhile the one with the smallest ``J_k`` is published (hypothesis 0 before
the scoring). Then the smallest ``J_k`` goes on alone. DEPARTURE from MMAE: (H1) leaves out
``H P H^T`` and ``ln det S`` of the Gaussian likelihood (paper 000's ``P`` is an ellipsoid
bound, not a covariance).
"""
from __future__ import annotations

import copy
import math
from typing import List, Optional

import numpy as np

from adcs_nodes.core import attitude
from adcs_nodes.core.control import positive
from adcs_nodes.core.estimation.magnetic_filter import MagneticFilter

LOCK_DEG = 3.0
"""Attitude ellipsoid ``2 sqrt(trace P_phi)`` [deg] below which the filter has locked onto a
branch and the bank starts (ASSUMPTION)."""


def locked(f: MagneticFilter) -> bool:
    """True when the attitude ellipsoid ``2 sqrt(trace P_phi)`` is below :data:`LOCK_DEG`."""
    return math.degrees(2.0 * math.sqrt(max(0.0, float(np.trace(f.P[:3, :3]))))) < LOCK_DEG


def turned_about_field(f: MagneticFilter, b_body: np.ndarray, psi: float) -> MagneticFilter:
    """Copy of ``f`` with ``N . R(b_hat_body, psi)`` [rad] (same ``omega'``, ``m'``, ``P``)."""
    g = copy.deepcopy(f)
    turn = attitude.from_axis_angle(b_body / np.linalg.norm(b_body), psi)
    g.set_state(attitude.multiply(f.q_orbit_body, turn), f.omega_body_eci_body, f.m, f.P)
    return g


def prediction_error(f: MagneticFilter, b_body: np.ndarray, b_ref_orbit: np.ndarray,
                     theta_axes: np.ndarray) -> float:
    """``z^T Theta^-1 z`` (H1) of reading ``b_body`` (3,) [T] before ``f``'s update;
    ``theta_axes`` (3,) [T^2] the reading's variance per body axis."""
    z = f.residual(b_body, b_ref_orbit)
    return float(np.sum(z * z / theta_axes))


class HypothesisBank:
    """The hypotheses' filters and scores (module docstring); it runs once, at the first lock:
    ``count`` ``K`` >= 2 hypotheses, decided ``window_s`` [s] > 0 after the start."""

    def __init__(self, count: int, window_s: float) -> None:
        if int(count) < 2:
            raise ValueError(f'count must be >= 2 hypotheses, got {count}')
        self.count, self.window = int(count), positive(window_s, 'window_s', 's')
        self.members: List[MagneticFilter] = []
        self.scores: List[float] = []
        self.t_start: Optional[float] = None
        self.chosen: Optional[int] = None      # index of the winner, once decided

    @property
    def active(self) -> bool:
        """True while hypotheses run side by side."""
        return bool(self.members)

    def maybe_start(self, f: MagneticFilter, b_body: np.ndarray, t: float) -> None:
        """Start the bank from ``f`` (hypothesis 0) at ``t`` [s] if ``f`` has locked and the
        bank has never started."""
        if self.t_start is not None or not locked(f):
            return
        self.members = [f] + [turned_about_field(f, b_body, 2.0 * math.pi * k / self.count)
                              for k in range(1, self.count)]
        self.scores = [0.0] * self.count
        self.t_start = t

    def score(self, b_body: np.ndarray, b_ref_orbit: np.ndarray, theta_axes: np.ndarray,
              t: float) -> None:
        """Add each hypothesis's (H1) of this reading (in the scoring half of the window)."""
        if self.active and t >= self.t_start + 0.5 * self.window:
            for k, f in enumerate(self.members):
                self.scores[k] += prediction_error(f, b_body, b_ref_orbit, theta_axes)

    def drop(self, k: int) -> None:
        """Remove hypothesis ``k`` (diverged)."""
        del self.members[k], self.scores[k]

    def clear(self) -> None:
        """Stop the bank without a decision (a filter reset)."""
        self.members, self.scores = [], []

    def best(self) -> MagneticFilter:
        """The likeliest hypothesis so far (the first on a tie: hypothesis 0 before scoring)."""
        return self.members[int(np.argmin(self.scores))]

    def decide(self, t: float) -> Optional[MagneticFilter]:
        """The winning filter at the end of the window (the bank stops), else None."""
        if not self.active or t < self.t_start + self.window:
            return None
        winner = self.best()
        self.chosen = self.members.index(winner)
        self.clear()
        return winner
