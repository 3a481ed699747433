"""``adcs sweep``: a Monte Carlo campaign per grid point, plain engine (``docs/montecarlo.md``)."""
from __future__ import annotations

import argparse
import csv
import hashlib
import io
import itertools
import json
import math
import os
import re
import sys
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from adcs_nodes.tools.analyse import metrics
from adcs_nodes.tools.campaigns.cli import add_campaign_arguments, campaign_config
from adcs_nodes.tools.campaigns.config import CampaignError
from adcs_nodes.tools.campaigns.files import (SERIES_FILE, load_result, run_dir_of,
                                              write_json_atomic, write_text_atomic)
from adcs_nodes.tools.campaigns.summary import orbit_period_s
from adcs_nodes.tools.analyse.papers.paper000 import CONVERGED_DEG

#: Columns of ``sweep.csv`` after the swept keys.
COLUMNS = ('runs', 'done', 'captured', 'in_4_orbits', 'in_4_orbits_pct', 'capture_median_orbits',
           'capture_p90_orbits', 'hold_median_of_medians_deg', 'hold_p90_of_medians_deg',
           'converged_half_orbit', 'converged_half_orbit_pct', 'converge_p90_orbits',
           'converged_5deg_half_orbit', 'converged_5deg_half_orbit_pct',
           'est_err_median_deg', 'run_wall_median_s', 'out')


class SweepError(CampaignError):
    """A bad grid (key, value) or sweep argument: exit 2."""


# ---------------------------------------------------------------------- the grid
def split_values(text: str) -> List[str]:
    """Split ``V1,V2,...`` at the commas outside brackets and quotes; SweepError."""
    parts, depth, quote, cur = [], 0, '', ''
    for ch in text:
        if quote:
            cur += ch
            if ch == quote:
                quote = ''
        elif ch in '\'"':
            quote = ch
            cur += ch
        elif ch in '[{':
            depth += 1
            cur += ch
        elif ch in ']}':
            depth -= 1
            if depth < 0:
                raise SweepError(f'unbalanced brackets in {text!r}')
            cur += ch
        elif ch == ',' and depth == 0:
            parts.append(cur)
            cur = ''
        else:
            cur += ch
    if quote or depth:
        raise SweepError(f'unbalanced {"quotes" if quote else "brackets"} in {text!r}')
    parts.append(cur)
    if any(not p.strip() for p in parts):
        raise SweepError(f'an empty value in {text!r} (values are separated by commas)')
    return [p.strip() for p in parts]


def parse_grid(items: Sequence[str]) -> List[Tuple[str, List[Any]]]:
    """``--set KEY=V1,V2`` items to ``[(key, [values])]`` (YAML values)."""
    from adcs_nodes.scenario import parse_overrides
    if not items:
        raise SweepError('give at least one --set KEY=V1,V2,... (the grid)')
    grid: List[Tuple[str, List[Any]]] = []
    for item in items:
        key, sep, text = str(item).partition('=')
        if not sep:
            parse_overrides([item])          # its message: expected KEY=VALUE
        key = key.strip()
        if any(key == k for k, _ in grid):
            raise SweepError(f'--set {key} is given twice: give its values in one --set '
                             f'{key}=V1,V2,...')
        values = [parse_overrides([f'{key}={v}'])[key] for v in split_values(text)]
        dups = [v for i, v in enumerate(values) if v in values[:i]]
        if dups:
            raise SweepError(f'--set {key}: the value {dups[0]!r} is given twice')
        grid.append((key, values))
    return grid


def grid_points(grid: Sequence[Tuple[str, Sequence[Any]]]) -> List[Dict[str, Any]]:
    """Cartesian product of the grid, the last key fastest: ``[{key: value}]``."""
    keys = [k for k, _ in grid]
    return [dict(zip(keys, combo)) for combo in itertools.product(*(v for _, v in grid))]


def swept_keys(grid: Sequence[Tuple[str, Sequence[Any]]]) -> List[str]:
    """The keys with more than one value."""
    return [k for k, v in grid if len(v) > 1]


