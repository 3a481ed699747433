"""``adcs compare``: controllers side by side on one scenario and the same Monte Carlo draws:
a campaign per controller in ``OUT/controllers/<name>`` (:func:`~.sweep.run_campaigns`, the
same seed), one table (``compare.md``, ``compare.json``) and one figure (``compare.png``).
Who flies, the metrics and their windows: ``docs/montecarlo.md``, "Controllers compared"."""
from __future__ import annotations

import argparse
import os
import sys
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from adcs_nodes.tools.analyse.metrics import angle_between_deg
from adcs_nodes.tools.campaigns.capture import ORBIT_FRAME
from adcs_nodes.tools.campaigns.config import CampaignError
from adcs_nodes.tools.campaigns.files import (FAILED_FILE, SERIES_FILE, load_result,
                                              run_dir_of, write_json_atomic, write_text_atomic)

#: An actuator sample at or above this fraction of its limit counts as saturated (ASSUMPTION).
SATURATED = 0.999


def parse_controllers(text: str) -> List[str]:
    """``--controllers a,b,c``: registered names, each once; else CampaignError."""
    from adcs_nodes import registry
    names = [n.strip() for n in str(text).split(',')]
    if not all(names) or len(set(names)) < len(names):
        raise CampaignError(f'--controllers {text!r}: give each name once, comma-separated '
                            '(e.g. magnetic,mpi,fuzzy)')
    for name in names:
        try:
            registry.get('controller', name)
        except ValueError as exc:
            raise CampaignError(f'--controllers: {exc}') from None
    return names


def flying(base: Dict[str, Any], name: str) -> Tuple[Optional[Dict[str, Any]], str]:
    """``(scenario, how)``: ``base`` with controller ``name`` flying from t = 0 or after the
    automatic sequence's detumble, or ``(None, why it cannot fly this scenario)``."""
    from adcs_nodes.scenario import (ScenarioError, apply_overrides, controller_names,
                                     controller_problems, default_safe)
    if 'controllers' not in base:
        return None, 'the scenario has no controllers section (open loop)'
    problems = controller_problems(base, name)     # (one said twice: 'needs X' in 'A: needs X')
    if problems:
        return None, '; '.join(p for p in problems if not any(
            q != p and q.endswith(p) for q in problems))
    man = base.get('manager') or {}
    auto = man.get('auto') or {}            # after B-dot's detumble, all is the controller's
    phases = ['manager.' + p for p in ('auto.acquire', 'auto.point') if auto.get(p[5:])] or \
        ['manager.initial']
    sets, how = dict.fromkeys(phases, name), phases[:]
    if name not in base['controllers']:
        sets[f'controllers.{name}'] = {}
        how.append('registry defaults (not in the scenario)')
    if not man:
        sets['manager.safe'] = default_safe(controller_names(base))
    if man.get('schedule'):
        sets['manager.schedule'] = []
        how.append('scripted switches removed')
    try:
        return apply_overrides(base, sets), ', '.join(how)
    except ScenarioError as exc:
        return None, str(exc).split(': ', 1)[-1]


def run_metrics(run_dir: str, result: Dict[str, Any], name: str,
                sc: Dict[str, Any]) -> Dict[str, Any]:
    """One finished run's metrics from its ``series.npz`` (:func:`~.worker.run_series`):
    ``pointing_deg`` the judged angles to the target over the run's second half [deg];
    ``settle_s`` the campaign's capture time [s] (None: never); ``effort_Nms`` paper 003's
    energy, the rectangle-rule integral of ``sum_i |tau_wheel_i| + sum_k |(m x b_body)_k|``
    [N m s]; ``peak_h_Nms`` the largest ``|h_i|`` of a wheel (None: no wheels);
    ``saturated_s`` the time any coil, wheel torque or wheel momentum is at :data:`SATURATED`
    of its limit [s]; ``flown_s`` the time ``name``'s command was forwarded [s]; ``lost``
    another controller forwarded after ``name``'s first frame."""
    s = dict(np.load(os.path.join(run_dir, SERIES_FILE)))
    t = s['t_s']
    dt = np.append(np.diff(t), 0.0)                 # each sample holds to the next
    angle = s['angle_deg'] if result.get('capture_reference') == ORBIT_FRAME else \
        angle_between_deg(s['q_orbit_target'], s['q_orbit_body'])
    window = s['target_judged'] & (t >= t[0] + 0.5 * (t[-1] - t[0]))
    craft = sc['spacecraft']
    wheels = craft.get('wheels') or []
    tau_w, h_w, dipole = s['wheel_torque_Nm'], s['wheel_momentum_Nms'], s['dipole_body_Am2']
    tau_m = np.cross(dipole, s['b_body_T'])          # magnetic torque, body axes [N m]
    effort = np.sum(np.abs(tau_w), axis=1) + np.sum(np.abs(tau_m), axis=1)
    limits = [(dipole, craft.get('magnetorquer', {}).get('max_dipole_Am2') or [np.inf] * 3),
              (tau_w, [w['max_torque_Nm'] for w in wheels]),
              (h_w, [w['max_momentum_Nms'] for w in wheels])]
    sat = np.any([np.any(np.abs(x) >= SATURATED * np.asarray(lim, float), axis=1)
                  for x, lim in limits], axis=0)
    mine = s['active'] == name
    return {'t_s': t, 'angle_deg': angle, 'pointing_deg': angle[window],
            'settle_s': result.get('capture_time_s'),
            'effort_Nms': float(np.sum(effort * dt)),
            'peak_h_Nms': float(np.max(np.abs(h_w))) if wheels else None,
            'saturated_s': float(np.sum(dt[sat])), 'flown_s': float(np.sum(dt[mine])),
            'lost': bool(np.any(mine[:-1] & ~mine[1:]))}


