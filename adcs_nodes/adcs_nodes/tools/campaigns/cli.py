"""``adcs montecarlo`` arguments and entry points."""
from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Any, Dict, List, Optional

from adcs_nodes.tools.campaigns.campaign import Campaign
from adcs_nodes.tools.campaigns.capture import capture_reference
from adcs_nodes.tools.campaigns.config import (ENGINES, CampaignConfig, CampaignError,
                                               Dispersion, apply_dispersion,
                                               default_max_rate_deg_s, plain_engine_problem,
                                               resolve_engine, scenario_hash)
from adcs_nodes.tools.campaigns.runner import serve

#: The most runs of one campaign (one directory each under ``runs/``) and runs at once.
MAX_RUNS = 100_000
MAX_JOBS = 256
#: Printed by a multi-run campaign on the graph engine when the plain engine could run it.
GRAPH_HINT = ('[montecarlo] engine graph: every run is the whole ROS graph, recorded to a bag '
              '(paper000_control, 6 orbits: 60-185 s CPU per run, by machine load). '
              '--engine plain (the auto choice for this scenario) runs the same components '
              'without ROS, gives the same series to the last bit and a few s CPU per run, '
              'without bags.')


def add_campaign_arguments(parser: argparse.ArgumentParser, what: str = 'campaign',
                           runs: Optional[int] = None) -> None:
    """The arguments ``adcs montecarlo``, ``sweep`` and ``compare`` (``what``) share; ``runs``:
    the default (None: required)."""
    parser.add_argument('scenario', help='base scenario YAML (closed loop, e.g. '
                        'scenarios/paper000_control.yaml)')
    parser.add_argument('--runs', type=int, required=runs is None, default=runs, metavar='N',
                        help='number of runs' + {'sweep': ' per grid point', 'compare':
                                                 f' per controller (default {runs})'}.get(
                                                     what, '') + f' (at most {MAX_RUNS})')
    parser.add_argument('--jobs', type=int, default=1, metavar='J',
                        help='runs at once on this machine: J worker processes, started '
                        'once and fed runs (default 1; with --dask-local: the number of Dask '
                        'workers; ignored '
                        f'with --scheduler; at most {MAX_JOBS})')
    where = parser.add_mutually_exclusive_group()
    where.add_argument('--scheduler', metavar='ADDRESS',
                       help='submit the runs to this Dask distributed scheduler '
                       '(e.g. tcp://host:8786); --out must be on a shared file system')
    where.add_argument('--dask-local', action='store_true',
                       help='start a Dask LocalCluster of --jobs worker processes (one thread '
                       'each) on this machine' + (' per grid point' if what == 'sweep' else '')
                       + ' and stop it at the end')
    parser.add_argument('--out', metavar='DIR', help=f'{what} directory (default '
                        f'{"montecarlo" if what == "campaign" else what}_<scenario name>); '
                        f'a {what} there is resumed')
    add_dispersion_arguments(parser)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``adcs montecarlo`` arguments to ``parser``."""
    add_campaign_arguments(parser)
    parser.add_argument('--auto-detumble', action='store_true',
                        help='B-dot detumble first (below 0.5 deg/s), then the magnetic law '
                        '(writes manager.auto into each run)')
    parser.add_argument('--bdot-gain', type=float, default=None, metavar='K',
                        help='B-dot gain of the detumble [A m^2 s/T] (default: the '
                        'scenario\'s)')
    parser.add_argument('--engine', choices=ENGINES + ('auto',), default='auto',
                        help='auto (default): plain unless a sensor is external, else graph; '
                        'a campaign being resumed keeps the engine in its campaign.json. '
                        'graph: the ROS graph, one bag per run; plain: the FrameLoop without '
                        'ROS (sim_node.engine: the graph\'s series to the last bit, no bag, '
                        'far less CPU)')
    parser.add_argument('--compose', action='store_true',
                        help='each run composed in one process (faster, same trajectory)')


def add_dispersion_arguments(parser: argparse.ArgumentParser) -> None:
    """The run length, seed, capture threshold and dispersion options of a campaign."""
    parser.add_argument('--duration', type=float, metavar='S',
                        help='simulated seconds per run (default: the scenario duration_s)')
    parser.add_argument('--seed', type=int, metavar='S',
                        help='campaign seed (default: the scenario seed)')
    parser.add_argument('--max-rate-deg-s', type=float, default=None, metavar='W',
                        help='each initial rate component uniform in +-W deg/s (default: the '
                        'scenario paper\'s: 3 for paper 000, 0.3 for paper 001, else 3)')
    parser.add_argument('--capture-deg', type=float, default=5.0, metavar='A',
                        help='captured when the angle between the body and the guidance '
                        'target (the orbit frame without a guidance profile, as paper 000) '
                        'enters A deg and then stays below 2 A to the end (default 5)')
    parser.add_argument('--mag-bias-nT', type=float, default=None, metavar='B',
                        help='disperse the magnetometer bias per axis uniform in +-B nT '
                        '(default: the scenario\'s bias)')
    parser.add_argument('--misalignment-deg', type=float, default=None, metavar='M',
                        help='disperse the magnetometer misalignment rotation vector per '
                        'component uniform in +-M deg (default: the scenario\'s)')


def max_rate_deg_s(args: argparse.Namespace, base: Dict[str, Any]) -> float:
    """``--max-rate-deg-s``, else the scenario's default [deg/s]."""
    value = getattr(args, 'max_rate_deg_s', None)
    return float(value) if value is not None else default_max_rate_deg_s(base)


