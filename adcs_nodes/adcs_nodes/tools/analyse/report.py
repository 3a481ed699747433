"""Bag to report: metrics, PNG plots and ``summary.md``, on ``header.stamp`` (sim time; the
log time only for types without a header), so two runs of one simulation give one report."""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np
from matplotlib.figure import Figure

from adcs_nodes.tools.analyse import papers
from adcs_nodes.bag import cdr_stamp_ns, open_bag, raw_messages, stamp_kind
from adcs_nodes.tools.analyse.metrics import (angle_between_deg, angle_to_identity_deg,
                                              estimate_errors_deg, run_metrics)

STATE_TOPIC = '/sim/state'
ENV_TOPIC = '/sim/environment'
MAG_TOPIC = '/sensors/magnetometer'
WHEELS_TOPIC = '/sim/wheels'
ESTIMATE_TOPIC = '/adcs/attitude_estimate'
TARGET_TOPIC = '/adcs/attitude_target'
STATUS_TOPIC = '/adcs/controller_status'
#: A controller phase is "settled" when the truth stays within this angle of the target over
#: its last ``SETTLED_WINDOW_S`` or its second half if shorter (ASSUMPTION: 10 deg for the last
#: 10 minutes, issue 36).
SETTLED_DEG, SETTLED_WINDOW_S = 10.0, 600.0

Expectation = Tuple[str, str, Any, Any]   # verdict: True, False, None (info), NotComparable

_RAD2DEG = 180.0 / math.pi
_T2UT = 1e6


@dataclass
class _TopicStats:
    msgtype: str
    count: int = 0
    first_ns: Optional[int] = None
    last_ns: Optional[int] = None
    from_header: bool = True

    def add(self, t_ns: int) -> None:
        self.count += 1
        self.first_ns = t_ns if self.first_ns is None else min(self.first_ns, t_ns)
        self.last_ns = t_ns if self.last_ns is None else max(self.last_ns, t_ns)

    def rate_hz(self) -> Optional[float]:
        if self.count < 2 or self.last_ns is None or self.last_ns <= self.first_ns:
            return None
        return (self.count - 1) / ((self.last_ns - self.first_ns) * 1e-9)


@dataclass
class _Data:
    """Time series pulled from the bag (stamps in ns)."""

    stats: Dict[str, _TopicStats] = field(default_factory=dict)
    state: Dict[str, list] = field(default_factory=lambda: {
        't': [], 'q_orbit_body': [], 'q_eci_body': [], 'w_eci': [], 'w_orbit': []})
    env: Dict[str, list] = field(default_factory=lambda: {'t': [], 'b_eci': [], 'n': []})
    mag: Dict[str, list] = field(default_factory=lambda: {'t': [], 'b': []})
    wheels: Dict[str, list] = field(default_factory=lambda: {'t': [], 'h': [], 'names': []})
    est: Dict[str, list] = field(default_factory=lambda: {'t': [], 'q_eci_body': [], 'w_eci': []})
    target: Dict[str, list] = field(default_factory=lambda: {'t': [], 'q': [], 'frame': []})
    status: Dict[str, list] = field(default_factory=lambda: {'t': [], 'active': []})


def _xyz(v) -> List[float]:
    return [v.x, v.y, v.z] + ([v.w] if hasattr(v, 'w') else [])


#: What :func:`_collect` keeps of each topic: ``{topic: (series of _Data, {key: field})}``.
_FIELDS = {STATE_TOPIC: ('state', {'q_orbit_body': 'q_orbit_body', 'q_eci_body': 'q_eci_body',
                                   'w_eci': 'omega_body_eci_body',
                                   'w_orbit': 'omega_body_orbit_body'}),
           ENV_TOPIC: ('env', {'b_eci': 'b_eci'}), MAG_TOPIC: ('mag', {'b': 'magnetic_field'}),
           ESTIMATE_TOPIC: ('est', {'q_eci_body': 'q_eci_body', 'w_eci': 'omega_body_eci_body'})}