def summarise(name: str, runs: Sequence[Dict[str, Any]], n_runs: int, errors: int,
              duration_s: float) -> Dict[str, Any]:
    """The table row of one controller from its runs' :func:`run_metrics` (pure)."""
    def med(key: str, f=np.median) -> Optional[float]:
        v = [r[key] for r in runs if r[key] is not None]
        return float(f(v)) if v else None
    pooled = np.concatenate([r['pointing_deg'] for r in runs]) if runs else np.zeros(0)
    pooled = pooled[np.isfinite(pooled)]
    return {'controller': name, 'runs': n_runs, 'done': len(runs), 'errors': errors,
            'pointing_median_deg': float(np.median(pooled)) if pooled.size else None,
            'pointing_p95_deg': float(np.percentile(pooled, 95)) if pooled.size else None,
            'settled': sum(r['settle_s'] is not None for r in runs),
            'settle_median_s': med('settle_s'), 'settle_max_s': med('settle_s', np.max),
            'effort_median_Nms': med('effort_Nms'), 'peak_h_max_Nms': med('peak_h_Nms', np.max),
            'saturated_median_s': med('saturated_s'),
            'flown_median_pct': None if not runs else 100.0 * med('flown_s') / duration_s,
            'lost': sum(r['lost'] for r in runs), 'reason': None}


def collect(out: str, name: str, sc: Dict[str, Any], n_runs: int,
            duration_s: float) -> Tuple[Dict[str, Any], List[Dict[str, Any]]]:
    """``(row, per-run metrics)`` of the campaign of controller ``name`` in ``out``."""
    done = [(d, load_result(d)) for d in (run_dir_of(out, i) for i in range(n_runs))]
    runs = [run_metrics(d, r, name, sc) for d, r in done if r is not None]
    errors = sum(r is None and os.path.isfile(os.path.join(d, FAILED_FILE)) for d, r in done)
    return summarise(name, runs, n_runs, errors, duration_s), runs


def _f(v: Any, spec: str = '.3g') -> str:
    return 'n/a' if v is None else format(v, spec)


def table_markdown(rows: Sequence[Dict[str, Any]]) -> str:
    """The comparison table: one line per controller, a refused one with its reason."""
    head = ['controller', 'runs done', 'pointing error median / p95 [deg]', 'settled',
            'settling time median / max [s]', 'control effort median [N m s]',
            'peak wheel momentum max [N m s]', 'saturation time median [s]',
            'forwarded median [% of run]', 'failures']
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for r in rows:
        if r['reason'] is not None:
            lines.append(f'| {r["controller"]} | cannot fly this scenario: {r["reason"]} |'
                         + ' |' * (len(head) - 2))
            continue
        fails = [f'{r["errors"]} error(s)'] * bool(r['errors']) + \
            [f'{r["lost"]} lost the command'] * bool(r['lost'])
        lines.append('| ' + ' | '.join([
            r['controller'], f'{r["done"]}/{r["runs"]}',
            f'{_f(r["pointing_median_deg"])} / {_f(r["pointing_p95_deg"])}',
            f'{r["settled"]}/{r["done"]}',
            f'{_f(r["settle_median_s"], ".0f")} / {_f(r["settle_max_s"], ".0f")}',
            _f(r['effort_median_Nms']), _f(r['peak_h_max_Nms']),
            _f(r['saturated_median_s'], '.0f'), _f(r['flown_median_pct'], '.0f'),
            ', '.join(fails) or '0']) + ' |')
    return '\n'.join(lines) + '\n'


