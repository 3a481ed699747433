"""``adcs``: the command-line launcher of the ADCS node graph (every command and option: the
README, "Commands"; ``adcs COMMAND --help``).

Exit codes: 0 success, 1 run failure (a world node or the recorder died, recorder lagged),
2 bad input (scenario, arguments, bag, a node refusing its parameters), 3 degraded run (it
ended, but lost a flight-software node or fell back to the safe controller for part of the
time: the summary line says which), 130 interrupted.
"""
from __future__ import annotations

import argparse
import faulthandler
import math
import os
import signal
import sys
from typing import List, Optional

from adcs_nodes import registry
from adcs_nodes.scenario import ScenarioError, list_scenarios, load_scenario

#: Nodes that are not registry components: (package, executable, role).
CORE_NODES = [
    ('sim_node', 'environment', 'orbit + geomagnetic field (sim/environment)'),
    ('sim_node', 'dynamics', 'rigid-body dynamics, actuators, clock master (/clock, sim/state)'),
    ('adcs_nodes', 'estimator', 'attitude estimator, parameter algorithm:=<estimator> '
     '(adcs/attitude_estimate)'),
    ('adcs_nodes', 'controller', 'any registered controller, parameter controller:=<name> '
     '(adcs/controllers/<name>/command)'),
    ('adcs_nodes', 'guidance', 'attitude target profile (adcs/attitude_target)'),
    ('adcs_nodes', 'controller_manager', 'forwards the active controller, switching and '
     'fallback (adcs/actuator_command)'),
    ('adcs_nodes', 'recorder', 'rosbag2 MCAP recorder of every topic'),
]


def registry_lines() -> List[str]:
    """``adcs list``'s registry part: every controller, estimator and sensor, one line each."""
    out = []
    for kind in registry.KINDS:
        out.append(f'{kind.capitalize()}s (registry):')
        for name, e in registry.entries(kind).items():
            extra = ''
            if e.inputs:
                extra += f' [inputs: {", ".join(e.inputs)}'
                extra += f'; commands: {", ".join(e.actuators)}]' if e.actuators else ']'
            if e.node:
                extra += f' [ros2 run {e.node[0]} {e.node[1].rsplit(".", 1)[1]} -> {e.node[3]}]'
            out.append(f'  {name:20s} {e.description}{extra}')
    return out


def _default_scenario_dir() -> str:
    here = os.path.dirname(os.path.abspath(__file__))
    for cand in (os.path.join(os.getcwd(), 'scenarios'),
                 os.path.normpath(os.path.join(here, '..', '..', '..', 'scenarios'))):
        if os.path.isdir(cand):
            return cand
    return os.path.join(os.getcwd(), 'scenarios')


#: ``adcs run --real-time``: a run that kept less than this share of the asked pace says so.
REAL_TIME_KEPT = 0.9


def cmd_run(args) -> int:
    from adcs_nodes.tools.run.launcher import LaunchError, Launcher, pace
    from adcs_nodes.tools.run.launch_graph import with_duration
    engine = args.engine or ('composed' if args.compose else 'graph')
    try:
        sc = load_scenario(args.scenario)
        if args.set:
            from adcs_nodes.scenario import apply_overrides
            sc = apply_overrides(sc, args.set)
        sc = with_duration(sc, args.duration)     # a fault after the end: refused up front
        if args.compose and engine != 'composed':
            raise LaunchError(f'--compose means --engine composed, not {engine}')
        rate_factor, max_rate = pace(args.rate, args.real_time)
        if engine == 'plain':
            if args.real_time or args.rate is not None:
                raise LaunchError('the plain engine has no real-time mode and no pace (it runs '
                                  'as fast as it can): use --engine graph or composed')
            from sim_node.engine import EngineError
            from adcs_nodes.tools.run.plain import run_plain
            try:
                result = run_plain(sc, None, args.record, progress=not args.quiet)
            except EngineError as exc:
                raise LaunchError(str(exc)) from None
        else:
            launcher = Launcher(sc, record=args.record,
                                real_time=args.real_time,
                                rate_factor=rate_factor, max_rate=max_rate,
                                compose=engine == 'composed', progress=not args.quiet,
                                domain=args.domain)
    except (ScenarioError, LaunchError, ValueError) as exc:
        print(f'adcs run: {exc}', file=sys.stderr)
        return 2
    if engine != 'plain':
        result = launcher.run()
    rtf = result.sim_time_s / result.wall_time_s if result.wall_time_s else 0.0
    stream = sys.stdout if result.exit_code == 0 else sys.stderr
    print(f'[adcs] {result.message}', file=stream)
    print(f'[adcs] {result.sim_time_s:g} s sim in {result.wall_time_s:.1f} s wall '
          f'({rtf:.1f}x real time), missed frames {result.missed_frames}')
    rate = args.rate or 1.0
    # the pace from frame 0 (the wall time above also counts the start-up)
    kept = result.frames_per_s * float(sc['timing']['frame_s'])
    if args.real_time and kept and kept < REAL_TIME_KEPT * rate:
        print(f'[adcs] WARNING: real time at rate {rate:g} asked for {rate:g}x; this run kept '
              f'{kept:.2f}x on this machine: the world ran late, and samples that came after '
              'their frame were rejected (counted above)'
              + ('; all nodes in one process (--engine composed) keep a faster pace'
                 if engine == 'graph' else ''), file=sys.stderr)
    if result.bag and os.path.exists(result.bag):      # (only a bag that was written)
        print(f'[adcs] bag: {result.bag}')
    if result.exit_code in (0, 3) and args.report and result.bag:   # degraded: a whole bag
        return cmd_report(argparse.Namespace(bag=result.bag, out=None)) or result.exit_code
    return result.exit_code