def point_name(point: Dict[str, Any]) -> str:
    """Directory name of a grid point: its overrides made file-safe, plus their short hash."""
    text = '__'.join(f'{k.rsplit(".", 1)[-1]}={_value_text(v)}' for k, v in point.items())
    safe = re.sub(r'[^A-Za-z0-9._=+-]+', '_', text)[:120]
    digest = hashlib.sha256(json.dumps(point, sort_keys=True).encode()).hexdigest()[:8]
    return f'{safe}-{digest}'


def _value_text(v: Any) -> str:
    return json.dumps(v) if isinstance(v, (list, dict)) else str(v)


# ---------------------------------------------------------------------- metrics of a point
def run_convergence(run_dir: str, period_s: Optional[float]) -> Dict[str, Any]:
    """Filter convergence of a finished plain run [s; None: never]: below ``CONVERGED_DEG``
    for good in the first orbit (paper 000), and below 5 deg for good over the run."""
    path = os.path.join(run_dir, SERIES_FILE)
    none = {'converged_s': None, 'converged_5deg_s': None, 'has_estimate': False}
    if not os.path.isfile(path):
        return none
    with np.load(path) as data:
        t, err = data['t_s'] - data['t_s'][0], data['est_err_deg']
    if not np.isfinite(err).any():
        return none
    first = t <= period_s if period_s else np.ones(t.size, bool)
    return {'converged_s': metrics.last_exit_time(t[first], err[first], CONVERGED_DEG),
            'converged_5deg_s': metrics.last_exit_time(t, err, metrics.CAPTURE_BAND_DEG),
            'has_estimate': True}


def point_metrics(results: Sequence[Dict[str, Any]], runs: int,
                  period_s: Optional[float]) -> Dict[str, Any]:
    """The row of one grid point (:data:`COLUMNS` but ``out``) from its finished runs."""
    done = [r for r in results if r.get('status') in ('captured', 'not_captured')]
    cap = [r for r in done if r['status'] == 'captured']
    in_time = sum(1 for r in done if r.get('captured_in_time'))
    period = period_s or math.nan
    cap_orbits = np.array([r['capture_time_s'] / period for r in cap])
    med = np.array([r['hold_median_deg'] for r in done
                    if isinstance(r.get('hold_median_deg'), (int, float))])
    est = [r for r in done if r.get('has_estimate')]
    half = 0.5 * period

    def within(key: str) -> int:
        return sum(1 for r in est if r.get(key) is not None and r[key] <= half)

    conv, conv5 = within('converged_s'), within('converged_5deg_s')
    conv_orbits = np.array([math.inf if r.get('converged_s') is None
                            else r['converged_s'] / period for r in est])
    err = np.array([r['est_err_median_deg'] for r in est
                    if isinstance(r.get('est_err_median_deg'), (int, float))])
    wall = np.array([r['wall_time_s'] for r in done
                     if isinstance(r.get('wall_time_s'), (int, float))])

    def q(a: np.ndarray, p: float) -> Optional[float]:
        # 'higher' (a sample, never an interpolation): an inf (never converged) stays inf
        return float(np.percentile(a, p, method='higher' if np.isinf(a).any() else 'linear')) \
            if a.size else None

    return {
        'runs': runs, 'done': len(done), 'captured': len(cap), 'in_4_orbits': in_time,
        'in_4_orbits_pct': 100.0 * in_time / len(done) if done else None,
        'capture_median_orbits': q(cap_orbits, 50), 'capture_p90_orbits': q(cap_orbits, 90),
        'hold_median_of_medians_deg': q(med, 50), 'hold_p90_of_medians_deg': q(med, 90),
        'converged_half_orbit': conv if est else None,
        'converged_half_orbit_pct': 100.0 * conv / len(est) if est else None,
        'converge_p90_orbits': q(conv_orbits, 90) if est else None,
        'converged_5deg_half_orbit': conv5 if est else None,
        'converged_5deg_half_orbit_pct': 100.0 * conv5 / len(est) if est else None,
        'est_err_median_deg': q(err, 50), 'run_wall_median_s': q(wall, 50)}


def collect_point(out: str, runs: int, period_s: Optional[float]) -> Dict[str, Any]:
    """:func:`point_metrics` of the campaign in ``out`` (its finished runs on disk)."""
    results = []
    for i in range(runs):
        run_dir = run_dir_of(out, i)
        res = load_result(run_dir)
        if res is not None:
            results.append({**res, **run_convergence(run_dir, period_s)})
    return {**point_metrics(results, runs, period_s), 'out': out}


