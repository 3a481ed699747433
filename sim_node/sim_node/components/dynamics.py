"""The dynamics' frame step: the truth of frame k (``sim/state``, ``sim/wheels``,
``sim/appendages``) and the integration from t_k to t_k+1 with the held command.

The equations of motion are :mod:`sim_node.models.dynamics` (rigid body, wheels, flexible
modes and the orbit in one compiled RK4 kernel); here: the initial state from the first
environment, the samples of the truth, a malformed command made safe (zero), the environment
carried along its orbit when it is stamped earlier than the frame, and the wheel driver
status.
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from adcs_nodes.components.base import Log, silent
from adcs_nodes.core import attitude as att
from adcs_nodes.core import samples as s
from adcs_nodes.core.lockstep import ZERO, derive_seed, ns_to_seconds
from adcs_nodes.core.samples import all_finite
from sim_node.faults import ActuatorFaults, Fault
from sim_node.models.dynamics import ActuatorCommand as Command
from sim_node.models.dynamics import FrameEnvironment, SpacecraftState, propagate_environment
from sim_node.models.spacecraft_config import initial_state, spacecraft_from_config

_ZERO3 = np.zeros(3)


def _f(a: Any) -> np.ndarray:
    return np.array(a, dtype=float)


class DynamicsComponent:
    """The spacecraft's motion (see module docstring).

    Parameters
    ----------
    spacecraft_cfg, initial_cfg : dict
        The ``spacecraft.*`` and ``initial.*`` sections (scenario keys).
    seed : int
        The scenario seed (the disturbance stream is ``derive_seed(seed,
        'dynamics/disturbance')``).
    frame_ns, substeps : int
        Frame length and RK4 substeps per frame.
    log : Log
    """

    def __init__(self, spacecraft_cfg: Dict[str, Any], initial_cfg: Dict[str, Any],
                 seed: int, frame_ns: int, substeps: int, log: Log = silent,
                 faults: Sequence[Fault] = ()) -> None:
        if substeps < 1:
            raise ValueError('substeps must be >= 1')
        self.spacecraft = spacecraft_from_config(
            spacecraft_cfg, seed=derive_seed(seed, 'dynamics/disturbance'))
        self.initial_cfg = initial_cfg
        wheels = spacecraft_cfg.get('wheels') or []
        self.wheel_names = [w['name'] for w in wheels] or [
            f'wheel{i}' for i in range(self.spacecraft.n_wheels)]
        self.wheel_h0 = [w['h0_Nms'] for w in wheels] or None
        self.frame_ns = int(frame_ns)
        self.substeps = int(substeps)
        self.log = log
        self.state: Optional[SpacecraftState] = None
        self._last_q_orbit_body: Optional[np.ndarray] = None
        self.last_cmd = self.spacecraft.zero_command()
        self.applied: Dict[str, Any] = {}
        self.rejected_commands = 0
        n = self.spacecraft.n_wheels
        self.applied_wheel_torque = np.zeros(n)
        self.wheel_torque_limited = np.zeros(n, dtype=bool)
        self.wheel_momentum_limited = np.zeros(n, dtype=bool)
        self.torque_limited_frames = 0
        self.momentum_limited_frames = 0
        self.faults = ActuatorFaults(faults, self.wheel_names)

    # ------------------------------------------------------------------ commands
    def to_command(self, x: s.ActuatorCommand) -> Command:
        """Sample -> model command; NaN or a wrong wheel count -> zero command, logged."""
        n = self.spacecraft.n_wheels
        wheel = _f(x.wheel_torque_Nm)
        if wheel.size == 0:
            wheel = np.zeros(n)
        dipole, torque = _f(x.dipole_body_Am2), _f(x.torque_body_Nm)
        if wheel.size != n or not all_finite(dipole, torque, wheel):
            self.rejected_commands += 1
            self.log('warning', f'rejected actuator command from {x.source!r} (non-finite '
                     f'or {wheel.size} wheel torques for {n} wheels): using zero command')
            return self.spacecraft.zero_command()
        return Command(dipole_body=dipole, wheel_torque=wheel, torque_body=torque)

    # ------------------------------------------------------------------ truth of frame k
    def truth(self, t_ns: int, env: s.EnvironmentSample) -> s.AttitudeState:
        """``sim/state`` of frame ``t_ns`` (the state is initialised at the first frame)."""
        if self.state is None:
            self.state = initial_state(self.initial_cfg, env.q_eci_orbit,
                                       env.omega_orbit_eci_eci, self.spacecraft, self.wheel_h0)
        st = self.state
        r_body_eci = att.to_matrix(st.q_eci_body).T
        q_orbit_body = att.multiply(att.conjugate(env.q_eci_orbit), st.q_eci_body)
        if self._last_q_orbit_body is not None and q_orbit_body @ self._last_q_orbit_body < 0:
            q_orbit_body = -q_orbit_body     # keep the published sign continuous in time
        self._last_q_orbit_body = q_orbit_body
        w = _f(st.omega_body_eci_body)
        return s.AttitudeState(t_ns, _f(st.q_eci_body), q_orbit_body, w,
                               w - r_body_eci @ env.omega_orbit_eci_eci,
                               np.zeros(36))     # truth: no covariance

    def fault_events(self, t_ns: int) -> Optional[s.FaultEvents]:
        """``sim/faults`` of frame ``t_ns``: the faults that start or end in it (None: none)."""
        events = self.faults.events(t_ns, self.frame_ns)
        if not events:
            return None
        out = []
        for e in events:
            f = e['fault']
            out.append(s.FaultEvent(f.index, bool(e['active']), f.kind, f.target, f.describe(),
                                    tuple((k, str(v)) for k, v in sorted(f.params.items()))))
            self.log('warning' if e['active'] else 'info',
                     f't={t_ns / 1e9:g} s: fault ' + ('active: ' if e['active'] else 'cleared: ')
                     + f.describe())
        return s.FaultEvents(t_ns, tuple(out))

    def wheels(self, t_ns: int) -> s.WheelState:
        """``sim/wheels`` of the current state (momentum, speed, applied torque)."""
        st = self.state
        h = _f(st.h_wheels)
        wheels = self.spacecraft.wheels
        names = tuple(self.wheel_names)
        if wheels is None:
            return s.WheelState(t_ns, names, h, np.zeros(0), np.zeros(0), _ZERO3)
        return s.WheelState(t_ns, names, h, _f(wheels.speed(h, st.omega_body_eci_body)),
                            _f(self.applied_wheel_torque), _f(wheels.h_body(h)))

    def appendages(self, t_ns: int) -> Optional[s.AppendageState]:
        """``sim/appendages`` (modal coordinates) of a flexible spacecraft, else None."""
        if not self.spacecraft.n_modes:
            return None
        st = self.state
        return s.AppendageState(t_ns, _f(st.eta), _f(st.eta_dot),
                                _f(self.spacecraft.flexible.frequencies_hz))

    # ------------------------------------------------------------------ t_k -> t_k+1
    def step(self, t_ns: int, env_sample: s.EnvironmentSample, cmd: Any) -> None:
        """Zero-order-hold the command and integrate from t_k to t_k+1.

        ``cmd``: a model command, :data:`~adcs_nodes.core.lockstep.ZERO` (timeout or dead
        producer) or ``None`` (no command due: hold the previous one).
        """
        if cmd is ZERO:
            self.last_cmd = self.spacecraft.zero_command()
        elif cmd is not None:
            self.last_cmd = cmd
        env = FrameEnvironment(r_eci=env_sample.r_eci_m, v_eci=env_sample.v_eci_m_s,
                               b_eci=env_sample.b_eci_T, b_dot_eci=env_sample.b_dot_eci_T_s)
        # environment stamped earlier (timeout, real-time mode): carry it along its orbit and
        # field line; such a sample is no base for the model's in-frame field cubic (E8)
        dt_env = ns_to_seconds(t_ns - env_sample.t_ns)
        if dt_env:
            env = propagate_environment(env, dt_env, self.spacecraft.mu)
            self.spacecraft.reset_field_history()
        cmd = self.last_cmd
        dipole, wheel = self.faults.apply(t_ns, cmd.dipole_body, cmd.wheel_torque)
        if dipole is not cmd.dipole_body or wheel is not cmd.wheel_torque:
            cmd = Command(dipole_body=dipole, wheel_torque=wheel, torque_body=cmd.torque_body)
        self.state, self.applied = self.spacecraft.step(
            self.state, ns_to_seconds(t_ns), ns_to_seconds(self.frame_ns), env, cmd,
            self.substeps)
        if dt_env:
            self.spacecraft.reset_field_history()
        self.applied_wheel_torque = self.applied.get('wheel_torque', self.applied_wheel_torque)
        if 'momentum_limited' in self.applied:
            self._wheel_status(self.applied['torque_limited'], self.applied['momentum_limited'])

    def _wheel_status(self, torque_limited: np.ndarray, momentum_limited: np.ndarray) -> None:
        """Keep the wheel driver status of the last frame; log momentum-limit transitions."""
        for i in np.flatnonzero(momentum_limited != self.wheel_momentum_limited):
            self.log('info', f'{self.wheel_names[i]}: torque cut at the momentum limit'
                     if momentum_limited[i] else f'{self.wheel_names[i]}: off the momentum limit')
        self.wheel_torque_limited = np.asarray(torque_limited, dtype=bool)
        self.wheel_momentum_limited = np.asarray(momentum_limited, dtype=bool)
        self.torque_limited_frames += int(self.wheel_torque_limited.any())
        self.momentum_limited_frames += int(self.wheel_momentum_limited.any())

    def wheel_diagnostics(self) -> Dict[str, Any]:
        """Wheel driver status for ``/diagnostics`` (wheels only)."""
        if not self.spacecraft.n_wheels:
            return {}
        names = np.asarray(self.wheel_names, dtype=object)
        limited: List[str] = list(names[self.wheel_torque_limited])
        return {'wheels_torque_limited': ', '.join(limited) or 'none',
                'wheels_momentum_limited':
                    ', '.join(names[self.wheel_momentum_limited]) or 'none',
                'torque_limited_frames': self.torque_limited_frames,
                'momentum_limited_frames': self.momentum_limited_frames}
