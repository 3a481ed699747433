"""Bag to report: metrics, PNG plots and ``summary.md``, on ``header.stamp`` (sim time; the
log time only for types without a header), so two runs of one simulation give one report."""
from __future__ import annotations

import json
import math
import os
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np
from matplotlib.figure import Figure

from adcs_nodes.tools.analyse import papers
from adcs_nodes.tools.analyse.bag_series import (  # noqa: F401 (_Data: the series' type)
    SETTLED_DEG, SETTLED_WINDOW_S, STATE_TOPIC, RunData as _Data, TimeAxis, controller_phases,
    estimate_error, orbit_period_s, ragged, read_run, time_axis)
from adcs_nodes.tools.analyse.metrics import angle_to_identity_deg, run_metrics
from adcs_nodes.tools.analyse.papers.series import save_figure

Expectation = Tuple[str, str, Any, Any]   # verdict: True, False, None (info), NotComparable

_RAD2DEG = 180.0 / math.pi
_T2UT = 1e6


def _plot(out: Path, name: str, plots: List[str], axis: TimeAxis, panels,
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
    save_figure(fig, str(out), name, 110)
    plots.append(name)


def _plot_truth(data, axis, out, plots) -> None:
    s = data.state
    t = axis(s['s'])
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
            t, b = axis(series['s']), np.array(series[key]) * _T2UT
            panels.append((label, [(t, b[:, i], c, '-') for i, c in enumerate('xyz')]
                           + [(t, np.linalg.norm(b, axis=1), 'norm', 'k--')], 4))
    _plot(out, 'field.png', plots, axis, panels)


def _plot_wheels(data, axis, out, plots) -> None:
    h, names, t = ragged(data.wheels['h']), data.wheel_names, axis(data.wheels['s'])
    _plot(out, 'wheels.png', plots, axis, [('wheel momentum [N m s]', [
        (t, h[:, i], names[i] if i < len(names) else f'wheel {i}', '-')
        for i in range(h.shape[1])], 1)])


def _plot_estimate(err, axis, out, plots) -> None:
    t = axis(err['s'])
    _plot(out, 'estimate_error.png', plots, axis, [
        ('attitude estimate error [deg]', [(t, err['deg'], None, '-')], 0),
        ('rate estimate error [deg/s]', [(t, err['rate'] * _RAD2DEG, None, '-')], 0)])


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
    data = read_run(bag_path)
    if not any(st.stamps for st in data.stats.values()):
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


def _bag_metrics(data: _Data, bag_path) -> Tuple[Dict[str, Any], TimeAxis, Any]:
    """``(metrics, time axis of the plots, estimate errors or None)`` of :func:`make_report`."""
    metrics: Dict[str, Any] = {'bag': str(bag_path), 'topics': {}}
    for topic in sorted(data.stats):
        st = data.stats[topic]
        metrics['topics'][topic] = {
            'type': st.msgtype, 'count': len(st.stamps), 'rate_hz': st.rate_hz(),
            'rate_source': 'header' if st.from_header else 'log_time'}
    stamped = [max(st.stamps) for st in data.stats.values() if st.from_header and st.stamps]
    t0, t1 = data.t0, (data.state['t'][-1] if data.state['t'] else max(stamped, default=0))
    metrics['duration_s'] = (t1 - t0) * 1e-9
    metrics['start_utc'] = datetime.fromtimestamp(t0 * 1e-9, tz=timezone.utc).strftime(
        '%Y-%m-%d %H:%M:%S.%f UTC') if t0 else None
    period = orbit_period_s(data)
    if period:
        metrics['orbit_period_s'] = period
    if data.state['t']:
        metrics.update(_truth_metrics(data, period))
        metrics['controller_phases'] = controller_phases(data, t0)
    for key, b in (('field_mean_norm_uT', data.env['b_eci']),
                   ('magnetometer_mean_norm_uT', data.mag['b'])):
        if b:
            metrics[key] = float(np.linalg.norm(np.array(b), axis=1).mean() * _T2UT)
    h = ragged(data.wheels['h'])
    if h.size:
        metrics['wheel_max_abs_momentum_Nms'] = float(np.nanmax(np.abs(h)))
        metrics['wheel_final_momentum_Nms'] = [float(x) for x in h[-1]]
    errors = estimate_error(data)
    if errors is not None:
        deg = errors['deg']
        metrics.update({
            'estimate_final_error_deg': float(deg[-1]),
            'estimate_max_error_deg': float(deg.max()),
            'estimate_rms_error_deg': float(np.sqrt(np.mean(deg ** 2))),
            'estimate_matched': len(deg),
            'estimate_on_truth_grid': errors['on_grid'],
            'estimate_truth': 'interpolated at each estimate stamp (slerp)',
        })
    return metrics, time_axis(metrics['duration_s'], period), errors


def _truth_metrics(data: _Data, period: Optional[float]) -> Dict[str, Any]:
    """The truth's angle to the orbit frame and rates (with a period, its ``run_metrics``)."""
    angles = angle_to_identity_deg(np.array(data.state['q_orbit_body']))
    w = np.linalg.norm(np.array(data.state['w_eci']), axis=1) * _RAD2DEG
    w_orb = np.linalg.norm(np.array(data.state['w_orbit']), axis=1) * _RAD2DEG
    out = {'final_angle_orbit_deg': float(angles[-1]), 'max_angle_orbit_deg': float(angles.max()),
           'final_q_orbit_body': [float(x) for x in data.state['q_orbit_body'][-1]],
           'final_rate_deg_s': float(w[-1]), 'max_rate_deg_s': float(w.max()),
           'final_rate_orbit_deg_s': float(w_orb[-1])}
    if period:
        run = run_metrics(np.asarray(data.state['s']), angles, period)
        out.update({k: run[k] for k in (
            'capture_orbits', 'last_exit_orbits', 'hold_rms_deg', 'hold_median_deg',
            'hold_p95_deg', 'hold_max_deg', 'hold_samples')
            if run[k] is not None and math.isfinite(run[k])})
    return out


def _draw_plots(data: _Data, axis: TimeAxis, errors, out: Path,
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