def config_from_args(args: argparse.Namespace) -> tuple:
    """Validate the arguments: ``(CampaignConfig, base scenario, out dir)``."""
    from adcs_nodes.scenario import load_scenario

    base = load_scenario(args.scenario)
    if not 1 <= args.runs <= MAX_RUNS:
        raise CampaignError(f'--runs must be in [1, {MAX_RUNS}], got {args.runs}')
    if not 1 <= args.jobs <= MAX_JOBS:
        raise CampaignError(f'--jobs must be in [1, {MAX_JOBS}], got {args.jobs}')
    for name in ('max_rate_deg_s', 'mag_bias_nT', 'misalignment_deg', 'bdot_gain'):
        value = getattr(args, name, None)
        if value is None:
            continue
        if not (math.isfinite(value) and value >= 0.0):
            raise CampaignError(f'--{name.replace("_", "-")} must be >= 0, got {value}')
    if not (math.isfinite(args.capture_deg) and 0.0 < args.capture_deg <= 180.0):
        raise CampaignError(f'--capture-deg must be in (0, 180], got {args.capture_deg}')
    duration = float(args.duration if args.duration is not None else base['duration_s'])
    frames = duration / base['timing']['frame_s']
    if not duration > 0 or abs(frames - round(frames)) > 1e-9:
        raise CampaignError(f'--duration {duration:g} s is not a positive whole number of '
                            f'{base["timing"]["frame_s"]:g} s frames')
    out = args.out or f'montecarlo_{base["name"]}'
    engine, args.engine_reason = resolve_engine(getattr(args, 'engine', None), base, out)
    cfg = campaign_config(args, base, base, duration, engine)
    if cfg.auto_detumble and not {'magnetic', 'bdot'} <= set(base.get('controllers', {})):
        raise CampaignError('--auto-detumble needs the controllers magnetic and bdot in the '
                            'scenario')
    check_dispersion(cfg, base)
    return cfg, base, out


def plain_config(args: argparse.Namespace, command: str) -> tuple:
    """:func:`config_from_args`'s checks for ``adcs sweep`` and ``compare`` (the plain engine,
    no detumble): ``(cfg, base, out)``, ``out`` absolute (default ``<command>_<name>``)."""
    cfg, base, _ = config_from_args(argparse.Namespace(**{
        **vars(args), 'engine': 'plain', 'compose': False, 'auto_detumble': False,
        'bdot_gain': None}))
    problem = plain_engine_problem(base)
    if problem is not None:
        raise CampaignError(f'adcs {command} runs on the plain engine only: {problem}')
    return cfg, base, os.path.abspath(args.out or f'{command}_{base["name"]}')


