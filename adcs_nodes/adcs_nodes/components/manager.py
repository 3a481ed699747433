"""The controller manager's frame step: every controller's command message (shadow mode) and
the estimate -> :meth:`ControllerManagerCore.step` -> ``adcs/actuator_command`` and the
per-actuator command topics (``actuators/magnetorquer/command``, ``actuators/wheels/command``).

The switching, schedule, automatic sequence and fallback rules are the core's
(:mod:`adcs_nodes.core.manager`); here: the parameters, the message edge and the fault log.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Dict, List, Optional, Tuple

from adcs_msgs.msg import ActuatorCommand
from adcs_nodes.components.base import FrameClock, Log, silent
from adcs_nodes.components.controller import command_from_msg, command_msg, estimate_from_msg
from adcs_nodes.core.control import Command
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.core.manager import AutoSequence, ControllerManagerCore
from adcs_nodes.core.spec import all_or_none
from adcs_nodes.nodes.convert import stamp_ns
from adcs_nodes.registry import Param
from adcs_nodes.spec import SCHEDULE

#: The manager's parameters (``['']``: a list default with one placeholder, none).
MANAGER_PARAMS = (
    Param('controllers', 'str[]', ['bdot'], '-', 'controllers whose commands are forwarded '
          '(registered names; adcs/controllers/<name>/command)', read_only=True),
    Param('safe', 'str', 'bdot', '-', 'safe-mode controller (fallback; one of controllers)',
          read_only=True),
    Param('initial', 'str', '', '-', "controller active at start ('': auto or safe)",
          read_only=True),
    Param('period_s', 'float', 2.0, 's', 'manager period', positive=True, read_only=True),
    Param('controller_period_s', 'float', 0.0, 's', 'period of the controller commands '
          '(0: period_s)', min=0.0, read_only=True),
    Param('estimator_period_s', 'float', 0.0, 's', 'period of the watched estimate '
          '(0: not watched)', min=0.0, read_only=True),
    *replace(SCHEDULE, read_only=True).columns('schedule_'),
    Param('max_wheel_torque_Nm', 'float[]', [], 'N m', 'wheel torque limits (none: no '
          'wheels)', positive=True, read_only=True),
    Param('estimate_users', 'str[]', ['*'], '-', "controllers that need the estimate "
          "('*': all)", read_only=True),
    Param('max_dipole_Am2', 'float[]', [40.0, 40.0, 40.0], 'A m^2', 'magnetorquer limits per '
          'body axis', length=3, min=0.0, read_only=True, check=all_or_none),
    Param('max_torque_Nm', 'float[]', [0.0, 0.0, 0.0], 'N m', 'ideal body-torque limits per '
          'body axis', length=3, min=0.0, read_only=True),
    Param('stale_after_s', 'float', -1.0, 's', 'a command older than this is stale (-1: '
          'lockstep 0, live 1.5 x the longest period)', min=-1.0, read_only=True),
    Param('wheel_names', 'str[]', [''], '-', "wheel names in JointState order (['']: "
          "wheel0, wheel1, ...)", read_only=True),
    Param('fallback', 'str[]', [''], '-', "controllers tried in order before the safe one "
          "when the active command is unusable (['']: none)", read_only=True),
)


def manager_core(p: Dict[str, Any], auto_cfg: Dict[str, Any], live: bool,
                 sample_timing: bool = False) -> ControllerManagerCore:
    """The manager core of the :data:`MANAGER_PARAMS` values ``p`` and the ``auto.*``
    section (``{}``: no automatic sequence).

    ``sample_timing`` (live or real-time mode: every frame fires on the clock, with what has
    arrived): the first command comes through the estimator, a controller and the manager
    one period each after the samples it needs (the estimator takes a sample one own period
    after its stamp), so the frames of that chain (plus the live staleness limit) before the
    first command is forwarded are start-up frames, not missed ones (``startup_s``).
    """
    names = [n for n in p['controllers'] if n]
    period_s = float(p['period_s'])
    ctrl_period_s = float(p['controller_period_s']) or period_s
    est_period_s = float(p['estimator_period_s'])
    sched_t, sched_name = list(p['schedule_t_s']), list(p['schedule_controller'])
    if len(sched_t) != len(sched_name):
        raise ValueError('schedule_t_s and schedule_controller differ in length')
    schedule = [(float(t), str(n)) for t, n in zip(sched_t, sched_name) if n]
    wheel_limits = list(p['max_wheel_torque_Nm'])
    users = [n for n in p['estimate_users'] if n]
    stale = float(p['stale_after_s'])
    if stale < 0.0:
        stale = 1.5 * max(period_s, ctrl_period_s, est_period_s) if live else 0.0
    startup_s = (est_period_s + ctrl_period_s + period_s + (stale if live else 0.0)) \
        if sample_timing else 0.0
    return ControllerManagerCore(
        names, str(p['safe']), initial=str(p['initial']) or None,
        max_dipole_Am2=list(p['max_dipole_Am2']),
        max_wheel_torque=[] if wheel_limits == [-1.0] else wheel_limits,
        max_torque=list(p['max_torque_Nm']), stale_after_s=stale, schedule=schedule,
        auto=AutoSequence.from_dict(auto_cfg) if auto_cfg else None,
        estimate_period_s=est_period_s if est_period_s > 0 else None,
        estimate_users=None if users == ['*'] else users,
        fallback=[n for n in p['fallback'] if n], startup_s=startup_s)


class ManagerComponent:
    """The controller manager's frame step around its core.

    Parameters
    ----------
    core : ControllerManagerCore
    clock : FrameClock
    log : Log
        Where fault changes are reported (once per change of kind).
    """

    def __init__(self, core: ControllerManagerCore, clock: FrameClock,
                 log: Log = silent) -> None:
        self.core = core
        self.names = list(core.names)
        self.clock = clock
        self.log = log
        self.t_last: Optional[float] = None
        self._fault_kind: List[str] = []

    def step(self, t_ns: int, msgs: Dict[str, Any]) -> Tuple[ActuatorCommand, Dict[str, Any]]:
        """The actuator command message of frame ``t_ns`` and the core's status."""
        t = t_ns / NS_PER_S
        self.t_last = t
        commands: Dict[str, Tuple[float, Optional[Command]]] = {}
        for n in self.names:
            m = msgs.get(n)
            if m is not None:
                commands[n] = (self.clock.elapsed_ns(stamp_ns(m.header.stamp)) / NS_PER_S,
                               command_from_msg(m))
        est_msg = msgs.get('_estimate')
        est_t = None if est_msg is None else \
            self.clock.elapsed_ns(stamp_ns(est_msg.header.stamp)) / NS_PER_S
        cmd, status = self.core.step(t, commands, estimate_from_msg(est_msg), estimate_t=est_t)
        fault_kind = status.get('fault', '').split(' ', 2)[:2]   # e.g. ['magnetic:', 'stale:']
        if fault_kind != self._fault_kind:
            if status.get('fault'):
                self.log('warning', f't={t:g} s: {status["fault"]} (logged once)')
            else:
                self.log('info', f't={t:g} s: fault cleared')
            self._fault_kind = fault_kind
        return command_msg(cmd, self.clock.stamp(t_ns), status.get('source') or 'zero'), status
