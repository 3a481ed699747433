"""Studies on the FrameLoop (the plain engine): a scenario with ``--set`` overrides, run without
ROS, judged by the same paper tables as ``adcs report``.

``python -m adcs_nodes.tools.analyse.study COMMAND ...`` (each takes ``--set KEY=VALUE``,
``--duration S``, ``--ideal``: the controllers get the true state, ``--out FILE.json``): ``run``
(one run's paper table and metrics), ``sweep SCENARIO KEY VALUE...`` (the measured columns
side by side), ``wings`` and ``hold-horizon`` (paper 001: one wing vs two, the MPI hold
horizon), ``table1`` (paper 003's Table 1 readings and the reference slew, ``--figures``:
Figs. 6-9), ``sensitivity`` (paper 000's hold accuracy,
:mod:`adcs_nodes.tools.analyse.paper000_sensitivity`). Exit 2 for a bad scenario or override."""
from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any, Dict, List, Optional, Sequence, Tuple

from adcs_nodes.tools.analyse import papers
from adcs_nodes.tools.analyse.papers.series import Topics, run_topics, scenario_dict  # noqa: F401

#: Topics of the generic run summary (angle to the orbit frame, estimation error).
SUMMARY_TOPICS = ('sim/state', 'adcs/attitude_estimate')


def run_rows(sc: Dict[str, Any], duration_s: Optional[float] = None, overrides: Any = None,
             ideal: bool = False) -> Tuple[Dict[str, Any], List[papers.Row], Dict[str, Any]]:
    """One FrameLoop run: ``(effective scenario, paper rows, :func:`summary`)``."""
    from adcs_nodes.scenario import apply_overrides
    if overrides:
        sc = apply_overrides(sc, overrides)
    wanted = tuple(dict.fromkeys(papers.topics_for(sc.get('name')) + SUMMARY_TOPICS))
    topics = run_topics(sc, wanted, duration_s, ideal=ideal)
    return sc, papers.rows_for(sc, topics), summary(topics, sc)


def summary(topics: Topics, sc: Dict[str, Any]) -> Dict[str, Any]:
    """Run metrics of the angle to the orbit frame and the estimation error (JSON-ready)."""
    import math

    import numpy as np

    from adcs_nodes.tools.analyse import metrics
    from adcs_nodes.tools.analyse.papers.paper000 import estimate_errors
    from adcs_nodes.tools.analyse.papers.series import epoch_ns, quat, sorted_items
    truth = sorted_items(topics.get('sim/state', {}))
    if not truth:
        return {}
    e0 = epoch_ns(sc)
    t = np.array([(k - e0) / 1e9 for k, _ in truth])
    angle = metrics.angle_to_identity_deg([quat(m.q_orbit_body) for _, m in truth])
    from adcs_nodes.tools.analyse.papers.series import orbit_period_s
    period = orbit_period_s(sc)
    out = metrics.run_metrics(t, angle, period)
    est = estimate_errors(topics, sc)
    if est['t_s'].size:
        hs = metrics.hold_stats(est['t_s'], est['att_deg'], 0.5 * (period or 0.0))
        out['est_err_median_deg'] = hs.median if hs.samples else None
    out['duration_s'] = float(t[-1] - t[0])
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in out.items()}


# ---------------------------------------------------------------------- text
def rows_text(title: str, rows: Sequence[papers.Row]) -> str:
    """The paper table as ``adcs report`` prints it, under a title."""
    if not rows:
        return f'{title}\n_No paper comparison for this scenario._\n'
    return '\n'.join([title, ''] + papers.table_lines(rows)) + '\n'


def sweep_text(key: str, results: Sequence[Tuple[Any, List[papers.Row]]]) -> str:
    """One line per paper quantity, the measured value and verdict of each run side by side."""
    if not results or not results[0][1]:
        return '_No paper comparison for this scenario._\n'
    head = ['quantity', 'paper'] + [f'{key}={v}' for v, _ in results]
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for i, (name, paper, _, _) in enumerate(results[0][1]):
        cells = [name, paper]
        for _, rows in results:
            _, _, measured, ok = rows[i]
            verdict = papers.verdict_text(ok)
            verdict = 'not comparable' if verdict.startswith('not comparable') else verdict
            cells.append(f'{measured} ({verdict})')
        lines.append('| ' + ' | '.join(str(c).replace('|', '\\|') for c in cells) + ' |')
    return '\n'.join(lines) + '\n'