def plot(path: str, series: Dict[str, List[Tuple[np.ndarray, np.ndarray]]]) -> None:
    """``compare.png`` of ``{name: [(t_s, angle_deg)] of its runs}``: per controller the
    median angle to the target over time and the 5-95 % band (the report's colours)."""
    from matplotlib.figure import Figure
    from adcs_nodes.tools.analyse.bag_series import time_axis
    from adcs_nodes.tools.analyse.report_html import colours_for
    fig = Figure(figsize=(10.0, 4.5))
    ax = fig.add_subplot()
    colours = colours_for(list(series))
    t_end = max((t[-1] for runs in series.values() for t, _ in runs), default=1.0)
    axis = time_axis(t_end)
    for name, runs in series.items():
        lo, mid, hi = np.nanpercentile([a for _, a in runs], [5, 50, 95], axis=0)
        t = axis(runs[0][0])
        ax.fill_between(t, lo, hi, color=colours[name], alpha=0.2, lw=0)
        ax.plot(t, mid, color=colours[name], lw=1.2, label=f'{name} (median of {len(runs)})')
    ax.set(yscale='log', xlabel=axis.label, ylabel='angle to the target [deg]')
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=90, bbox_inches='tight')


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``adcs compare`` arguments to ``parser``."""
    from adcs_nodes.tools.campaigns.cli import add_campaign_arguments
    add_campaign_arguments(parser, 'compare', runs=10)
    parser.add_argument('--controllers', required=True, metavar='A,B,...',
                        help='registered controllers, comma-separated (e.g. magnetic,mpi,fuzzy'
                        '); each holds the pointing phase in turn on the same draws')


def prepare(args: argparse.Namespace, log: Any) -> Tuple[Dict, Any, str, List[Dict]]:
    """Check everything before a run: ``(base, cfg, out, entries)``, per controller ``name``,
    ``how`` it flies or why not (``scenario`` None), ``scenario``, ``label``, ``cfg``, ``out``
    (:func:`~.sweep.run_campaigns`); CampaignError or ScenarioError (exit 2)."""
    from adcs_nodes.tools.campaigns.cli import campaign_config, plain_config
    names = parse_controllers(args.controllers)
    cfg, base, out = plain_config(args, 'compare')
    entries = []
    for name in names:
        sc, how = flying(base, name)
        if sc is None:
            log(f'[compare] {name} cannot fly {base["name"]}: {how}')
        entries.append({'name': name, 'how': how, 'scenario': sc,
                        'label': f'controller {name} ({how})',
                        'out': os.path.join(out, 'controllers', name),
                        'cfg': sc and campaign_config(args, base, sc, cfg.duration_s, 'plain')})
    if not any(e['scenario'] for e in entries):
        raise CampaignError(f'no controller of {args.controllers} can fly {base["name"]}')
    return base, cfg, out, entries


def run_from_args(args: argparse.Namespace, log: Any = None) -> int:
    """``adcs compare``: run or resume each controller's campaign, write and print the table;
    exit code (0, 1 a run failed, 2 bad arguments or nothing can fly, 130 interrupted)."""
    from adcs_nodes.scenario import ScenarioError
    from adcs_nodes.tools.campaigns.sweep import run_campaigns
    log = log or (lambda text: print(text, flush=True))
    try:
        base, cfg, out, entries = prepare(args, log)
    except (CampaignError, ScenarioError) as exc:
        print(f'adcs compare: {exc}', file=sys.stderr)
        return 2
    flown = [e for e in entries if e['scenario'] is not None]
    log(f'[compare] {len(flown)} controller(s) x {cfg.runs} runs of {base["name"]} '
        f'({cfg.duration_s:g} s each, seed {cfg.seed}, engine plain), output in {out}')
    code = run_campaigns(flown, args, log, 'compare')
    if code == 2:
        return 2
    rows, series = [], {}
    for e in entries:
        if e['scenario'] is None:
            rows.append({'controller': e['name'], 'reason': e['how']})
            continue
        row, runs = collect(e['out'], e['name'], e['scenario'], cfg.runs, cfg.duration_s)
        rows.append({**row, 'how': e['how']})
        series[e['name']] = [(r['t_s'], r['angle_deg']) for r in runs]
    text = (f'{base["name"]}, {cfg.runs} runs per controller, seed {cfg.seed}, '
            f'{cfg.duration_s:g} s:\n\n' + table_markdown(rows) + '\n' + ''.join(
                f'* {r["controller"]}: {r["how"]}\n' for r in rows if r.get('how')))
    write_text_atomic(os.path.join(out, 'compare.md'), text)
    write_json_atomic(os.path.join(out, 'compare.json'), {
        'scenario': base['_path'], 'seed': cfg.seed, 'duration_s': cfg.duration_s,
        'runs': cfg.runs, 'rows': rows})
    if any(series.values()):
        plot(os.path.join(out, 'compare.png'), {k: v for k, v in series.items() if v})
    log('\n[compare] ' + text)
    log(f'[compare] table in {os.path.join(out, "compare.md")}, figure compare.png')
    return code
