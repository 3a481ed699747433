"""Paper 004 (yaw from a horizon sensor and a magnetometer): formula (3) against TRIAD.
Claims: the two yaw errors are "close" (RMS within 0.5 deg); formula (3) degrades near u =
90/270 deg (its largest error within 30 deg of them above the largest elsewhere)."""
from __future__ import annotations

import math
from typing import Any, Dict, List

import numpy as np

from adcs_nodes.tools.analyse.papers import INFO, NotComparable, Row
from adcs_nodes.tools.analyse.papers.series import Topics, epoch_ns, quat, sorted_items, vec

TOPICS = ('sim/state', 'sensors/horizon', 'sensors/magnetometer')

CLOSE_DEG = 0.5          # "close": RMS within this [deg]
NEAR_DEG = 30.0          # "near u = 90/270": within this [deg]


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def yaw_errors(topics: Topics, sc: Dict[str, Any]) -> Dict[str, np.ndarray]:
    """Yaw errors of formula (3) and TRIAD per magnetometer sample with a horizon sample:
    ``t_s``, ``u_deg`` (argument of latitude), ``eq3_deg``, ``triad_deg``, (n,) each."""
    from adcs_nodes.components.base import parse_epoch
    from adcs_nodes.core import attitude as att
    from adcs_nodes.core.estimation.horizon_yaw import (triad_from_horizon_and_field,
                                                        yaw_from_horizon_and_field)
    from adcs_nodes.core.estimation.onboard import make_onboard_reference
    e0 = epoch_ns(sc)
    est = sc['estimator']
    ref = make_onboard_reference(est['onboard_orbit'], est['onboard_field'],
                                 parse_epoch(str(sc['epoch'])))
    truth = topics.get('sim/state', {})
    horizon = topics.get('sensors/horizon', {})
    q_body_mag = sc['sensors']['magnetometer']['q_body_sensor_xyzw']
    out: Dict[str, List[float]] = {'u_deg': [], 'eq3_deg': [], 'triad_deg': [], 't_s': []}
    for stamp, mag in sorted_items(topics.get('sensors/magnetometer', {})):
        hor, s = horizon.get(stamp), truth.get(stamp)
        if hor is None or s is None or not hor.valid:
            continue
        t = (stamp - e0) / 1e9
        r = ref.at(t)
        b_body = att.rotate(q_body_mag, vec(mag.magnetic_field))
        yaw_true = att.to_euler_321(quat(s.q_orbit_body))[2]
        try:
            yaw3 = yaw_from_horizon_and_field(hor.roll, hor.pitch, b_body, r.b_orbit)
            q_tr = triad_from_horizon_and_field(hor.roll, hor.pitch, b_body, r.b_orbit)
        except ValueError:
            continue
        yaw_tr = att.to_euler_321(q_tr)[2]
        out['t_s'].append(t)
        out['u_deg'].append(math.degrees(r.u))
        out['eq3_deg'].append(math.degrees(_wrap(yaw3 - yaw_true)))
        out['triad_deg'].append(math.degrees(_wrap(yaw_tr - yaw_true)))
    return {k: np.array(v, dtype=float) for k, v in out.items()}


def metrics(u_deg: np.ndarray, eq3_deg: np.ndarray, triad_deg: np.ndarray) -> Dict[str, Any]:
    """Max and RMS of both errors, formula (3)'s largest near u = 90/270 and elsewhere."""
    u = np.asarray(u_deg, float)
    e3 = np.asarray(eq3_deg, float)
    et = np.asarray(triad_deg, float)
    near = np.minimum(np.abs(u - 90.0), np.abs(u - 270.0)) < NEAR_DEG
    nan = float('nan')
    return {
        'eq3_max_deg': float(np.abs(e3).max()), 'eq3_rms_deg': float(np.sqrt(np.mean(e3 ** 2))),
        'triad_max_deg': float(np.abs(et).max()),
        'triad_rms_deg': float(np.sqrt(np.mean(et ** 2))),
        'peak_u_deg': float(u[int(np.argmax(np.abs(e3)))]),
        'near_max_deg': float(np.abs(e3[near]).max()) if near.any() else nan,
        'far_max_deg': float(np.abs(e3[~near]).max()) if (~near).any() else nan,
        'samples': int(u.size)}


def rows(m: Dict[str, Any]) -> List[Row]:
    """The table of :func:`metrics`."""
    diff = abs(m['eq3_rms_deg'] - m['triad_rms_deg'])
    both = math.isfinite(m['near_max_deg']) and math.isfinite(m['far_max_deg'])
    return [
        ('yaw error of formula (3): max / RMS', '(figure only)',
         f'{m["eq3_max_deg"]:.2f} / {m["eq3_rms_deg"]:.2f} deg', INFO),
        ('yaw error of TRIAD: max / RMS', '(figure only)',
         f'{m["triad_max_deg"]:.2f} / {m["triad_rms_deg"]:.2f} deg', INFO),
        ('formula (3) and TRIAD errors close', '"close"', f'RMS differ by {diff:.2f} deg',
         diff < CLOSE_DEG),
        ('largest error near u = 90 or 270 deg', 'degrades there (near-polar orbit)',
         f'peak at u = {m["peak_u_deg"]:.0f} deg; max {m["near_max_deg"]:.2f} deg within '
         f'30 deg of 90/270 vs {m["far_max_deg"]:.2f} deg elsewhere',
         bool(m['near_max_deg'] > m['far_max_deg']) if both else NotComparable(
             'the run covers only one of the two regions (near and away from u = 90/270 deg)')),
    ]


def check(topics: Topics, sc: Dict[str, Any]) -> List[Row]:
    """Paper 004's table of a run."""
    e = yaw_errors(topics, sc)
    if e['u_deg'].size == 0:
        return [('yaw samples', 'one orbit', 'none', False)]
    return rows(metrics(e['u_deg'], e['eq3_deg'], e['triad_deg']))
