"""Reaction-wheel torque allocation, written once for every wheel controller (pure numpy).

Used by the MPI law (:mod:`adcs_nodes.core.control.mpi`, paper 001) and by the eigenaxis torque
laws (:mod:`adcs_nodes.core.control.eigenaxis`: the fuzzy slew of paper 003 and the reference
slew). The wheel model is the plant's (:mod:`sim_node.models.actuators`, (W1)-(W4))::

    h_b    = A_w h_w                 wheel momentum in body axes; A_w (3, n), column k the
                                     unit spin axis of wheel k, body axes                 (W1)
    h_dot_b = A_w tau_w              tau_w (n,): motor torques; the body feels -A_w tau_w  (W3)

Allocation (minimum-norm least squares; ``A_w`` must span 3-D)::

    tau_w = A_w^+ h_dot_b,   A_w^+ = A_w^T (A_w A_w^T)^-1                                  (A1)

(``A_w tau_w = h_dot_b`` exactly, ``tau_w`` of smallest norm).

Torque limit ``|tau_i| <= l_i``, one of two policies (``saturation``)::

    'scale':  tau_w <- sigma tau_w,  sigma = min(1, min_i l_i / |tau_i|)                   (A2)
              (paper 000, eq. (31): keeps the direction of the body torque)
    'clip':   tau_i <- clip(tau_i, -l_i, l_i)  (what each wheel driver does on its own)    (A3)

Optional momentum headroom over one hold period ``T`` (the plant's own rule), per wheel::

    tau_i <- clip(tau_i, min((-H_i - h_i) / T, 0), max((H_i - h_i) / T, 0))                (A4)

The MPI law (paper 001) offers both policies (the paper does not say which, digest P17) and
(A4); the eigenaxis laws (paper 003: a torque limit only) scale (A2) without (A4).

Failed wheels (:class:`adcs_nodes.core.wheel_health.WheelHealth`) are left out: (A1) on the
healthy columns ``A_h`` only (failed wheels 0). When ``A_h`` does not span 3-D, the remainder
``r = h_dot_b - A_h tau_h`` (orthogonal to their span) is the body torque ``T = -r`` asked of
the magnetorquers in the field ``b`` (body axes), then scaled onto the dipole limits (31)::

    m = b x T / |b|^2          (m x b = T - (T . b^) b^: all of T but its part along b)   (A5)
"""
from __future__ import annotations

import math
from typing import Optional, Tuple

import numpy as np
from numpy.typing import ArrayLike

from adcs_nodes.core.control import cross3, limits_vector, scale_to_limits

__all__ = ['WheelAllocator', 'SATURATION']

#: The torque-limit policies: (A2) and (A3).
SATURATION = ('scale', 'clip')


