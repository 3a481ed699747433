"""Paper 001 (MPI control of a flexible spacecraft with reaction wheels): its tables. Error =
true minus desired LVLH 3-1-2 Euler angles, per axis (digest sections 5 and 8); the paper's own
bounds; the tracking row and the robustness case: ``docs/paper001.md``."""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from adcs_nodes.tools.analyse.papers import INFO, NotComparable, Row
from adcs_nodes.tools.analyse.papers.series import Topics, epoch_ns, quat, save_figure, vec

TOPICS = ('sim/state', 'adcs/attitude_target', 'adcs/actuator_command', 'sim/wheels',
          'sim/appendages', 'adcs/attitude_estimate')

STAB_WINDOWS = ((500.0, 1000.0), (4200.0, 5000.0))
TRACK_WINDOW = (1100.0, 3500.0)
#: (maneuver end [s], end of the window that follows [s])
MANEUVER_ENDS = ((200.0, 1000.0), (3700.0, 5000.0))
BACK_WITHIN_DEG = 0.1
#: A commanded wheel torque at or above this is "at the limit" [N m].
AT_LIMIT_NM = 0.999

_KEYS = ('t', 'e', 'e_d', 'de', 'de_d', 'tau_cmd', 'tau', 'h', 'eta', 'est_err_deg', 'w_bo')


def series(topics: Topics, sc: Dict[str, Any]) -> Dict[str, np.ndarray]:
    """One row per frame with every topic: ``e``, ``e_d`` true and desired LVLH 3-1-2 angles
    [rad], their rates [rad/s]; wheel torques [N m], momenta [N m s]; ``eta``; ``w_bo``."""
    from adcs_nodes.core import attitude as att
    from adcs_nodes.core.control import mpi
    e0 = epoch_ns(sc)
    state = topics.get('sim/state', {})
    target = topics.get('adcs/attitude_target', {})
    cmd = topics.get('adcs/actuator_command', {})
    wheels = topics.get('sim/wheels', {})
    est = topics.get('adcs/attitude_estimate', {})
    app = topics.get('sim/appendages', {})
    common = sorted(set(state).intersection(target, cmd, wheels, est))
    keys = sorted(wheels)
    nxt = dict(zip(keys[:-1], keys[1:]))
    rec: Dict[str, list] = {k: [] for k in _KEYS}
    for t in common:
        s, tg = state[t], target[t]
        q_ob, w_bo = quat(s.q_orbit_body), vec(s.omega_body_orbit_body)
        e = mpi.lvlh_euler312_of(q_ob)
        e_d = mpi.lvlh_euler312_of(quat(tg.q_ref_body))
        rec['t'].append((t - e0) / 1e9)
        rec['e'].append(e)
        rec['e_d'].append(e_d)
        rec['de'].append(mpi.euler312_rates_from_body_rate(e, w_bo))
        rec['de_d'].append(mpi.euler312_rates_from_body_rate(e_d, vec(tg.omega_body_ref_body)))
        rec['tau_cmd'].append(np.asarray(cmd[t].wheel_torque, float))
        rec['tau'].append(np.asarray(wheels[nxt.get(t, t)].torque, float))
        rec['h'].append(np.asarray(wheels[t].momentum, float))
        a = app.get(t)
        rec['eta'].append(np.asarray(a.eta, float) if a is not None else np.zeros(0))
        rec['est_err_deg'].append(math.degrees(att.angle_between(quat(est[t].q_orbit_body),
                                                                 q_ob)))
        rec['w_bo'].append(w_bo)
    out = {k: np.array(v) for k, v in rec.items()}
    if not common:                  # empty, but with the shapes of a run
        for k in ('e', 'e_d', 'de', 'de_d', 'w_bo'):
            out[k] = np.zeros((0, 3))
        for k in ('tau', 'tau_cmd', 'h', 'eta'):
            out[k] = np.zeros((0, 0))
    return out


def _wrap_deg(a: np.ndarray) -> np.ndarray:
    return (a + 180.0) % 360.0 - 180.0