def campaign_config(args: argparse.Namespace, base: Dict[str, Any], sc: Dict[str, Any],
                    duration: float, engine: str) -> CampaignConfig:
    """The campaign of the arguments on scenario ``sc`` (``base``, or a sweep's point)."""
    return CampaignConfig(
        scenario_path=base['_path'], scenario_sha256=scenario_hash(sc), runs=args.runs,
        seed=int(args.seed if args.seed is not None else base['seed']), duration_s=duration,
        max_rate_deg_s=max_rate_deg_s(args, base), capture_deg=args.capture_deg,
        mag_bias_nT=args.mag_bias_nT, misalignment_deg=args.misalignment_deg,
        auto_detumble=bool(getattr(args, 'auto_detumble', False)),
        bdot_gain=getattr(args, 'bdot_gain', None), engine=engine,
        compose=bool(getattr(args, 'compose', False)), capture_reference=capture_reference(sc))


def check_dispersion(cfg: CampaignConfig, base: Dict[str, Any]) -> None:
    """The widest run ``cfg`` can draw validated up front (CampaignError)."""
    from adcs_nodes.scenario import ScenarioError, apply_overrides
    w, b, m = cfg.max_rate_deg_s, cfg.mag_bias_nT, cfg.misalignment_deg
    worst = Dispersion(0, 0, [0.0, 0.0, 0.0, 1.0], [w] * 3,
                       None if b is None else [b * 1e-9] * 3, None if m is None else [m] * 3)
    try:
        apply_overrides({**apply_dispersion(base, worst, cfg.duration_s, cfg),
                         '_path': base['_path']}, {})
    except ScenarioError as exc:
        bounds = ', '.join(f'--{k} {v:g}' for k, v in (
            ('max-rate-deg-s', w), ('mag-bias-nT', b), ('misalignment-deg', m)) if v is not None)
        raise CampaignError(f'the dispersion bounds ({bounds}) give runs the scenario refuses: '
                            f'{str(exc).split(": ", 1)[-1]}') from None


def run_from_args(args: argparse.Namespace) -> int:
    """``adcs montecarlo``: run or resume a campaign; returns the exit code."""
    from adcs_nodes.scenario import ScenarioError

    try:
        cfg, base, out = config_from_args(args)
        campaign = Campaign(cfg, base, out, log=lambda text: print(text, flush=True))
        dask_local = bool(getattr(args, 'dask_local', False))
        if args.scheduler:
            mode = f'on the Dask scheduler {args.scheduler}'
        elif dask_local:
            mode = f'on a Dask LocalCluster of {args.jobs} worker process(es), 1 thread each'
        else:
            mode = f'{args.jobs} at a time'
        print(f'[montecarlo] {cfg.runs} runs of {base["name"]} ({cfg.duration_s:g} s each, '
              f'seed {cfg.seed}, engine {cfg.engine} [{args.engine_reason}]) {mode}, output in '
              f'{campaign.out}', flush=True)
        print(f'[montecarlo] initial rate components uniform in +-{cfg.max_rate_deg_s:g} deg/s; '
              f'captured: the angle to the {cfg.capture_reference} enters '
              f'{cfg.capture_deg:g} deg and stays below {2 * cfg.capture_deg:g} deg',
              flush=True)
        if cfg.engine == 'graph' and cfg.runs > 1 and plain_engine_problem(base) is None:
            print(GRAPH_HINT, flush=True)
        return campaign.run(jobs=args.jobs, scheduler=args.scheduler, dask_local=dask_local)
    except (CampaignError, ScenarioError) as exc:
        print(f'adcs montecarlo: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('adcs montecarlo: interrupted (finished runs are kept)', file=sys.stderr)
        return 130


def main(argv: Optional[List[str]] = None) -> int:
    """The campaign command, or (``_worker STOP_FILE``) a worker process."""
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ['_worker'] and len(argv) == 2:
        return serve(argv[1])
    parser = argparse.ArgumentParser(prog='adcs montecarlo',
                                     description='Dispersed Monte Carlo campaign.')
    add_arguments(parser)
    return run_from_args(parser.parse_args(argv))
