"""``adcs replay``'s arguments and entry point."""
from __future__ import annotations

import argparse
import sys
from adcs_nodes.tools.replay.common import LockstepStall, ReplayError

DESCRIPTION = (
    'Publish the recorded inputs of a bag so flight software runs without sim_node.\n\n'
    'Driver-like (default): the sensor topics, best-effort, with their stamps at the wall\n'
    'time they come due (--rate), /clock beside them (or --now: wall-clock stamps), for\n'
    'nodes in live mode.\n\n'
    'Lockstep (--lockstep): for nodes started alone in timing_mode lockstep with the\n'
    'recorded parameters (--write-params FILE writes them), every input they awaited in\n'
    'the run (/clock, /tf_static, sensors, the previous-frame actuator command), frame by\n'
    'frame, paced by their lockstep/progress: they publish the recorded outputs again,\n'
    'bit for bit.\n\n'
    'A bag is data: the plugins its run used are never imported from it; give them with\n'
    '--plugin (docs/security.md).')
EPILOG = (
    'lockstep example:\n'
    '  adcs run scenarios/paper000_control.yaml --record out/ctl --duration 300\n'
    '  adcs replay out/ctl --lockstep --write-params out/ctl/estimator.yaml\n'
    '  python -m adcs_nodes.nodes.estimator --ros-args -r __node:=estimator \\\n'
    '      --params-file out/ctl/estimator.yaml &\n'
    '  adcs replay out/ctl --lockstep\n'
    'exit codes: 0 done, 1 lockstep node not ready or stalled, 2 bad input, 130 interrupted')


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Arguments (and help text) of ``adcs replay``."""
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.description, p.epilog = DESCRIPTION, EPILOG
    p.add_argument('bag', help='rosbag2 bag directory (or .mcap file) recorded by adcs run')
    p.add_argument('--topics', nargs='+', metavar='TOPIC',
                   help='topics to replay (default: every /sensors/* topic of the bag; with '
                   '--lockstep: the inputs the nodes awaited in the run)')
    p.add_argument('--rate', type=float, default=1.0, metavar='F',
                   help='sim seconds per wall second (default 1)')
    p.add_argument('--time-offset', type=float, default=0.0, metavar='S',
                   help='add S seconds to every stamp and to /clock (default 0)')
    p.add_argument('--now', action='store_true',
                   help='stamp with the wall clock (first sample = now), no /clock; --rate 1')
    p.add_argument('--no-clock', action='store_true', help='do not publish /clock')
    p.add_argument('--wait', type=float, default=None, metavar='S',
                   help='wait up to S seconds for a subscriber on every topic first, then 1 s '
                   'more for the subscribers to match (default 0; with --lockstep: for the '
                   'nodes to be ready, default 60)')
    p.add_argument('--start', type=float, default=0.0, metavar='S',
                   help='skip the first S seconds of the recording')
    p.add_argument('--duration', type=float, metavar='S', help='replay only S seconds')
    g = p.add_argument_group('lockstep replay')
    g.add_argument('--lockstep', action='store_true',
                   help='replay frame by frame to nodes in timing_mode lockstep (see above)')
    g.add_argument('--nodes', nargs='+', default=['estimator'], metavar='NAME',
                   help='the graph nodes fed and followed (default: estimator)')
    g.add_argument('--write-params', metavar='FILE',
                   help="write the nodes' parameters for a lockstep run alone and exit")
    g.add_argument('--stall-timeout', type=float, default=30.0, metavar='S',
                   help='give up (exit 1) when a node made no progress for S s (default 30)')
    g.add_argument('--plugin', action='append', default=[], metavar='MODULE_OR_PY',
                   help='a plugin the recorded run used (the bag names them; they are never '
                   'imported from it): give each you trust; repeatable')


def _lockstep_options(args: argparse.Namespace) -> None:
    """Driver-like options make no sense frame by frame: refuse them."""
    bad = [opt for opt, on in (('--rate', args.rate != 1.0),
                               ('--time-offset', args.time_offset != 0.0),
                               ('--now', args.now), ('--no-clock', args.no_clock),
                               ('--start', args.start != 0.0),
                               ('--duration', args.duration is not None)) if on]
    if bad:
        raise ReplayError(f'--lockstep replays every recorded frame with its recorded stamps: '
                          f'{", ".join(bad)} cannot be used with it')


def run_from_args(args: argparse.Namespace) -> int:
    """``adcs replay`` entry point: exit code."""
    from adcs_nodes.tools.replay.live import replay
    from adcs_nodes.tools.replay.lockstep import replay_lockstep, write_params
    plugins = getattr(args, 'plugin', None) or []
    try:
        if getattr(args, 'write_params', None):
            write_params(args.bag, args.nodes, args.write_params, plugins=plugins)
        elif getattr(args, 'lockstep', False):
            _lockstep_options(args)
            replay_lockstep(args.bag, args.nodes, args.topics,
                            wait_s=60.0 if args.wait is None else args.wait,
                            stall_s=args.stall_timeout, plugins=plugins)
        else:
            replay(args.bag, args.topics, rate=args.rate, time_offset_s=args.time_offset,
                   now=args.now, clock=False if args.no_clock else None,
                   wait_s=args.wait or 0.0, start_s=args.start, duration_s=args.duration)
    except ReplayError as exc:
        print(f'adcs replay: {exc}', file=sys.stderr)
        return 2
    except LockstepStall as exc:
        print(f'adcs replay: {exc}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print('adcs replay: interrupted', file=sys.stderr)
        return 130
    return 0
