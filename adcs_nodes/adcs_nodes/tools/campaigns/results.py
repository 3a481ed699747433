"""Metrics of one run: the angle between the body and its guidance target (the orbit frame for
paper 000; :mod:`.capture`) judged by :mod:`adcs_nodes.tools.analyse.metrics`."""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional

import numpy as np

from adcs_nodes.tools.analyse import metrics
from adcs_nodes.tools.campaigns.capture import ORBIT_FRAME

STATE_TOPIC = '/sim/state'
TARGET_TOPIC = '/adcs/attitude_target'


def read_truth(bag: str) -> Dict[str, np.ndarray]:
    """``/sim/state`` of a bag, a row per stamp (rates [rad/s]), with the angle to the latest
    target (NaN: none yet); ValueError without ``/sim/state``."""
    from adcs_nodes.bag import header_stamp_ns, read_messages

    stamps: List[int] = []
    q, q_eci, w_eci, w_orb = [], [], [], []
    targets: List[tuple] = []          # (stamp, q_ref_body, frame, judged)
    for topic, _, msg in read_messages(bag, [STATE_TOPIC, TARGET_TOPIC]):
        stamp = header_stamp_ns(msg)
        if topic == TARGET_TOPIC:
            if not targets or stamp > targets[-1][0]:
                targets.append((stamp, _xyzw(msg.q_ref_body), msg.header.frame_id or 'orbit',
                                msg.profile != 'maneuver'))
            continue
        if stamps and stamp <= stamps[-1]:
            continue
        stamps.append(stamp)
        q.append(_xyzw(msg.q_orbit_body))
        q_eci.append(_xyzw(msg.q_eci_body))
        w_eci.append(_xyz(msg.omega_body_eci_body))
        w_orb.append(_xyz(msg.omega_body_orbit_body))
    if not stamps:
        raise ValueError(f'{bag}: no {STATE_TOPIC} message')
    t_ns = np.asarray(stamps, dtype=np.int64)
    angle, judged = np.full(t_ns.size, np.nan), np.ones(t_ns.size, dtype=bool)
    if targets:
        j = np.searchsorted(np.array([x[0] for x in targets], dtype=np.int64), t_ns,
                            side='right') - 1
        have = j >= 0
        jj = j[have]
        eci = np.array([x[2] == 'eci' for x in targets])[jj]
        q_body = np.where(eci[:, None], np.asarray(q_eci)[have], np.asarray(q)[have])
        angle[have] = angle_to_target_deg(q_body, np.array([x[1] for x in targets])[jj])
        judged[have] = np.array([x[3] for x in targets])[jj]
    return {'t_s': (t_ns - stamps[0]) / 1e9, 'q': np.asarray(q), 'w_eci': np.asarray(w_eci),
            'w_orbit': np.asarray(w_orb), 'target_angle_deg': angle, 'target_judged': judged}


def _xyz(v: Any) -> tuple:
    return (v.x, v.y, v.z)


def _xyzw(o: Any) -> tuple:
    return (o.x, o.y, o.z, o.w)


def angle_to_target_deg(q_frame_body: np.ndarray, q_frame_target: np.ndarray) -> np.ndarray:
    """Angle [deg] of ``q_frame_target^* (x) q_frame_body``, shape (n,)."""
    return metrics.angle_between_deg(q_frame_target, q_frame_body)


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
