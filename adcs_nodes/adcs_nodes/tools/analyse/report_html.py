"""``report.html``: one self-contained page of a run (no network, no script, inline PNGs) from
any engine's bag: timeline, wheels, dipole, estimator error with its 3-sigma bound, switches,
fallbacks, faults and the paper table of ``metrics.json``."""
from __future__ import annotations

import base64
import html
import io
import json
import math
import os
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

import numpy as np
from matplotlib.figure import Figure

from adcs_nodes.tools.analyse.bag_series import (RunData, TimeAxis, estimate_error,
                                                 orbit_period_s, pointing_deg, ragged, read_run,
                                                 samples, spans)
from adcs_nodes.tools.analyse.bag_series import time_axis as _time_axis

#: One colour per controller (others get the next free one); 'zero' and '' are grey.
PALETTE = ('#4c72b0', '#dd8452', '#55a868', '#c44e52', '#8172b3', '#937860', '#da8bc3',
           '#8c8c8c', '#ccb974', '#64b5cd')
KNOWN_COLOURS = {'bdot': '#c44e52', 'magnetic': '#dd8452', 'mpi': '#4c72b0',
                 'fuzzy': '#55a868', 'reference_slew': '#8172b3', 'zero': '#bbbbbb',
                 '': '#eeeeee', '-': '#eeeeee', 'detumble': '#f4b6b6', 'acquire': '#f8d3b0',
                 'point': '#b6cbe8'}
_DEG = 180.0 / math.pi


def colours_for(names: Sequence[str]) -> Dict[str, str]:
    """``{name: colour}``: :data:`KNOWN_COLOURS`, then ``names`` in the free :data:`PALETTE`."""
    out = dict(KNOWN_COLOURS)
    free = [c for c in PALETTE if c not in out.values()]
    for n in names:
        if n not in out:
            out[n] = free.pop(0) if free else '#999999'
    return out


def _switches(s: RunData, schedule: Dict[float, str]) -> List[Dict[str, str]]:
    """Each switch and fallback with its reason, in time order."""
    rows: List[Dict[str, str]] = []
    prev: Optional[Dict[str, Any]] = None
    status = samples(s.status)
    for e in status:
        if prev is None:
            rows.append({'t': e['s'], 'what': f'start: {e["active"]}'
                         + (f' (mode {e["mode"]})' if e['mode'] else ''),
                         'why': 'initial controller' + (', automatic sequence'
                                                        if e['mode'] else '')})
        else:
            if e['switch_count'] != prev['switch_count'] or e['active'] != prev['active']:
                if e['mode'] and e['mode'] != prev['mode']:
                    why = f'automatic sequence: {prev["mode"] or "-"} -> {e["mode"]}'
                elif any(abs(e['s'] - ts) < 1e-6 and n in (e['active'], 'auto')
                         for ts, n in schedule.items()):
                    why = 'scheduled (manager.schedule)'
                elif prev['active'] != e['active'] and e['last_fault'] != prev['last_fault']:
                    why = f'latched fallback: {e["last_fault"]}'
                else:
                    why = 'operator request (adcs switch / adcs slew) or schedule'
                rows.append({'t': e['s'], 'what': f'switch {prev["active"]} -> {e["active"]}'
                             + (f' (mode {e["mode"]})' if e['mode'] else ''), 'why': why})
            if e['last_fault'] and e['last_fault'] != prev['last_fault']:
                rows.append({'t': e['s'], 'what': f'fallback from {e["active"]}',
                             'why': e['last_fault']})
        prev = e
    times = s.status['s']

    def active_at(t: float) -> str:
        i = int(np.searchsorted(times, t + 1e-6)) - 1
        return s.status['active'][i] if i >= 0 else ''
    fell_back = False
    for start, _, src in spans(s.cmd['s'], s.cmd['source'], None)[1:]:
        if src == 'zero':
            continue
        if times and src != active_at(start):
            rows.append({'t': start, 'what': f'commands from {src} (not the active '
                         f'{active_at(start)})', 'why': 'fallback to the safe controller '
                         '(adcs/actuator_command source)'})
            fell_back = True
        elif fell_back:
            rows.append({'t': start, 'what': f'commands from {src} again',
                         'why': 'its command is valid again'})
            fell_back = False
    rows.sort(key=lambda r: r['t'])
    return rows


