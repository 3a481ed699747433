"""``adcs compare``: controllers side by side on one scenario and the same Monte Carlo draws.

One campaign per controller (the plain engine, local or Dask, resumable: :mod:`.sweep`'s
:func:`~.sweep.run_campaigns`) in ``OUT/controllers/<name>``, all with the same seed, so run
*i* starts from the same attitude, rate and noise seeds for every controller; then one table
(``compare.md``, ``compare.json``) and one figure (``compare.png``). How a controller is made
the one that flies, the metrics and their windows: ``docs/montecarlo.md``, "Controllers
compared".
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from adcs_nodes.tools.campaigns.capture import ORBIT_FRAME
from adcs_nodes.tools.campaigns.config import CampaignError
from adcs_nodes.tools.campaigns.files import (FAILED_FILE, SERIES_FILE, load_result,
                                              run_dir_of, write_json_atomic, write_text_atomic)
from adcs_nodes.tools.campaigns.results import angle_to_target_deg

#: An actuator sample at or above this fraction of its limit counts as saturated (ASSUMPTION).
SATURATED = 0.999


def parse_controllers(text: str) -> List[str]:
    """``--controllers a,b,c``: registered names, each once; CampaignError otherwise."""
    from adcs_nodes import registry
    names = [n.strip() for n in str(text).split(',')]
    if not all(names):
        raise CampaignError(f'--controllers {text!r}: an empty name (give a comma-separated '
                            'list, e.g. magnetic,mpi,fuzzy)')
    for i, name in enumerate(names):
        if name in names[:i]:
            raise CampaignError(f'--controllers: {name!r} is given twice')
        try:
            registry.get('controller', name)
        except ValueError as exc:
            raise CampaignError(f'--controllers: {exc}') from None
    return names


def flying(base: Dict[str, Any], name: str) -> Tuple[Optional[Dict[str, Any]], str]:
    """``(scenario, how)``: ``base`` with controller ``name`` holding the pointing phase, or
    ``(None, why it cannot fly this scenario)``."""
    from adcs_nodes.scenario import (ScenarioError, apply_overrides, controller_names,
                                     controller_problems, default_safe)
    if 'controllers' not in base:
        return None, 'the scenario has no controllers section (open loop)'
    problems = controller_problems(base, name)     # (one said twice: 'needs X' in 'A: needs X')
    if problems:
        return None, '; '.join(p for p in problems if not any(
            q != p and q.endswith(p) for q in problems))
    man, how, sets = base.get('manager'), [], {}
    if name not in base['controllers']:
        sets[f'controllers.{name}'] = {}
        how.append('registry defaults (not in the scenario)')
    if man is None:
        sets['manager.safe'] = default_safe(controller_names(base))
    phase = 'initial' if not (man or {}).get('auto') else (
        'auto.point' if man['auto'].get('point') else 'auto.acquire')
    sets[f'manager.{phase}'] = name
    how.insert(0, f'manager.{phase}')
    if (man or {}).get('schedule'):
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
    with np.load(os.path.join(run_dir, SERIES_FILE)) as s:
        s = dict(s)
    t = s['t_s']
    dt = np.append(np.diff(t), 0.0)                 # each sample holds to the next
    angle = s['angle_deg'] if result.get('capture_reference') == ORBIT_FRAME else \
        angle_to_target_deg(s['q_orbit_body'], s['q_orbit_target'])
    window = s['target_judged'] & (t >= t[0] + 0.5 * (t[-1] - t[0]))
    craft = sc['spacecraft']
    wheels = craft.get('wheels') or []
    m_max = np.array(craft.get('magnetorquer', {}).get('max_dipole_Am2') or [np.inf] * 3)
    tau_w, h_w, dipole = s['wheel_torque_Nm'], s['wheel_momentum_Nms'], s['dipole_body_Am2']
    effort = np.sum(np.abs(tau_w), axis=1) + np.sum(np.abs(np.cross(dipole, s['b_body_T'])),
                                                     axis=1)
    sat = np.any(np.abs(dipole) >= SATURATED * m_max, axis=1)
    if wheels:
        sat |= np.any(np.abs(tau_w) >= SATURATED * np.array(
            [w['max_torque_Nm'] for w in wheels]), axis=1)
        sat |= np.any(np.abs(h_w) >= SATURATED * np.array(
            [w['max_momentum_Nms'] for w in wheels]), axis=1)
    mine = s['active'] == name
    first = int(np.argmax(mine)) if mine.any() else t.size
    return {'t_s': t, 'angle_deg': angle, 'pointing_deg': angle[window], 'settle_s': result.get('capture_time_s'),
            'effort_Nms': float(np.sum(effort * dt)),
            'peak_h_Nms': float(np.max(np.abs(h_w))) if wheels else None,
            'saturated_s': float(np.sum(dt[sat])), 'flown_s': float(np.sum(dt[mine])),
            'lost': bool(np.any(~mine[first:]))}


def summarise(name: str, runs: Sequence[Dict[str, Any]], n_runs: int, errors: int,
              duration_s: float) -> Dict[str, Any]:
    """The table row of one controller from its runs' :func:`run_metrics` (pure)."""
    def med(key: str, f=np.median) -> Optional[float]:
        v = [r[key] for r in runs if r[key] is not None]
        return float(f(v)) if v else None
    pooled = np.concatenate([r['pointing_deg'] for r in runs]) if runs else np.zeros(0)
    pooled = pooled[np.isfinite(pooled)]
    settled = [r for r in runs if r['settle_s'] is not None]
    return {'controller': name, 'runs': n_runs, 'done': len(runs), 'errors': errors,
            'pointing_median_deg': float(np.median(pooled)) if pooled.size else None,
            'pointing_p95_deg': float(np.percentile(pooled, 95)) if pooled.size else None,
            'settled': len(settled), 'settle_median_s': med('settle_s'),
            'settle_max_s': med('settle_s', np.max), 'effort_median_Nms': med('effort_Nms'),
            'peak_h_max_Nms': med('peak_h_Nms', np.max),
            'saturated_median_s': med('saturated_s'),
            'flown_median_pct': None if not runs else 100.0 * med('flown_s') / duration_s,
            'lost': sum(r['lost'] for r in runs), 'reason': None}