def cmd_list(args) -> int:
    directory = args.dir or _default_scenario_dir()
    if not os.path.isdir(directory):
        print(f'adcs list: no scenario directory {directory}', file=sys.stderr)
        return 2
    print(f'Scenarios in {directory}:')
    for fname, desc in list_scenarios(directory):
        print(f'  {fname:32s} {desc}')
    print('Nodes (ros2 run <package> <executable>):')
    for pkg, exe, role in CORE_NODES:
        print(f'  {pkg + " " + exe:32s} {role}')
    print('\n'.join(registry_lines()))
    return 0


def cmd_validate(args) -> int:
    try:
        sc = load_scenario(args.scenario)
    except ScenarioError as exc:
        print(f'adcs validate: {exc}', file=sys.stderr)
        return 2
    print(f'{args.scenario}: OK ({sc["name"]}, {sc["duration_s"]:g} s, '
          f'frame {sc["timing"]["frame_s"]:g} s)')
    return 0


def _live(command: str, action) -> int:
    """Run ``action()`` on a running graph: print its text, or the LiveError (exit 2)."""
    from adcs_nodes.tools.run.live import LiveError, finish
    try:
        text = action()
    except LiveError as exc:
        print(f'adcs {command}: {exc}', file=sys.stderr)
        return finish(2)
    if isinstance(text, int):       # (status --watch: its exit code)
        return finish(text)
    print(text)
    return finish(0)


def cmd_switch(args) -> int:
    from adcs_nodes.tools.run.live import switch
    return _live('switch', lambda: switch(args.controller, args.run))


def cmd_slew(args) -> int:
    from adcs_nodes.tools.run.slew import slew
    if not all(math.isfinite(v) for v in args.to):
        print(f'adcs slew: --to needs three finite angles [deg], got {args.to}',
              file=sys.stderr)
        return 2
    return _live('slew', lambda: slew(*args.to, frame=args.frame, controller=args.controller,
                                      tolerance_deg=args.tolerance_deg,
                                      timeout_s=args.timeout_s, pid=args.run))


def cmd_status(args) -> int:
    from adcs_nodes.tools.run.live import status, watch
    return _live('status', lambda: watch(args.run, count=args.count) if args.watch
                 else status(args.run))


def cmd_fault(args) -> int:
    from adcs_nodes.tools.run.live import fault, parse_params
    return _live('fault', lambda: fault(args.kind, args.target, args.at,
                                        parse_params(args.param), args.run))


def cmd_schema(args) -> int:
    from adcs_nodes.scenario import schema_markdown
    print(schema_markdown(), end='')
    return 0


def bag_checked(bag: str, command: str) -> bool:
    """The bag's stored scenario is usable as data (else one line, False); plugins noted."""
    from adcs_nodes.tools.bagfile import BagError, bag_scenario, plugin_note
    try:
        note = plugin_note(bag, bag_scenario(bag))
    except BagError as exc:
        print(f'adcs {command}: {exc}', file=sys.stderr)
        return False
    if note:
        print(f'adcs {command}: note: {note}', file=sys.stderr)
    return True


