"""The spacecraft and its initial state: their specs (:data:`SPACECRAFT`, :data:`INITIAL`:
the scenario's ``spacecraft`` and ``initial`` sections, the dynamics node's ``spacecraft.*``
and ``initial.*`` parameters) and the models built from their validated values. Each random
model has its own seed derived from ``seed`` and its name.
"""
from __future__ import annotations

import math
from typing import Any, Dict, List

import numpy as np

from adcs_nodes.core import attitude as att
from adcs_nodes.core.lockstep import derive_seed
from adcs_nodes.core.spec import REQUIRED, Param, Section, SpecError, all_or_none
from sim_node.models.actuators import Magnetorquer, WheelCluster, WheelMomentumError
from sim_node.models.disturbances import (ConstantTorque, HarmonicTorque, PeriodicPulseTorque,
                                          RandomTorque)
from sim_node.models.dynamics import FlexibleModes, Spacecraft, SpacecraftState
from sim_node.models.flexible import DEFAULT_DAMPING, paper001_modes


def _unique_names(wheels: List[Dict[str, Any]]) -> List[Dict[str, Any]]:
    names = [w['name'] for w in wheels]
    if len(set(names)) != len(names):
        raise SpecError('', f'duplicate wheel names {names}')
    return wheels


def _amplitudes(name: str, what: str) -> Param:
    return Param(name, 'vec3', [0.0, 0.0, 0.0], 'N m', what, min=0.0)


def _named(name: str) -> str:
    if not name:
        raise ValueError('a wheel needs a name')
    return name


_WHEEL = (
    Param('name', 'str', REQUIRED, '-', 'wheel name', check=_named),
    Param('axis', 'vec3', REQUIRED, '-', 'spin axis, body axes (normalised)'),
    Param('max_torque_Nm', 'float', REQUIRED, 'N m', 'motor torque limit', positive=True),
    Param('max_momentum_Nms', 'float', REQUIRED, 'N m s', 'momentum limit', positive=True),
    Param('inertia_kgm2', 'float', 1e-3, 'kg m^2', 'wheel inertia about its axis',
          positive=True),
    Param('h0_Nms', 'float', 0.0, 'N m s', 'initial wheel momentum'))

#: The ``spacecraft`` section.
SPACECRAFT = Section('spacecraft', (
    Param('inertia_kgm2', 'matrix3', REQUIRED, 'kg m^2', 'inertia tensor about the centre of '
          'mass, body axes: 3 diagonal values or a 3x3 matrix'),
    Param('gravity_gradient', 'bool', True, '-', 'apply the gravity-gradient torque'),
    Section('magnetorquer', (Param('max_dipole_Am2', 'vec3', REQUIRED, 'A m^2',
                                   'per-axis dipole limit (all zero: none)', min=0.0,
                                   check=all_or_none),), optional=True),
    Section('ideal_torque', (Param('max_torque_Nm', 'vec3', REQUIRED, 'N m', 'per-axis limit '
                                   'of an ideal body-torque actuator (thrusters, or a '
                                   'stand-in for wheels)', min=0.0),), optional=True),
    Param('wheels', 'table', [], '-', 'reaction wheels', fields=_WHEEL, check=_unique_names),
    Param('wheel_error_std_Nms', 'float', 0.0, 'N m s', 'momentum control error of every '
          'wheel, 1-sigma, redrawn each wheel_error_period_s (paper 001: 0.01/3); 0: none',
          min=0.0),
    Param('wheel_error_period_s', 'float', None, 's', 'period of the momentum error draws '
          '(default: controllers.period_s, else timing.frame_s)', positive=True),
    Section('flexible', (
        Param('model', 'str', 'paper001', '-', "flexible appendage modes: paper 001's two "
              'solar wings (5 modes each, coupling (32))', choices=('paper001',)),
        Param('wings', 'str', 'two', '-', 'two: both wings (the -X wing mirrored, 10 modes); '
              'one: the +X wing only (5 modes)', choices=('one', 'two')),
        Param('damping', 'float', DEFAULT_DAMPING, '-', 'modal damping ratio of every mode '
              '(the paper gives none)', min=0.0, max=1.0)), optional=True),
    Section('disturbance', (
        Param('constant_torque_Nm', 'vec3', [0.0, 0.0, 0.0], 'N m', 'constant body torque'),
        Param('random_std_Nm', 'float', 0.0, 'N m', 'std of the random body torque per axis',
              min=0.0),
        Param('random_period_s', 'float', 2.0, 's', 'hold time of each random draw',
              positive=True),
        _amplitudes('aerodynamic_Nm', 'aerodynamic torque amplitude per body axis, a sin(2 pi '
                    't / harmonic_period_s + seeded phase)'),
        _amplitudes('solar_pressure_Nm', 'solar pressure torque amplitude, same waveform'),
        _amplitudes('synthetic_gravity_gradient_Nm', 'a harmonic stand-in for the gravity '
                    'gradient at twice that frequency (paper 001 magnitudes)'),
        Param('harmonic_period_s', 'float', None, 's', 'period of the harmonic torques '
              '(default: the orbital period)', positive=True),
        Param('residual_magnetic_Nm', 'vec3', [0.0, 0.0, 0.0], 'N m', 'constant residual '
              'magnetic torque'),
        _amplitudes('unloading_Nm', 'momentum unloading torque per axis, seeded signs, on '
                    'unloading_duration_s every unloading_period_s'),
        Param('unloading_period_s', 'float', 600.0, 's', 'unloading period', positive=True),
        Param('unloading_duration_s', 'float', 60.0, 's', 'unloading pulse length', min=0.0),
        Param('unloading_start_s', 'float', 0.0, 's', 'first unloading pulse', min=0.0))),
), 'the spacecraft', standalone={'inertia_kgm2': [118.0, 118.0, 19.6]})   # paper 000's


