"""Paper comparisons: metrics of a recorded run next to the papers' published numbers.

``adcs report BAG`` reads ``<bag>/scenario.yaml`` (written by the launcher) and, when the
scenario's ``name`` has an entry in :data:`CHECKS`, adds the rows of that check to the
report's paper-comparison table. Each row is ``(quantity, paper value, measured, verdict)``
with ``verdict`` True (PASS) or False (FAIL) for a row that compares with a number or claim of
the paper, and ``None`` for information (no paper value): an information row never passes or
fails and is not counted.

The pass criteria turn the papers' words into numbers; each is stated in the row text:

* paper 000 estimation: "estimates converge within half an orbit", accuracy "about 1 deg"
  -> converged (error below 2 deg for good) by T/2, median error over the second half-orbit
  below 1.5 deg;
* paper 000 control: "reaches the required attitude within 3-4 orbits", "held with accuracy
  of the order of 1 deg" (:mod:`adcs_nodes.tools.metrics`) -> captured (entered the 5 deg band
  and stayed within 10 deg to the end) within 4 orbits; RMS of the angle to the orbital frame
  over the hold (4 orbits to the end) below 2 deg (median and 95th percentile for
  information). The last exit from 5 deg is reported under its own name, for information;
* paper000_control_misaligned (stress case, not a paper claim): the same numbers, information
  only;
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
from adcs_nodes.tools import metrics
from adcs_nodes.tools.bag import header_stamp_ns, read_messages

Row = Tuple[str, str, Any, Optional[bool]]
#: Verdict of an information row (no paper value to compare with).
INFO = None


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

    The last exit from the band: :func:`adcs_nodes.tools.metrics.last_exit_time`.

    Examples
    --------
    >>> capture_time(np.array([0., 1., 2., 3.]), np.array([9., 1., 9., 1.]), 5.0)
    3.0
    """
    return metrics.last_exit_time(t_s, angle_deg, threshold_deg)


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
        ('attitude error, 95th percentile over T/2..T', '(not given)', f'{p95:.2f} deg', INFO),
        ('rate error, median over T/2..T', '(not given)', f'{rate_med:.4f} deg/s', INFO),
    ]
    return rows


def control_rows(m: Dict[str, Any], est_median_deg: Optional[float], dipole_text: str,
                 claim: bool = True) -> List[Row]:
    """Paper 000 closed-loop rows from :func:`adcs_nodes.tools.metrics.run_metrics` output.

    Parameters
    ----------
    m : dict
        ``run_metrics`` of the angle between body and orbit frame (period known).
    est_median_deg : float or None
        Median attitude-estimation error over the hold [deg].
    dipole_text : str
        Dipole use, for information.
    claim : bool
        True: the capture and accuracy rows compare with the paper (PASS/FAIL); False (a stress
        scenario): every row is information.
    """
    def orbits(x: Optional[float]) -> str:
        return 'never' if x is None else f'{x:.2f} orbits'

    verdict = (lambda ok: bool(ok)) if claim else (lambda ok: INFO)
    hold = (f'RMS {m["hold_rms_deg"]:.2f} deg (median {m["hold_median_deg"]:.2f}, 95 % '
            f'{m["hold_p95_deg"]:.2f}, max {m["hold_max_deg"]:.2f})' if m['hold_samples']
            else 'no sample after 4 orbits')
    paper_hold = 'of the order of 1 deg' if claim else '(stress case; paper: ~1 deg)'
    return [
        ('capture: enters 5 deg, then stays within 10 deg', '3-4 orbits' if claim else
         '(stress case; paper: 3-4 orbits)', orbits(m['capture_orbits']),
         verdict(m['captured_in_time'])),
        ('hold accuracy, angle to orbit frame from 4 orbits to the end', paper_hold, hold,
         verdict(m['hold_complete'] and m['hold_samples'] and m['hold_rms_deg'] < 2.0)),
        ('last exit from 5 deg', '(not given)', orbits(m['last_exit_orbits']), INFO),
        ('first entry below 5 deg', '(not given)', 'never' if m['first_entry_s'] is None
         else f'{m["first_entry_s"] / m["period_s"]:.2f} orbits', INFO),
        ('final angle to orbit frame', '(not given)', f'{m["final_deg"]:.2f} deg', INFO),
        ('estimation error, median over the hold', '(not given)',
         'n/a' if est_median_deg is None else f'{est_median_deg:.2f} deg', INFO),
        ('dipole use: mean |m|, frames with a saturated coil', '(not given)', dipole_text, INFO),
    ]


