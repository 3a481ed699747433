"""Build the spacecraft model and its initial state from flat configuration dicts.

The dynamics node passes its ``spacecraft.*`` and ``initial.*`` parameters here (the launcher
derives them from the scenario's ``spacecraft`` and ``initial`` sections, see
``adcs_nodes.tools.graph``). Keys, all SI:

spacecraft: ``inertia_kgm2`` (9, row-major, or 3 diagonal), ``gravity_gradient``,
``max_dipole_Am2`` (3, optional: no magnetorquer without it), ``wheel_axes`` (3n),
``wheel_max_torque_Nm``, ``wheel_max_momentum_Nms``, ``wheel_inertia_kgm2``, ``wheel_h0_Nms``
(n each), ``constant_torque_Nm`` (3), ``random_std_Nm``, ``random_period_s``.

initial: ``q_orbit_body`` (4, scalar last) and ``omega_body_eci_body`` or
``omega_body_orbit_body`` (3, rad/s).
"""
from __future__ import annotations

from typing import Any, Dict

import numpy as np

from adcs_nodes.core import attitude as att
from sim_node.models.actuators import Magnetorquer, WheelCluster
from sim_node.models.disturbances import ConstantTorque, RandomTorque
from sim_node.models.dynamics import Spacecraft, SpacecraftState

#: Defaults when the dynamics node runs alone: paper 000's microsatellite, no actuators.
DEFAULT_SPACECRAFT: Dict[str, Any] = {'inertia_kgm2': [118.0, 118.0, 19.6],
                                      'gravity_gradient': True}
#: Defaults: aligned with the orbit frame, at rest in it.
DEFAULT_INITIAL: Dict[str, Any] = {'q_orbit_body': [0.0, 0.0, 0.0, 1.0],
                                   'omega_body_orbit_body': [0.0, 0.0, 0.0]}


def _inertia(value) -> np.ndarray:
    a = np.asarray(value, dtype=float).reshape(-1)
    if a.size == 3:
        return np.diag(a)
    if a.size == 9:
        return a.reshape(3, 3)
    raise ValueError(f'spacecraft.inertia_kgm2 needs 3 or 9 values, got {a.size}')


def spacecraft_from_config(cfg: Dict[str, Any], seed: int) -> Spacecraft:
    """:class:`Spacecraft` from the flat ``spacecraft.*`` dict (see module docstring)."""
    known = {'inertia_kgm2', 'gravity_gradient', 'max_dipole_Am2', 'wheel_names', 'wheel_axes',
             'wheel_max_torque_Nm', 'wheel_max_momentum_Nms', 'wheel_inertia_kgm2',
             'wheel_h0_Nms', 'constant_torque_Nm', 'random_std_Nm', 'random_period_s'}
    unknown = set(cfg) - known
    if unknown:
        raise ValueError(f'unknown spacecraft parameters: {", ".join(sorted(unknown))}')
    mtq = Magnetorquer(cfg['max_dipole_Am2']) if 'max_dipole_Am2' in cfg else None
    wheels = None
    if len(cfg.get('wheel_axes', [])):
        axes = np.asarray(cfg['wheel_axes'], dtype=float).reshape(-1, 3)
        n = axes.shape[0]
        wheels = WheelCluster(axes, cfg['wheel_max_torque_Nm'], cfg['wheel_max_momentum_Nms'],
                              cfg.get('wheel_inertia_kgm2', [1e-3] * n))
    dist = []
    const = np.asarray(cfg.get('constant_torque_Nm', [0.0, 0.0, 0.0]), dtype=float)
    if np.any(const):
        dist.append(ConstantTorque(const))
    std = float(cfg.get('random_std_Nm', 0.0))
    if std > 0:
        dist.append(RandomTorque(std, float(cfg.get('random_period_s', 2.0)), seed))
    return Spacecraft(_inertia(cfg['inertia_kgm2']), magnetorquer=mtq, wheels=wheels,
                      disturbances=dist, gravity_gradient=bool(cfg.get('gravity_gradient', True)))


def initial_state(cfg: Dict[str, Any], q_eci_orbit, omega_orbit_eci_eci,
                  spacecraft: Spacecraft, wheel_h0=None) -> SpacecraftState:
    """Initial :class:`SpacecraftState` from ``initial.*`` and the orbit frame at t0.

    Parameters
    ----------
    cfg : dict
        ``q_orbit_body`` (4, scalar last) and ``omega_body_eci_body`` or
        ``omega_body_orbit_body`` [rad/s, body axes].
    q_eci_orbit : array_like, shape (4,)
        Orbit frame at t0.
    omega_orbit_eci_eci : array_like, shape (3,)
        Rate of the orbit frame w.r.t. ECI, ECI axes [rad/s] (for a relative initial rate).
    spacecraft : Spacecraft
    wheel_h0 : array_like, shape (n_wheels,), optional
        Initial wheel momenta [N m s]; zero by default.
    """
    q_orbit_body = att.normalize(cfg.get('q_orbit_body', [0.0, 0.0, 0.0, 1.0]))
    q_eci_body = att.normalize(att.multiply(q_eci_orbit, q_orbit_body))
    if 'omega_body_eci_body' in cfg:
        omega = np.asarray(cfg['omega_body_eci_body'], dtype=float)
    else:
        rel = np.asarray(cfg.get('omega_body_orbit_body', [0.0, 0.0, 0.0]), dtype=float)
        omega = rel + att.to_matrix(q_eci_body).T @ np.asarray(omega_orbit_eci_eci, float)
    h0 = np.zeros(spacecraft.n_wheels) if wheel_h0 is None else np.asarray(wheel_h0, float)
    state = SpacecraftState(q_eci_body, omega, h0)
    spacecraft.check_state(state)
    return state
