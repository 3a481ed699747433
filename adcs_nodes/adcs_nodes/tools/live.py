"""Talk to a running graph started by ``adcs run``: ``adcs switch`` and ``adcs status``.

A run announces itself in ``~/.cache/adcs/runs/active-<launcher pid>.json`` (domain id,
scenario, bag, node PIDs). These commands join that ROS domain with a short-lived node, call
the controller manager's services or read the latched status, and leave.
"""
from __future__ import annotations

import glob
import json
import os
import re
import sys
import threading
import time
from typing import Dict, List, Optional

from adcs_nodes.tools.launcher import RUNS_DIR

MANAGER = 'controller_manager'
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


#: Wall seconds a command on a running graph (status, switch, ...) may take in all: a process
#: that joined a busy domain was once seen never to return (``adcs status`` beside a graph
#: running flat out after a controller was killed); it then exits 1 with a message.
SESSION_DEADLINE_S = 60.0
#: Wall seconds a command waits for a service or action server, then as long for its answer:
#: discovery of a new process on a domain took 10-13 s at load 18; both fit in the session
#: deadline.
SERVER_WAIT_S = 25.0


def _give_up() -> None:
    sys.stderr.write(f'adcs: no answer from ROS within {SESSION_DEADLINE_S:g} s (the run\'s '
                     'domain may be overloaded); giving up\n')
    sys.stderr.flush()
    os._exit(1)


class _Session:
    """A short-lived rclpy context on the run's domain (the process exits 1 if the whole
    command takes longer than :data:`SESSION_DEADLINE_S`)."""

    def __init__(self, run: Dict, deadline: bool = True) -> None:
        if deadline:       # (not for a long action: adcs slew has its own timeout)
            watchdog = threading.Timer(SESSION_DEADLINE_S, _give_up)
            watchdog.daemon = True
            watchdog.start()
        from adcs_nodes.tools.launcher import child_env, use_dds_env
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
        """Shut the session down, waiting at most ``wait_s``; a shutdown still blocked then
        (a flooded domain) is left to the process's end: :func:`finish` exits at once."""
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
    """Exit code of a command that used a session; exits the process at once (output
    flushed) when a session's shutdown is stuck, instead of hanging at interpreter exit."""
    if _STUCK:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def switch(name: str, pid: Optional[int] = None) -> str:
    """Switch the active controller of a running graph; returns the manager's answer.

    Raises
    ------
    LiveError
        No run, no manager, or the manager refused (unknown name: the message lists the
        known controllers).
    """
    from adcs_nodes.tools.scenario import shorten_message
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
    """Human-readable status of a running graph: controllers and lockstep health.

    Listens ``wait_s`` (discovery of a new participant takes up to ~3 s).
    """
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
            from adcs_nodes.nodes.convert import stamp_ns
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