def _collect(bag_path) -> _Data:
    data = _Data()
    with open_bag(bag_path) as reader:
        kinds = {}
        for conn in reader.connections:
            kinds[conn.topic] = stamp_kind(reader.typestore, conn.msgtype)
            data.stats.setdefault(conn.topic, _TopicStats(conn.msgtype,
                                                          from_header=bool(kinds[conn.topic])))
        for conn, t_log, raw in raw_messages(reader, reader.connections, bag_path):
            stamp = cdr_stamp_ns(raw) if kinds[conn.topic] else None
            data.stats[conn.topic].add(stamp if stamp is not None else t_log)
            if conn.topic in _FIELDS or conn.topic in (WHEELS_TOPIC, TARGET_TOPIC, STATUS_TOPIC):
                _store(data, conn.topic, reader.deserialize(raw, conn.msgtype))
    return data


def _store(data: _Data, topic: str, msg) -> None:
    t = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
    if topic == TARGET_TOPIC:
        data.target['t'].append(t)
        data.target['q'].append(_xyz(msg.q_ref_body))
        data.target['frame'].append(msg.header.frame_id)
        return
    if topic == STATUS_TOPIC:
        data.status['t'].append(t)
        data.status['active'].append(msg.active)
        return
    if topic == WHEELS_TOPIC:
        data.wheels['t'].append(t)
        data.wheels['h'].append([float(x) for x in msg.momentum])
        data.wheels['names'] = data.wheels['names'] or list(msg.names)
        return
    name, fields = _FIELDS[topic]
    series = getattr(data, name)
    series['t'].append(t)
    for key, attr in fields.items():
        series[key].append(_xyz(getattr(msg, attr)))
    if topic == ENV_TOPIC:
        series['n'].append(float(msg.orbit_rate))


class _TimeAxis:
    """Relative time in seconds or orbits, from a reference stamp."""

    def __init__(self, t0_ns: int, duration_s: float, orbit_period_s: Optional[float]) -> None:
        self.t0_ns = t0_ns
        self.use_orbits = bool(orbit_period_s) and duration_s >= 0.5 * orbit_period_s
        self.scale = orbit_period_s if self.use_orbits else 1.0
        self.label = 'time [orbits]' if self.use_orbits else 'time [s]'

    def __call__(self, t_ns: Sequence[int]) -> np.ndarray:
        return (np.asarray(t_ns, dtype=np.int64) - self.t0_ns) * 1e-9 / self.scale


def _plot(out: Path, name: str, plots: List[str], axis: '_TimeAxis', panels,
          height: float = 3.0) -> None:
    """One PNG of panels ``(ylabel, lines, legend columns)``, lines ``(t, y, label, style)``."""
    fig = Figure(figsize=(8, height * len(panels) + (0 if len(panels) > 1 else 1)))
    axes = np.atleast_1d(fig.subplots(len(panels), 1, sharex=True))
    for ax, (ylabel, lines, ncol) in zip(axes, panels):
        for t, y, label, style in lines:
            ax.plot(t, y, style, label=label)
        ax.set_ylabel(ylabel)
        if ncol:
            ax.legend(loc='best', ncol=ncol)
        ax.grid(True)
    axes[-1].set_xlabel(axis.label)
    fig.tight_layout()
    fig.savefig(out / name, dpi=110)
    plots.append(name)


def _plot_truth(data, axis, out, plots) -> None:
    s = data.state
    t = axis(s['t'])
    q = np.array(s['q_orbit_body'])
    w = np.array(s['w_eci']) * _RAD2DEG
    _plot(out, 'attitude.png', plots, axis, [
        ('angle body to orbit frame [deg]', [(t, angle_to_identity_deg(q), None, '-')], 0),
        ('q_orbit_body [-]', [(t, q[:, i], f'q_{c}', '-') for i, c in enumerate('xyzw')], 4)])
    _plot(out, 'rates.png', plots, axis, [
        ('omega_body_eci_body [deg/s]',
         [(t, w[:, i], f'omega_{c}', '-') for i, c in enumerate('xyz')], 3),
        ('rate norm [deg/s]', [(t, np.linalg.norm(w, axis=1), '|omega_body_eci_body|', '-'),
                               (t, np.linalg.norm(np.array(s['w_orbit']), axis=1) * _RAD2DEG,
                                '|omega_body_orbit_body|', '-')], 1)])


