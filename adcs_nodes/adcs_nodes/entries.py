"""Built-in registry entries: controllers and estimator algorithms of the flight software.

One entry per component (see :mod:`adcs_nodes.registry`). A ``build(params, ctx)`` function
turns validated parameters plus the graph context into the core object. The context ``ctx``
(a dict, filled by the node from its parameters) holds:

* ``inertia_kgm2``: (3, 3) onboard inertia [kg m^2];
* ``max_dipole_Am2``: (3,) coil limits [A m^2], or None without magnetorquers;
* ``wheel_axes_body``: (n, 3) spin axes; ``wheel_max_torque_Nm``, ``wheel_max_momentum_Nms``,
  ``wheel_inertia_kgm2``: (n,) each (n = 0 without wheels);
* ``period_s``: the component's period [s]; ``epoch``: aware datetime of t = 0;
* ``reference``: the onboard orbit/field model (:class:`~adcs_nodes.core.estimation.onboard.
  OnboardReference`), or None;
* ``seed``: the component's random seed.

Adding a controller: write its core module (``reset()``, ``update(ControlInputs, t, dt) ->
Command``), then add one ``register(Entry(...))`` here (or in a plugin module): nothing else.
"""
from __future__ import annotations

import math
from typing import Any, Dict

import numpy as np

from adcs_nodes.registry import Entry, Param, register

# ---------------------------------------------------------------------- controllers


def _n_wheels(ctx: Dict[str, Any]) -> int:
    return len(ctx.get('wheel_max_torque_Nm') or [])


def _build_magnetic(p: Dict[str, Any], ctx: Dict[str, Any]):
    from adcs_nodes.core.control.magnetic import MagneticController
    return MagneticController(
        mode=p['mode'], alpha=p['alpha_per_s'], k=p['k_Nms'],
        max_dipole_Am2=ctx['max_dipole_Am2'], beta=p['beta'] if p['beta'] > 0 else None,
        switch_angle_deg=p['switch_angle_deg'], switch_rate_deg_s=p['switch_rate_deg_s'],
        n_wheels=_n_wheels(ctx), inertia=ctx['inertia_kgm2'] if p['feedforward'] else None)


def _magnetic_gains(p: Dict[str, Any]) -> None:
    from adcs_nodes.core.control.magnetic import check_gains
    check_gains(p['alpha_per_s'], p['k_Nms'], p['beta'] if p['beta'] > 0 else None)


register(Entry(
    'controller', 'magnetic',
    'paper 000 magnetorquer laws to the orbital frame: three-axis (29)-(31), one-axis, '
    'two-stage',
    'adcs_nodes.core.control.magnetic:MagneticController',
    (Param('mode', 'str', 'three_axis', '-', 'paper 000 law',
           choices=('three_axis', 'one_axis', 'two_stage')),
     Param('alpha_per_s', 'float', 3e-3, '1/s', 'kinematic gain alpha of (16)', positive=True),
     Param('k_Nms', 'float', 0.2, 'N m s', 'rate gain k of (27)', positive=True),
     Param('beta', 'float', 0.0, 'J', 'Lyapunov weight of (25) for the start-up check '
           'k > beta/(2 alpha) (28); 0: no check', min=0.0),
     Param('switch_angle_deg', 'float', 15.0, 'deg', 'two_stage: switch below this angle',
           positive=True, max=180.0),
     Param('switch_rate_deg_s', 'float', 0.2, 'deg/s', 'two_stage: and below this rate',
           positive=True),
     Param('feedforward', 'bool', False, '-', 'beyond paper 000: add the gyroscopic and '
           'gravity-gradient torques of the estimate to M* (F1); false: the paper\'s law')),
    _build_magnetic, inputs=('estimate', 'target', 'magnetometer'),
    actuators=('magnetorquer',), check=_magnetic_gains))


