"""``adcs switch``, ``adcs status [--watch]``, ``adcs fault``: join a running graph's domain
(from its ``active-<pid>.json``) with a short-lived node, and leave."""
from __future__ import annotations

import glob
import json
import math
import os
import re
import sys
import threading
import time
from typing import Dict, List, Optional

from adcs_nodes.tools.run.launcher import RUNS_DIR

#: What a controller name can be (the registry's names); anything else is refused unsent.
CONTROLLER_NAME = re.compile(r'[A-Za-z0-9_.-]{1,100}')


class LiveError(RuntimeError):
    """No run to talk to, or it did not answer; the message says what to do."""


def active_runs() -> List[Dict]:
    """Manifests of the runs whose launcher process is alive (stale files are removed)."""
    runs = []
    for path in sorted(glob.glob(os.path.join(RUNS_DIR, 'active-*.json'))):
        try:
            with open(path) as fh:
                data = json.load(fh)
            os.kill(int(data['pid']), 0)
        except (OSError, ValueError, KeyError):
            try:
                os.unlink(path)     # launcher gone (killed): forget the run
            except OSError:
                pass
            continue
        runs.append(data)
    return runs


def pick_run(pid: Optional[int]) -> Dict:
    """The run to talk to: the one with launcher ``pid``, or the only active one."""
    runs = active_runs()
    if pid is not None:
        for run in runs:
            if int(run['pid']) == pid:
                return run
        raise LiveError(f'no active adcs run with launcher pid {pid}')
    if not runs:
        raise LiveError('no active adcs run (start one with `adcs run SCENARIO`)')
    if len(runs) > 1:
        listing = ', '.join(f'{r["pid"]} ({os.path.basename(r["scenario"])})' for r in runs)
        raise LiveError(f'{len(runs)} runs are active: {listing}; choose one with --run PID')
    return runs[0]


#: Wall seconds a command on a running graph may take in all (then exit 1).
SESSION_DEADLINE_S = 60.0
#: Wall seconds a command waits for a service or action server, then as long for its answer.
SERVER_WAIT_S = 25.0


def _give_up() -> None:
    sys.stderr.write(f'adcs: no answer from ROS within {SESSION_DEADLINE_S:g} s (the run\'s '
                     'domain may be overloaded); giving up\n')
    sys.stderr.flush()
    os._exit(1)


class _Session:
    """A short-lived rclpy context on the run's domain (exit 1 after the deadline)."""

    def __init__(self, run: Dict, deadline: bool = True) -> None:
        if deadline:       # (not for a long action: adcs slew has its own timeout)
            watchdog = threading.Timer(SESSION_DEADLINE_S, _give_up)
            watchdog.daemon = True
            watchdog.start()
        from adcs_nodes.tools.run.launcher import child_env, use_dds_env
        use_dds_env(child_env(int(run['domain'])))
        import rclpy
        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('adcs_cli', context=self.context,
                                      start_parameter_services=False)
        from rclpy.executors import SingleThreadedExecutor
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def call(self, srv_type, name: str, request, timeout_s: float = SERVER_WAIT_S):
        client = self.node.create_client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout_s):
            raise LiveError(f'service {name} not available within {timeout_s:g} s '
                            '(does this scenario run a controller manager?)')
        # wait_for_service sees the graph, not the DDS match: a request sent before the server's
        # reader matched ours is lost. Requests here are idempotent, so resend until answered.
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            future = client.call_async(request)
            self.executor.spin_until_future_complete(future, timeout_sec=1.0)
            if future.done():
                return future.result()
            client.remove_pending_request(future)
        raise LiveError(f'service {name} did not answer within {timeout_s:g} s')

    def spin(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)

    def close(self, wait_s: float = 5.0) -> None:
        """Shut the session down, waiting at most ``wait_s`` (then :func:`finish` exits)."""
        def _close() -> None:
            self.executor.shutdown()
            self.node.destroy_node()
            self.rclpy.shutdown(context=self.context)
        closer = threading.Thread(target=_close, daemon=True)
        closer.start()
        closer.join(wait_s)
        global _STUCK
        _STUCK = _STUCK or closer.is_alive()


