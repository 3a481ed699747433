"""Metrics of one run: the angle to the orbit frame judged by :mod:`adcs_nodes.tools.metrics`."""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional

import numpy as np

from adcs_nodes.tools import metrics

STATE_TOPIC = '/sim/state'


def read_truth(bag: str) -> Dict[str, np.ndarray]:
    """``/sim/state`` of a bag as arrays, one entry per sim-time stamp (repeats dropped).

    Returns
    -------
    dict
        ``t_s`` (n,) sim time since the first sample [s], ``q`` (n, 4) ``q_orbit_body`` scalar
        last, ``w_eci`` (n, 3) ``omega_body_eci_body`` [rad/s], ``w_orbit`` (n, 3)
        ``omega_body_orbit_body`` [rad/s].

    Raises
    ------
    ValueError
        If the bag has no ``/sim/state`` message.
    """
    from adcs_nodes.bag import header_stamp_ns, read_messages

    stamps: List[int] = []
    q, w_eci, w_orb = [], [], []
    for _, _, msg in read_messages(bag, [STATE_TOPIC]):
        stamp = header_stamp_ns(msg)
        if stamps and stamp <= stamps[-1]:
            continue
        stamps.append(stamp)
        o = msg.q_orbit_body
        q.append((o.x, o.y, o.z, o.w))
        w_eci.append(_xyz(msg.omega_body_eci_body))
        w_orb.append(_xyz(msg.omega_body_orbit_body))
    if not stamps:
        raise ValueError(f'{bag}: no {STATE_TOPIC} message')
    t = (np.asarray(stamps, dtype=np.int64) - stamps[0]) / 1e9
    return {'t_s': t, 'q': np.asarray(q), 'w_eci': np.asarray(w_eci),
            'w_orbit': np.asarray(w_orb)}


def _xyz(v: Any) -> tuple:
    return (v.x, v.y, v.z)


def series_metrics(t_s: np.ndarray, q_orbit_body: np.ndarray, w_eci: np.ndarray,
                   w_orbit: np.ndarray, capture_deg: float,
                   period_s: Optional[float]) -> Dict[str, Any]:
    """Run metrics and status from the truth series of one run.

    Parameters
    ----------
    t_s : numpy.ndarray, shape (n,)
        Sim time since the start [s].
    q_orbit_body : numpy.ndarray, shape (n, 4)
        Truth attitude, scalar last.
    w_eci, w_orbit : numpy.ndarray, shape (n, 3)
        ``omega_body_eci_body`` and ``omega_body_orbit_body`` [rad/s].
    capture_deg : float
        Capture band [deg]; the hold band is twice it (:mod:`adcs_nodes.tools.metrics`).
    period_s : float or None
        Orbit period [s] (for "captured within 4 orbits" and the hold window).

    Returns
    -------
    dict
        ``status`` (``captured``: entered the band and stayed within the hold band to the end;
        else ``not_captured``), every key of :func:`adcs_nodes.tools.metrics.run_metrics`
        (``capture_time_s``, ``captured_in_time``, ``last_exit_s``, ``hold_rms_deg``, ...),
        ``final_angle_deg``, ``final_rate_deg_s`` (w.r.t. the orbit frame),
        ``max_rate_deg_s`` (largest w.r.t. ECI), ``samples`` and ``bag_initial`` (first sample:
        ``q_orbit_body_xyzw``, ``omega_body_eci_body_rad_s``, ``omega_body_eci_body_deg_s``).
    """
    angle = metrics.angle_to_identity_deg(q_orbit_body)
    out = metrics.run_metrics(t_s, angle, period_s, band=capture_deg,
                              hold_band=2.0 * capture_deg)
    w0 = np.asarray(w_eci[0], dtype=float)
    out.update({
        'status': 'not_captured' if out['capture_time_s'] is None else 'captured',
        'final_angle_deg': float(angle[-1]),
        'final_rate_deg_s': float(np.degrees(np.linalg.norm(w_orbit[-1]))),
        'max_rate_deg_s': float(np.degrees(np.linalg.norm(w_eci, axis=1).max())),
        'samples': int(np.asarray(t_s).size),
        'bag_initial': {
            'q_orbit_body_xyzw': [float(c) for c in q_orbit_body[0]],
            'omega_body_eci_body_rad_s': [float(c) for c in w0],
            'omega_body_eci_body_deg_s': [math.degrees(c) for c in w0],
        },
    })
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in out.items()}


def bag_metrics(bag: str, capture_deg: float, period_s: Optional[float] = None
                ) -> Dict[str, Any]:
    """:func:`series_metrics` of a run's bag (its ``/sim/state``, the truth)."""
    truth = read_truth(bag)
    return series_metrics(truth['t_s'], truth['q'], truth['w_eci'], truth['w_orbit'],
                          capture_deg, period_s)