def tracking_lag_s(err_deg: np.ndarray, rate_d_deg_s: np.ndarray) -> List[Optional[float]]:
    """Per axis, the lag ``L`` [s] of the fit ``err = -L rate_d + c`` (digest P15: ``L =
    tau``); None where the desired rate does not vary."""
    out: List[Optional[float]] = []
    for k in range(err_deg.shape[1]):
        x = rate_d_deg_s[:, k] - rate_d_deg_s[:, k].mean()
        sxx = float(x @ x)
        out.append(-float(x @ (err_deg[:, k] - err_deg[:, k].mean())) / sxx
                   if sxx > 1e-12 * max(1, x.size) else None)
    return out


def metrics(r: Dict[str, np.ndarray]) -> Dict[str, Any]:
    """The paper's numbers from :func:`series` (per axis where a list); window statistics
    only when the run reaches their window."""
    t = np.asarray(r['t'], float)
    err = _wrap_deg(np.degrees(r['e'] - r['e_d']))
    derr = np.degrees(r['de'] - r['de_d'])

    def window(a: float, b: float) -> np.ndarray:
        return (t >= a) & (t < b)

    out: Dict[str, Any] = {'t_end_s': float(t[-1]) if t.size else 0.0}
    stab = np.zeros(t.shape, bool)
    for a, b in STAB_WINDOWS:
        stab |= window(a, b)
    trk = window(*TRACK_WINDOW)
    if stab.any():
        out['stab_angle_3sigma_deg'] = (3 * err[stab].std(axis=0)).tolist()
        out['stab_angle_max_deg'] = np.abs(err[stab]).max(axis=0).tolist()
        out['stab_rate_3sigma_deg_s'] = (3 * derr[stab].std(axis=0)).tolist()
    if trk.any():
        out['track_angle_3sigma_deg'] = (3 * err[trk].std(axis=0)).tolist()
        out['track_angle_max_deg'] = np.abs(err[trk]).max(axis=0).tolist()
        out['track_rate_3sigma_deg_s'] = (3 * derr[trk].std(axis=0)).tolist()
        out['track_lag_s'] = tracking_lag_s(err[trk], np.degrees(r['de_d'][trk]))
    for t_end, until in MANEUVER_ENDS:
        i = int(np.searchsorted(t, t_end))
        if i >= len(t):
            continue
        out[f'error_at_{int(t_end)}s_deg'] = err[i].tolist()
        w = window(t_end, until)
        bad = np.flatnonzero(np.any(np.abs(err[w]) >= BACK_WITHIN_DEG, axis=1))
        tw = t[w]
        step = float(t[1] - t[0]) if t.size > 1 else 0.0
        out[f'back_within_0.1deg_after_{int(t_end)}s_s'] = (
            float(tw[bad[-1]] - t_end + step) if len(bad) and bad[-1] + 1 < len(tw)
            else (0.0 if not len(bad) else None))
        out[f'overshoot_after_{int(t_end)}s_deg'] = np.abs(err[w]).max(axis=0).tolist()
    tau, tau_cmd, h, eta = r['tau'], r['tau_cmd'], r['h'], r['eta']
    out['max_abs_h_Nms'] = np.abs(h).max(axis=0).tolist() if h.size else []
    out['max_abs_wheel_torque_Nm'] = np.abs(tau).max(axis=0).tolist() if tau.size else []
    at_limit = np.any(np.abs(tau_cmd) > AT_LIMIT_NM, axis=1) if tau_cmd.size else \
        np.zeros(t.shape, bool)
    out['torque_at_limit_fraction'] = float(np.mean(at_limit)) if t.size else 0.0
    out['max_abs_eta'] = float(np.abs(eta).max()) if eta.size else 0.0
    out['estimate_error_median_deg'] = float(np.median(r['est_err_deg'])) if t.size else \
        float('nan')
    sat_t = t[at_limit]
    out['torque_limit_episodes_start_s'] = [float(sat_t[0])] + [
        float(b) for a, b in zip(sat_t, sat_t[1:]) if b - a > 1.0] if len(sat_t) else []
    return out


def _axes(v: List[float], unit: str, digits: int = 4) -> str:
    return ' / '.join(f'{x:.{digits}f}' for x in v) + f' {unit}'


#: "About 0.02 deg" read as 0.02 to one significant figure: below 0.025 deg (ASSUMPTION).
TRACK_MAX_DEG = 0.025