#: True when a session's shutdown did not finish (see :meth:`_Session.close`).
_STUCK = False


def finish(code: int) -> int:
    """Exit code of a command; exits at once when a session's shutdown is stuck."""
    if _STUCK:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def switch(name: str, pid: Optional[int] = None) -> str:
    """Switch the active controller of a running graph; the manager's answer, or LiveError."""
    from adcs_nodes.scenario import shorten_message
    if not CONTROLLER_NAME.fullmatch(name):
        raise LiveError(shorten_message(
            f'{name!r} is not a controller name ({len(name)} characters; names are 1 to 100 '
            'letters, digits, "_", "." or "-"; `adcs status` lists them)'))
    from adcs_msgs.srv import SwitchController
    session = _Session(pick_run(pid))
    try:
        res = session.call(SwitchController, '/adcs/switch_controller',
                           SwitchController.Request(name=name))
    finally:
        session.close()
    if not res.success:
        raise LiveError(shorten_message(res.message))
    return shorten_message(f'{res.message} (active: {res.active})')


def status(pid: Optional[int] = None, wait_s: float = 3.0) -> str:
    """Controllers and lockstep health of a running graph, after listening ``wait_s``."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from adcs_msgs.msg import ControllerStatus, LockstepStatus
    run = pick_run(pid)
    session = _Session(run)
    ctrl: List = []
    nodes: Dict[str, LockstepStatus] = {}
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    try:
        session.node.create_subscription(ControllerStatus, 'adcs/controller_status',
                                         ctrl.append, latched)
        session.node.create_subscription(LockstepStatus, 'lockstep/status',
                                         lambda m: nodes.__setitem__(m.node, m), 50)
        session.spin(wait_s)
    finally:
        session.close()
    lines = [f'run {run["pid"]}: {run["scenario"]} (ROS_DOMAIN_ID={run["domain"]}, '
             f'bag {run.get("bag") or "none"})']
    if ctrl:
        c = ctrl[-1]
        if run.get('epoch'):
            from adcs_nodes.msgs.fields import stamp_ns
            from adcs_nodes.nodes.lockstep_node import epoch_to_ns, parse_epoch
            t = (stamp_ns(c.header.stamp) - epoch_to_ns(parse_epoch(run['epoch']))) / 1e9
            lines.append(f'sim time: {t:.1f} s (last controller frame)')
        lines.append(f'controller: {c.active}  mode: {c.mode or "-"}  available: '
                     f'{", ".join(c.available)}  switches: {c.switch_count}  missed frames: '
                     f'{c.missed_frames}  last fault: {c.last_fault or "-"}')
    else:
        lines.append('controller: no controller manager in this run')
    for name in sorted(nodes):
        s = nodes[name]
        lines.append(f'  {name:22s} frames {s.frames:8d}  missed {s.missed_frames}'
                     + (f' (last: {s.last_missed_input})' if s.last_missed_input else ''))
    return '\n'.join(lines)


# ---------------------------------------------------------------------- adcs fault
#: Where a running graph takes live faults (``sim_node.faults.INJECT_TOPIC``).
INJECT_TOPIC = 'sim/inject_fault'
#: Wall seconds ``adcs fault`` waits for the fault's announcement on ``sim/faults``.
ANNOUNCE_WAIT_S = 15.0
#: Without ``--at`` a live fault starts this much wall time ahead: every node has it then.
LEAD_WALL_S = 1.0


def _run_scenario(run: Dict) -> Dict:
    """The run's scenario as data: the bag's, else the scenario file's ({}: neither)."""
    from adcs_nodes.scenario import read_yaml
    paths = ([os.path.join(run['bag'], 'scenario.yaml')] if run.get('bag') else []) \
        + [run.get('scenario') or '']
    for path in paths:
        try:
            data = read_yaml(path)
        except ValueError:                # (ScenarioError) try the next one
            continue
        if isinstance(data, dict):
            return data
    return {}