def collect(out: str, name: str, sc: Dict[str, Any], n_runs: int,
            duration_s: float) -> Tuple[Dict[str, Any], List[Dict[str, Any]]]:
    """``(row, per-run metrics)`` of the campaign of controller ``name`` in ``out``."""
    runs, errors = [], 0
    for i in range(n_runs):
        run_dir = run_dir_of(out, i)
        result = load_result(run_dir)
        if result is not None:
            runs.append(run_metrics(run_dir, result, name, sc))
        else:
            errors += os.path.isfile(os.path.join(run_dir, FAILED_FILE))
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
    """``compare.png``: the angle to the target over time, per controller the median over
    its runs and the 5-95 % band (the report's colours); ``series``: ``{name: [(t_s,
    angle_deg)]}`` of its finished runs."""
    from matplotlib.figure import Figure
    from adcs_nodes.tools.analyse.report_html import _colours, _time_axis
    fig = Figure(figsize=(10.0, 4.5))
    ax = fig.add_subplot()
    colours = _colours(list(series))
    t_end = max((t[-1] for runs in series.values() for t, _ in runs), default=1.0)
    axis = _time_axis(t_end)
    for name, runs in series.items():
        n = min(t.size for t, _ in runs)
        t, a = runs[0][0][:n] / axis.scale, np.array([a[:n] for _, a in runs])
        lo, mid, hi = np.nanpercentile(a, [5, 50, 95], axis=0)
        ax.fill_between(t, lo, hi, color=colours[name], alpha=0.2, lw=0)
        ax.plot(t, mid, color=colours[name], lw=1.2, label=f'{name} (median of {len(runs)})')
    ax.set_yscale('log')
    ax.set_xlabel(f'sim time [{axis.unit}]')
    ax.set_ylabel('angle to the target [deg]', fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=90, bbox_inches='tight')