#: Why the 3700 s row is not comparable (docs/paper001.md, "The error at 3700 s").
END_ERROR_REASON = (
    "the paper's shrinking horizon leaves ~1 % of the remaining maneuver angle at t_f "
    '(0.96 % from rest, double integrator): 0.26-0.43 deg from the tracking state at 3500 s '
    '(sine phase: ASSUMPTION), 0.19-0.27 deg here without the torque limit; below 0.2 deg only '
    'through the unpublished saturation policy (scale 0.204, clip 0.209)')

#: (metric key, quantity, paper text, pass check or a NotComparable verdict, window text for a
#: run that ends before it)
ROWS: List[tuple] = [
    ('stab_angle_3sigma_deg', 'stabilisation angle 3-sigma, x/y/z', '0.005 deg',
     lambda v: max(v) <= 0.005, '500-1000 s'),
    ('stab_rate_3sigma_deg_s', 'stabilisation rate 3-sigma, x/y/z', '0.004 deg/s',
     lambda v: max(v) <= 0.004, '500-1000 s'),
    ('track_angle_max_deg', 'tracking error, max |error|, x/y/z',
     'max about 0.02 deg ("3-sigma")',
     lambda v: max(v) < TRACK_MAX_DEG, '1100-3500 s'),
    ('track_rate_3sigma_deg_s', 'tracking rate 3-sigma, x/y/z', '0.004 deg/s',
     lambda v: max(v) <= 0.004, '1100-3500 s'),
    ('error_at_200s_deg', 'error at the end of the first maneuver (200 s)', '< 0.2 deg',
     lambda v: max(abs(x) for x in v) < 0.2, '200 s'),
    ('error_at_3700s_deg', 'error at the end of the second maneuver (3700 s)', '< 0.2 deg',
     NotComparable(END_ERROR_REASON), '3700 s'),
    ('back_within_0.1deg_after_200s_s', 'back within 0.1 deg after 200 s', 'about 40 s',
     lambda v: v is not None and v <= 50.0, '200 s'),
    ('back_within_0.1deg_after_3700s_s', 'back within 0.1 deg after 3700 s', 'about 70 s',
     lambda v: v is not None and v <= 80.0, '3700 s'),
    ('max_abs_h_Nms', 'wheel momentum, max |h|', 'within 55 N m s',
     lambda v: len(v) > 0 and max(v) < 55.0, None),
    ('max_abs_wheel_torque_Nm', 'wheel torque, max |tau|', '1 N m limit',
     lambda v: len(v) > 0 and max(v) <= 1.0 + 1e-9, None),
]

_UNITS = {'stab_angle_3sigma_deg': 'deg', 'stab_rate_3sigma_deg_s': 'deg/s',
          'track_angle_max_deg': 'deg', 'track_rate_3sigma_deg_s': 'deg/s',
          'track_angle_3sigma_deg': 'deg', 'error_at_200s_deg': 'deg',
          'error_at_3700s_deg': 'deg', 'max_abs_h_Nms': 'N m s',
          'max_abs_wheel_torque_Nm': 'N m'}

#: MPI options that depart from the paper: key -> (the paper's value, what the option does).
DEPARTURES: Dict[str, tuple] = {
    'hold_horizon_s': (0.0, 'stabilisation/tracking horizon {} s instead of one control '
                       'period (digest P14)'),
    'reference_time': ('t0', 'desired state propagated to t0 + tau (digest P15)'),
}


def departures(sc: Dict[str, Any]) -> List[str]:
    """What the scenario's ``mpi`` does that the paper does not (:data:`DEPARTURES`)."""
    p = ((sc.get('controllers') or {}).get('mpi') or {})
    out = []
    for key, (paper, text) in DEPARTURES.items():
        value = p.get(key, paper)
        if value != paper and not (key == 'hold_horizon_s' and not float(value) > 0.0):
            out.append(text.format(value))
    return out


def _measured(key: str, value: Any) -> str:
    if value is None:
        return 'never'
    if isinstance(value, list):
        digits = 2 if key.startswith('max_abs') else 4
        return _axes(value, _UNITS.get(key, ''), digits)
    return f'{value:.1f} s'