# ---------------------------------------------------------------------- figures
def _png(fig: Figure) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format='png', dpi=90)
    return buf.getvalue()


def _mark_faults(ax, s: RunData, axis: TimeAxis, label: bool = False) -> None:
    """Dashed lines at each fault's start (red) and end (green), ``label``: named."""
    span = max(ax.get_xlim()[1] - ax.get_xlim()[0], 1e-9) if label else 1.0
    last_x, level = None, 0
    for f in samples(s.faults):
        x = f['s'] / axis.scale
        colour = '#d62728' if f['active'] else '#2ca02c'
        ax.axvline(x, color=colour, lw=1.0, ls='--')
        if label and f['active']:
            level = level + 1 if last_x is not None and x - last_x < 0.12 * span else 0
            last_x = x
            ax.annotate(f'{f["kind"]} {f["target"]}', (x, 1.0 + 0.08 * level),
                        xycoords=('data', 'axes fraction'), fontsize=7, va='bottom',
                        ha='left', color=colour, annotation_clip=False)


def _style(ax, s: RunData, axis: TimeAxis, ylabel: str, last: bool, label: bool = False) -> None:
    """Y label, grid and fault marks of one panel; the time label on the ``last`` one."""
    ax.set_ylabel(ylabel, fontsize=8)
    ax.grid(True, alpha=0.3)
    if last:
        ax.set_xlabel(axis.label)
    else:
        ax.tick_params(labelbottom=False)
    _mark_faults(ax, s, axis, label=label)


def _shade(ax, runs, colours, axis: TimeAxis, alpha: float = 0.12) -> None:
    for a, b, lab in runs:
        if lab not in ('zero', ''):
            ax.axvspan(a / axis.scale, b / axis.scale, color=colours[lab], alpha=alpha, lw=0)


def _overview(s: RunData, axis: TimeAxis, t_end: float, colours: Dict[str, str],
              pointing) -> Figure:
    fig = Figure(figsize=(11.0, 6.2))
    gs = fig.add_gridspec(3, 1, height_ratios=[1.1, 2.0, 1.5], hspace=0.12)
    band = fig.add_subplot(gs[0])
    rows = [('commanding', spans(s.cmd['s'], s.cmd['source'], t_end)),
            ('active', spans(s.status['s'], s.status['active'], t_end)),
            ('mode', spans(s.status['s'], [m or '-' for m in s.status['mode']], t_end))]
    phases = rows[1][1] or rows[0][1]       # the shading: the controller phases of summary.md
    for k, (_, runs) in enumerate(rows):
        y = len(rows) - 1 - k
        for a, b, lab in runs:
            band.broken_barh([(a / axis.scale, max(b - a, 1e-9) / axis.scale)], (y + 0.1, 0.8),
                             color=colours.get(lab, '#999999'), lw=0)
            if (b - a) / max(t_end, 1e-9) > 0.04 and lab:
                band.text((a + b) / 2 / axis.scale, y + 0.5,
                          'no sequence' if lab == '-' else lab, ha='center', va='center',
                          fontsize=8)
    band.set_yticks([len(rows) - 1 - k + 0.5 for k in range(len(rows))])
    band.set_yticklabels([r[0] for r in rows], fontsize=8)
    band.set_ylim(0, len(rows))
    band.set_xlim(0, t_end / axis.scale)
    band.tick_params(labelbottom=False)
    _mark_faults(band, s, axis, label=True)
    band.set_title('controllers: forwarded command, active, manager mode; faults dashed',
                   fontsize=9, loc='left', pad=14)
    err_ax = fig.add_subplot(gs[1], sharex=band)
    _shade(err_ax, phases, colours, axis)
    if pointing is not None:
        err_ax.semilogy(axis(s.state['s']), np.maximum(pointing, 1e-4), color='k', lw=0.8)
    else:
        err_ax.text(0.5, 0.5, 'no attitude target recorded', transform=err_ax.transAxes,
                    ha='center')
    _style(err_ax, s, axis, 'attitude error\nto target [deg]', last=False)
    rate_ax = fig.add_subplot(gs[2], sharex=band)
    _shade(rate_ax, phases, colours, axis)
    if s.state['t']:
        for key, frame in (('w_eci', 'ECI'), ('w_orbit', 'the orbit frame')):
            rate_ax.semilogy(axis(s.state['s']), np.maximum(
                np.linalg.norm(s.state[key], axis=1) * _DEG, 1e-5), lw=0.8,
                label=f'|omega| w.r.t. {frame}')
        rate_ax.legend(fontsize=7, loc='upper right')
    _style(rate_ax, s, axis, 'body rate\n[deg/s]', last=True)
    fig.subplots_adjust(left=0.1, right=0.98, top=0.95, bottom=0.08)
    return fig


