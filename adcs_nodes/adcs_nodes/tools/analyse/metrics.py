"""End-of-run metrics of an attitude error ``e`` [deg] at ``t`` [s] as paper 000 (section 4)
words them, for the report, the campaigns and the studies: capture = the first ``e < band``
after the last ``e >= hold_band``; a non-finite error is outside every band."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, Optional

import numpy as np
from numpy.typing import ArrayLike

#: Capture band [deg] (ASSUMPTION: the paper gives none).
CAPTURE_BAND_DEG = 5.0
#: Hold band [deg] the error must stay within after capture (ASSUMPTION: 2 x the band).
HOLD_BAND_DEG = 10.0
#: Start of the hold window [orbits]: the end of the paper's "3-4 orbits".
HOLD_FROM_ORBITS = 4.0


def _arrays(t: ArrayLike, e: ArrayLike) -> tuple:
    t = np.asarray(t, dtype=float).reshape(-1)
    e = np.asarray(e, dtype=float).reshape(-1)
    if t.shape != e.shape:
        raise ValueError(f't and e must have the same length, got {t.size} and {e.size}')
    return t, e


def _outside(e: np.ndarray, limit: float) -> np.ndarray:
    """``e >= limit`` with NaN counted as outside."""
    return ~(e < limit)


def capture_index(e: ArrayLike, band: float = CAPTURE_BAND_DEG,
                  hold_band: Optional[float] = HOLD_BAND_DEG) -> Optional[int]:
    """Index of the first entry into ``band`` after which ``e < hold_band`` (>= ``band``;
    None: ``band``, the last exit) to the end; None when the run never captures."""
    e = np.asarray(e, dtype=float).reshape(-1)
    hold = band if hold_band is None else float(hold_band)
    if hold < band:
        raise ValueError(f'hold_band ({hold}) must be >= band ({band})')
    out = np.flatnonzero(_outside(e, hold))
    start = int(out[-1]) + 1 if out.size else 0
    inside = np.flatnonzero(e[start:] < band)
    return None if inside.size == 0 else start + int(inside[0])


def capture_time(t: ArrayLike, e: ArrayLike, band: float = CAPTURE_BAND_DEG,
                 hold_band: Optional[float] = HOLD_BAND_DEG) -> Optional[float]:
    """Capture time [s of ``t``] (see :func:`capture_index`), or None."""
    t, e = _arrays(t, e)
    i = capture_index(e, band, hold_band)
    return None if i is None else float(t[i])


def last_exit_time(t: ArrayLike, e: ArrayLike, band: float = CAPTURE_BAND_DEG
                   ) -> Optional[float]:
    """Start of the final stay below ``band`` (after the last exit from it), or None."""
    return capture_time(t, e, band, None)


def first_entry_time(t: ArrayLike, e: ArrayLike, band: float = CAPTURE_BAND_DEG
                     ) -> Optional[float]:
    """First time with ``e < band``, or None."""
    t, e = _arrays(t, e)
    inside = np.flatnonzero(e < band)
    return None if inside.size == 0 else float(t[inside[0]])


@dataclass(frozen=True)
class HoldStats:
    """RMS, median, 95th percentile and max of the error over the hold window [deg] (NaN: no
    sample), its finite ``samples`` and start ``t_from_s`` [s]."""

    rms: float
    median: float
    p95: float
    max: float
    samples: int
    t_from_s: float


def hold_stats(t: ArrayLike, e: ArrayLike, t_from: float) -> HoldStats:
    """:class:`HoldStats` of ``e`` over ``t >= t_from`` to the end."""
    t, e = _arrays(t, e)
    w = e[(t >= t_from) & np.isfinite(e)]
    if w.size == 0:
        nan = float('nan')
        return HoldStats(nan, nan, nan, nan, 0, float(t_from))
    return HoldStats(float(np.sqrt(np.mean(w ** 2))), float(np.median(w)),
                     float(np.percentile(w, 95)), float(np.max(w)), int(w.size), float(t_from))


def run_metrics(t: ArrayLike, e: ArrayLike, period_s: Optional[float],
                band: float = CAPTURE_BAND_DEG, hold_band: float = HOLD_BAND_DEG,
                hold_from_orbits: float = HOLD_FROM_ORBITS,
                capture_within_orbits: float = HOLD_FROM_ORBITS) -> Dict[str, Any]:
    """End-of-run metrics of ``e`` (n,) [deg] at ``t`` (n,) [s] (no period: hold = 2nd half)."""
    t, e = _arrays(t, e)
    if t.size == 0:
        raise ValueError('run_metrics needs at least one sample')
    t_cap = capture_time(t, e, band, hold_band)
    t_exit = last_exit_time(t, e, band)
    if period_s:
        t_hold = t[0] + hold_from_orbits * period_s
        deadline = t[0] + capture_within_orbits * period_s
    else:
        t_hold = t[0] + 0.5 * (t[-1] - t[0])
        deadline = math.inf
    hs = hold_stats(t, e, t_hold)

    def orbits(x: Optional[float]) -> Optional[float]:
        return None if x is None or not period_s else (x - t[0]) / period_s

    return {
        'capture_time_s': t_cap, 'capture_orbits': orbits(t_cap),
        'captured_in_time': bool(t_cap is not None and t_cap <= deadline),
        'last_exit_s': t_exit, 'last_exit_orbits': orbits(t_exit),
        'first_entry_s': first_entry_time(t, e, band),
        'hold_rms_deg': hs.rms, 'hold_median_deg': hs.median, 'hold_p95_deg': hs.p95,
        'hold_max_deg': hs.max, 'hold_samples': hs.samples, 'hold_from_s': hs.t_from_s,
        'hold_complete': bool(t[-1] > t_hold),
        'final_deg': float(e[-1]), 'band_deg': float(band), 'hold_band_deg': float(hold_band),
        'period_s': float(period_s) if period_s else None,
    }


def angle_to_identity_deg(q_xyzw: ArrayLike) -> np.ndarray:
    """Rotation angle [deg] ``2 atan2(|v|, |w|)`` of each of ``q_xyzw`` (n, 4); shape (n,)."""
    q = np.asarray(q_xyzw, dtype=float).reshape(-1, 4)
    return np.degrees(2.0 * np.arctan2(np.linalg.norm(q[:, :3], axis=1), np.abs(q[:, 3])))


def angle_between_deg(q_a: ArrayLike, q_b: ArrayLike) -> np.ndarray:
    """Angle of the rotation ``q_a^* q_b`` between two quaternion series [deg], shape (n,)."""
    a = np.asarray(q_a, dtype=float).reshape(-1, 4)
    b = np.asarray(q_b, dtype=float).reshape(-1, 4)
    ax, ay, az, aw = -a[:, 0], -a[:, 1], -a[:, 2], a[:, 3]      # conjugate of q_a
    bx, by, bz, bw = b.T
    x = aw * bx + ax * bw + ay * bz - az * by
    y = aw * by - ax * bz + ay * bw + az * bx
    z = aw * bz + ax * by - ay * bx + az * bw
    w = aw * bw - ax * bx - ay * by - az * bz
    return angle_to_identity_deg(np.stack([x, y, z, w], axis=1))


def slerp_at(t_src: ArrayLike, q_src: ArrayLike, t: ArrayLike) -> np.ndarray:
    """``q_src`` (n, 4) at increasing ``t_src`` slerped to ``t`` (m,), ``q_i (q_i^* q_j)^u``
    on the shorter arc, clamped to the ends; (m, 4)."""
    ts = np.asarray(t_src, dtype=float).reshape(-1)
    qs = np.asarray(q_src, dtype=float).reshape(-1, 4)
    t = np.asarray(t, dtype=float).reshape(-1)
    if ts.size == 0 or ts.size != qs.shape[0]:
        raise ValueError(f'need as many times as quaternions (> 0), got {ts.size} and '
                         f'{qs.shape[0]}')
    i = np.clip(np.searchsorted(ts, t, side='right') - 1, 0, ts.size - 1)
    j = np.minimum(i + 1, ts.size - 1)
    span = ts[j] - ts[i]
    u = np.clip(np.where(span > 0.0, (t - ts[i]) / np.where(span > 0.0, span, 1.0), 0.0),
                0.0, 1.0)
    a, b = qs[i], qs[j].copy()
    b[np.sum(a * b, axis=1) < 0.0] *= -1.0            # the shorter arc
    dot = np.clip(np.sum(a * b, axis=1) / (np.linalg.norm(a, axis=1)
                                           * np.linalg.norm(b, axis=1)), -1.0, 1.0)
    omega = np.arccos(dot)                             # half the rotation angle a -> b
    small = omega < 1e-9
    s = np.sin(np.where(small, 1.0, omega))
    wa = np.where(small, 1.0 - u, np.sin((1.0 - u) * omega) / s)
    wb = np.where(small, u, np.sin(u * omega) / s)
    out = wa[:, None] * a + wb[:, None] * b
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    exact = u == 0.0
    out[exact] = qs[i[exact]]
    return out


def estimate_errors_deg(t_truth: ArrayLike, q_truth: ArrayLike, t_est: ArrayLike,
                        q_est: ArrayLike) -> Dict[str, Any]:
    """Estimates against the truth slerped to each stamp: ``t``, ``deg`` (of ``q_est^*
    q_truth(t)``) inside the truth's span, ``on_grid``, ``outside``."""
    tt = np.asarray(t_truth, dtype=float).reshape(-1)
    te = np.asarray(t_est, dtype=float).reshape(-1)
    qe = np.asarray(q_est, dtype=float).reshape(-1, 4)
    if te.size != qe.shape[0]:
        raise ValueError(f'need as many estimate stamps as quaternions, got {te.size} and '
                         f'{qe.shape[0]}')
    if tt.size == 0 or te.size == 0:
        return {'t': np.zeros(0), 'deg': np.zeros(0), 'on_grid': 0, 'outside': int(te.size)}
    inside = (te >= tt[0]) & (te <= tt[-1])
    t_in = te[inside]
    q_true = slerp_at(tt, q_truth, t_in)
    return {'t': t_in, 'deg': angle_between_deg(qe[inside], q_true),
            'on_grid': int(np.isin(t_in, tt).sum()), 'outside': int((~inside).sum())}
