"""A controller's frame step: input samples -> the controller context (:class:`ControlInputs`)
-> the registered controller's ``update`` -> ``adcs/controllers/<name>/command``.

Conditioning (the same for the node and the FrameLoop):

* the estimate (``adcs/attitude_estimate``): the orbit rate is recovered from its two rates,
  ``omega0 = |omega_body_eci_body - omega_body_orbit_body|``;
* the target (``adcs/attitude_target``): a frame other than ``orbit``/``eci``, a non-finite
  value or a near-zero quaternion is no target;
* the magnetometer: only a fresh sample, rotated into body axes by its mount; with the
  estimate, the onboard-model field ``n* = R(q_orbit_body)^T B*`` is offered too (between
  samples);
* wheel speeds (``sensors/wheels``): the right count and finite, and the wheel momentum from
  them (:func:`adcs_nodes.entries.wheel_momentum`);
* a plugin's input kinds (``inputs.register``): their fresh samples in ``ControlInputs.samples``.

Wheel health (a controller reading the tachometer and the applied command, e.g. ``mpi``):
each wheel's state (:class:`adcs_nodes.core.wheel_health.WheelHealth`) goes to the core as
``ControlInputs.wheel_ok``, with the magnetorquer limits and the onboard-model field for the
axis the wheels left no longer cover; a failed wheel gets its probe torque, and the source is
``'<name>; <each failed wheel and why>'``. The output is checked where it leaves the
controller (:func:`~adcs_nodes.core.command_health.command_fields`): a bad one, or a refusal
(``Command.refused``), goes out as a zero command from ``'<name>: <reason>'``, and the manager
falls back as for a stale command.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Dict, Optional

import numpy as np

from adcs_nodes import inputs
from adcs_nodes.components import conditioning as cond
from adcs_nodes.core import attitude as att
from adcs_nodes.core.command_health import command_fields
from adcs_nodes.core.control import Command, ControlInputs, Estimate, Target
from adcs_nodes.core.estimation.onboard import make_onboard_reference
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.core.spec import all_or_none
from adcs_nodes.core.samples import ActuatorCommand, AttitudeState, AttitudeTarget, all_finite
from adcs_nodes.core.wheel_health import WheelHealth
from adcs_nodes.entries import wheel_momentum
from adcs_nodes.registry import Param


def _triples(values):
    if len(values) % 3:
        raise ValueError(f'expected 3 values per wheel, got {len(values)}')
    return values


#: The spacecraft context every controller node knows (defaults: paper 000's satellite).
CONTEXT_PARAMS = (
    Param('expected_mounts', 'str[]', [], '-', 'sensor frames whose /tf_static mount must '
          'have arrived before the node is ready (the launcher sets them)', read_only=True),
    Param('controller', 'str', 'magnetic', '-', 'registered controller this node runs',
          read_only=True),
    Param('period_s', 'float', 2.0, 's', 'control period', positive=True, read_only=True),
    Param('inertia_kgm2', 'matrix3', [118.0, 118.0, 19.6], 'kg m^2',
          "the controller's own inertia", read_only=True),
    Param('max_dipole_Am2', 'float[]', [40.0, 40.0, 40.0], 'A m^2',
          'magnetorquer limits per body axis (all zero: no magnetorquer)', length=3, min=0.0,
          read_only=True, check=all_or_none),
    Param('wheel_axes_body', 'float[]', [], '-', 'wheel spin axes, body axes, 3 per wheel',
          read_only=True, check=_triples),
    Param('wheel_max_torque_Nm', 'float[]', [], 'N m', 'wheel motor torque limits',
          positive=True, read_only=True),
    Param('wheel_max_momentum_Nms', 'float[]', [], 'N m s', 'wheel momentum limits',
          positive=True, read_only=True),
    Param('wheel_inertia_kgm2', 'float[]', [], 'kg m^2', 'wheel inertias about their axes',
          positive=True, read_only=True),
) + inputs.period_params(inputs.NAMES)


def plugin_period_params(entry: Any) -> tuple:
    """The period parameters of ``entry``'s plugin input kinds (the built-ins' are in
    :data:`CONTEXT_PARAMS`)."""
    return inputs.period_params([n for n in entry.inputs if n not in inputs.NAMES])


def inertia_matrix(values) -> np.ndarray:
    """3 diagonal values or 9 row-major -> (3, 3) [kg m^2]; ValueError otherwise."""
    a = np.asarray(values, dtype=float)
    if a.size == 3:
        return np.diag(a)
    if a.size == 9:
        return a.reshape(3, 3)
    raise ValueError(f'inertia_kgm2 needs 3 or 9 values, got {a.size}')


def controller_context(entry: Any, ctx_p: Dict[str, Any], epoch: Any, seed: int,
                       onboard_orbit: Dict[str, Any],
                       onboard_field: Dict[str, Any]) -> Dict[str, Any]:
    """The spacecraft context a controller is built with, from its :data:`CONTEXT_PARAMS`
    values ``ctx_p``; the onboard reference only for a controller that reads the estimate and
    the magnetometer. ``ValueError`` for actuators the spacecraft lacks or bad wheel axes."""
    axes = np.asarray(ctx_p['wheel_axes_body'], dtype=float)
    n_wheels = len(ctx_p['wheel_max_torque_Nm'])
    if axes.size != 3 * n_wheels:
        raise ValueError(f'wheel_axes_body needs 3 values per wheel ({n_wheels} wheels), '
                         f'got {axes.size}')
    ctx: Dict[str, Any] = {
        'inertia_kgm2': inertia_matrix(ctx_p['inertia_kgm2']),
        'max_dipole_Am2': ctx_p['max_dipole_Am2'] if any(ctx_p['max_dipole_Am2']) else None,
        'wheel_axes_body': axes.reshape(n_wheels, 3),
        'wheel_max_torque_Nm': ctx_p['wheel_max_torque_Nm'],
        'wheel_max_momentum_Nms': ctx_p['wheel_max_momentum_Nms'],
        'wheel_inertia_kgm2': ctx_p['wheel_inertia_kgm2'],
        'period_s': ctx_p['period_s'], 'epoch': epoch, 'seed': seed, 'reference': None}
    if 'magnetorquer' in entry.actuators and ctx['max_dipole_Am2'] is None:
        raise ValueError(f'controller {entry.name} commands magnetorquers but '
                         'max_dipole_Am2 is empty (no magnetorquer)')
    if 'wheels' in entry.actuators and n_wheels == 0:
        raise ValueError(f'controller {entry.name} commands wheels but none are configured')
    if {'estimate', 'magnetometer'} <= set(entry.inputs):
        ctx['reference'] = make_onboard_reference(onboard_orbit, onboard_field, epoch)
    elif 'estimate' in entry.inputs and n_wheels and ctx['max_dipole_Am2'] is not None:
        # the field for the magnetorquers' share when a wheel has failed (A5)
        ctx['backup_reference'] = make_onboard_reference(onboard_orbit, onboard_field, epoch)
    return ctx


def estimate_of(x: Optional[AttitudeState]) -> Optional[Estimate]:
    """Controller-core estimate of an ``adcs/attitude_estimate`` sample (None if absent).

    The orbit rate is recovered from its two rates:
    ``|omega_body_eci_body - omega_body_orbit_body| = omega0``.
    """
    if x is None:
        return None
    w_abs, w_rel, q, q_eci = (x.omega_body_eci_body, x.omega_body_orbit_body, x.q_orbit_body,
                              x.q_eci_body)
    valid = all_finite(q, w_abs, w_rel, q_eci)
    d = w_abs - w_rel
    omega0 = math.sqrt(d.dot(d)) if valid else 0.0       # np.linalg.norm's operations
    return Estimate(q, w_abs, omega0, valid, q_eci if valid else None)


def target_of(x: Optional[AttitudeTarget]) -> Optional[Target]:
    """Core target of an ``adcs/attitude_target`` sample (None if absent or malformed: a
    frame other than ``orbit``/``eci``, a value not finite, a near-zero quaternion)."""
    if x is None:
        return None
    q, w, a = x.q_ref_body, x.omega_body_ref_body, x.omega_dot_body_ref_body
    frame = x.frame or 'orbit'
    if frame not in ('orbit', 'eci') or not all_finite(q, w, a) or q.shape != (4,):
        return None
    q_max = max(map(abs, q.tolist()))             # |q| of 1e300 would overflow: scaled first
    if q_max == 0.0 or math.sqrt(sum((v / q_max) ** 2 for v in q.tolist())) * q_max < 0.5:
        return None
    return Target(att.normalize(q), w, a, frame, float(x.time_to_go_s))


def command_sample(cmd: Command, t_ns: int, source: str) -> ActuatorCommand:
    """Core command -> the ``ActuatorCommand`` sample sent (arrays copied as float64)."""
    return ActuatorCommand(t_ns, np.array(cmd.dipole_body, dtype=float),
                           np.array(cmd.wheel_torque, dtype=float).reshape(-1),
                           np.array(cmd.torque_body, dtype=float), source)


def command_of(x: ActuatorCommand) -> Command:
    """An ``ActuatorCommand`` sample -> core command (values as sent, unchecked); a
    ``source`` ``'<name>: <reason>'`` is a refusal with its ``reason``, ``'<name>; <note>'``
    a usable command with a ``note`` in ``info`` (e.g. a failed wheel)."""
    src = str(x.source)
    i, j = src.find('; '), src.find(': ')
    refused = j >= 0 and not 0 <= i < j
    note = src[i + 2:] if i >= 0 and not refused else ''
    return Command(x.dipole_body_Am2, x.wheel_torque_Nm, x.torque_body_Nm,
                   src[j + 2:] if refused else '', {'note': note} if note else {}, refused)


_NO_LIMIT = np.full(3, np.inf)
#: Input keys of the built-in records (a plugin's kinds reach its controller as ``samples``).
_BUILTIN = frozenset(rec.key for rec in inputs.INPUTS)


class ControllerComponent:
    """One registered controller core with its input conditioning.

    Parameters
    ----------
    core
        The built controller (``entry.build(params, context)``).
    name : str
        Its registry name (the command's ``source``).
    ctx : dict
        The spacecraft context it was built with (``reference``: onboard models or None,
        ``wheel_*``: the wheels).
    mounts
        ``lookup(frame_id) -> q_body_sensor or None``.
    """

    def __init__(self, core: Any, name: str, ctx: Dict[str, Any], mounts: Any) -> None:
        self.core = core
        self.name = name
        self.ctx = ctx
        self.mounts = mounts
        self.n_wheels = len(ctx.get('wheel_max_torque_Nm') or [])
        self._last_t: Optional[int] = None
        #: the wheel check (a controller reading the tachometer and the applied command)
        self.wheel_health: Optional[WheelHealth] = None
        if self.n_wheels and len(ctx.get('wheel_inertia_kgm2') or []) == self.n_wheels \
                and len(ctx.get('wheel_max_momentum_Nms') or []) == self.n_wheels:
            self.wheel_health = WheelHealth(ctx['wheel_inertia_kgm2'],
                                            ctx['wheel_max_momentum_Nms'], ctx['period_s'],
                                            max_torque_Nm=ctx['wheel_max_torque_Nm'])
        dipole = ctx.get('max_dipole_Am2')
        self.backup_dipole = None if dipole is None else np.asarray(dipole, dtype=float)
        self.max_dipole = np.zeros(3) if dipole is None else self.backup_dipole
        self.max_wheel = np.asarray(ctx.get('wheel_max_torque_Nm') or [], dtype=float)

    def inputs_for(self, t_ns: int, inputs: Dict[str, Any],
                   fresh: Callable[[str], bool]) -> ControlInputs:
        """Samples of frame ``t_ns`` -> the core's :class:`ControlInputs`.

        Sensor samples (magnetometer, horizon, gyro, star tracker) only when fresh (lockstep:
        stamped t; live: newer than the last one used), each checked
        (:mod:`~adcs_nodes.components.conditioning`; a rejected one reads as None); the
        estimate, target and wheel speeds are the latest.
        """
        def sample(key, convert):
            x = inputs.get(key)
            return convert(x)[0] if x is not None and fresh(key) else None
        t = t_ns / NS_PER_S
        estimate = estimate_of(inputs.get('est'))
        b_model = None
        health = self.wheel_health
        wheel_ok = None if health is None or all(health.ok) else health.ok
        ref = self.ctx['reference'] or (None if wheel_ok is None else
                                        self.ctx.get('backup_reference'))
        if ref is not None and estimate is not None and estimate.is_usable():
            b_model = att.to_matrix(estimate.q_orbit_body).T @ ref.at(t).b_orbit  # n* = R^T B*
        wheels = inputs.get('wheels')
        speeds = None if wheels is None else cond.wheel_speeds(wheels, self.n_wheels)[0]
        return ControlInputs(
            estimate, target_of(inputs.get('target')),
            sample('mag', lambda x: cond.field_body(x, self.mounts)), b_model, speeds,
            wheel_momentum(speeds, self.ctx),
            horizon_roll_pitch=sample('horizon', cond.horizon_roll_pitch),
            gyro_rate_body=sample('gyro', lambda x: cond.gyro_rate_body(x, self.mounts)),
            q_eci_body_meas=sample('star', cond.star_q_eci_body),
            applied_dipole_body=cond.applied_dipole(inputs['cmd']) if 'cmd' in inputs else None,
            samples={k: v for k, v in inputs.items() if k not in _BUILTIN and fresh(k)},
            wheel_ok=wheel_ok,
            backup_dipole_Am2=None if wheel_ok is None else self.backup_dipole)

    def step(self, t_ns: int, inputs: Dict[str, Any],
             fresh: Callable[[str], bool]) -> ActuatorCommand:
        """This controller's command for frame ``t_ns``, checked (module docstring)."""
        dt = 0.0 if self._last_t is None else (t_ns - self._last_t) / NS_PER_S
        self._last_t = t_ns
        self._check_wheels(inputs)
        cmd = self.core.update(self.inputs_for(t_ns, inputs, fresh), t_ns / NS_PER_S, dt)
        health = self.wheel_health
        failed = health is not None and not all(health.ok)
        why = command_fields(cmd, self.max_dipole, self.max_wheel, _NO_LIMIT)[1]
        if failed and not why and np.shape(cmd.wheel_torque) == (self.n_wheels,):
            bad = [n for n, ok, v in zip(health.names, health.ok, cmd.wheel_torque)
                   if not ok and v != 0.0]
            why = f'commands torque on the failed wheel {", ".join(bad)}' if bad else ''
        if why or getattr(cmd, 'refused', False):
            why = '; '.join(r for r in (health.reason() if failed else '',
                                        why or cmd.reason or 'refused') if r)
            return command_sample(Command.zero(self.n_wheels), t_ns, f'{self.name}: {why}')
        if not failed:
            return command_sample(cmd, t_ns, self.name)
        if np.shape(cmd.wheel_torque) == (self.n_wheels,):                  # its probe
            cmd = Command(cmd.dipole_body, cmd.wheel_torque + health.probe(), cmd.torque_body)
        return command_sample(cmd, t_ns, f'{self.name}; {health.reason()}')

    def _check_wheels(self, inputs: Dict[str, Any]) -> None:
        """This frame's wheel check (with both the tachometer and the applied command)."""
        if self.wheel_health is None or 'wheels' not in inputs or 'cmd' not in inputs:
            return
        wheels, cmd = inputs.get('wheels'), inputs.get('cmd')
        if wheels is None:
            return
        if len(wheels.names) == self.n_wheels:
            self.wheel_health.names = list(wheels.names)
        speeds = cond.wheel_speeds(wheels, self.n_wheels)[0]
        self.wheel_health.update(
            wheels.t_ns / NS_PER_S, speeds, None if cmd is None else cmd.t_ns / NS_PER_S,
            None if cmd is None else cmd.wheel_torque_Nm)
