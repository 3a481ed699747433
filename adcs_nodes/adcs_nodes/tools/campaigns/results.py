"""Metrics of one run: the angle between the body and its guidance target (the orbit frame for
paper 000; :mod:`.capture`) judged by :mod:`adcs_nodes.tools.analyse.metrics`."""
from __future__ import annotations

import math
from typing import Any, Dict, Optional

import numpy as np

from adcs_nodes.tools.analyse import bag_series, metrics
from adcs_nodes.tools.campaigns.capture import ORBIT_FRAME


def read_truth(bag: str) -> Dict[str, np.ndarray]:
    """``/sim/state`` of a bag (:func:`~adcs_nodes.tools.analyse.bag_series.read_run`), a row
    per stamp (rates [rad/s]), with the angle to the latest target [deg] (NaN: none yet) and
    whether it is judged (not a ``maneuver``); ValueError without ``/sim/state``."""
    data = bag_series.read_run(bag)
    if not data.state['t']:
        raise ValueError(f'{bag}: no {bag_series.STATE_TOPIC} message')
    t_ns = np.asarray(data.state['t'], dtype=np.int64)
    first = np.diff(t_ns, prepend=t_ns[0] - 1) > 0            # one row per stamp
    angle = bag_series.pointing_deg(data)
    judged = np.ones(t_ns.size, dtype=bool)
    if angle is None:
        angle = np.full(t_ns.size, np.nan)
    else:
        k = np.searchsorted(np.asarray(data.target['t'], dtype=np.int64), t_ns, 'right') - 1
        judged[k >= 0] = np.asarray(data.target['judged'])[k[k >= 0]]
    state = {k: np.asarray(v)[first] for k, v in data.state.items()}
    return {'t_s': (t_ns[first] - t_ns[0]) / 1e9, 'q': state['q_orbit_body'],
            'w_eci': state['w_eci'], 'w_orbit': state['w_orbit'],
            'target_angle_deg': angle[first], 'target_judged': judged[first]}


def series_metrics(t_s: np.ndarray, q_orbit_body: np.ndarray, w_eci: np.ndarray,
                   w_orbit: np.ndarray, capture_deg: float, period_s: Optional[float],
                   angle_deg: Optional[np.ndarray] = None,
                   judged: Optional[np.ndarray] = None) -> Dict[str, Any]:
    """``status`` and ``run_metrics`` over the ``judged`` samples of one run's truth (rates
    [rad/s]); ``capture_deg`` the band; ``angle_deg`` to the target (default: orbit frame)."""
    t = np.asarray(t_s, dtype=float)
    angle = (metrics.angle_to_identity_deg(q_orbit_body) if angle_deg is None
             else np.asarray(angle_deg, dtype=float))
    if judged is None or np.all(judged):
        t_j, angle_j = t, angle
    elif np.any(judged):
        t_j, angle_j = t[judged], angle[judged]
    else:
        t_j, angle_j = t, np.full(t.size, np.nan)
    out = metrics.run_metrics(t_j, angle_j, period_s, band=capture_deg,
                              hold_band=2.0 * capture_deg)
    w0 = np.asarray(w_eci[0], dtype=float)
    out.update({
        'status': 'not_captured' if out['capture_time_s'] is None else 'captured',
        'final_angle_deg': float(angle[-1]),
        'final_rate_deg_s': float(np.degrees(np.linalg.norm(w_orbit[-1]))),
        'max_rate_deg_s': float(np.degrees(np.linalg.norm(w_eci, axis=1).max())),
        'samples': int(t.size),
        'bag_initial': {
            'q_orbit_body_xyzw': [float(c) for c in q_orbit_body[0]],
            'omega_body_eci_body_rad_s': [float(c) for c in w0],
            'omega_body_eci_body_deg_s': [math.degrees(c) for c in w0],
        },
    })
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in out.items()}


def bag_metrics(bag: str, capture_deg: float, period_s: Optional[float] = None,
                reference: str = ORBIT_FRAME) -> Dict[str, Any]:
    """:func:`series_metrics` of a run's bag, to the orbit frame or the recorded target."""
    truth = read_truth(bag)
    target = reference != ORBIT_FRAME
    return {**series_metrics(truth['t_s'], truth['q'], truth['w_eci'], truth['w_orbit'],
                             capture_deg, period_s,
                             angle_deg=truth['target_angle_deg'] if target else None,
                             judged=truth['target_judged'] if target else None),
            'capture_reference': reference}