def parse_params(items: List[str]) -> Dict:
    """``KEY=VALUE`` (YAML value) pairs of ``--param``; LiveError for a malformed one."""
    import yaml
    out: Dict = {}
    for item in items:
        key, sep, text = item.partition('=')
        if not sep or not key:
            raise LiveError(f'--param {item!r}: expected KEY=VALUE (e.g. duration_s=60)')
        try:
            out[key] = yaml.safe_load(text)
        except Exception as exc:          # yaml.YAMLError
            raise LiveError(f'--param {item!r}: not a YAML value ({exc})') from None
    return out


def check_fault(kind: str, target: str, params: Dict, at_s: Optional[float],
                sc: Dict) -> Dict:
    """The fault checked against the run's scenario ``sc`` as a scripted one is; LiveError."""
    from adcs_nodes.scenario import check_fault, fault_targets
    try:
        params = check_fault(kind, target, params, fault_targets(sc) if sc else {
            'sensor': [target], 'wheel': [target], 'magnetorquer': [target]}, scripted=False)
    except ValueError as exc:
        raise LiveError(getattr(exc, 'why', str(exc))) from None
    if at_s is not None:
        duration = float(sc.get('duration_s') or math.inf)
        if not (math.isfinite(at_s) and 0.0 <= at_s <= duration):
            raise LiveError(f'--at {at_s:g} s is outside the run [0, {duration:g}] s')
    return params


