"""Build the spacecraft model and its initial state from flat configuration dicts.

The dynamics node passes its ``spacecraft.*`` and ``initial.*`` parameters here (the launcher
derives them from the scenario's ``spacecraft`` and ``initial`` sections, see
``adcs_nodes.graph``). Keys, all SI:

spacecraft: ``inertia_kgm2`` (9, row-major, or 3 diagonal), ``gravity_gradient``,
``max_dipole_Am2`` (3, optional: no magnetorquer without it), ``wheel_axes`` (3n),
``wheel_max_torque_Nm``, ``wheel_max_momentum_Nms``, ``wheel_inertia_kgm2``, ``wheel_h0_Nms``
(n each), ``constant_torque_Nm`` (3), ``random_std_Nm``, ``random_period_s``;
paper 001's torque models (``disturbances`` (D4), (D5)): ``aerodynamic_Nm``,
``solar_pressure_Nm``, ``synthetic_gravity_gradient_Nm``, ``residual_magnetic_Nm``,
``unloading_Nm`` (3 each, amplitudes), ``harmonic_period_s`` (period of the aerodynamic and
solar torques; the synthetic gravity gradient runs at half of it), ``unloading_period_s``,
``unloading_duration_s``, ``unloading_start_s``; wheel momentum control error
``wheel_error_std_Nms`` (1-sigma, 0: none) and ``wheel_error_period_s``; flexible appendages
``flexible.model`` (``paper001``), ``flexible.wings`` (``one``/``two``), ``flexible.damping``.
Each random model has its own seed derived from ``seed`` and its name.

initial: ``q_orbit_body`` (4, scalar last) and ``omega_body_eci_body`` or
``omega_body_orbit_body`` (3, rad/s).
"""
from __future__ import annotations

from typing import Any, Dict

import numpy as np

import math

from adcs_nodes.core import attitude as att
from adcs_nodes.core.lockstep import derive_seed
from sim_node.models.actuators import Magnetorquer, WheelCluster, WheelMomentumError
from sim_node.models.disturbances import (ConstantTorque, HarmonicTorque, PeriodicPulseTorque,
                                          RandomTorque)
from sim_node.models.dynamics import FlexibleModes, Spacecraft, SpacecraftState
from sim_node.models.flexible import DEFAULT_DAMPING, paper001_modes

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
             'wheel_h0_Nms', 'constant_torque_Nm', 'random_std_Nm', 'random_period_s',
             'aerodynamic_Nm', 'solar_pressure_Nm', 'synthetic_gravity_gradient_Nm',
             'residual_magnetic_Nm', 'unloading_Nm', 'harmonic_period_s', 'unloading_period_s',
             'unloading_duration_s', 'unloading_start_s', 'wheel_error_std_Nms',
             'wheel_error_period_s', 'flexible.model', 'flexible.wings', 'flexible.damping'}
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
    dist += _paper001_torques(cfg, seed)
    wheel_error = None
    err = float(cfg.get('wheel_error_std_Nms', 0.0))
    if err > 0.0:
        if wheels is None:
            raise ValueError('spacecraft.wheel_error_std_Nms needs wheels')
        wheel_error = WheelMomentumError(err, float(cfg.get('wheel_error_period_s', 0.2)),
                                         wheels.n, derive_seed(seed, 'wheel_error'))
    return Spacecraft(_inertia(cfg['inertia_kgm2']), magnetorquer=mtq, wheels=wheels,
                      disturbances=dist, gravity_gradient=bool(cfg.get('gravity_gradient', True)),
                      flexible=flexible_from_config(cfg), wheel_error=wheel_error)


def flexible_from_config(cfg: Dict[str, Any]) -> FlexibleModes | None:
    """:class:`FlexibleModes` of ``flexible.model`` (None without it); ``paper001``: the
    paper's five modes per wing and coupling (32) (``sim_node.models.flexible``)."""
    model = str(cfg.get('flexible.model', ''))
    if not model:
        return None
    if model != 'paper001':
        raise ValueError(f"spacecraft.flexible.model must be 'paper001', got {model!r}")
    coupling, freq = paper001_modes(str(cfg.get('flexible.wings', 'two')))
    return FlexibleModes(coupling, freq, float(cfg.get('flexible.damping', DEFAULT_DAMPING)))


def _amplitude(cfg: Dict[str, Any], key: str) -> np.ndarray:
    a = np.asarray(cfg.get(key, [0.0, 0.0, 0.0]), dtype=float).reshape(-1)
    if a.size == 1:
        a = np.full(3, a[0])
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a < 0.0):
        raise ValueError(f'spacecraft.{key} must be 3 finite amplitudes >= 0, got {a}')
    return a


def _paper001_torques(cfg: Dict[str, Any], seed: int) -> list:
    """Paper 001's torque models (Sec. 6: magnitudes only; waveforms ASSUMPTION, digest
    section 6): aerodynamic and solar pressure ``a sin(2 pi t / T + phi)`` (D4) with
    seeded phases, a synthetic gravity gradient at twice that frequency, residual magnetic
    constant (D2), unloading pulses (D5) with seeded signs. Zero amplitudes: no model."""
    out = []
    period = float(cfg.get('harmonic_period_s', 0.0))
    for key, factor in (('aerodynamic_Nm', 1.0), ('solar_pressure_Nm', 1.0),
                        ('synthetic_gravity_gradient_Nm', 2.0)):
        amp = _amplitude(cfg, key)
        if not amp.any():
            continue
        if not (math.isfinite(period) and period > 0.0):
            raise ValueError(f'spacecraft.{key} needs harmonic_period_s > 0, got {period}')
        out.append(HarmonicTorque(amp, factor * 2.0 * math.pi / period,
                                  seed=derive_seed(seed, key) % 2**63))
    residual = np.asarray(cfg.get('residual_magnetic_Nm', [0.0, 0.0, 0.0]), dtype=float)
    if residual.any():
        out.append(ConstantTorque(residual))
    amp = _amplitude(cfg, 'unloading_Nm')
    if amp.any():
        out.append(PeriodicPulseTorque(amp, float(cfg.get('unloading_period_s', 600.0)),
                                       float(cfg.get('unloading_duration_s', 60.0)),
                                       float(cfg.get('unloading_start_s', 0.0)),
                                       seed=derive_seed(seed, 'unloading_Nm') % 2**63))
    return out


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
    state = spacecraft.zero_state(q_eci_body, omega, h0)     # modes at rest (paper 001)
    spacecraft.check_state(state)
    return state
