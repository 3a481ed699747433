"""Paper comparisons: metrics of a recorded run next to the papers' published numbers.

``adcs report BAG`` reads ``<bag>/scenario.yaml`` (written by the launcher) and, when the
scenario's ``name`` has an entry in :data:`CHECKS`, adds the rows of that check to the
report's paper-comparison table. Each row is ``(quantity, paper value, measured, pass)``.

The pass criteria turn the papers' words into numbers; each is stated in the row text:

* paper 000 estimation: "estimates converge within half an orbit", accuracy "about 1 deg"
  -> converged (error below 2 deg for good) by T/2, median error over the second half-orbit
  below 1.5 deg;
* paper 000 control: "capture of the orbital frame in 3-4 orbits", "accuracy of the order of
  1 deg" -> angle to the orbital frame below 5 deg for good within 4 orbits, then RMS below
  2 deg over the last orbit;
* paper 004: formula (3) and TRIAD yaw errors "close" -> RMS of the two within 0.5 deg of
  each other; degradation near u = 90/270 deg -> the largest error lies there.

Pure Python + numpy (bag reading through :mod:`adcs_nodes.tools.bag`); no rclpy.
"""
from __future__ import annotations

import math
import os
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np
import yaml

from adcs_nodes.core import attitude as att
from adcs_nodes.tools.bag import header_stamp_ns, read_messages

Row = Tuple[str, str, Any, bool]


def _q(m) -> List[float]:
    return [m.x, m.y, m.z, m.w]


def _v(m) -> np.ndarray:
    return np.array([m.x, m.y, m.z])


def load_scenario_of(bag: str) -> Optional[Dict[str, Any]]:
    """The effective scenario stored beside the bag, or None."""
    path = os.path.join(bag, 'scenario.yaml')
    if not os.path.isfile(path):
        return None
    with open(path, encoding='utf-8') as fh:
        return yaml.safe_load(fh)


def series(bag: str, topic: str) -> Dict[int, Any]:
    """``{header stamp [ns]: message}`` of one topic."""
    return {header_stamp_ns(m): m for _, _, m in read_messages(bag, [topic])}


def capture_time(t_s: np.ndarray, angle_deg: np.ndarray, threshold_deg: float) -> Optional[float]:
    """First time after which ``angle_deg`` stays below ``threshold_deg`` to the end (or None).

    Examples
    --------
    >>> capture_time(np.array([0., 1., 2., 3.]), np.array([9., 1., 9., 1.]), 5.0)
    3.0
    """
    above = np.nonzero(np.asarray(angle_deg) >= threshold_deg)[0]
    if above.size == 0:
        return float(t_s[0])
    if above[-1] == len(t_s) - 1:
        return None
    return float(t_s[above[-1] + 1])


def orbit_period_s(sc: Dict[str, Any]) -> float:
    """Period of the scenario's circular orbit (Kepler) [s]."""
    from adcs_nodes.core.orbit import MU_EARTH, R_EARTH
    a = R_EARTH + 1e3 * float(sc['orbit']['altitude_km'])
    return 2.0 * math.pi * math.sqrt(a ** 3 / MU_EARTH)