# ---------------------------------------------------------------------- commands
def _default(name: str) -> str:
    """``scenarios/<name>.yaml`` of the repository, else of the installed share directory."""
    here = os.path.normpath(os.path.join(os.path.dirname(os.path.realpath(__file__)), '..',
                                         '..', '..', '..', 'scenarios', f'{name}.yaml'))
    if os.path.isfile(here):
        return here
    from adcs_nodes.tools.run.launch_graph import installed_scenario_dir
    return os.path.join(installed_scenario_dir() or 'scenarios', f'{name}.yaml')


def _load(path: str, sets: Sequence[str]) -> Dict[str, Any]:
    from adcs_nodes.scenario import apply_overrides, load_scenario
    sc = load_scenario(path)
    return apply_overrides(sc, list(sets)) if sets else sc


def cmd_run(args) -> int:
    sc = _load(args.scenario, args.set)
    sc, rows, summ = run_rows(sc, args.duration, ideal=args.ideal)
    title = f'{sc["name"]} on the FrameLoop' + (' (ideal estimate)' if args.ideal else '') + \
        (f', --set {" ".join(args.set)}' if args.set else '')
    print(rows_text(title, rows))
    print(json.dumps(summ, indent=1, default=float))
    _write(args.out, {'scenario': sc['name'], 'set': args.set, 'summary': summ,
                      'rows': _json_rows(rows)})
    return 0


def sweep(sc: Dict[str, Any], key: str, values: Sequence[Any], duration_s=None,
          ideal: bool = False, log=print) -> List[Tuple[Any, List[papers.Row], Dict]]:
    """One FrameLoop run per value of ``key`` (validated first): ``[(value, rows, summary)]``."""
    from adcs_nodes.scenario import apply_overrides
    edited = [apply_overrides(sc, {key: value}) for value in values]
    out = []
    for value, one in zip(values, edited):
        log(f'[study] {key} = {value} ...')
        _, rows, summ = run_rows(one, duration_s, ideal=ideal)
        out.append((value, rows, summ))
    return out


def cmd_sweep(args, key: Optional[str] = None, values: Optional[List[Any]] = None) -> int:
    from adcs_nodes.scenario import parse_overrides
    key = key or args.key
    if values is None:
        values = [parse_overrides([f'{key}={v}'])[key] for v in args.values]
    sc = _load(args.scenario, args.set)
    res = sweep(sc, key, values, args.duration, args.ideal,
                log=lambda s: print(s, file=sys.stderr, flush=True))
    print(f'{sc["name"]} on the FrameLoop, {key} swept' +
          (f', --set {" ".join(args.set)}' if args.set else '') + '\n')
    print(sweep_text(key, [(v, rows) for v, rows, _ in res]))
    _write(args.out, {'scenario': sc['name'], 'key': key, 'set': args.set,
                      'runs': [{'value': v, 'summary': s, 'rows': _json_rows(r)}
                               for v, r, s in res]})
    return 0


def cmd_table1(args) -> int:
    from adcs_nodes.tools.analyse.papers import paper003
    sc = _load(args.scenario, args.set)
    runs, series = table1(sc, args.duration, args.ideal,
                          log=lambda s: print(s, file=sys.stderr, flush=True))
    print(paper003.format_runs(runs))
    if args.figures:
        for path in paper003.figures(series, args.figures):
            print(f'figure: {path}')
    _write(args.out, {'scenario': sc['name'], 'runs': runs})
    return 0


def table1(sc: Dict[str, Any], duration_s: Optional[float] = None, ideal: bool = False,
           log=print) -> Tuple[Dict[str, Dict[str, float]], Dict[str, Dict[str, Any]]]:
    """Paper 003's ``cases`` on the FrameLoop: ``({name: metrics}, {name: series})``."""
    from adcs_nodes.tools.analyse.papers import paper003
    runs, series = {}, {}
    for name, overrides in paper003.cases().items():
        log(f'[study] {name} ...')
        topics = run_topics(sc, paper003.TOPICS, duration_s, overrides, ideal)
        r = paper003.series(topics, sc)
        series[name] = r
        runs[name] = paper003.metrics(r['t'], r['phi'], r['torque'])
    return runs, series