def _build_bdot(p: Dict[str, Any], ctx: Dict[str, Any]):
    from adcs_nodes.core.control.bdot import BdotController
    return BdotController(gain=p['gain_Am2s_per_T'], max_dipole_Am2=ctx['max_dipole_Am2'],
                          filter_time_constant_s=p['filter_time_constant_s'],
                          n_wheels=_n_wheels(ctx))


register(Entry(
    'controller', 'bdot',
    'B-dot detumbling, the safe mode: needs nothing but the magnetometer',
    'adcs_nodes.core.control.bdot:BdotController',
    (Param('gain_Am2s_per_T', 'float', 1.0e6, 'A m^2 s/T', 'B-dot gain k: m = -k dB/dt',
           positive=True),
     Param('filter_time_constant_s', 'float', 0.0, 's', 'low-pass of dB/dt (0: none)',
           min=0.0)),
    _build_bdot, inputs=('magnetometer',), actuators=('magnetorquer',)))


def _wheel_kwargs(ctx: Dict[str, Any]) -> Dict[str, Any]:
    """Reaction wheels of the context for a torque controller (none: ideal body torque)."""
    if not _n_wheels(ctx):
        return {}
    return dict(wheel_axes_body=ctx['wheel_axes_body'],
                wheel_max_torque_Nm=ctx['wheel_max_torque_Nm'])


_FUZZY_BREAKPOINTS = ('phi_peaks_deg', 'dphi_peaks_deg_s', 'mk_peaks_Nm', 'mk_half_width_Nm',
                      'mk_gain', 'g_peaks_deg_s', 'dg_peaks_deg_s2', 'mgk_peaks_Nm',
                      'mgk_half_width_Nm')


def _build_fuzzy(p: Dict[str, Any], ctx: Dict[str, Any]):
    from adcs_nodes.core.control.fuzzy import FuzzyEigenaxisController
    return FuzzyEigenaxisController(
        ctx['inertia_kgm2'], p['max_torque_Nm'], table1_rows=p['table1_rows'],
        compensation=p['compensation'], saturation=p['saturation'], n_points=p['n_points'],
        **_wheel_kwargs(ctx), **{k: p[k] for k in _FUZZY_BREAKPOINTS})


_ASSUMED = 'ASSUMPTION (paper: figure only)'


def _increasing(peaks):
    if any(b <= a for a, b in zip(peaks, peaks[1:])):
        raise ValueError(f'must be strictly increasing, got {peaks}')
    return peaks