def cmd_export(args) -> int:
    from adcs_nodes.tools.analyse.export import export_csv
    if not bag_checked(args.bag, 'export'):
        return 2
    try:
        files = export_csv(args.bag, args.csv, getattr(args, 'topic', None))
    except (FileNotFoundError, ValueError) as exc:
        print(f'adcs export: {exc}', file=sys.stderr)
        return 2
    for f in files:
        print(f)
    return 0


def cmd_report(args) -> int:
    from adcs_nodes.tools.analyse.report import make_report
    from adcs_nodes.tools.analyse.reproductions import expectations_for
    out = args.out or os.path.normpath(args.bag.rstrip('/')) + '_report'
    if not bag_checked(args.bag, 'report'):
        return 2
    try:
        _, rows = expectations_for(args.bag)
        make_report(args.bag, out, expectations=rows)
    except (FileNotFoundError, ValueError) as exc:
        print(f'adcs report: {exc}', file=sys.stderr)
        return 2
    summary = os.path.join(out, 'summary.md')
    if os.path.isfile(summary):
        with open(summary, encoding='utf-8') as fh:
            print(fh.read())
    from adcs_nodes.tools.analyse.report_html import write_report_html
    try:     # the page for people, beside it (its paper table from metrics.json)
        page = write_report_html(args.bag, out)
    except (FileNotFoundError, ValueError) as exc:
        print(f'adcs report: report.html: {exc}', file=sys.stderr)
        return 2
    print(f'[adcs] report written to {out} (open {page} in a browser)')
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog='adcs', description='Run, record and analyse the satellite ADCS node graph.',
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='Exit' + __doc__.split('Exit', 1)[1].rstrip('\n"'))
    sub = ap.add_subparsers(dest='command', required=True)
    # shared argument groups
    run_pid = argparse.ArgumentParser(add_help=False)
    run_pid.add_argument('--run', type=int, metavar='PID', help='launcher PID when several runs')
    a_bag = argparse.ArgumentParser(add_help=False)
    a_bag.add_argument('bag', help='rosbag2 bag directory (or .mcap file) recorded by adcs run')

    p = sub.add_parser('run', help='run a scenario')
    p.add_argument('scenario', help='scenario YAML file (see `adcs list`)')
    p.add_argument('--record', metavar='BAG', help='record every topic to this rosbag2 MCAP '
                   'bag directory (must not exist)')
    p.add_argument('--duration', type=float, metavar='S',
                   help='simulated seconds (default: the scenario duration_s)')
    p.add_argument('--real-time', action='store_true',
                   help='pace the clock by the wall clock (latest-value inputs, no lockstep)')
    p.add_argument('--rate', type=float, metavar='F',
                   help='with --real-time: sim seconds per wall second (default 1); without '
                   'it: a lockstep run paced to at most F sim seconds per wall second (the '
                   'same series, to watch it live or to leave CPU to other programs)')
    p.add_argument('--engine', choices=('plain', 'composed', 'graph'),
                   help='graph (default): one process per node; composed: all nodes in one '
                   'process; plain: the FrameLoop without ROS (fastest; the same series on '
                   'every data topic, no drivers)')
    p.add_argument('--compose', action='store_true', help='the same as --engine composed')
    p.add_argument('--domain', type=int, metavar='N',
                   help='ROS_DOMAIN_ID of the run (0..232; default: a free one at random), '
                   'e.g. the one your driver already uses')
    p.add_argument('--report', action='store_true', help='write the report of the bag after')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    p.add_argument('--set', action='append', default=[], metavar='KEY=VALUE',
                   help='change one scenario key (dotted, YAML value; null removes it), '
                   'validated as the file is, e.g. --set spacecraft.flexible.wings=one '
                   '--set manager.initial=reference_slew; repeatable')
    p.set_defaults(func=cmd_run)

    p = sub.add_parser('list', help='list scenarios and nodes')
    p.add_argument('--dir', help='scenario directory (default ./scenarios)')
    p.set_defaults(func=cmd_list)

    p = sub.add_parser('validate', help='check a scenario file')
    p.add_argument('scenario')
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser('switch', help='switch the active controller of a running graph',
                       parents=[run_pid])
    p.add_argument('controller', help='controller name (see `adcs status`)')
    p.set_defaults(func=cmd_switch)

    p = sub.add_parser('slew', help='slew a running graph to an attitude (adcs/slew action) '
                       'and wait for the result', parents=[run_pid])
    p.add_argument('--to', nargs=3, type=float, required=True, metavar=('ROLL', 'PITCH', 'YAW'),
                   help='target attitude, 3-2-1 Euler angles [deg]')
    p.add_argument('--frame', choices=('inertial', 'orbit'), default='inertial',
                   help='frame of the target attitude (default: inertial)')
    p.add_argument('--controller', default='', help='switch to this controller for the slew')
    p.add_argument('--tolerance-deg', type=float, default=0.0,
                   help='done below this angle (default: the server\'s, 0.1 deg)')
    p.add_argument('--timeout-s', type=float, default=0.0,
                   help='abort after this much sim time (default: the server\'s, 600 s)')
    p.set_defaults(func=cmd_slew)

    p = sub.add_parser('status', help='controllers and lockstep health of a running graph',
                       parents=[run_pid])
    p.add_argument('--watch', action='store_true', help='refresh once a second until the run '
                   'ends (Ctrl-C stops): controller, mode, attitude error, rates, wheel '
                   'momentum, faults, missed frames')
    p.add_argument('--count', type=int, metavar='N', help=argparse.SUPPRESS)   # (tests)
    p.set_defaults(func=cmd_status)

    p = sub.add_parser('fault', help='inject one fault into a running graph (sim/faults '
                       'announces it; not deterministic: its frame depends on wall time)',
                       parents=[run_pid])
    p.add_argument('kind', help='fault kind (adcs list: dropout, nan, stuck, bias_step, '
                   'noise_burst, wheel_stuck, wheel_torque_lost, coil_open)')
    p.add_argument('target', help='what it strikes: a sensor (e.g. magnetometer), a wheel '
                   'name, a magnetorquer axis x|y|z')
    p.add_argument('--at', type=float, metavar='S', help='sim time it starts [s] (default: '
                   'the next frame)')
    p.add_argument('--param', action='append', default=[], metavar='KEY=VALUE',
                   help='a parameter of the kind (YAML value), e.g. duration_s=60 or '
                   'bias=[1e-6,0,0]; repeatable')
    p.set_defaults(func=cmd_fault)

    from adcs_nodes.tools import campaigns as montecarlo, replay
    from adcs_nodes.tools.campaigns import compare, sweep
    for name, tool, text in (
            ('montecarlo', montecarlo, 'dispersed Monte Carlo campaign (parallel, resumable)'),
            ('sweep', sweep, 'a Monte Carlo campaign per point of a grid of scenario values '
             '(plain engine, resumable): capture, hold, filter convergence'),
            ('compare', compare, 'controllers side by side: a Monte Carlo campaign per '
             'controller on the same draws (plain engine, resumable), one table'),
            ('replay', replay, 'publish recorded sensor topics as a driver would')):
        p = sub.add_parser(name, help=text)
        tool.add_arguments(p)
        p.set_defaults(func=tool.run_from_args)

    p = sub.add_parser('schema', help='print every scenario key (Markdown table)')
    p.set_defaults(func=cmd_schema)

    p = sub.add_parser('export', help='export a bag to CSV files', parents=[a_bag])
    p.add_argument('--csv', required=True, metavar='DIR', help='output directory')
    p.add_argument('--topic', action='append', metavar='TOPIC',
                   help='only this topic (repeatable; default: every topic)')
    p.set_defaults(func=cmd_export)

    p = sub.add_parser('report', help='metrics, plots and summary of a bag', parents=[a_bag])
    p.add_argument('--out', metavar='DIR', help='output directory (default BAG_report)')
    p.set_defaults(func=cmd_report)
    return ap


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``adcs`` console script."""
    # a crash inside a C library (rclpy, Fast DDS) prints where Python was
    try:
        faulthandler.enable()
    except (OSError, ValueError):   # stderr without a file descriptor (captured in tests)
        pass
    args = build_parser().parse_args(argv)
    if args.command in CTRL_C_COMMANDS:
        ctrl_c_stops()
    return args.func(args)


#: The commands that talk to a running graph for as long as the user wants: SIGINT (Ctrl-C,
#: ``kill -INT``) ends them cleanly, whatever the starting process did with SIGINT.
CTRL_C_COMMANDS = ('status', 'slew', 'switch', 'fault', 'replay')


def ctrl_c_stops() -> None:
    """``KeyboardInterrupt`` on SIGINT even where it was inherited ignored (as the nodes)."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


if __name__ == '__main__':
    raise SystemExit(main())