def _plot_field(data, axis, out, plots) -> None:
    panels = []
    for series, key, label in ((data.env, 'b_eci', 'b_eci [uT] (ECI)'),
                               (data.mag, 'b', 'magnetometer [uT] (sensor frame)')):
        if series['t']:
            t, b = axis(series['t']), np.array(series[key]) * _T2UT
            panels.append((label, [(t, b[:, i], c, '-') for i, c in enumerate('xyz')]
                           + [(t, np.linalg.norm(b, axis=1), 'norm', 'k--')], 4))
    _plot(out, 'field.png', plots, axis, panels)


def _wheel_matrix(data) -> np.ndarray:
    width = max((len(h) for h in data.wheels['h']), default=0)
    h = np.full((len(data.wheels['h']), width), np.nan)
    for i, row in enumerate(data.wheels['h']):
        h[i, :len(row)] = row
    return h


def _plot_wheels(data, axis, out, plots) -> None:
    h, names, t = _wheel_matrix(data), data.wheels['names'], axis(data.wheels['t'])
    _plot(out, 'wheels.png', plots, axis, [('wheel momentum [N m s]', [
        (t, h[:, i], names[i] if i < len(names) else f'wheel {i}', '-')
        for i in range(h.shape[1])], 1)])


def _estimate_errors(data) -> Optional[Tuple[List[int], np.ndarray, np.ndarray]]:
    """``(stamps [ns], angle [rad], rate error [rad/s])`` of the estimates at their stamps."""
    ts = np.asarray(data.state['t'], dtype=np.int64)
    te = np.asarray(data.est['t'], dtype=np.int64)
    t0 = ts[0]
    err = estimate_errors_deg((ts - t0) * 1e-9, data.state['q_eci_body'], (te - t0) * 1e-9,
                              data.est['q_eci_body'])
    if not err['t'].size:
        return None
    inside = (te >= ts[0]) & (te <= ts[-1])
    stamps = te[inside]
    w_true = np.asarray(data.state['w_eci'], dtype=float)
    w_at = np.stack([np.interp(err['t'], (ts - t0) * 1e-9, w_true[:, k]) for k in range(3)],
                    axis=1)
    rate_err = np.linalg.norm(np.asarray(data.est['w_eci'], dtype=float)[inside] - w_at, axis=1)
    data.est_on_grid = err['on_grid']
    return [int(t) for t in stamps], np.radians(err['deg']), rate_err


def _plot_estimate(errors, axis, out, plots) -> None:
    stamps, angles, rate_err = errors
    t = axis(stamps)
    _plot(out, 'estimate_error.png', plots, axis, [
        ('attitude estimate error [deg]', [(t, angles * _RAD2DEG, None, '-')], 0),
        ('rate estimate error [deg/s]', [(t, rate_err * _RAD2DEG, None, '-')], 0)])


def _utc(t_ns: int) -> str:
    return datetime.fromtimestamp(t_ns * 1e-9, tz=timezone.utc).strftime(
        '%Y-%m-%d %H:%M:%S.%f UTC')