class WheelAllocator:
    """Motor torques of a wheel cluster for a demanded body-axis wheel momentum rate.

    ``wheel_axes_body`` (n, 3) spanning 3-D (normalised here); ``max_torque_Nm`` (n,) or
    scalar ``l_i > 0`` [N m]; ``saturation`` (A2) ``'scale'`` or (A3) ``'clip'``;
    ``max_momentum_Nms`` (n,) ``H_i > 0`` [N m s] and ``period_s`` ``T`` [s] for (A4)
    (``None``: no headroom). ``ValueError`` on a bad argument.
    """

    def __init__(self, wheel_axes_body: ArrayLike, max_torque_Nm: ArrayLike,
                 saturation: str = 'scale', max_momentum_Nms: Optional[ArrayLike] = None,
                 period_s: Optional[float] = None) -> None:
        axes = np.array(wheel_axes_body, dtype=float).reshape(-1, 3) \
            if np.size(wheel_axes_body) else np.zeros((0, 3))
        if axes.shape[0] == 0 or not np.all(np.isfinite(axes)):
            raise ValueError('wheel_axes_body is empty or not finite (no reaction wheels)')
        norms = np.linalg.norm(axes, axis=1)
        if np.any(norms < 1e-9) or np.linalg.matrix_rank(axes) < 3:
            raise ValueError('wheel axes must be non-zero and span three dimensions, got '
                             f'{axes.tolist()}')
        if saturation not in SATURATION:
            raise ValueError(f'saturation must be one of {SATURATION}, got {saturation!r}')
        n = axes.shape[0]
        self.A_w = (axes / norms[:, None]).T                                        # (3, n)
        self.A_w_pinv = np.linalg.pinv(self.A_w)                                    # (A1)
        self.max_torque = limits_vector(max_torque_Nm, 'wheel_max_torque_Nm', n,
                                        allow_zero=False)
        self.saturation = saturation
        self.max_momentum: Optional[np.ndarray] = None
        self.period: Optional[float] = None
        if max_momentum_Nms is not None:
            self.max_momentum = limits_vector(max_momentum_Nms, 'wheel_max_momentum_Nms', n,
                                              allow_zero=False)
            p = float(period_s) if period_s is not None else float('nan')
            if not (math.isfinite(p) and p > 0.0):
                raise ValueError(f'period_s must be finite and > 0 [s] with a momentum limit, '
                                 f'got {period_s!r}')
            self.period = p

    @property
    def n(self) -> int:
        """Number of wheels."""
        return self.A_w.shape[1]

    def torques(self, h_dot_body: ArrayLike) -> np.ndarray:
        """Unlimited motor torques (A1) [N m], shape (n,), for ``h_dot_b`` (3,) [N m]."""
        return self.A_w_pinv @ np.asarray(h_dot_body, dtype=float)

    def limit(self, tau_w: ArrayLike, h_w: Optional[ArrayLike] = None
              ) -> Tuple[np.ndarray, float]:
        """``(tau_out (n,) [N m], sigma)``: the finite motor torques ``tau_w`` (n,) [N m] after
        (A2) or (A3) (``sigma`` the factor of (A2), else 1), then (A4) with the wheel momenta
        ``h_w`` (n,) [N m s] (required with a momentum limit)."""
        tau_w = np.asarray(tau_w, dtype=float)
        if self.saturation == 'clip':
            out, sigma = np.clip(tau_w, -self.max_torque, self.max_torque), 1.0      # (A3)
        else:
            out, sigma = scale_to_limits(tau_w, self.max_torque)                     # (A2)
        if self.max_momentum is None:
            return out, sigma
        if h_w is None:
            raise ValueError('h_w is required with a momentum limit')
        h_w = np.asarray(h_w, dtype=float)
        hi = np.maximum((self.max_momentum - h_w) / self.period, 0.0)
        lo = np.minimum((-self.max_momentum - h_w) / self.period, 0.0)
        return np.clip(out, lo, hi), sigma                                           # (A4)

    def allocate(self, h_dot_body: ArrayLike, h_w: Optional[ArrayLike] = None
                 ) -> Tuple[np.ndarray, float, np.ndarray]:
        """(A1) then :meth:`limit`: ``(tau_out, sigma, tau_unlimited)``, each [N m] or [-]."""
        tau_w = self.torques(h_dot_body)
        out, sigma = self.limit(tau_w, h_w)
        return out, sigma, tau_w

    def allocate_healthy(self, h_dot_body: ArrayLike, h_w: Optional[ArrayLike] = None,
                         ok: Optional[ArrayLike] = None, b_body: Optional[ArrayLike] = None,
                         max_dipole_Am2: Optional[ArrayLike] = None) -> tuple:
        """:meth:`allocate` on the wheels ``ok`` (n,) bool (None: all), the rest by (A5).

        Returns ``(tau_out (n,) [N m], dipole (3,) [A m^2], sigma, tau_unlimited (n,),
        refusal)``; ``refusal`` (all zero) when the healthy wheels do not span 3-D and there is
        no magnetorquer (``max_dipole_Am2`` (3,), None: none) or no field ``b_body`` (3,) [T].
        """
        if ok is None or all(ok):
            out, sigma, tau_w = self.allocate(h_dot_body, h_w)
            return out, np.zeros(3), sigma, tau_w, ''
        ok = np.asarray(ok, dtype=bool)
        h_dot = np.asarray(h_dot_body, dtype=float)
        a_h = self.A_w[:, ok]
        tau_w = np.zeros(self.n)
        if a_h.shape[1]:
            tau_w[ok] = np.linalg.pinv(a_h) @ h_dot                                   # (A1)
        dipole = np.zeros(3)
        rank = int(np.linalg.matrix_rank(a_h)) if a_h.shape[1] else 0
        if rank < 3:
            b = None if b_body is None else np.asarray(b_body, dtype=float)
            bb = float(b @ b) if b is not None and b.shape == (3,) else math.nan
            no_rods = max_dipole_Am2 is None or not np.any(np.asarray(max_dipole_Am2) > 0.0)
            if no_rods or not (math.isfinite(bb) and bb > 0.0):
                what = 'no magnetorquer' if no_rods else 'no usable magnetic field'
                return (np.zeros(self.n), dipole, 0.0, tau_w,
                        f'the {int(ok.sum())} healthy wheels of {self.n} span {rank} axes, '
                        f'and {what} for the rest')
            t_body = -(h_dot - self.A_w @ tau_w)                # the body torque left over
            dipole, _ = scale_to_limits(cross3(b, t_body) / bb, max_dipole_Am2)  # (A5), (31)
        out, sigma = self.limit(tau_w, h_w)                                      # (A2)-(A4)
        return out, dipole, sigma, tau_w, ''