# ---------------------------------------------------------------------- the table
def _fmt(v: Any, digits: int = 2) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return 'never' if isinstance(v, float) and math.isinf(v) else 'n/a'
    return f'{v:.{digits}f}' if isinstance(v, float) else str(v)


def table_markdown(rows: Sequence[Dict[str, Any]], keys: Sequence[str]) -> str:
    """The sweep table: one line per point, the swept keys first."""
    head = list(keys) + ['done', 'captured <= 4 orbits', 'capture median / p90 [orbits]',
                         'hold median of medians / p90 [deg]',
                         'filter converged <= T/2 (2 deg, 1st orbit)', 'converged p90 [orbits]',
                         'filter converged <= T/2 (5 deg, run)', 'est. error median [deg]',
                         'run wall median [s]']
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for r in rows:
        done = r['done']
        cells = [_value_text(r['point'][k]) for k in keys] + [
            f'{done}/{r["runs"]}',
            f'{r["in_4_orbits"]}/{done} ({_fmt(r["in_4_orbits_pct"], 0)} %)' if done else 'n/a',
            f'{_fmt(r["capture_median_orbits"])} / {_fmt(r["capture_p90_orbits"])}',
            f'{_fmt(r["hold_median_of_medians_deg"])} / {_fmt(r["hold_p90_of_medians_deg"])}',
            ('n/a' if r['converged_half_orbit'] is None else
             f'{r["converged_half_orbit"]}/{done} ({_fmt(r["converged_half_orbit_pct"], 0)} %)'),
            _fmt(r['converge_p90_orbits']),
            ('n/a' if r['converged_5deg_half_orbit'] is None else
             f'{r["converged_5deg_half_orbit"]}/{done} '
             f'({_fmt(r["converged_5deg_half_orbit_pct"], 0)} %)'),
            _fmt(r['est_err_median_deg']),
            _fmt(r['run_wall_median_s'], 1)]
        lines.append('| ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines) + '\n'


def map_markdown(rows: Sequence[Dict[str, Any]], keys: Sequence[str]) -> str:
    """Captured within 4 orbits over two swept keys (first down, second across); '' else."""
    if len(keys) != 2:
        return ''
    k1, k2 = keys
    v1 = list(dict.fromkeys(_value_text(r['point'][k1]) for r in rows))
    v2 = list(dict.fromkeys(_value_text(r['point'][k2]) for r in rows))
    cell = {(_value_text(r['point'][k1]), _value_text(r['point'][k2])):
            f'{r["in_4_orbits"]}/{r["done"]}' for r in rows}
    lines = [f'| {k1} \\ {k2} | ' + ' | '.join(v2) + ' |', '|---|' + '---|' * len(v2)]
    for a in v1:
        lines.append(f'| {a} | ' + ' | '.join(cell.get((a, b), '') for b in v2) + ' |')
    return '\n'.join(lines) + '\n'


def write_csv(path: str, rows: Sequence[Dict[str, Any]], keys: Sequence[str]) -> None:
    """``sweep.csv`` (atomically): the point's values of every grid key, then :data:`COLUMNS`."""
    text = io.StringIO()
    w = csv.writer(text)
    w.writerow(list(keys) + list(COLUMNS))
    w.writerows([_value_text(r['point'][k]) for k in keys]
                + ['' if r[c] is None else (repr(r[c]) if isinstance(r[c], float) else r[c])
                   for c in COLUMNS] for r in rows)
    write_text_atomic(path, text.getvalue())


def plot_map(path: str, rows: Sequence[Dict[str, Any]], keys: Sequence[str]) -> bool:
    """``sweep.png`` over one or two swept keys (else False, nothing written)."""
    if len(keys) not in (1, 2) or not rows:
        return False
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    pct = [np.nan if r['in_4_orbits_pct'] is None else r['in_4_orbits_pct'] for r in rows]
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    if len(keys) == 1:
        labels = [_value_text(r['point'][keys[0]]) for r in rows]
        ax.bar(range(len(rows)), pct, color='tab:blue')
        ax.set_xticks(range(len(rows)), labels)
        ax.set_xlabel(keys[0])
        ax.set_ylabel('captured within 4 orbits [%]')
        ax.set_ylim(0, 105)
    else:
        v1 = list(dict.fromkeys(_value_text(r['point'][keys[0]]) for r in rows))
        v2 = list(dict.fromkeys(_value_text(r['point'][keys[1]]) for r in rows))
        grid = np.full((len(v1), len(v2)), np.nan)
        for r, p in zip(rows, pct):
            grid[v1.index(_value_text(r['point'][keys[0]])),
                 v2.index(_value_text(r['point'][keys[1]]))] = p
        im = ax.imshow(grid, vmin=0, vmax=100, cmap='viridis', aspect='auto')
        for i in range(len(v1)):
            for j in range(len(v2)):
                if np.isfinite(grid[i, j]):
                    ax.text(j, i, f'{grid[i, j]:.0f}', ha='center', va='center',
                            color='w' if grid[i, j] < 60 else 'k')
        ax.set_xticks(range(len(v2)), v2)
        ax.set_yticks(range(len(v1)), v1)
        ax.set_xlabel(keys[1])
        ax.set_ylabel(keys[0])
        fig.colorbar(im, ax=ax, label='captured within 4 orbits [%]')
    ax.set_title(f'captured within 4 orbits, {max(r["done"] for r in rows)} runs per point')
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return True


# ---------------------------------------------------------------------- command
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``adcs sweep`` arguments to ``parser``."""
    add_campaign_arguments(parser, 'sweep')   # the same as adcs montecarlo's
    parser.add_argument('--set', action='append', default=[], metavar='KEY=V1,V2,...',
                        help='a dotted scenario key and its values (YAML, separated by commas '
                        'outside brackets), e.g. --set controllers.magnetic.alpha_per_s='
                        '1.5e-3,2e-3; repeatable: the grid is the product; one value: fixed')
    parser.add_argument('--table', action='store_true',
                        help='run nothing: the table of the finished runs in OUT as they are '
                        '(no identity check: after a code or scenario change, these are the '
                        'runs of the earlier version)')


Prepared = Tuple[Dict[str, Any], List[Tuple[str, List[Any]]], List[Dict[str, Any]], str]


def prepare(args: argparse.Namespace) -> Prepared:
    """Validate everything first: ``(base scenario, grid, points, out)``."""
    from adcs_nodes.tools.campaigns.cli import plain_config
    from adcs_nodes.scenario import apply_overrides
    grid = parse_grid(args.set)
    base, out = plain_config(args, 'sweep')[1:]
    points = []
    for point in grid_points(grid):
        sc = apply_overrides(base, point)   # its message names the point's overrides
        cfg = campaign_config(args, base, sc, float(
            args.duration if args.duration is not None else sc['duration_s']), 'plain')
        frames = cfg.duration_s / sc['timing']['frame_s']
        if abs(frames - round(frames)) > 1e-9:
            raise SweepError(f'grid point {_point_text(point)}: the duration '
                             f'{cfg.duration_s:g} s is not a whole number of '
                             f'{sc["timing"]["frame_s"]:g} s frames')
        points.append({'point': point, 'scenario': sc, 'cfg': cfg,
                       'out': os.path.join(out, 'points', point_name(point))})
    return base, grid, points, out


def _point_text(point: Dict[str, Any]) -> str:
    return ', '.join(f'{k}={_value_text(v)}' for k, v in point.items())


def run_from_args(args: argparse.Namespace, log=None) -> int:
    """``adcs sweep``: run or resume every grid point, print the table; the exit code."""
    from adcs_nodes.scenario import ScenarioError
    log = log or (lambda text: print(text, flush=True))
    try:
        base, grid, points, out = prepare(args)
    except (CampaignError, ScenarioError) as exc:
        print(f'adcs sweep: {exc}', file=sys.stderr)
        return 2
    keys = swept_keys(grid) or [grid[0][0]]
    period = orbit_period_s(base)
    table_only = bool(getattr(args, 'table', False))
    os.makedirs(out, exist_ok=True)
    if not table_only:
        _write_sweep_json(out, base, grid, points, args)
    cfg0 = points[0]['cfg']
    log(f'[sweep] {len(points)} grid point(s) x {args.runs} runs of {base["name"]} '
        f'({cfg0.duration_s:g} s each, seed {cfg0.seed}, engine plain), output in {out}'
        + (' (--table: nothing runs)' if table_only else ''))
    code = 0 if table_only else run_campaigns(
        [{**p, 'label': 'point ' + _point_text(p['point'])} for p in points], args, log)
    if code == 2:
        return 2
    rows = [{'point': p['point'], **collect_point(p['out'], args.runs, period)}
            for p in points]
    text = write_outputs(out, rows, keys, [k for k, _ in grid])
    log(f'\n[sweep] {base["name"]}, {args.runs} runs per point, seed {cfg0.seed}:')
    log(text)
    log(f'[sweep] table in {os.path.join(out, "sweep.md")} and sweep.csv')
    return code


def run_campaigns(points: Sequence[Dict[str, Any]], args: argparse.Namespace, log: Any,
                  command: str = 'sweep') -> int:
    """Run or resume the campaign of each point in turn (``label``, ``cfg``, ``scenario``,
    ``out``; ``args.jobs``, ``scheduler``, ``dask_local``): the exit code (0, 1 a run failed,
    2 a refused campaign, 130 interrupted: the later points do not start)."""
    from adcs_nodes.tools.campaigns.campaign import Campaign
    code, t0 = 0, time.monotonic()
    for n, p in enumerate(points, 1):
        log(f'[{command}] {p["label"]} ({n}/{len(points)}, {command} '
            f'{time.monotonic() - t0:.0f} s)')
        try:
            c = Campaign(p['cfg'], p['scenario'], p['out'], log=log).run(
                jobs=args.jobs, scheduler=args.scheduler,
                dask_local=bool(getattr(args, 'dask_local', False)))
        except CampaignError as exc:
            print(f'adcs {command}: {p["label"]}: {exc}', file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            c = 130
        if c == 130:
            log(f'[{command}] interrupted: finished runs are kept; run the same command again '
                'to resume')
            return 130
        code = max(code, c)
    return code


def _write_sweep_json(out: str, base: Dict[str, Any], grid: Any,
                      points: Sequence[Dict[str, Any]], args: argparse.Namespace) -> None:
    """``sweep.json``: the grid and the campaign arguments of this invocation."""
    cfg = points[0]['cfg']
    write_json_atomic(os.path.join(out, 'sweep.json'), {
        'scenario': base['_path'], 'grid': grid, 'runs': args.runs, 'seed': cfg.seed,
        'duration_s': cfg.duration_s, 'max_rate_deg_s': cfg.max_rate_deg_s,
        'capture_deg': args.capture_deg, 'mag_bias_nT': args.mag_bias_nT,
        'misalignment_deg': args.misalignment_deg, 'points': [p['out'] for p in points],
        'command': _command(args),
        'updated_utc': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())})


def write_outputs(out: str, rows: Sequence[Dict[str, Any]], keys: Sequence[str],
                  all_keys: Sequence[str]) -> str:
    """``sweep.csv``, ``sweep.md`` and ``sweep.png`` of the rows; the text of ``sweep.md``."""
    write_csv(os.path.join(out, 'sweep.csv'), rows, all_keys)
    text = table_markdown(rows, keys)
    gain_map = map_markdown(rows, keys)
    if gain_map:
        text += '\nCaptured within 4 orbits:\n\n' + gain_map
    write_text_atomic(os.path.join(out, 'sweep.md'), text)
    plot_map(os.path.join(out, 'sweep.png'), rows, keys)
    return text


def _command(args: argparse.Namespace) -> str:
    parts = ['adcs', 'sweep', args.scenario]
    for item in args.set:
        parts += ['--set', item]
    parts += ['--runs', str(args.runs), '--jobs', str(args.jobs)]
    for name in ('seed', 'duration', 'mag_bias_nT', 'misalignment_deg'):
        if getattr(args, name, None) is not None:
            parts += [f'--{name.replace("_", "-")}', str(getattr(args, name))]
    if args.max_rate_deg_s is not None:
        parts += ['--max-rate-deg-s', str(args.max_rate_deg_s)]
    if args.capture_deg != 5.0:
        parts += ['--capture-deg', str(args.capture_deg)]
    return ' '.join(parts)