def _summary_md(bag_path, metrics: Dict[str, Any], expectations: Sequence[Expectation],
                sections: Sequence[Tuple[str, str]] = ()) -> str:
    lines = [
        '# ADCS run report', '',
        f'* bag: `{bag_path}`',
    ]
    if metrics.get('start_utc'):
        lines.append(f"* start (sim time): {metrics['start_utc']}")
    duration = f"{metrics['duration_s']:.6g} s"
    if metrics.get('orbit_period_s'):
        duration += f" ({metrics['duration_s'] / metrics['orbit_period_s']:.4g} orbits of " \
                    f"{metrics['orbit_period_s']:.6g} s)"
    lines += [f'* duration: {duration}',
              '* times are header stamps (simulated time), not bag log times', '',
              '## Topics', '',
              '| topic | type | messages | rate [Hz] |', '|---|---|---:|---:|']
    for topic, info in metrics['topics'].items():
        rate = '-' if info['rate_hz'] is None else f"{info['rate_hz']:.4g}"
        if info['rate_hz'] is not None and info['rate_source'] != 'header':
            rate += ' (log time)'
        lines.append(f"| `{topic}` | `{info['type']}` | {info['count']} | {rate} |")
    lines += ['', '## Attitude and rates', '']
    rows = [
        ('final angle body to orbit frame', 'final_angle_orbit_deg', 'deg'),
        ('max angle body to orbit frame', 'max_angle_orbit_deg', 'deg'),
        ('final \\|omega_body_eci_body\\|', 'final_rate_deg_s', 'deg/s'),
        ('max \\|omega_body_eci_body\\|', 'max_rate_deg_s', 'deg/s'),
        ('final \\|omega_body_orbit_body\\|', 'final_rate_orbit_deg_s', 'deg/s'),
        ('final attitude estimate error', 'estimate_final_error_deg', 'deg'),
        ('max attitude estimate error', 'estimate_max_error_deg', 'deg'),
        ('rms attitude estimate error', 'estimate_rms_error_deg', 'deg'),
        ('estimates judged (against the truth slerped to each estimate stamp)',
         'estimate_matched', ''),
        ('... of them stamped on a truth sample', 'estimate_on_truth_grid', ''),
        ('capture: enters 5 deg, stays within 10 deg', 'capture_orbits', 'orbits'),
        ('last exit from 5 deg', 'last_exit_orbits', 'orbits'),
        ('hold RMS (4 orbits to the end)', 'hold_rms_deg', 'deg'),
        ('hold median', 'hold_median_deg', 'deg'),
        ('hold 95th percentile', 'hold_p95_deg', 'deg'),
        ('max \\|wheel momentum\\|', 'wheel_max_abs_momentum_Nms', 'N m s'),
        ('mean \\|b_eci\\|', 'field_mean_norm_uT', 'uT'),
        ('mean \\|magnetometer\\|', 'magnetometer_mean_norm_uT', 'uT'),
    ]
    present = [(label, key, unit) for label, key, unit in rows if key in metrics]
    if present:
        lines += ['| quantity | value | unit |', '|---|---:|---|']
        lines += [f'| {label} | {papers.fmt(metrics[key])} | {unit} |'
                  for label, key, unit in present]
    else:
        lines.append(f'No `{STATE_TOPIC}` in the bag.')
    if metrics.get('controller_phases'):
        lines += ['', '## Pointing by controller phase', '',
                  f'Angle body to guidance target; settled: within {SETTLED_DEG:g} deg over the '
                  f"phase's last {SETTLED_WINDOW_S:g} s (or its second half).", '',
                  '| controller | from [s] | to [s] | angle at the end [deg] | max over the '
                  'last window [deg] | settled |', '|---|---:|---:|---:|---:|---|']
        lines += [f"| {p['controller']} | {p['from_s']:.6g} | {p['to_s']:.6g} | "
                  f"{papers.fmt(p['end_angle_deg'])} | {papers.fmt(p['last_window_max_deg'])} | "
                  f"{'yes' if p['settled'] else 'no'} |" for p in metrics['controller_phases']]
    lines += ['', '## Paper comparison', '']
    if not expectations:
        lines += ['| quantity | paper | measured | verdict |', '|---|---|---|---|', '',
                  '_No paper comparison for this run._']
    else:
        lines += papers.table_lines(expectations)
    for title, text in sections:
        lines += ['', f'## {title}', '', text.rstrip()]
    lines += ['', '## Plots', '']
    lines += [f'![{Path(p).stem}]({p})' for p in metrics['plots']]
    return '\n'.join(lines) + '\n'