def _rate(omega_deg_s: List[float]) -> List[float]:
    rate = math.sqrt(sum(w * w for w in omega_deg_s))
    if rate > MAX_RATE_DEG_S:
        raise ValueError(f'rate {rate:.6g} deg/s is above {MAX_RATE_DEG_S:g} deg/s')
    return omega_deg_s


#: ASSUMPTION: the largest initial body rate norm [deg/s] (catches typing errors).
MAX_RATE_DEG_S = 100.0
#: The ``initial`` section (absent keys: aligned with the orbit frame, at rest in it).
INITIAL = Section('initial', (
    Param('q_orbit_body_wxyz', 'quat', None, '-', 'initial attitude body->orbit, scalar FIRST '
          "(paper 000's Lambda)"),
    Param('q_orbit_body_xyzw', 'quat', None, '-', 'initial attitude body->orbit, scalar last'),
    Param('omega_body_eci_body_deg_s', 'vec3', None, 'deg/s', 'initial rate w.r.t. ECI, body '
          'axes', check=_rate),
    Param('omega_body_orbit_body_deg_s', 'vec3', None, 'deg/s', 'initial rate w.r.t. the '
          'orbit frame, body axes', check=_rate),
), 'the initial state')


def spacecraft_from_config(cfg: Dict[str, Any], seed: int) -> Spacecraft:
    """:class:`Spacecraft` from the :data:`SPACECRAFT` values ``cfg`` (validated here:
    :class:`~adcs_nodes.core.spec.SpecError` naming the key)."""
    cfg = SPACECRAFT.validate(cfg)
    mtq = Magnetorquer(cfg['magnetorquer']['max_dipole_Am2']) if 'magnetorquer' in cfg \
        else None
    wheels = None
    if cfg['wheels']:
        wheels = WheelCluster(np.asarray([w['axis'] for w in cfg['wheels']], dtype=float),
                              [w['max_torque_Nm'] for w in cfg['wheels']],
                              [w['max_momentum_Nms'] for w in cfg['wheels']],
                              [w['inertia_kgm2'] for w in cfg['wheels']])
    dist_cfg = cfg['disturbance']
    dist = []
    const = np.asarray(dist_cfg['constant_torque_Nm'], dtype=float)
    if np.any(const):
        dist.append(ConstantTorque(const))
    if dist_cfg['random_std_Nm'] > 0:
        dist.append(RandomTorque(dist_cfg['random_std_Nm'], dist_cfg['random_period_s'], seed))
    dist += _paper001_torques(dist_cfg, seed)
    wheel_error = None
    err = cfg['wheel_error_std_Nms']
    if err > 0.0:
        if wheels is None:
            raise ValueError('spacecraft.wheel_error_std_Nms needs wheels')
        wheel_error = WheelMomentumError(err, cfg.get('wheel_error_period_s', 0.2), wheels.n,
                                         derive_seed(seed, 'wheel_error'))
    return Spacecraft(np.asarray(cfg['inertia_kgm2'], dtype=float), magnetorquer=mtq,
                      wheels=wheels, disturbances=dist, gravity_gradient=cfg['gravity_gradient'],
                      flexible=flexible_from_config(cfg.get('flexible')),
                      wheel_error=wheel_error)