def _wheels_fig(s: RunData, axis: TimeAxis) -> Figure:
    fig = Figure(figsize=(11.0, 4.6))
    t, names, first = axis(s.wheels['s']), s.wheel_names, None
    for k, (ylabel, y) in enumerate((
            ('speed [rpm]', ragged(s.wheels['speed']) * 60.0 / (2.0 * math.pi)),
            ('momentum [N m s]', ragged(s.wheels['h'])))):
        ax = fig.add_subplot(2, 1, k + 1, sharex=first)
        for i in range(y.shape[1]):
            ax.plot(t, y[:, i], lw=0.8, label=names[i] if i < len(names) else f'wheel{i}')
        if first is None:
            ax.legend(fontsize=7, loc='upper left')
            ax.set_xlim(t[0], t[-1])
            first = ax
        _style(ax, s, axis, ylabel, last=k == 1, label=k == 0)
    fig.subplots_adjust(left=0.1, right=0.98, top=0.9, bottom=0.12, hspace=0.1)
    return fig


def _dipole_fig(s: RunData, axis: TimeAxis) -> Figure:
    fig = Figure(figsize=(11.0, 2.8))
    ax = fig.add_subplot(1, 1, 1)
    t = axis(s.cmd['s'])
    d = np.asarray(s.cmd['dipole'])
    for i, n in enumerate('xyz'):
        ax.plot(t, d[:, i], lw=0.6, label=f'm_{n}')
    ax.legend(fontsize=7, loc='upper right', ncol=3)
    _style(ax, s, axis, 'dipole [A m^2]', last=True)
    fig.subplots_adjust(left=0.1, right=0.98, top=0.95, bottom=0.18)
    return fig


def _estimate_fig(s: RunData, axis: TimeAxis, e: Dict[str, Any]) -> Figure:
    with_diag = bool(s.diag['t'])
    fig = Figure(figsize=(11.0, 6.2 if with_diag else 5.2))
    n_rows = 4 if with_diag else 3
    t = axis(e['s'])
    first = None
    for i, n in enumerate('xyz'):
        ax = fig.add_subplot(n_rows, 1, i + 1, sharex=first)
        first = first or ax
        sig = e['sigma3'][:, i]
        if np.isfinite(sig).any():
            ax.fill_between(t, -sig, sig, color='#4c72b0', alpha=0.2, lw=0,
                            label='3-sigma (estimate covariance)')
        ax.plot(t, e['err'][:, i], lw=0.6, color='k', label='error (truth at the stamp)')
        ax.set_xlim(t[0], t[-1])
        _style(ax, s, axis, f'{n} [deg]', last=i == n_rows - 1, label=i == 0)
        if i == 0:
            ax.legend(fontsize=7, loc='upper right', ncol=2)
        finite = np.abs(e['err'][:, i])
        finite = finite[np.isfinite(finite)]
        if finite.size:      # the error sets the scale (a tumbling start's bound may not)
            ax.set_ylim(-1.15 * max(float(finite.max()), 1e-6),
                        1.15 * max(float(finite.max()), 1e-6))
    if with_diag:
        ax = fig.add_subplot(n_rows, 1, n_rows, sharex=first)
        ax.step(axis(s.diag['s']), s.diag['rejected'], where='post',
                lw=0.8, color='#c44e52')
        _style(ax, s, axis, 'rejected\nsamples', last=True)
    fig.subplots_adjust(left=0.1, right=0.98, top=0.92, bottom=0.1, hspace=0.1)
    return fig