def make_report(bag_path: os.PathLike | str, out_dir: os.PathLike | str,
                expectations: Optional[Sequence[Expectation]] = None,
                sections: Optional[Sequence[Tuple[str, str]]] = None) -> Dict[str, Any]:
    """PNG plots, ``summary.md`` and ``metrics.json`` of a bag in ``out_dir``, with the paper
    rows ``expectations`` and markdown ``sections``; the metrics."""
    expectations = list(expectations or [])
    if sections is None:
        from adcs_nodes.tools.analyse.reproductions import sections_for
        try:
            sections = sections_for(str(bag_path))
        except (OSError, ValueError, ImportError):
            sections = []
    data = _collect(bag_path)
    if not any(st.count for st in data.stats.values()):
        raise ValueError(f'{bag_path}: nothing to report: no message could be read from it')
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    metrics, axis, errors = _bag_metrics(data, bag_path)
    plots = _draw_plots(data, axis, errors, out, wheels='wheel_final_momentum_Nms' in metrics)
    if expectations:
        try:
            drawn = papers.figures_for_bag(str(bag_path), str(out))
            plots += [os.path.relpath(p, out) for p in drawn]
        except (OSError, ValueError, KeyError) as exc:   # a bag without the paper's topics
            metrics['paper_figures_error'] = str(exc)
    metrics['expectations'] = [
        {'name': name, 'paper': paper, 'measured': _json_value(measured),
         'pass': bool(ok) if papers.is_counted(ok) else None,
         'verdict': papers.verdict_text(ok)}
        for name, paper, measured, ok in expectations]
    counted = [bool(e[3]) for e in expectations if papers.is_counted(e[3])]
    metrics['all_pass'] = all(counted) if counted else None
    metrics['plots'] = plots
    summary = out / 'summary.md'
    summary.write_text(_summary_md(bag_path, metrics, expectations, sections),
                       encoding='utf-8')
    metrics['summary'] = str(summary)
    metrics_file = out / 'metrics.json'
    metrics['metrics_file'] = str(metrics_file)
    metrics_file.write_text(json.dumps(metrics, indent=2, default=_json_value) + '\n',
                            encoding='utf-8')
    return metrics


def _bag_metrics(data: _Data, bag_path) -> Tuple[Dict[str, Any], '_TimeAxis', Any]:
    """``(metrics, time axis of the plots, estimate errors or None)`` of :func:`make_report`."""
    metrics: Dict[str, Any] = {'bag': str(bag_path), 'topics': {}}
    for topic in sorted(data.stats):
        st = data.stats[topic]
        metrics['topics'][topic] = {
            'type': st.msgtype, 'count': st.count, 'rate_hz': st.rate_hz(),
            'rate_source': 'header' if st.from_header else 'log_time'}
    stamped = [st for st in data.stats.values() if st.from_header and st.count]
    if data.state['t']:
        t0, t1 = data.state['t'][0], data.state['t'][-1]
    elif stamped:
        t0 = min(st.first_ns for st in stamped)
        t1 = max(st.last_ns for st in stamped)
    else:
        t0 = t1 = 0
    metrics['duration_s'] = (t1 - t0) * 1e-9
    metrics['start_utc'] = _utc(t0) if t0 else None
    rates = [n for n in data.env['n'] if n > 0.0]
    period = 2.0 * math.pi / rates[-1] if rates else None
    if period:
        metrics['orbit_period_s'] = period
    if data.state['t']:
        metrics.update(_truth_metrics(data, t0, period))
        metrics['controller_phases'] = controller_phases(data, t0)
    if data.env['t']:
        metrics['field_mean_norm_uT'] = float(
            np.linalg.norm(np.array(data.env['b_eci']), axis=1).mean() * _T2UT)
    if data.mag['t']:
        metrics['magnetometer_mean_norm_uT'] = float(
            np.linalg.norm(np.array(data.mag['b']), axis=1).mean() * _T2UT)
    if data.wheels['t']:
        h = _wheel_matrix(data)
        if h.size:
            metrics['wheel_max_abs_momentum_Nms'] = float(np.nanmax(np.abs(h)))
            metrics['wheel_final_momentum_Nms'] = [float(x) for x in h[-1]]
    errors = _estimate_errors(data) if data.est['t'] and data.state['t'] else None
    if errors is not None:
        deg = errors[1] * _RAD2DEG
        metrics.update({
            'estimate_final_error_deg': float(deg[-1]),
            'estimate_max_error_deg': float(deg.max()),
            'estimate_rms_error_deg': float(np.sqrt(np.mean(deg ** 2))),
            'estimate_matched': len(deg),
            'estimate_on_truth_grid': int(getattr(data, 'est_on_grid', 0)),
            'estimate_truth': 'interpolated at each estimate stamp (slerp)',
        })
    return metrics, _TimeAxis(t0, metrics['duration_s'], period), errors