def flexible_from_config(flex: Dict[str, Any] | None) -> FlexibleModes | None:
    """:class:`FlexibleModes` of the validated ``flexible`` section (None without it):
    ``paper001``: the paper's five modes per wing and coupling (32)
    (``sim_node.models.flexible``)."""
    if flex is None:
        return None
    coupling, freq = paper001_modes(flex['wings'])
    return FlexibleModes(coupling, freq, flex['damping'])


def _paper001_torques(dist: Dict[str, Any], seed: int) -> list:
    """Paper 001's torque models (Sec. 6: magnitudes only; waveforms ASSUMPTION, digest
    section 6): aerodynamic and solar pressure ``a sin(2 pi t / T + phi)`` (D4) with
    seeded phases, a synthetic gravity gradient at twice that frequency, residual magnetic
    constant (D2), unloading pulses (D5) with seeded signs. Zero amplitudes: no model."""
    out = []
    period = dist.get('harmonic_period_s')
    for key, factor in (('aerodynamic_Nm', 1.0), ('solar_pressure_Nm', 1.0),
                        ('synthetic_gravity_gradient_Nm', 2.0)):
        amp = np.asarray(dist[key], dtype=float)
        if not amp.any():
            continue
        if period is None:
            raise ValueError(f'spacecraft.disturbance.{key} needs harmonic_period_s')
        out.append(HarmonicTorque(amp, factor * 2.0 * math.pi / period,
                                  seed=derive_seed(seed, key) % 2**63))
    residual = np.asarray(dist['residual_magnetic_Nm'], dtype=float)
    if residual.any():
        out.append(ConstantTorque(residual))
    amp = np.asarray(dist['unloading_Nm'], dtype=float)
    if amp.any():
        out.append(PeriodicPulseTorque(amp, dist['unloading_period_s'],
                                       dist['unloading_duration_s'], dist['unloading_start_s'],
                                       seed=derive_seed(seed, 'unloading_Nm') % 2**63))
    return out


def initial_state(cfg: Dict[str, Any], q_eci_orbit, omega_orbit_eci_eci,
                  spacecraft: Spacecraft, wheel_h0=None) -> SpacecraftState:
    """Initial :class:`SpacecraftState` from the validated :data:`INITIAL` values ``cfg``
    (default: aligned with and at rest in the orbit frame), the orbit frame ``q_eci_orbit``
    (4,) at t0 and its rate ``omega_orbit_eci_eci`` (3,) [rad/s], ECI, and the wheel momenta
    ``wheel_h0`` (n_wheels,) [N m s] (default zero)."""
    if 'q_orbit_body_wxyz' in cfg:
        w, x, y, z = cfg['q_orbit_body_wxyz']
        q_orbit_body = [x, y, z, w]
    else:
        q_orbit_body = cfg.get('q_orbit_body_xyzw', [0.0, 0.0, 0.0, 1.0])
    q_orbit_body = att.normalize(q_orbit_body)
    q_eci_body = att.normalize(att.multiply(q_eci_orbit, q_orbit_body))
    if 'omega_body_eci_body_deg_s' in cfg:
        omega = np.asarray([math.radians(v) for v in cfg['omega_body_eci_body_deg_s']])
    else:
        rel_deg_s = cfg.get('omega_body_orbit_body_deg_s', [0.0, 0.0, 0.0])
        rel = np.asarray([math.radians(v) for v in rel_deg_s])
        omega = rel + att.to_matrix(q_eci_body).T @ np.asarray(omega_orbit_eci_eci, float)
    h0 = np.zeros(spacecraft.n_wheels) if wheel_h0 is None else np.asarray(wheel_h0, float)
    state = spacecraft.zero_state(q_eci_body, omega, h0)     # modes at rest (paper 001)
    spacecraft.check_state(state)
    return state