# ---------------------------------------------------------------------- page
_CSS = """body{font-family:sans-serif;margin:1.5em auto;max-width:1050px;color:#222}
h1{font-size:1.5em}h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;font-size:0.85em;margin:0.5em 0}
td,th{border:1px solid #ccc;padding:2px 6px;text-align:left;vertical-align:top}
th{background:#f2f2f2}img{max-width:100%}.note{color:#666;font-size:0.85em}
.pass{color:#1a7f37}.fail{color:#c00}"""


def _table(head: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    out = ['<table><tr>' + ''.join(f'<th>{html.escape(str(h))}</th>' for h in head)
           + '</tr>']
    for r in rows:
        out.append('<tr>' + ''.join(f'<td>{c}</td>' for c in r) + '</tr>')
    return '\n'.join(out) + '</table>'


def _img(png: bytes, alt: str) -> str:
    return (f'<img class="plot" alt="{html.escape(alt)}" src="data:image/png;base64,'
            f'{base64.b64encode(png).decode("ascii")}">')


def _scenario(bag_path) -> Dict[str, Any]:
    """The bag's ``scenario.yaml`` as data (``adcs run`` writes it beside the bag), or {}."""
    from adcs_nodes.tools.bagfile import BagError, bag_scenario
    try:
        return bag_scenario(str(bag_path)) or {}
    except BagError:
        return {}


def _paper_rows(out_dir: Path) -> Optional[List[Dict[str, Any]]]:
    """The paper table of the report's ``metrics.json``, or None."""
    try:
        with open(out_dir / 'metrics.json', encoding='utf-8') as fh:
            rows = json.load(fh).get('expectations')
    except (OSError, ValueError, AttributeError):
        return None
    return rows if isinstance(rows, list) and rows else None


def _fmt_t(t: float, axis: TimeAxis) -> str:
    return f'{t:.0f} s' + (f' ({t / axis.scale:.1f} {axis.unit})' if axis.unit != 's' else '')


def write_report_html(bag_path: os.PathLike | str, out_dir: os.PathLike | str) -> str:
    """Write ``report.html`` and ``overview.png`` of the bag into ``out_dir``; its path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    s = read_run(bag_path)
    sc = _scenario(bag_path)
    t_end = max(s.state['s'][-1:] + s.cmd['s'][-1:] + [1e-9])
    axis = _time_axis(t_end, orbit_period_s(s))
    title = str(sc.get('name') or Path(str(bag_path).rstrip('/')).name)
    parts = [f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
             f'<title>ADCS run {html.escape(title)}</title><style>{_CSS}</style></head><body>',
             f'<h1>ADCS run: {html.escape(title)}</h1>']
    if sc.get('description'):
        parts.append(f'<p>{html.escape(str(sc["description"]))}</p>')
    parts.append(f'<p class="note">bag {html.escape(str(bag_path))}; {_fmt_t(t_end, axis)} '
                 'of sim time; topics: ' + ', '.join(
                     f'{html.escape(k)} ({len(v.stamps)})' for k, v in sorted(s.stats.items())
                     if v.stamps) + '</p>')
    missing: List[str] = []
    parts += _timeline_sections(s, sc, axis, t_end, out, missing)
    parts += _plot_sections(s, axis, missing) + _paper_section(out)
    if missing:
        parts.append('<h2>Not shown</h2><ul>' + ''.join(
            f'<li>{html.escape(m)}</li>' for m in missing) + '</ul>')
    parts.append('</body></html>\n')
    path = out / 'report.html'
    path.write_text('\n'.join(parts), encoding='utf-8')
    return str(path)


def _timeline_sections(s: RunData, sc: Dict[str, Any], axis: TimeAxis, t_end: float, out: Path,
                       missing: List[str]) -> List[str]:
    """The timeline figure (also ``overview.png``), the switches and the faults."""
    parts = ['<h2>Timeline</h2>']
    if s.cmd['t'] or s.status['t'] or s.state['t']:
        colours = colours_for(sorted(set(s.cmd['source'] + s.status['active'] + s.status['mode'])))
        png = _png(_overview(s, axis, t_end, colours, pointing_deg(s)))
        (out / 'overview.png').write_bytes(png)
        parts.append(_img(png, 'timeline: controllers, modes, faults, attitude error, rates'))
    else:
        missing.append('timeline (no sim/state, adcs/actuator_command or '
                       'adcs/controller_status)')
    parts.append('<h2>Switches and fallbacks</h2>')
    schedule = {float(e.get('t_s', -1.0)): str(e.get('controller', ''))
                for e in (sc.get('manager') or {}).get('schedule') or [] if isinstance(e, dict)}
    rows = _switches(s, schedule)
    parts.append(_table(['t', 'what', 'why'], [
        (_fmt_t(r['t'], axis), html.escape(r['what']), html.escape(r['why'])) for r in rows])
        if rows else '<p class="note">no adcs/controller_status or adcs/actuator_command '
        'recorded</p>')
    parts.append('<h2>Faults</h2>')
    parts.append(_table(['t', 'fault', 'state'], [
        (_fmt_t(f['s'], axis), html.escape(f['message'].split(': ', 1)[-1]),
         'active' if f['active'] else 'cleared') for f in samples(s.faults)])
        if s.faults['t'] else '<p class="note">no fault announced on sim/faults</p>')
    return parts


def _plot_sections(s: RunData, axis: TimeAxis, missing: List[str]) -> List[str]:
    """Wheels, dipole, and the estimator against the truth."""
    parts, est = [], estimate_error(s)
    for title, shown, draw, alt, why in (
            ('Reaction wheels', ragged(s.wheels['h']).size, lambda: _wheels_fig(s, axis),
             'wheel speeds and momentum', 'reaction wheels (no sim/wheels with wheels)'),
            ('Magnetorquer dipole', s.cmd['t'], lambda: _dipole_fig(s, axis),
             'magnetorquer dipole command', 'magnetorquer dipole (no adcs/actuator_command)'),
            ('Estimator against the truth', est is not None, lambda: _estimate_fig(s, axis, est),
             'estimator error per body axis with its 3-sigma bound',
             'estimator (no adcs/attitude_estimate with sim/state)')):
        parts.append(f'<h2>{title}</h2>')
        if shown:
            parts.append(_img(_png(draw()), alt))
        else:
            missing.append(why)
    if est is not None and s.diag['t']:
        last = next((r for r in reversed(s.diag['last']) if r), '')
        parts.append(f'<p class="note">rejected samples: {s.diag["rejected"][-1]}'
                     + (f'; last: {html.escape(last)}' if last else '') + '</p>')
    return parts


def _paper_section(out: Path) -> List[str]:
    paper = _paper_rows(out)
    if not paper:
        return ['<h2>Paper comparison</h2>', '<p class="note">no paper table for this run '
                '(the report\'s metrics.json has none: the scenario reproduces no paper, or '
                'the report was not written first)</p>']
    css = {True: 'pass', False: 'fail', None: ''}
    return ['<h2>Paper comparison</h2>', _table(['quantity', 'paper', 'measured', 'verdict'], [
        (html.escape(str(r.get('name', ''))), html.escape(str(r.get('paper', ''))),
         html.escape(str(r.get('measured', ''))),
         f'<span class="{css.get(r.get("pass"), "")}">'
         f'{html.escape(str(r.get("verdict", "")))}</span>') for r in paper])]