def check_paper000_control(bag: str, sc: Dict[str, Any], claim: bool = True) -> List[Row]:
    """Paper 000, section 4: capture of the orbital frame with magnetorquers only."""
    period = orbit_period_s(sc)
    epoch = _epoch_ns(sc)
    truth = sorted(series(bag, '/sim/state').items())
    if not truth:
        return [('truth state', 'recorded', 'none', False)]
    t = np.array([(k - epoch) / 1e9 for k, _ in truth])
    angle = metrics.angle_to_identity_deg([_q(m.q_orbit_body) for _, m in truth])
    m = metrics.run_metrics(t, angle, period)
    cmds = [m_ for _, m_ in sorted(series(bag, '/adcs/actuator_command').items())]
    dip = np.array([_v(c.dipole_body) for c in cmds]) if cmds else np.zeros((0, 3))
    limit = np.array(sc['spacecraft']['magnetorquer']['max_dipole_Am2'])
    sat = float(np.mean(np.any(np.abs(dip) >= 0.999 * limit, axis=1))) if len(dip) else 0.0
    t_e, e_att, _ = _estimate_errors(bag, epoch)
    hold = t_e >= m['hold_from_s']
    est_med = float(np.median(e_att[hold])) if hold.any() else None
    dip_text = (f'{float(np.mean(np.linalg.norm(dip, axis=1))) if len(dip) else 0:.1f} A m^2, '
                f'{100 * sat:.0f} %')
    return control_rows(m, est_med, dip_text, claim)


def check_paper000_control_misaligned(bag: str, sc: Dict[str, Any]) -> List[Row]:
    """Stress case of paper 000's closed loop (1 deg misalignment): information rows only."""
    return check_paper000_control(bag, sc, claim=False)


_PARAM_NAMES = {'random_period_s': 'random torque correlation [s]',
                'misalignment_deg': 'magnetometer misalignment [deg]'}


def sensitivity_markdown(data: Optional[Dict[str, Any]] = None) -> str:
    """Markdown table of the paper 000 hold-accuracy sensitivity (plain loop measurement).

    ``data`` is the JSON of ``python -m sim_node.tools.closed_loop sensitivity``; default: the
    measurement stored in :mod:`adcs_nodes.tools.paper000_sensitivity`.
    """
    if data is None:
        from adcs_nodes.tools.paper000_sensitivity import MEASURED as data
    base = data['baseline']
    lines = [
        f'Scenario `{data["scenario"]}`, seed {data["seed"]}, one parameter changed at a time '
        f'from the scenario (random-torque correlation {base["random_period_s"]:g} s, '
        f'misalignment {base["misalignment_deg"]:g} deg). "From the paper state": '
        f'{data["duration_s"] / 5913.8:.1f} orbits from the paper\'s initial tumble, hold from '
        f'4 orbits. "On target": started on the orbital frame, '
        f'{data["hold_only_orbits"]:g} orbits, hold from {data["hold_only_from_orbits"]:g} '
        'orbit (the hold alone, without the acquisition, which is chaotic: one run of it is '
        'one sample of the Monte Carlo). Plain numpy loop of the project\'s cores '
        '(`python -m sim_node.tools.closed_loop sensitivity`), not the ROS graph.', '',
        '| parameter | value | capture [orbits] | last exit 5 deg [orbits] | hold RMS / median '
        '/ 95 % [deg] | on target: RMS / median / 95 % [deg] | on target: estimation error '
        'median [deg] |',
        '|---|---:|---:|---:|---|---|---:|']
    for c in data['cases']:
        name = _PARAM_NAMES.get(c['parameter'], c['parameter'])
        cap = 'never' if c['capture_orbits'] is None else f'{c["capture_orbits"]:.2f}'
        ext = 'never' if c['last_exit_orbits'] is None else f'{c["last_exit_orbits"]:.2f}'
        h = c['hold_only']
        lines.append(f'| {name} | {c["value"]:g} | {cap} | {ext} | {c["hold_rms_deg"]:.2f} / '
                     f'{c["hold_median_deg"]:.2f} / {c["hold_p95_deg"]:.2f} | '
                     f'{h["rms_deg"]:.2f} / {h["median_deg"]:.2f} / {h["p95_deg"]:.2f} | '
                     f'{h["est_err_median_deg"]:.2f} |')
    if data.get('note'):
        lines += ['', data['note']]
    return '\n'.join(lines) + '\n'


#: Scenario name -> extra report sections ``[(title, markdown)]``.
SECTIONS: Dict[str, Callable[[], List[Tuple[str, str]]]] = {
    'paper000_control': lambda: [('Sensitivity of the hold accuracy', sensitivity_markdown())],
    'paper000_control_misaligned': lambda: [('Sensitivity of the hold accuracy',
                                             sensitivity_markdown())],
}


def sections_for(bag: str) -> List[Tuple[str, str]]:
    """Extra report sections for the scenario of ``bag`` (empty if none)."""
    sc = load_scenario_of(bag)
    make = SECTIONS.get((sc or {}).get('name', ''))
    return make() if make else []


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
         f'{np.abs(e["eq3_deg"]).max():.2f} / {rms3:.2f} deg', INFO),
        ('yaw error of TRIAD: max / RMS', '(figure only)',
         f'{np.abs(e["triad_deg"]).max():.2f} / {rmst:.2f} deg', INFO),
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
    'paper000_control_misaligned': check_paper000_control_misaligned,
    'paper004_yaw': check_paper004_yaw,
}


def expectations_for(bag: str) -> Tuple[Optional[str], List[Row]]:
    """``(scenario name, rows)`` of the paper comparison that applies to ``bag``."""
    sc = load_scenario_of(bag)
    if sc is None:
        return None, []
    check = CHECKS.get(sc.get('name', ''))
    return sc.get('name'), (check(bag, sc) if check else [])
