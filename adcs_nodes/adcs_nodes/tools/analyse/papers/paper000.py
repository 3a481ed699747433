"""Paper 000 (magnetometer-only estimation and three-axis magnetic control): its table.

Claims (section 4) as numbers: "converge within half an orbit", "about 1 deg" -> below 2 deg
for good by T/2, median over T/2..T below 1.5 deg; "within 3-4 orbits", "of the order of 1
deg" -> captured within 4 orbits, RMS to the orbit frame from 4 orbits on below 2 deg.
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from adcs_nodes.tools.analyse import metrics
from adcs_nodes.tools.analyse.papers import INFO, NotComparable, Row
from adcs_nodes.tools.analyse.papers.series import (Topics, epoch_ns, orbit_period_s, quat,
                                                    sorted_items, vec)

TOPICS = ('sim/state', 'adcs/attitude_estimate', 'adcs/actuator_command')

CONVERGED_DEG = 2.0          # estimation: converged = below this for good [deg]
EST_MEDIAN_LIMIT_DEG = 1.5   # "about 1 deg"
HOLD_RMS_LIMIT_DEG = 2.0     # "of the order of 1 deg"


# ---------------------------------------------------------------------- series
def estimate_errors(topics: Topics, sc: Dict[str, Any]) -> Dict[str, np.ndarray]:
    """Estimate against the truth at its stamps: ``t_s`` [s], ``att_deg`` (``q_orbit_body``),
    ``rate_deg_s`` (``|omega_est - omega_true|``, ECI)."""
    truth = sorted_items(topics.get('sim/state', {}))
    est = sorted_items(topics.get('adcs/attitude_estimate', {}))
    e0 = epoch_ns(sc)
    empty = {'t_s': np.zeros(0), 'att_deg': np.zeros(0), 'rate_deg_s': np.zeros(0)}
    if not truth or not est:
        return empty
    t_true = np.array([(k - e0) / 1e9 for k, _ in truth])
    t_est = np.array([(k - e0) / 1e9 for k, _ in est])
    err = metrics.estimate_errors_deg(t_true, [quat(m.q_orbit_body) for _, m in truth],
                                      t_est, [quat(m.q_orbit_body) for _, m in est])
    if not err['t'].size:
        return empty
    inside = (t_est >= t_true[0]) & (t_est <= t_true[-1])
    w_true = np.array([vec(m.omega_body_eci_body) for _, m in truth])
    w_est = np.array([vec(m.omega_body_eci_body) for _, m in est])[inside]
    w_at = np.stack([np.interp(err['t'], t_true, w_true[:, k]) for k in range(3)], axis=1)
    return {'t_s': err['t'], 'att_deg': err['deg'],
            'rate_deg_s': np.degrees(np.linalg.norm(w_est - w_at, axis=1))}


def estimation_series(topics: Topics, sc: Dict[str, Any]) -> Dict[str, np.ndarray]:
    """:func:`estimate_errors` plus ``period_s`` (the orbit) and ``t_end_s`` (the run's end)."""
    out = estimate_errors(topics, sc)
    t_state = [(k - epoch_ns(sc)) / 1e9 for k in topics.get('sim/state', {})]
    out['t_end_s'] = max(t_state) if t_state else (float(out['t_s'][-1]) if out['t_s'].size
                                                   else 0.0)
    out['period_s'] = orbit_period_s(sc)
    return out


def control_series(topics: Topics, sc: Dict[str, Any]) -> Dict[str, Any]:
    """True angle to the orbit frame, dipoles [A m^2] and estimate errors of a run."""
    e0 = epoch_ns(sc)
    truth = sorted_items(topics.get('sim/state', {}))
    cmds = [m for _, m in sorted_items(topics.get('adcs/actuator_command', {}))]
    est = estimate_errors(topics, sc)
    return {
        't_s': np.array([(k - e0) / 1e9 for k, _ in truth]),
        'angle_deg': metrics.angle_to_identity_deg([quat(m.q_orbit_body) for _, m in truth])
        if truth else np.zeros(0),
        'dipole': np.array([vec(c.dipole_body) for c in cmds]).reshape(-1, 3),
        'dipole_limit': np.asarray(sc['spacecraft']['magnetorquer']['max_dipole_Am2'], float),
        'est_t_s': est['t_s'], 'est_deg': est['att_deg'], 'period_s': orbit_period_s(sc)}


# ---------------------------------------------------------------------- metrics
def estimation_metrics(t_s: np.ndarray, att_deg: np.ndarray, rate_deg_s: np.ndarray,
                       period_s: float, t_end_s: Optional[float] = None) -> Dict[str, Any]:
    """Convergence (``converged_s``: below 2 deg for good from then) and accuracy over
    ``T/2 <= t <= T`` (NaN: no sample) of the estimate."""
    t = np.asarray(t_s, float)
    e = np.asarray(att_deg, float)
    r = np.asarray(rate_deg_s, float)
    half = (t >= period_s / 2) & (t <= period_s)
    nan = float('nan')
    return {
        'converged_s': metrics.last_exit_time(t, e, CONVERGED_DEG) if t.size else None,
        'median_deg': float(np.median(e[half])) if half.any() else nan,
        'p95_deg': float(np.percentile(e[half], 95)) if half.any() else nan,
        'rate_median_deg_s': float(np.median(r[half])) if half.any() else nan,
        'window_samples': int(half.sum()), 'period_s': float(period_s),
        't_end_s': float(t[-1] if t_end_s is None and t.size else (t_end_s or 0.0))}


def control_metrics(t_s: np.ndarray, angle_deg: np.ndarray, period_s: float,
                    dipole: np.ndarray, dipole_limit: Sequence[float],
                    est_t_s: np.ndarray, est_deg: np.ndarray) -> Dict[str, Any]:
    """``run_metrics`` plus the estimation error over the hold and the dipole use."""
    m = metrics.run_metrics(t_s, angle_deg, period_s)
    dip = np.asarray(dipole, float).reshape(-1, 3)
    limit = np.asarray(dipole_limit, float)
    est_t, est_e = np.asarray(est_t_s, float), np.asarray(est_deg, float)
    hold = est_t >= m['hold_from_s']
    m.update({
        'est_median_deg': float(np.median(est_e[hold])) if hold.any() else None,
        'dipole_mean_Am2': float(np.mean(np.linalg.norm(dip, axis=1))) if len(dip) else 0.0,
        'dipole_saturated_fraction': float(np.mean(np.any(np.abs(dip) >= 0.999 * limit,
                                                          axis=1))) if len(dip) else 0.0,
        't_end_s': float(np.asarray(t_s, float)[-1])})
    return m


# ---------------------------------------------------------------------- rows
def estimation_rows(m: Dict[str, Any]) -> List[Row]:
    """Rows of :func:`estimation_metrics`."""
    period, t_end, t_conv = m['period_s'], m['t_end_s'], m['converged_s']
    if t_conv is not None and t_conv <= period / 2:
        conv_ok: Any = True
    elif t_end < period / 2:
        conv_ok = NotComparable(f'the run ends at {t_end / period:.2f} orbit, before T/2')
    else:
        conv_ok = False
    short = NotComparable(f'the run ends at {t_end / period:.2f} orbit: no sample in T/2..T')
    has = m['window_samples'] > 0
    return [
        ('time to converge (attitude error < 2 deg for good)', '<= 0.5 orbit',
         'never' if t_conv is None else f'{t_conv / period:.2f} orbit ({t_conv:.0f} s)',
         conv_ok),
        ('attitude error, median over T/2..T', 'about 1 deg', f'{m["median_deg"]:.2f} deg',
         m['median_deg'] < EST_MEDIAN_LIMIT_DEG if has else short),
        ('attitude error, 95th percentile over T/2..T', '(not given)',
         f'{m["p95_deg"]:.2f} deg', INFO),
        ('rate error, median over T/2..T', '(not given)', f'{m["rate_median_deg_s"]:.4f} deg/s',
         INFO),
    ]


def control_rows(m: Dict[str, Any], est_median_deg: Optional[float], dipole_text: str,
                 claim: bool = True) -> List[Row]:
    """Closed-loop rows of ``run_metrics`` ``m`` (``claim`` False: information only)."""
    def orbits(x: Optional[float]) -> str:
        return 'never' if x is None else f'{x:.2f} orbits'

    end, period = m.get('t_end_s'), m['period_s']
    ends = (f'the run ends at {end / period:.2f} orbits' if end is not None and period
            else 'the run ends before 4 orbits')
    if not claim:
        cap_ok: Any = INFO
        hold_ok: Any = INFO
    else:
        if m['captured_in_time']:
            cap_ok = True
        elif not m['hold_complete'] and m['capture_orbits'] is None:
            cap_ok = NotComparable(f'{ends}, before the 4-orbit deadline, not captured yet')
        else:
            cap_ok = False
        if not m['hold_complete'] or not m['hold_samples']:
            hold_ok = NotComparable(f'{ends}: no sample after 4 orbits')
        else:
            hold_ok = bool(m['hold_rms_deg'] < HOLD_RMS_LIMIT_DEG)
    hold = (f'RMS {m["hold_rms_deg"]:.2f} deg (median {m["hold_median_deg"]:.2f}, 95 % '
            f'{m["hold_p95_deg"]:.2f}, max {m["hold_max_deg"]:.2f})' if m['hold_samples']
            else 'no sample after 4 orbits')
    paper_hold = 'of the order of 1 deg' if claim else '(stress case; paper: ~1 deg)'
    return [
        ('capture: enters 5 deg, then stays within 10 deg', '3-4 orbits' if claim else
         '(stress case; paper: 3-4 orbits)', orbits(m['capture_orbits']), cap_ok),
        ('hold accuracy, angle to orbit frame from 4 orbits to the end', paper_hold, hold,
         hold_ok),
        ('last exit from 5 deg', '(not given)', orbits(m['last_exit_orbits']), INFO),
        ('first entry below 5 deg', '(not given)', 'never' if m['first_entry_s'] is None
         else f'{m["first_entry_s"] / m["period_s"]:.2f} orbits', INFO),
        ('final angle to orbit frame', '(not given)', f'{m["final_deg"]:.2f} deg', INFO),
        ('estimation error, median over the hold', '(not given)',
         'n/a' if est_median_deg is None else f'{est_median_deg:.2f} deg', INFO),
        ('dipole use: mean |m|, frames with a saturated coil', '(not given)', dipole_text, INFO),
    ]


def dipole_text(m: Dict[str, Any]) -> str:
    """``'<mean> A m^2, <saturated> %'`` of :func:`control_metrics`."""
    return f'{m["dipole_mean_Am2"]:.1f} A m^2, {100 * m["dipole_saturated_fraction"]:.0f} %'


# ---------------------------------------------------------------------- checks
def check_estimation(topics: Topics, sc: Dict[str, Any]) -> List[Row]:
    """Paper 000, section 4: estimator convergence from a wrong initial attitude."""
    s = estimation_series(topics, sc)
    if s['t_s'].size == 0:
        return [('estimate', 'published', 'none', False)]
    return estimation_rows(estimation_metrics(s['t_s'], s['att_deg'], s['rate_deg_s'],
                                              s['period_s'], s['t_end_s']))


def check_control(topics: Topics, sc: Dict[str, Any], claim: bool = True) -> List[Row]:
    """Paper 000, section 4: capture of the orbital frame with magnetorquers only."""
    s = control_series(topics, sc)
    if s['t_s'].size == 0:
        return [('truth state', 'recorded', 'none', False)]
    m = control_metrics(s['t_s'], s['angle_deg'], s['period_s'], s['dipole'],
                        s['dipole_limit'], s['est_t_s'], s['est_deg'])
    return control_rows(m, m['est_median_deg'], dipole_text(m), claim)


def check_control_stress(topics: Topics, sc: Dict[str, Any]) -> List[Row]:
    """The misaligned stress case of the closed loop: information rows only."""
    return check_control(topics, sc, claim=False)


def misalignment_vector(deg: float) -> List[float]:
    """Rotation vector [deg] of magnitude ``deg`` along (0.6, -0.6, 0.5)."""
    d = np.array([0.6, -0.6, 0.5])
    return [float(x) for x in d / np.linalg.norm(d) * deg]


def orbits_text(x: Optional[float]) -> str:
    """``'never'`` or ``'2.50'``."""
    return 'never' if x is None or (isinstance(x, float) and math.isnan(x)) else f'{x:.2f}'