def rows(m: Dict[str, Any], claim: bool = True, departed: Sequence[str] = (),
         label: str = 'robustness') -> List[Row]:
    """The table of :func:`metrics` (``claim`` False: information rows, ``departed`` named)."""
    out: List[Row] = []
    for key, quantity, paper, check, window in ROWS:
        if key not in m:
            why = f'the run ends at {m["t_end_s"]:.0f} s, before {window}'
            out.append((quantity, paper, '-', NotComparable(why)) if claim else
                       (quantity, f'({label}; paper: {paper})', f'- ({why})', INFO))
            continue
        value = m[key]
        ok = check if isinstance(check, NotComparable) else bool(check(value))
        if claim:
            out.append((quantity, paper, _measured(key, value), ok))
        else:
            bound = ('' if isinstance(ok, NotComparable) else "; within the paper's bound" if ok
                     else "; outside the paper's bound")
            out.append((quantity, f'({label}; paper: {paper})', _measured(key, value) + bound,
                        INFO))
    if 'track_angle_3sigma_deg' in m:
        lag = ' / '.join('-' if x is None else f'{0.0 if abs(x) < 5e-4 else x:.3f}'
                         for x in m['track_lag_s'])
        out += [
            ('tracking error 3-sigma, x/y/z (a periodic error: about 2x its peak)',
             '(see the max row)', _measured('track_angle_3sigma_deg',
                                            m['track_angle_3sigma_deg']), INFO),
            ('tracking lag: error = -lag x desired rate (least squares), x/y/z',
             '(digest P15: one control period, 0.2 s)', f'{lag} s', INFO),
        ]
    out += [
        ('max modal amplitude |eta|', '(not given)', f'{m["max_abs_eta"]:.4f}', INFO),
        ('commanded wheel torque at the limit', '(not given)',
         f'{100 * m["torque_at_limit_fraction"]:.0f} % of frames', INFO),
        ('estimation error, median', '(not given)',
         f'{m["estimate_error_median_deg"]:.5f} deg', INFO),
    ]
    if departed:
        out.append(('MPI departures from the paper (beyond the paper)', '(none: the paper\'s '
                    'law)', '; '.join(departed), INFO))
    return out


def check(topics: Topics, sc: Dict[str, Any], two_wings: bool = False) -> List[Row]:
    """Paper 001's table of a run (information where the MPI departs from the paper, and all
    of it in the robustness case ``two_wings``)."""
    r = series(topics, sc)
    if r['t'].size == 0:
        return [('truth, target, command, wheels and estimate', 'recorded', 'none',
                 INFO if two_wings else False)]
    departed = departures(sc)
    return rows(metrics(r), claim=not (departed or two_wings), departed=departed,
                label='robustness' if two_wings else 'variant')


def check_two_wings(topics: Topics, sc: Dict[str, Any]) -> List[Row]:
    """The robustness case (two mirrored wings): the same rows, all information."""
    return check(topics, sc, two_wings=True)


# ---------------------------------------------------------------------- figures
def plots(r: Dict[str, np.ndarray], out_dir: str) -> List[str]:
    """PNG figures like the paper's Figs. 4-9; the file paths."""
    from matplotlib.figure import Figure
    t = r['t']
    err = _wrap_deg(np.degrees(r['e'] - r['e_d']))
    panels: List[tuple] = [
        ('attitude_error.png', err, 'attitude error, 3-1-2 Euler [deg]', ('phi', 'theta', 'psi')),
        ('rate_error.png', np.degrees(r['de'] - r['de_d']), 'Euler-rate error [deg/s]',
         ('phi', 'theta', 'psi')),
        ('wheel_torque.png', r['tau'], 'applied wheel torque [N m]', ('x', 'y', 'z')),
        ('wheel_momentum.png', r['h'], 'wheel momentum [N m s]', ('x', 'y', 'z')),
    ]
    if r['eta'].size:
        panels.append(('modal_amplitudes.png', r['eta'], 'modal coordinates eta', None))
    paths = []
    for name, y, label, legend in panels:
        fig = Figure(figsize=(9, 3.5))
        ax = fig.subplots()
        ax.plot(t, y, lw=0.6)
        ax.set_xlabel('t [s]')
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        if legend:
            ax.legend(legend, loc='upper right', fontsize=8)
        if name == 'attitude_error.png':    # the paper's figures zoom on the small errors
            ax.set_ylim(-0.3, 0.3)
        paths.append(save_figure(fig, out_dir, name, 110))
    return paths


def figures_of(topics: Topics, sc: Dict[str, Any], out_dir: str) -> List[str]:
    """:func:`plots` of a run (none without a joined frame)."""
    r = series(topics, sc)
    return plots(r, out_dir) if r['t'].size else []