def cmd_sensitivity(args) -> int:
    from adcs_nodes.tools.analyse import paper000_sensitivity as sens
    sc = _load(args.scenario, args.set)
    res = sens.sensitivity(sc, args.duration, log=lambda s: print(s, flush=True))
    print(sens.sensitivity_markdown(res))
    _write(args.out, res)
    return 0


def _json_rows(rows: Sequence[papers.Row]) -> List[Dict[str, Any]]:
    return [{'quantity': q, 'paper': p, 'measured': str(m), 'verdict': papers.verdict_text(ok)}
            for q, p, m, ok in rows]


def _write(path: Optional[str], data: Any) -> None:
    if path:
        with open(path, 'w', encoding='utf-8') as fh:
            json.dump(data, fh, indent=1, default=float)
            fh.write('\n')


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog='python -m adcs_nodes.tools.analyse.study',
                                 description=__doc__.split('\n\n')[0],
                                 epilog=__doc__.split('\n\n', 1)[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument('--set', action='append', default=[], metavar='KEY=VALUE',
                        help='change one scenario key (dotted, YAML value; null removes it); '
                        'repeatable')
    common.add_argument('--duration', type=float, metavar='S',
                        help='simulated seconds (default: the scenario duration_s)')
    common.add_argument('--ideal', action='store_true',
                        help='the controllers get the true state as the estimate')
    common.add_argument('--out', metavar='FILE.json', help='also write the results as JSON')
    sub = ap.add_subparsers(dest='command', required=True)
    p = sub.add_parser('run', parents=[common], help='one run and its paper table')
    p.add_argument('scenario')
    p.set_defaults(func=cmd_run)
    p = sub.add_parser('sweep', parents=[common], help='one run per value of a key')
    p.add_argument('scenario')
    p.add_argument('key', help='dotted scenario key, e.g. controllers.mpi.hold_horizon_s')
    p.add_argument('values', nargs='+', help='YAML values, e.g. 0 0.4 1')
    p.set_defaults(func=cmd_sweep)
    p = sub.add_parser('wings', parents=[common], help='paper 001: one wing vs two')
    p.add_argument('scenario', nargs='?', default=_default('paper001_mpi'))
    p.set_defaults(func=lambda a: cmd_sweep(a, 'spacecraft.flexible.wings', ['one', 'two']))
    p = sub.add_parser('hold-horizon', parents=[common], help='paper 001: MPI hold horizon')
    p.add_argument('scenario', nargs='?', default=_default('paper001_mpi_two_wings'))
    p.add_argument('--values', type=float, nargs='+', default=[0.0, 0.4, 1.0, 2.0],
                   metavar='S', help='horizons [s] (default 0 0.4 1 2; 0: one control period)')
    p.set_defaults(func=lambda a: cmd_sweep(a, 'controllers.mpi.hold_horizon_s', a.values))
    p = sub.add_parser('table1', parents=[common], help='paper 003: Table 1 readings and '
                       'the reference slew')
    p.add_argument('scenario', nargs='?', default=_default('paper003_slew'))
    p.add_argument('--figures', metavar='DIR', help='write the paper-like Figs. 6-9 here')
    p.set_defaults(func=cmd_table1)
    p = sub.add_parser('sensitivity', parents=[common], help='paper 000: hold accuracy vs '
                       'random-torque correlation and misalignment')
    p.add_argument('scenario', nargs='?', default=_default('paper000_control'))
    p.set_defaults(func=cmd_sensitivity)
    return ap


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Command line (see the module docstring); exit 2 for a bad scenario or override."""
    from adcs_nodes.scenario import ScenarioError
    args = build_parser().parse_args(argv)
    try:
        from adcs_nodes.core.kernels import limit_blas_threads
        from sim_node.engine import EngineError
        limit_blas_threads()
        return args.func(args)
    except (ScenarioError, EngineError) as exc:
        print(f'study: {exc}', file=sys.stderr)
        return 2


if __name__ == '__main__':
    raise SystemExit(main())