def fault(kind: str, target: str, at_s: Optional[float] = None,
          params: Optional[Dict] = None, pid: Optional[int] = None,
          wait_s: float = ANNOUNCE_WAIT_S) -> str:
    """``adcs fault``: JSON on ``sim/inject_fault`` from ``at_s`` (default: soon), awaited on
    ``sim/faults`` when due within ``wait_s``; what happened, or LiveError."""
    from rclpy.duration import Duration
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String
    run = pick_run(pid)
    sc = _run_scenario(run)
    params = check_fault(kind, target, dict(params or {}), at_s, sc)
    listeners = 1 + len([k for k, cfg in (sc.get('sensors') or {}).items()
                         if not (isinstance(cfg, dict) and cfg.get('external'))])
    item = {'index': 1000 + int(time.time() * 1000) % 10**6, 'kind': kind, 'target': target,
            'at_s': at_s, 'params': params}
    session = _Session(run)
    try:
        watch = _FaultWatch(session, run)
        pub = session.node.create_publisher(
            String, INJECT_TOPIC, QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        now, pace = watch.wait_listeners(pub, listeners)
        if at_s is not None and now is not None and at_s < now:
            raise LiveError(f'--at {at_s:g} s has passed: the run is at t = {now:.1f} s')
        if at_s is None and now is not None:       # the frame LEAD_WALL_S ahead
            frame = float((sc.get('timing') or {}).get('frame_s') or 1.0)
            ahead = now + pace * (time.monotonic() - watch.clock[-1][0] + LEAD_WALL_S)
            item['at_s'] = math.ceil(ahead / frame - 1e-9) * frame
            if sc.get('duration_s') and item['at_s'] > float(sc['duration_s']):
                raise LiveError(f'the run ends (t = {float(sc["duration_s"]):g} s) before a '
                                f'fault could start (t = {item["at_s"]:g} s)')
        pub.publish(String(data=json.dumps(item, sort_keys=True)))
        acked = pub.wait_for_all_acked(Duration(seconds=5.0))
        due_s = (item['at_s'] - now) / pace if None not in (now, item['at_s']) else 0.0
        found = watch.announcement(item['index'], wait_s) if acked and due_s <= wait_s \
            else None
    finally:
        session.close()
    return _fault_text(kind, target, params, run, at_s, item['at_s'], now, acked, due_s,
                       found, wait_s)


class _FaultWatch:
    """``/clock`` (first and latest (wall s, sim s)) and ``sim/faults`` for ``adcs fault``."""

    def __init__(self, session: '_Session', run: Dict) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from rosgraph_msgs.msg import Clock

        from adcs_nodes.msgs.fields import stamp_ns
        from adcs_nodes.nodes.lockstep_node import QOS_DATA, epoch_to_ns, parse_epoch
        self.session, self.stamp_ns = session, stamp_ns
        self.epoch_ns = epoch_to_ns(parse_epoch(run['epoch']))
        self.clock: List = []
        self.seen: List = []
        session.node.create_subscription(Clock, '/clock', self._on_clock, QOS_DATA)
        session.node.create_subscription(DiagnosticArray, 'sim/faults', self.seen.append,
                                         QOS_DATA)

    def _on_clock(self, m) -> None:
        sample = (time.monotonic(), (self.stamp_ns(m.clock) - self.epoch_ns) / 1e9)
        self.clock[1:] = [sample] if self.clock else []
        if not self.clock:
            self.clock.append(sample)

    def wait_listeners(self, pub, listeners: int):
        """Wait for ``listeners`` and 0.3 s of ``/clock``: the run's time [s] and pace."""
        clock = self.clock
        deadline = time.monotonic() + SERVER_WAIT_S
        while (pub.get_subscription_count() < listeners or len(clock) < 2
               or clock[-1][0] - clock[0][0] < 0.3) and time.monotonic() < deadline:
            self.session.spin(0.05)
        if pub.get_subscription_count() == 0:
            raise LiveError(f'nobody listens on {INJECT_TOPIC} after {SERVER_WAIT_S:g} s (is '
                            'the run a graph with simulated sensors and dynamics?)')
        pace = 1.0
        if len(clock) > 1 and clock[-1][0] > clock[0][0]:
            pace = max(pace, (clock[-1][1] - clock[0][1]) / (clock[-1][0] - clock[0][0]))
        return (clock[-1][1] if clock else None), pace

    def announcement(self, index: int, wait_s: float):
        """``(t [s], text)`` of the fault's ``active`` announcement, None after ``wait_s``."""
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            self.session.spin(0.05)
            for msg in self.seen:
                for st in msg.status:
                    if st.name == f'fault/{index}' and st.message.startswith('active'):
                        return ((self.stamp_ns(msg.header.stamp) - self.epoch_ns) / 1e9,
                                st.message)
        return None


def _fault_text(kind, target, params, run, at_s, start_s, now, acked, due_s, found,
                wait_s) -> str:
    when = f'at t = {at_s:g} s' if at_s is not None else (
        f'from t = {start_s:g} s, about {LEAD_WALL_S:g} s of wall time ahead'
        if start_s is not None else 'at the next frame')
    sent = (f'fault {kind} {target} {params} sent to run {run["pid"]} ({when}'
            + (f'; the run was at t = {now:.1f} s' if now is not None else '') + ')')
    if not acked:
        raise LiveError(f'{sent}, but not every listener acknowledged it within 5 s (see the '
                        f'node logs in {run.get("run_dir", "the run directory")})')
    if found is not None:
        return (f'{sent}; announced on sim/faults at t = {found[0]:g} s: {found[1]} '
                '(a live fault is not deterministic: its frame depends on wall time)')
    if due_s > wait_s:
        return (f'{sent}; scheduled from t = {start_s:g} s (the first frame at or after it, '
                f'about {due_s:.0f} s of wall time from now); sim/faults announces it then')
    raise LiveError(f'{sent}, but no announcement on sim/faults within {wait_s:g} s (the '
                    'run may have ended, or a node refused it: see the node logs in '
                    f'{run.get("run_dir", "the run directory")})')


# ---------------------------------------------------------------------- adcs status --watch
def _sc_faults(sc: Dict) -> List[Dict]:
    """The scenario's faults as ``{name, text, start, end}`` [s] (end None: to the end)."""
    out = []
    for i, f in enumerate(sc.get('faults') or []):
        if not isinstance(f, dict):
            continue
        try:
            start = float(f.get('at_s', 0.0))
            duration = float((f.get('params') or {}).get('duration_s', 0.0) or 0.0)
        except (TypeError, ValueError):
            continue
        out.append({'name': f'fault/{f.get("index", i)}',
                    'text': f'{f.get("kind")} {f.get("target")}', 'start': start,
                    'end': start + duration if duration > 0 else None})
    return out


class _Watch:
    """What ``adcs status --watch`` shows, from the run's topics."""

    def __init__(self, run: Dict, sc: Dict) -> None:
        from adcs_nodes.nodes.lockstep_node import epoch_to_ns, parse_epoch
        self.run = run
        self.epoch_ns = epoch_to_ns(parse_epoch(run['epoch']))
        self.ctrl = None
        self.source = ''
        self.estimate = None
        self.target = None
        self.wheels = None
        self.nodes: Dict = {}
        self.t = None
        self.seen_faults: Dict[str, Dict] = {}
        self.sc_faults = _sc_faults(sc)
        craft = sc.get('spacecraft') or {}
        self.wheel_inertia = [float(w.get('inertia_kgm2', 0.001)) for w in
                              craft.get('wheels') or [] if isinstance(w, dict)]

    def _time(self, stamp) -> float:
        from adcs_nodes.msgs.fields import stamp_ns
        return (stamp_ns(stamp) - self.epoch_ns) / 1e9

    def on_estimate(self, msg) -> None:
        self.estimate = msg
        self.t = self._time(msg.header.stamp)

    def on_command(self, msg) -> None:
        self.source = msg.source
        self.t = max(self.t or 0.0, self._time(msg.header.stamp))

    def on_fault(self, msg) -> None:
        t = self._time(msg.header.stamp)
        for st in msg.status:
            what = ' '.join(st.message.split(': ', 1)[-1].split()[:2])    # kind target
            self.seen_faults[st.name] = {'text': what, 'time': t,
                                         'active': st.message.startswith('active')}

    def faults(self) -> List[str]:
        """Faults active now: the scenario's at this sim time and the announced ones."""
        t = self.t or 0.0
        active: Dict[str, str] = {}
        for f in self.sc_faults:
            if f['start'] <= t and (f['end'] is None or t < f['end']):
                active[f['name']] = f'{f["text"]} (since {f["start"]:g} s)'
        for name, f in self.seen_faults.items():
            if f['active']:
                active[name] = f'{f["text"]} (since {f["time"]:g} s)'
            else:
                active.pop(name, None)
        return list(active.values())

    def lines(self) -> List[str]:
        import numpy as np

        from adcs_nodes.core import attitude as att
        from adcs_nodes.tools.analyse.papers.series import quat, vec
        run = self.run
        out = [f'adcs status --watch: run {run["pid"]} {os.path.basename(run["scenario"])} '
               f'(ROS_DOMAIN_ID={run["domain"]}), {time.strftime("%H:%M:%S")}; Ctrl-C ends']
        out.append(f'sim time:        {self.t:.1f} s' if self.t is not None
                   else 'sim time:        (no estimate or command yet)')
        c = self.ctrl
        if c is not None:
            out.append(f'controller:      {c.active}   mode: {c.mode or "-"}   commanding: '
                       f'{self.source or "-"}   switches: {c.switch_count}')
        else:
            out.append('controller:      (no adcs/controller_status yet)')
        est, tgt = self.estimate, self.target
        if est is not None:
            if tgt is not None:
                frame = tgt.header.frame_id or 'orbit'
                try:
                    q_est = est.q_eci_body if frame == 'eci' else est.q_orbit_body
                    err = math.degrees(att.angle_between(quat(q_est), quat(tgt.q_ref_body)))
                    out.append(f'attitude error:  {err:.3f} deg (estimate to the target, '
                               f'{frame} frame)')
                except ValueError:
                    out.append('attitude error:  (estimate or target not finite)')
            else:
                out.append('attitude error:  (no adcs/attitude_target)')
            w_i, w_o = vec(est.omega_body_eci_body), vec(est.omega_body_orbit_body)
            out.append(f'rates:           {math.degrees(np.linalg.norm(w_i)):.4f} deg/s '
                       f'inertial, {math.degrees(np.linalg.norm(w_o)):.4f} deg/s to the '
                       f'orbit frame (estimate)')
        else:
            out.append('attitude error:  (no adcs/attitude_estimate)')
        w = self.wheels
        if w is not None and len(w.velocity) == len(self.wheel_inertia) and w.velocity:
            h = [v * j for v, j in zip(w.velocity, self.wheel_inertia)]
            names = list(w.name) or [f'wheel{i}' for i in range(len(h))]
            out.append('wheel momentum:  ' + '  '.join(f'{n} {v:+.4f}' for n, v in
                                                       zip(names, h)) + ' N m s (tachometer)')
        elif self.wheel_inertia:
            out.append('wheel momentum:  (no sensors/wheels yet)')
        else:
            out.append('wheel momentum:  (no wheels)')
        active = self.faults()
        out.append('faults:          ' + ('; '.join(active) if active else 'none active'))
        if c is not None and c.last_fault:
            out.append(f'last fallback:   {c.last_fault}')
        missed = sum(int(s.missed_frames) for s in self.nodes.values())
        worst = ', '.join(f'{n} {int(s.missed_frames)}' for n, s in sorted(self.nodes.items())
                          if s.missed_frames)
        out.append(f'missed frames:   {missed} in {len(self.nodes)} nodes'
                   + (f' ({worst})' if worst else '')
                   + (f'; manager fallback frames {c.missed_frames}' if c is not None else ''))
        return out


def _alive(run: Dict) -> bool:
    """The run's launcher is running: its manifest is there and its process exists."""
    if not os.path.exists(os.path.join(RUNS_DIR, f'active-{run["pid"]}.json')):
        return False
    try:
        os.kill(int(run['pid']), 0)
    except OSError:
        return False
    return True


def watch(pid: Optional[int] = None, interval_s: float = 1.0, out=None,
          count: Optional[int] = None) -> int:
    """``adcs status --watch``: the run's view every ``interval_s`` until it ends; 0."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from adcs_msgs.msg import (ActuatorCommand, AttitudeState, AttitudeTarget,
                               ControllerStatus, LockstepStatus)
    from diagnostic_msgs.msg import DiagnosticArray
    out = out or sys.stdout
    run = pick_run(pid)
    view = _Watch(run, _run_scenario(run))
    session = _Session(run, deadline=False)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    latest = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)   # newest only
    n = session.node
    n.create_subscription(ControllerStatus, 'adcs/controller_status',
                          lambda m: setattr(view, 'ctrl', m), latched)
    n.create_subscription(AttitudeState, 'adcs/attitude_estimate', view.on_estimate, latest)
    n.create_subscription(AttitudeTarget, 'adcs/attitude_target',
                          lambda m: setattr(view, 'target', m), latest)
    n.create_subscription(ActuatorCommand, 'adcs/actuator_command', view.on_command, latest)
    n.create_subscription(JointState, 'sensors/wheels', lambda m: setattr(view, 'wheels', m),
                          latest)
    n.create_subscription(LockstepStatus, 'lockstep/status',
                          lambda m: view.nodes.__setitem__(m.node, m), 50)
    n.create_subscription(DiagnosticArray, 'sim/faults', view.on_fault, 50)
    tty = hasattr(out, 'isatty') and out.isatty()
    shown = 0
    try:
        while count is None or shown < count:
            session.spin(interval_s)
            text = '\n'.join(view.lines())
            out.write(('\x1b[H\x1b[2J' + text + '\n') if tty else (text + '\n\n'))
            out.flush()
            shown += 1
            if not _alive(run):
                out.write(f'run {run["pid"]} ended\n')
                out.flush()
                break
    except KeyboardInterrupt:
        pass
    except Exception as exc:         # rclpy's ExternalShutdownException: Ctrl-C in a spin
        if type(exc).__name__ != 'ExternalShutdownException':
            raise
    finally:
        session.close()
    return 0