register(Entry(
    'controller', 'fuzzy',
    'paper 003 fuzzy eigenaxis slew: Mamdani Table 1 (angle, rate) + Table 2 (gyroscopic '
    'compensation); any target attitude; ideal torque or wheels',
    'adcs_nodes.core.control.fuzzy:FuzzyEigenaxisController',
    (Param('max_torque_Nm', 'float', 1.0, 'N m', 'per-axis torque limit |M_i| (paper: 1)',
           positive=True),
     Param('table1_rows', 'str', 'reversed', '-', 'Table 1 row reading: reversed (rows in the '
           "text's order of the phi terms; the one that settles) or as_printed",
           choices=('reversed', 'as_printed')),
     Param('compensation', 'bool', True, '-', 'run the gyroscopic compensation controller '
           '(Table 2)'),
     Param('saturation', 'str', 'scale', '-', 'torque limit: scale (keep the direction) or '
           'clip per axis', choices=('scale', 'clip')),
     Param('n_points', 'int', 501, '-', 'output grid points of the centroid', min=3,
           max=100001),
     Param('phi_peaks_deg', 'float[]', [0.0, 2.5, 10.0, 30.0, 90.0], 'deg',
           f'term peaks of phi (Н, ОМ, М, С, Б); {_ASSUMED}', length=5, min=0.0, max=180.0,
           check=_increasing),
     Param('dphi_peaks_deg_s', 'float[]', [-6.4, -4.8, -2.4, -0.8, 0.0, 0.8, 2.4, 4.8, 6.4],
           'deg/s', f'term peaks of phi_dot (ОБ .. ПБ); {_ASSUMED}', length=9, check=_increasing),
     Param('mk_peaks_Nm', 'float[]', [-1.0, -0.75, -0.5, -0.25, 0.0, 0.25, 0.5, 0.75, 1.0],
           'N m', f'term peaks of M_k (ОБ .. ПБ); {_ASSUMED}', length=9, check=_increasing),
     Param('mk_half_width_Nm', 'float', 0.25, 'N m', f'half width of the M_k triangles; '
           f'{_ASSUMED}', positive=True),
     Param('mk_gain', 'float', 3.7, '-', 'gain on the defuzzified M_k before the limit '
           '(ASSUMPTION: not in the paper)', positive=True),
     Param('g_peaks_deg_s', 'float[]', [-0.2, -0.1, 0.0, 0.1, 0.2], 'deg/s',
           f'term peaks of |phidot_g| (ОБ, ОС, Н, ПС, ПБ); {_ASSUMED}', length=5,
           check=_increasing),
     Param('dg_peaks_deg_s2', 'float[]', [-0.2, -0.1, 0.0, 0.1, 0.2], 'deg/s^2',
           f'term peaks of d|phidot_g|/dt (15); {_ASSUMED}', length=5, check=_increasing),
     Param('mgk_peaks_Nm', 'float[]', [-0.4, -0.2, 0.0, 0.2, 0.4], 'N m',
           f'term peaks of M_gk; {_ASSUMED}', length=5, check=_increasing),
     Param('mgk_half_width_Nm', 'float', 0.2, 'N m', f'half width of the M_gk triangles; '
           f'{_ASSUMED}', positive=True)),
    _build_fuzzy, inputs=('estimate', 'target'), actuators=('torque',)))


def _build_reference_slew(p: Dict[str, Any], ctx: Dict[str, Any]):
    from adcs_nodes.core.control.reference_slew import ReferenceSlewController
    return ReferenceSlewController(
        ctx['inertia_kgm2'], p['max_torque_Nm'], accel_fraction=p['accel_fraction'],
        rate_gain_per_s=p['rate_gain_per_s'], linear_gain_per_s=p['linear_gain_per_s'],
        max_rate_deg_s=p['max_rate_deg_s'] if p['max_rate_deg_s'] > 0 else float('inf'),
        gyroscopic_compensation=p['gyroscopic_compensation'], **_wheel_kwargs(ctx))


register(Entry(
    'controller', 'reference_slew',
    "paper 003's comparison: near time-optimal rest-to-rest eigenaxis slew (bang-bang rate "
    'profile, PD end) under a per-axis torque limit; ideal torque or wheels',
    'adcs_nodes.core.control.reference_slew:ReferenceSlewController',
    (Param('max_torque_Nm', 'float', 1.0, 'N m', 'per-axis torque limit |M_i|', positive=True),
     Param('accel_fraction', 'float', 0.9, '-', 'fraction of the admissible eigenaxis '
           'acceleration planned', positive=True, max=1.0),
     Param('rate_gain_per_s', 'float', 2.0, '1/s', 'rate-loop gain k', positive=True),
     Param('linear_gain_per_s', 'float', 0.5, '1/s', 'slope lambda of the linear (PD) end '
           'of the rate profile', positive=True),
     Param('max_rate_deg_s', 'float', 0.0, 'deg/s', 'cap on the profile rate (0: none)',
           min=0.0),
     Param('gyroscopic_compensation', 'bool', True, '-', 'add omega x J omega (off: the '
           'classical law on assumption (10) of paper 003)')),
    _build_reference_slew, inputs=('estimate', 'target'), actuators=('torque',)))


def _nine_or_none(values):
    if values and len(values) != 9:
        raise ValueError(f'expected 9 values (row-major 3x3) or none, got {len(values)}')
    return values


