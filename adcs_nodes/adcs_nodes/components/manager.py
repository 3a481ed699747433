"""The controller manager's frame step: every controller's command (shadow mode) and the
estimate -> :meth:`ControllerManagerCore.step` -> ``adcs/actuator_command``, the per-actuator
command topics and the status.

The switching, schedule, automatic sequence and fallback rules are the core's
(:mod:`adcs_nodes.core.manager`); here: the parameters, the samples and the fault log.

Per-actuator commands, in standard ROS types so a driver does not depend on ``adcs_msgs``
(same stamp as the command; held by the driver until the next, as the simulated dynamics
does; the values are the manager's: finite and inside the limits):

* ``actuators/magnetorquer/command`` (``geometry_msgs/Vector3Stamped``): the dipole [A m^2],
  body axes;
* ``actuators/wheels/command`` (``sensor_msgs/JointState``, ``effort``): the motor torques
  [N m] by wheel name, when the spacecraft has reaction wheels.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Dict, List, Optional, Sequence, Tuple

from adcs_nodes.components.base import Log, silent
from adcs_nodes.components.controller import command_of, command_sample, estimate_of
from adcs_nodes.core.control import Command
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.core.manager import AutoSequence, ControllerManagerCore
from adcs_nodes.core.samples import (ActuatorCommand, ControllerStatus, MagnetorquerCommand,
                                     WheelCommand)
from adcs_nodes.core.spec import all_or_none
from adcs_nodes.registry import Param
from adcs_nodes.spec import SCHEDULE

MAGNETORQUER_TOPIC = 'actuators/magnetorquer/command'
WHEELS_TOPIC = 'actuators/wheels/command'

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
    log : Log
        Where fault changes are reported (once per change of kind).
    """

    def __init__(self, core: ControllerManagerCore, log: Log = silent) -> None:
        self.core = core
        self.names = list(core.names)
        self.log = log
        self.t_last: Optional[float] = None
        self._fault_kind: List[str] = []

    def step(self, t_ns: int, inputs: Dict[str, Any]) -> Tuple[ActuatorCommand, Dict[str, Any]]:
        """The actuator command of frame ``t_ns`` and the core's status; ``inputs``: each
        controller's latest command by name, the estimate under ``_estimate``."""
        t = t_ns / NS_PER_S
        self.t_last = t
        commands: Dict[str, Tuple[float, Optional[Command]]] = {
            n: (x.t_ns / NS_PER_S, command_of(x)) for n in self.names
            if (x := inputs.get(n)) is not None}
        est = inputs.get('_estimate')
        cmd, status = self.core.step(t, commands, estimate_of(est),
                                     estimate_t=None if est is None else est.t_ns / NS_PER_S)
        text = status.get('fault') or status.get('note', '')     # a fallback, or a note
        fault_kind = text.split(' ', 2)[:2]                # e.g. ['magnetic:', 'stale:']
        if fault_kind != self._fault_kind:
            if text:
                self.log('warning', f't={t:g} s: {text} (logged once)')
            else:
                self.log('info', f't={t:g} s: fault cleared')
            self._fault_kind = fault_kind
        return command_sample(cmd, t_ns, status.get('source') or 'zero'), status

    def status(self, t_ns: int, status: Dict[str, Any]) -> ControllerStatus:
        """``adcs/controller_status`` of a status (:meth:`status_key` says when it changed)."""
        key = status_key(status, self.core.active)
        return ControllerStatus(t_ns, str(key[0]), tuple(self.names), str(key[1] or ''),
                                int(key[2]), int(status.get('missed_frames', 0)),
                                str(status.get('last_fault', '')))


def status_key(status: Dict[str, Any], active: str) -> tuple:
    """What a status change is (the fault text carries times: not part of it)."""
    return (status.get('active', active), status.get('mode', ''),
            status.get('switch_count', 0), status.get('source', ''), status.get('note', ''))


def actuator_commands(cmd: ActuatorCommand, wheel_names: Sequence[str]) -> List[tuple]:
    """``[(topic, sample)]`` of the per-actuator commands of ``cmd`` (module docstring): the
    dipole always, the wheel torques when there are wheels (zeros for a command without)."""
    out: List[tuple] = [(MAGNETORQUER_TOPIC, MagnetorquerCommand(cmd.t_ns, cmd.dipole_body_Am2))]
    if wheel_names:
        torque = cmd.wheel_torque_Nm
        out.append((WHEELS_TOPIC, WheelCommand(
            cmd.t_ns, tuple(wheel_names), tuple(float(v) for v in torque)
            if len(torque) == len(wheel_names) else (0.0,) * len(wheel_names))))
    return out


def wheel_names_for(count: int, names: Optional[Sequence[str]] = None) -> list:
    """``names`` when given (and of length ``count``), else ``wheel0 .. wheel<count-1>`` (the
    dynamics node's default names)."""
    names = [str(n) for n in (names or []) if str(n)]
    if names and len(names) != count:
        raise ValueError(f'{len(names)} wheel names for {count} wheels')
    return names or [f'wheel{i}' for i in range(count)]