# ---------------------------------------------------------------------- command
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``adcs compare`` arguments to ``parser``."""
    from adcs_nodes.tools.campaigns.cli import add_campaign_arguments
    add_campaign_arguments(parser, 'compare', runs=10)
    parser.add_argument('--controllers', required=True, metavar='A,B,...',
                        help='registered controllers, comma-separated (e.g. magnetic,mpi,fuzzy'
                        '); each holds the pointing phase in turn on the same draws')


def prepare(args: argparse.Namespace, log: Any) -> Tuple[Dict[str, Any], str, List[Dict], Dict]:
    """Validate everything before a run: ``(base, out, points, refused)``, a point per
    controller that can fly (:func:`~.sweep.run_campaigns`), ``refused`` ``{name: why}``;
    CampaignError or ScenarioError (exit 2)."""
    from adcs_nodes.scenario import load_scenario
    from adcs_nodes.tools.campaigns.cli import campaign_config, config_from_args
    from adcs_nodes.tools.campaigns.engine import plain_engine_problem
    names = parse_controllers(args.controllers)
    base = load_scenario(args.scenario)
    problem = plain_engine_problem(base)
    if problem is not None:
        raise CampaignError(f'adcs compare runs on the plain engine only: {problem}')
    out = os.path.abspath(args.out or f'compare_{base["name"]}')
    cfg = config_from_args(argparse.Namespace(**{
        **vars(args), 'out': os.path.join(out, '.check'), 'engine': 'plain',
        'compose': False, 'auto_detumble': False, 'bdot_gain': None}))[0]
    points, refused = [], {}
    for name in names:
        sc, how = flying(base, name)
        if sc is None:
            refused[name] = how
            log(f'[compare] {name} cannot fly {base["name"]}: {how}')
            continue
        points.append({'name': name, 'label': f'controller {name} ({how})', 'how': how,
                       'scenario': sc, 'out': os.path.join(out, 'controllers', name),
                       'cfg': campaign_config(args, base, sc, cfg.duration_s, 'plain')})
    return base, out, points, refused


def run_from_args(args: argparse.Namespace, log: Any = None) -> int:
    """``adcs compare``: run or resume each controller's campaign, then write and print the
    table; exit code (0 done, 1 a run failed, 2 bad arguments or no controller can fly, 130
    interrupted)."""
    from adcs_nodes.scenario import ScenarioError
    from adcs_nodes.tools.campaigns.sweep import run_campaigns
    log = log or (lambda text: print(text, flush=True))
    try:
        base, out, points, refused = prepare(args, log)
    except (CampaignError, ScenarioError) as exc:
        print(f'adcs compare: {exc}', file=sys.stderr)
        return 2
    if not points:
        print(f'adcs compare: no controller of {args.controllers} can fly {base["name"]}',
              file=sys.stderr)
        return 2
    cfg = points[0]['cfg']
    log(f'[compare] {len(points)} controller(s) x {cfg.runs} runs of {base["name"]} '
        f'({cfg.duration_s:g} s each, seed {cfg.seed}, engine plain), output in {out}')
    code = run_campaigns(points, args, log, 'compare')
    if code == 2:
        return 2
    rows, series = [], {}
    for name in parse_controllers(args.controllers):
        p = next((p for p in points if p['name'] == name), None)
        if p is None:
            rows.append({'controller': name, 'reason': refused[name]})
            continue
        row, runs = collect(p['out'], name, p['scenario'], cfg.runs, cfg.duration_s)
        rows.append({**row, 'how': p['how']})
        series[name] = [(r['t_s'], r['angle_deg']) for r in runs]
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