def _build_mpi(p: Dict[str, Any], ctx: Dict[str, Any]):
    from adcs_nodes.core.control.mpi import MPIController
    inertia = p['model_inertia_kgm2']
    inertia = np.reshape(inertia, (3, 3)) if inertia else ctx['inertia_kgm2']
    if not _n_wheels(ctx):
        raise ValueError('controller mpi needs reaction wheels (spacecraft.wheels)')
    return MPIController(
        inertia, ctx['wheel_axes_body'], ctx['wheel_max_torque_Nm'],
        ctx['wheel_max_momentum_Nms'], ctx['period_s'],
        **{k: v for k, v in p.items() if k != 'model_inertia_kgm2'})


register(Entry(
    'controller', 'mpi',
    'paper 001 MPI: feedback-linearised model, power-series state transition, generalised '
    'inverse to reaction-wheel torque; maneuvers with a deadline, stabilisation, tracking',
    'adcs_nodes.core.control.mpi:MPIController',
    (Param('series_order', 'int', 5, '-', 'order N of the power series of Phi and Q (19)-(21) '
           '(paper: 5)', min=1, max=30),
     Param('literal_model', 'bool', False, '-', "the paper's model without the constant "
           'gyroscopic terms [w0 hz, 0, -w0 hx] (digest P2)'),
     Param('min_horizon_s', 'float', 0.0, 's', 'horizon floor in a maneuver (ASSUMPTION); '
           '0: one control period', min=0.0),
     Param('hold_horizon_s', 'float', 0.0, 's', 'horizon when stabilising or tracking; 0: '
           "one control period (the paper's); DEPARTURE from the paper when > 0: longer "
           'softens the rate loop (digest P14); 0.4 with reference_time t0_plus_tau is the '
           'two-wing variant (docs/paper001.md)', min=0.0),
     Param('saturation', 'str', 'scale', '-', 'wheel torque limit: scale (one factor, keeps '
           'the direction) or clip per wheel', choices=('scale', 'clip')),
     Param('reference_time', 'str', 't0', '-', "desired state from the target at t0 (the "
           "paper's tracking lag) or propagated to t0 + tau (DEPARTURE from the paper)",
           choices=('t0', 't0_plus_tau')),
     Param('exact_transition', 'bool', False, '-', 'expm instead of the power series '
           '(digest P6 study)'),
     Param('model_inertia_kgm2', 'float[]', [], 'kg m^2', "the controller's own inertia, 9 values "
           'row-major (paper 001: eq. (31), 5 % off the truth); empty: the onboard inertia of '
           'the spacecraft', check=_nine_or_none)),
    # the applied command: the wheel check (components/controller.py, core/wheel_health.py)
    _build_mpi, inputs=('estimate', 'target', 'wheel_speeds', 'actuator_command'),
    actuators=('wheels',),
    requires=('spacecraft.wheels',)))


# ---------------------------------------------------------------------- estimators
_P0_HELP = ('initial covariance diagonal: attitude (phi or mu) [-], rate [rad^2/s^2], '
            'disturbance [1/s^4]; empty: the default of the measurement form')


def _filter_args(p: Dict[str, Any]) -> Dict[str, Any]:
    """Keyword arguments of the paper-000 filter wrappers from their registry parameters."""
    return dict(theta=p['theta_T2'], tau=p['tau'], p0_diag=p['p0_diag'] or None,
                measurement_form=p['measurement_form'], literal_update=p['literal_update'],
                substeps=p['substeps'], max_rate_rad_s=p['max_rate_rad_s'],
                max_disturbance_rad_s2=p['max_disturbance_rad_s2'],
                use_sensor_covariance=p['use_sensor_covariance'],
                theta_interval_s=p['theta_interval_s'], hypotheses=p['hypotheses'],
                hypothesis_window_s=p['hypothesis_window_s'],
                misalignment_std0_rad=math.radians(p['misalignment_std0_deg']))