def _truth_metrics(data: _Data, t0: int, period: Optional[float]) -> Dict[str, Any]:
    """The truth's angle to the orbit frame and rates (with a period, its ``run_metrics``)."""
    angles = angle_to_identity_deg(np.array(data.state['q_orbit_body']))
    w = np.linalg.norm(np.array(data.state['w_eci']), axis=1) * _RAD2DEG
    w_orb = np.linalg.norm(np.array(data.state['w_orbit']), axis=1) * _RAD2DEG
    out = {'final_angle_orbit_deg': float(angles[-1]), 'max_angle_orbit_deg': float(angles.max()),
           'final_q_orbit_body': [float(x) for x in data.state['q_orbit_body'][-1]],
           'final_rate_deg_s': float(w[-1]), 'max_rate_deg_s': float(w.max()),
           'final_rate_orbit_deg_s': float(w_orb[-1])}
    if period:
        t_s = (np.asarray(data.state['t'], dtype=np.int64) - t0) * 1e-9
        run = run_metrics(t_s, angles, period)
        out.update({k: run[k] for k in (
            'capture_orbits', 'last_exit_orbits', 'hold_rms_deg', 'hold_median_deg',
            'hold_p95_deg', 'hold_max_deg', 'hold_samples')
            if run[k] is not None and math.isfinite(run[k])})
    return out


def controller_phases(data: _Data, t0: int) -> List[Dict[str, Any]]:
    """Per span of one forwarded controller (``controller_status.active``): its times [s from
    ``t0``], the truth's angle to the guidance target at its end and its largest over the
    span's last ``SETTLED_WINDOW_S`` (or second half) [deg], within ``SETTLED_DEG`` or not."""
    if not (data.status['t'] and data.target['t'] and data.state['t']):
        return []
    t = np.asarray(data.state['t'], dtype=np.int64)
    k = np.searchsorted(np.asarray(data.target['t'], dtype=np.int64), t, side='right') - 1
    ok = k >= 0                                   # the target held since its last sample
    k = np.maximum(k, 0)
    frames = np.asarray(data.target['frame'])[k]
    truth = np.where((frames == 'eci')[:, None], np.asarray(data.state['q_eci_body']),
                     np.asarray(data.state['q_orbit_body']))
    angle = np.where(ok, angle_between_deg(truth, np.asarray(data.target['q'])[k]), np.nan)
    starts = [(ts, a) for i, (ts, a) in enumerate(zip(data.status['t'], data.status['active']))
              if i == 0 or a != data.status['active'][i - 1]]
    out = []
    for i, (start, name) in enumerate(starts):
        end = starts[i + 1][0] if i + 1 < len(starts) else int(t[-1]) + 1
        span = (t >= start) & (t < end) & ok
        if not span.any():
            continue
        window_ns = min(SETTLED_WINDOW_S * 1e9, (t[span][-1] - t[span][0]) / 2)
        last = span & (t >= t[span][-1] - window_ns)
        worst = float(np.max(angle[last]))
        out.append({'controller': name or '(none)', 'from_s': (start - t0) / 1e9,
                    'to_s': (min(end, int(t[-1])) - t0) / 1e9,
                    'end_angle_deg': float(angle[span][-1]), 'last_window_max_deg': worst,
                    'settled': worst <= SETTLED_DEG})
    return out


def _draw_plots(data: _Data, axis: '_TimeAxis', errors, out: Path,
                wheels: bool) -> List[str]:
    """The file names of the PNG plots of the series the bag has."""
    plots: List[str] = []
    if data.state['t']:
        _plot_truth(data, axis, out, plots)
    if data.env['t'] or data.mag['t']:
        _plot_field(data, axis, out, plots)
    if wheels:
        _plot_wheels(data, axis, out, plots)
    if errors is not None:
        _plot_estimate(errors, axis, out, plots)
    return plots


def _json_value(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return str(value)