def _estimate_errors(bag: str, epoch_ns: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    truth = series(bag, '/sim/state')
    t, e_att, e_rate = [], [], []
    for stamp, m in sorted(series(bag, '/adcs/attitude_estimate').items()):
        s = truth.get(stamp)
        if s is None:
            continue
        t.append((stamp - epoch_ns) / 1e9)
        e_att.append(math.degrees(att.angle_between(_q(m.q_orbit_body), _q(s.q_orbit_body))))
        e_rate.append(math.degrees(float(np.linalg.norm(
            _v(m.omega_body_eci_body) - _v(s.omega_body_eci_body)))))
    return np.array(t), np.array(e_att), np.array(e_rate)


def _epoch_ns(sc: Dict[str, Any]) -> int:
    from adcs_nodes.nodes.lockstep_node import epoch_to_ns, parse_epoch
    return epoch_to_ns(parse_epoch(sc['epoch']))


def check_paper000_estimation(bag: str, sc: Dict[str, Any]) -> List[Row]:
    """Paper 000, section 4: estimator convergence from a wrong initial attitude."""
    period = orbit_period_s(sc)
    t, e_att, e_rate = _estimate_errors(bag, _epoch_ns(sc))
    if t.size == 0:
        return [('estimate', 'published', 'none', False)]
    t_conv = capture_time(t, e_att, 2.0)
    half = (t >= period / 2) & (t <= period)
    med = float(np.median(e_att[half])) if half.any() else float('nan')
    p95 = float(np.percentile(e_att[half], 95)) if half.any() else float('nan')
    rate_med = float(np.median(e_rate[half])) if half.any() else float('nan')
    rows: List[Row] = [
        ('time to converge (attitude error < 2 deg for good)', '<= 0.5 orbit',
         'never' if t_conv is None else f'{t_conv / period:.2f} orbit ({t_conv:.0f} s)',
         t_conv is not None and t_conv <= period / 2),
        ('attitude error, median over T/2..T', 'about 1 deg', f'{med:.2f} deg', med < 1.5),
        ('attitude error, 95th percentile over T/2..T', '(not given)', f'{p95:.2f} deg', True),
        ('rate error, median over T/2..T', '(not given)', f'{rate_med:.4f} deg/s', True),
    ]
    return rows


def check_paper000_control(bag: str, sc: Dict[str, Any]) -> List[Row]:
    """Paper 000, section 4: capture of the orbital frame with magnetorquers only."""
    period = orbit_period_s(sc)
    epoch = _epoch_ns(sc)
    truth = sorted(series(bag, '/sim/state').items())
    t = np.array([(k - epoch) / 1e9 for k, _ in truth])
    angle = np.array([math.degrees(att.angle_between(_q(m.q_orbit_body), [0, 0, 0, 1]))
                      for _, m in truth])
    t_cap = capture_time(t, angle, 5.0)
    last = t >= t[-1] - period
    rms = float(np.sqrt(np.mean(angle[last] ** 2))) if last.any() else float('nan')
    cmds = [m for _, m in sorted(series(bag, '/adcs/actuator_command').items())]
    dip = np.array([_v(m.dipole_body) for m in cmds]) if cmds else np.zeros((0, 3))
    limit = np.array(sc['spacecraft']['magnetorquer']['max_dipole_Am2'])
    sat = float(np.mean(np.any(np.abs(dip) >= 0.999 * limit, axis=1))) if len(dip) else 0.0
    _, e_att, _ = _estimate_errors(bag, epoch)
    long_enough = t[-1] >= 4.0 * period
    rows: List[Row] = [
        ('capture time (angle to orbit frame < 5 deg for good)', '3-4 orbits',
         'not captured' if t_cap is None else f'{t_cap / period:.2f} orbits',
         t_cap is not None and t_cap <= 4.0 * period),
        ('angle to orbit frame, RMS over the last orbit', 'about 1 deg', f'{rms:.2f} deg',
         long_enough and rms < 2.0),
        ('final angle to orbit frame', '(not given)', f'{angle[-1]:.2f} deg', True),
        ('estimation error, median over the last orbit', '(not given)',
         f'{float(np.median(e_att[-max(1, len(e_att) // 6):])):.2f} deg'
         if e_att.size else 'n/a', True),
        ('dipole use: mean |m|, frames with a saturated coil', '(not given)',
         f'{float(np.mean(np.linalg.norm(dip, axis=1))) if len(dip) else 0:.1f} A m^2, '
         f'{100 * sat:.0f} %', True),
    ]
    return rows


def yaw_errors_paper004(bag: str, sc: Dict[str, Any]) -> Dict[str, np.ndarray]:
    """Yaw error of formula (3) and of TRIAD against the truth, per magnetometer sample.

    Both are computed from the recorded sensor messages with the flight code
    (:mod:`adcs_nodes.core.estimation.horizon_yaw`) and the flight software's own reference
    field, so the comparison uses exactly what the estimator saw.
    """
    from adcs_nodes.core.estimation.horizon_yaw import (triad_from_horizon_and_field,
                                                        yaw_from_horizon_and_field)
    from adcs_nodes.core.estimation.onboard import make_onboard_reference
    from adcs_nodes.nodes.lockstep_node import parse_epoch
    epoch = _epoch_ns(sc)
    est = sc['estimator']
    ref = make_onboard_reference(est['onboard_orbit'], est['onboard_field'],
                                 parse_epoch(sc['epoch']))
    truth = series(bag, '/sim/state')
    horizon = series(bag, '/sensors/horizon')
    q_body_mag = sc['sensors']['magnetometer']['q_body_sensor_xyzw']
    out: Dict[str, List[float]] = {'u_deg': [], 'eq3_deg': [], 'triad_deg': [], 't_s': []}
    for stamp, mag in sorted(series(bag, '/sensors/magnetometer').items()):
        hor, s = horizon.get(stamp), truth.get(stamp)
        if hor is None or s is None or not hor.valid:
            continue
        t = (stamp - epoch) / 1e9
        r = ref.at(t)
        b_body = att.rotate(q_body_mag, _v(mag.magnetic_field))
        yaw_true = att.to_euler_321(_q(s.q_orbit_body))[2]
        try:
            yaw3 = yaw_from_horizon_and_field(hor.roll, hor.pitch, b_body, r.b_orbit)
            q_tr = triad_from_horizon_and_field(hor.roll, hor.pitch, b_body, r.b_orbit)
        except ValueError:
            continue
        yaw_tr = att.to_euler_321(q_tr)[2]
        wrap = lambda a: (a + math.pi) % (2 * math.pi) - math.pi  # noqa: E731
        out['t_s'].append(t)
        out['u_deg'].append(math.degrees(r.u))
        out['eq3_deg'].append(math.degrees(wrap(yaw3 - yaw_true)))
        out['triad_deg'].append(math.degrees(wrap(yaw_tr - yaw_true)))
    return {k: np.array(v) for k, v in out.items()}


def check_paper004_yaw(bag: str, sc: Dict[str, Any]) -> List[Row]:
    """Paper 004: yaw from formula (3) vs TRIAD under a 5 % magnetometer scale error."""
    e = yaw_errors_paper004(bag, sc)
    if e['u_deg'].size == 0:
        return [('yaw samples', 'one orbit', 'none', False)]
    rms3 = float(np.sqrt(np.mean(e['eq3_deg'] ** 2)))
    rmst = float(np.sqrt(np.mean(e['triad_deg'] ** 2)))
    near = np.minimum(np.abs(e['u_deg'] - 90.0), np.abs(e['u_deg'] - 270.0)) < 30.0
    peak_u = float(e['u_deg'][int(np.argmax(np.abs(e['eq3_deg'])))])
    far = np.abs(e['eq3_deg'][~near]).max() if (~near).any() else float('nan')
    close = np.abs(e['eq3_deg'][near]).max() if near.any() else float('nan')
    return [
        ('yaw error of formula (3): max / RMS', '(figure only)',
         f'{np.abs(e["eq3_deg"]).max():.2f} / {rms3:.2f} deg', True),
        ('yaw error of TRIAD: max / RMS', '(figure only)',
         f'{np.abs(e["triad_deg"]).max():.2f} / {rmst:.2f} deg', True),
        ('formula (3) and TRIAD errors close', '"close"', f'RMS differ by {abs(rms3 - rmst):.2f} '
         'deg', abs(rms3 - rmst) < 0.5),
        ('largest error near u = 90 or 270 deg', 'degrades there (near-polar orbit)',
         f'peak at u = {peak_u:.0f} deg; max {close:.2f} deg within 30 deg of 90/270 vs '
         f'{far:.2f} deg elsewhere', bool(close > far)),
    ]


#: Scenario name -> comparison function.
CHECKS: Dict[str, Callable[[str, Dict[str, Any]], List[Row]]] = {
    'paper000_estimation': check_paper000_estimation,
    'paper000_control': check_paper000_control,
    'paper004_yaw': check_paper004_yaw,
}


def expectations_for(bag: str) -> Tuple[Optional[str], List[Row]]:
    """``(scenario name, rows)`` of the paper comparison that applies to ``bag``."""
    sc = load_scenario_of(bag)
    if sc is None:
        return None, []
    check = CHECKS.get(sc.get('name', ''))
    return sc.get('name'), (check(bag, sc) if check else [])