def _build_magnetic_filter(p: Dict[str, Any], ctx: Dict[str, Any]):
    from adcs_nodes.core.estimation.algorithms import MagneticFilterEstimator
    return MagneticFilterEstimator(ctx['inertia_kgm2'], **_filter_args(p))


MAGNETIC_FILTER_PARAMS = (
    Param('theta_T2', 'float', 9e-14, 'T^2', 'theta of (38): measurement noise bound',
          positive=True),
    Param('tau', 'float', 0.01, '-', 'tau of (38): covariance inflation', min=0.0),
    Param('p0_diag', 'float[]', [], '-', _P0_HELP, positive=True),
    Param('measurement_form', 'str', 'phi', '-', 'measurement model: (36) phi or (37) mu',
          choices=('phi', 'mu')),
    Param('literal_update', 'bool', False, '-', "the paper's literal (38) (raw residuals "
          'summed) instead of sequential innovations'),
    Param('substeps', 'int', 1, '-', 'RK4 substeps per prediction', min=1, max=1000),
    Param('max_rate_rad_s', 'float', 1.0, 'rad/s', 'divergence guard: a larger estimated '
          'rate restarts the filter (not in the paper)', positive=True),
    Param('max_disturbance_rad_s2', 'float', 1e-2, 'rad/s^2', 'divergence guard on the '
          'disturbance state (not in the paper)', positive=True),
    Param('use_sensor_covariance', 'bool', True, '-', "theta per axis from the sample's "
          'magnetic_field_covariance when the driver gives one (never below theta_T2); '
          "false: the paper's single theta"),
    Param('theta_interval_s', 'float', 10.0, 's', 'the sample interval theta_T2 and tau are '
          'given for (paper 000: 10 s); a sample d < this after the last one updates with '
          'theta x this/d and tau x d/this (the noise model follows the sample interval); '
          '0: off', min=0.0),
    Param('hypotheses', 'int', 1, '-', 'beyond paper 000: at the first lock, this many '
          'hypotheses turned about the measured field run side by side and the likeliest goes '
          "on (core/estimation/hypotheses.py); 1: the paper's single filter", min=1, max=12),
    Param('hypothesis_window_s', 'float', 2000.0, 's', 'time from the start of the hypotheses '
          'to the choice (scored over its second half)', positive=True),
    Param('misalignment_std0_deg', 'float', 0.0, 'deg', 'beyond paper 000: prior std of a '
          "magnetometer misalignment estimated in 3 more states; 0: the paper's 9 states",
          min=0.0, max=15.0),
)

register(Entry(
    'estimator', 'magnetic_filter',
    'paper 000 magnetometer-only attitude, rate and disturbance filter (33)-(39)',
    'adcs_nodes.core.estimation.algorithms:MagneticFilterEstimator',
    MAGNETIC_FILTER_PARAMS, _build_magnetic_filter,
    inputs=('magnetometer', 'actuator_command')))


def _build_magnetic_filter_bias(p: Dict[str, Any], ctx: Dict[str, Any]):
    from adcs_nodes.core.estimation.magnetic_filter_bias import MagneticFilterBiasEstimator
    return MagneticFilterBiasEstimator(
        ctx['inertia_kgm2'], **_filter_args(p), bias0_T=p['bias0_T'],
        bias_std0_T=p['bias_std0_T'], magnitude_std_T=p['magnitude_std_T'],
        bias_walk_T_sqrt_s=p['bias_walk_T_sqrt_s'], max_bias_T=p['max_bias_T'],
        bias_gate_sigma=p['bias_gate_sigma'])


register(Entry(
    'estimator', 'magnetic_filter_bias',
    "beyond paper 000: the paper's filter plus a constant magnetometer bias estimated from "
    'field-magnitude residuals',
    'adcs_nodes.core.estimation.magnetic_filter_bias:MagneticFilterBiasEstimator',
    MAGNETIC_FILTER_PARAMS + (
        Param('bias0_T', 'float[]', [0.0, 0.0, 0.0], 'T', 'initial bias estimate, body axes',
              length=3, min=-1e-4, max=1e-4),
        Param('bias_std0_T', 'float', 2e-7, 'T', 'initial bias std per axis', positive=True,
              max=1e-4),
        Param('magnitude_std_T', 'float', 3e-7, 'T', 'std of a field-magnitude residual',
              positive=True, max=1e-4),
        Param('bias_walk_T_sqrt_s', 'float', 0.0, 'T/sqrt(s)', 'bias random walk (0: '
              'constant bias)', min=0.0),
        Param('max_bias_T', 'float', 5e-6, 'T', 'largest accepted bias estimate per axis',
              positive=True),
        Param('bias_gate_sigma', 'float', 5.0, '-', 'magnitude residuals beyond this many '
              'sigma are not used for the bias', positive=True)),
    _build_magnetic_filter_bias, inputs=('magnetometer', 'actuator_command')))


def _build_geometric(method: str):
    def build(p: Dict[str, Any], ctx: Dict[str, Any]):
        from adcs_nodes.core.estimation.algorithms import GeometricEstimator
        return GeometricEstimator(method)
    return build


register(Entry(
    'estimator', 'triad',
    'TRIAD of the nadir (horizon sensor) and the field; rate by finite difference',
    'adcs_nodes.core.estimation.algorithms:GeometricEstimator', (),
    _build_geometric('triad'), inputs=('magnetometer', 'horizon')))

register(Entry(
    'estimator', 'horizon_mag_yaw',
    'paper 004: roll, pitch from the horizon sensor, yaw from formula (3); rate by finite '
    'difference',
    'adcs_nodes.core.estimation.algorithms:GeometricEstimator', (),
    _build_geometric('horizon_mag_yaw'), inputs=('magnetometer', 'horizon')))


def _build_mekf(p: Dict[str, Any], ctx: Dict[str, Any]):
    from adcs_nodes.core.estimation.mekf import MEKF
    return MEKF(**p)                     # the parameters are its keyword arguments


register(Entry(
    'estimator', 'mekf',
    'multiplicative EKF: star-tracker attitude + gyro rate with gyro-bias states (feeds the '
    'paper 001 MPI controller)',
    'adcs_nodes.core.estimation.mekf:MEKF',
    (Param('star_tracker_std_rad', 'float', math.radians(0.02 / 3.0), 'rad',
           'star-tracker noise per axis (paper 001: 0.02 deg 3-sigma)', positive=True),
     Param('gyro_noise_std_rad_s', 'float', 1e-6, 'rad/s', 'gyro white noise per sample '
           '(ASSUMPTION: the paper gives only the drift)', min=0.0),
     Param('gyro_bias_walk_rad_s_sqrt_s', 'float',
           math.radians(0.01 / 3.0) / 3600.0 / math.sqrt(3600.0), 'rad/s/sqrt(s)',
           'gyro bias random walk (paper 001: 0.01 deg/h 3-sigma drift after 1 h)', min=0.0),
     Param('p0_bias_rad_s', 'float', 1e-4, 'rad/s', 'initial bias std per axis',
           positive=True),
     Param('gate_nis', 'float', 100.0, '-', 'largest accepted normalised innovation squared '
           '(chi-square, 3 dof)', positive=True),
     Param('max_rejections', 'int', 10, '-', 'refused star-tracker samples in a row that '
           'restart the filter', min=1, max=100000)),
    _build_mekf, inputs=('star_tracker', 'gyro')))


def wheel_momentum(speed_rad_s: Any, ctx: Dict[str, Any]) -> Any:
    """Wheel momenta [N m s] from speeds [rad/s] and the context's wheel inertias."""
    if speed_rad_s is None:
        return None
    j = np.asarray(ctx.get('wheel_inertia_kgm2') or [], dtype=float)
    s = np.asarray(speed_rad_s, dtype=float)
    return s * j if s.shape == j.shape else None
