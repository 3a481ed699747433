"""The estimator's frame step: sensor samples -> checked core inputs -> the registered
estimator's ``step`` -> ``adcs/attitude_estimate`` (+ ``adcs/estimator/diagnostics``).

Conditioning (the same for the node and the FrameLoop):

* magnetometer: finite, ``min_field_T <= |B| <= max_field_T``, rotated from its sensor frame
  into body axes with the mount of its ``frame_id``; its covariance, when given, rotated
  the same way (per-axis variances);
* horizon sensor: ``valid`` and finite roll, pitch;
* gyro: finite, rotated by its mount; star tracker: finite unit quaternion;
* the applied command of the previous command frame (the estimator's prediction input): its
  dipole, zero when absent or not finite;
* the onboard reference (orbit, field) at the frame time: the flight software's own models.

A rejected sample is counted with its reason (``rejected_count``, ``last_rejection``) and
logged; a non-finite estimate is never published.
"""
from __future__ import annotations

import copy
import itertools
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from adcs_nodes import inputs
from adcs_nodes.components import conditioning as cond
from adcs_nodes.components.base import Log, covariance_to_body, silent
from adcs_nodes.core import attitude as att
from adcs_nodes.components.controller import inertia_matrix
from adcs_nodes.core.estimation.algorithms import EstimatorInputs, omega_orbit_from_eci
from adcs_nodes.core.estimation.onboard import make_onboard_reference
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.core.samples import AttitudeState, FilterDiagnostics, MagnetometerSample
from adcs_nodes.registry import Param

#: ``fresh(key) -> bool``: is the sample of input ``key`` new in this frame (lockstep:
#: stamped with the frame; live: newer than the one used before).
Fresh = Callable[[str], bool]


#: What every estimator node knows besides its algorithm's own parameters.
CONTEXT_PARAMS = (
    Param('expected_mounts', 'str[]', [], '-', 'sensor frames whose /tf_static mount must '
          'have arrived before the node is ready (the launcher sets them)', read_only=True),
    Param('algorithm', 'str', 'magnetic_filter', '-', 'registered estimator algorithm',
          read_only=True),
    Param('period_s', 'float', 2.0, 's', 'estimator period', positive=True, read_only=True),
    Param('inertia_kgm2', 'matrix3', [118.0, 118.0, 19.6], 'kg m^2', 'onboard inertia',
          read_only=True),
    Param('initial_q_orbit_body', 'quat', [0.0, 0.0, 0.0, 1.0], '-',
          'initial attitude estimate, body -> orbit, scalar last', read_only=True),
    Param('initial_omega_body_orbit_body', 'float[]', [0.0, 0.0, 0.0], 'rad/s',
          'initial rate estimate w.r.t. the orbit frame, body axes', length=3,
          read_only=True),
    Param('min_field_T', 'float', 1e-6, 'T', 'smallest plausible |B| (smaller: rejected)',
          positive=True),
    Param('max_field_T', 'float', 1e-3, 'T', 'largest plausible |B| (larger: rejected)',
          positive=True),
) + inputs.period_params(inputs.NAMES)


def _has_measurement(inputs: EstimatorInputs) -> bool:
    """True when the frame's inputs hold a fresh measurement of any sensor."""
    return any(v is not None for v in (inputs.b_body, inputs.horizon_roll_pitch,
                                       inputs.gyro_rate_body, inputs.q_eci_body_meas))


class EstimatorComponent:
    """One estimator (a registered algorithm's core) with its input conditioning.

    Parameters
    ----------
    core
        The built estimator core (``entry.build(params, context)``), initialised.
    algorithm : str
        Its registry name (for the diagnostics).
    reference
        Onboard reference (``make_onboard_reference``): ``at(t)`` -> orbit and field.
    field_range : (float, float)
        Plausible ``|B|`` [T].
    mounts
        ``lookup(frame_id) -> q_body_sensor or None``.
    log : Log
        Where rejections are reported.
    """

    def __init__(self, core: Any, algorithm: str, reference: Any,
                 field_range: Tuple[float, float], mounts: Any, log: Log = silent) -> None:
        self.core = core
        self.algorithm = algorithm
        self.reference = reference
        self.field_range = field_range
        self.mounts = mounts
        self.log = log
        self.update_count = 0
        self.rejected_count = 0
        self.last_rejection = ''
        #: rejections by kind: ``timeout`` (a stale lockstep input), ``check`` (a sample that
        #: failed conditioning), ``late`` (older than the filter), ``filter`` (the core's)
        self.rejected_by: Dict[str, int] = {}
        #: samples that reached the core, per input key, and the stamp [ns, elapsed] of the
        #: last one (what "usable" means for the starvation check)
        self.samples_used: Dict[str, int] = {}
        self.last_used_ns: Dict[str, int] = {}
        self._last_t: Optional[int] = None
        self.last_step = None
        self.last_ref = None

    # ------------------------------------------------------------------ inputs
    def reject(self, why: str, kind: str = 'check') -> None:
        """Count and log a rejected sample (``kind``: see ``rejected_by``)."""
        self.rejected_count += 1
        self.rejected_by[kind] = self.rejected_by.get(kind, 0) + 1
        self.last_rejection = why
        self.log('warning', f'measurement rejected: {why}')

    def field_var(self, x: MagnetometerSample) -> Optional[np.ndarray]:
        """Per-body-axis variances [T^2] of a sample's covariance, or None when it gives none
        (all zeros, ``[0] = -1``) or its mount is unknown."""
        q_body_sensor = self.mounts.lookup(x.frame_id)
        cov = None if q_body_sensor is None else covariance_to_body(
            x.covariance_T2, q_body_sensor)
        return None if cov is None else np.diag(cov).copy()

    def inputs_for(self, t_ns: int, samples: Dict[str, Any], fresh: Fresh) -> EstimatorInputs:
        """Fresh samples of frame ``t_ns``, checked (a rejected one counted with its reason)
        -> the core's :class:`EstimatorInputs`."""
        def take(key, check):
            x = samples.get(key)
            if x is None or not fresh(key):
                return None
            value, why = check(x)
            if why is not None:
                self.reject(why)
                return None
            self.samples_used[key] = self.samples_used.get(key, 0) + 1
            self.last_used_ns[key] = t_ns
            return value
        mag = samples.get('mag')
        return EstimatorInputs(
            self.reference.at(t_ns / NS_PER_S),
            b_body=take('mag', lambda x: cond.field_body(x, self.mounts, self.field_range)),
            horizon_roll_pitch=take('horizon', cond.horizon_roll_pitch),
            dipole_body=cond.applied_dipole(samples.get('cmd')),
            gyro_rate_body=take('gyro', lambda x: cond.gyro_rate_body(x, self.mounts)),
            q_eci_body_meas=take('star', cond.star_q_eci_body),
            b_body_var=self.field_var(mag) if mag is not None and fresh('mag') else None)

    # ------------------------------------------------------------------ frame
    def step(self, t_ns: int, inputs: Dict[str, Any], fresh: Fresh,
             missing: List[str] = (), samples: Sequence[Tuple[int, str, Any]] = (),
             sample_keys: Sequence[str] = ()) -> Optional[AttitudeState]:
        """One estimator step at elapsed sim time ``t_ns``; the estimate, or None.

        ``inputs``: the frame's sample of each input key (None: none yet). ``samples``:
        inputs in sample timing (a driver's, ``sample_keys``): ``(elapsed stamp, key,
        sample)`` in stamp order, each used once at its own stamp (predicted to it with the
        true time difference, then updated; samples of one instant together, as a two-vector
        estimator needs them), before the frame's own step; a sample older than the filter's
        time is rejected (late), never used.
        """
        t = t_ns / NS_PER_S
        for topic in missing:
            self.reject(f'stale input {topic} at t={t:g} s (timeout)', 'timeout')
        for s_ns, group in itertools.groupby(samples, key=lambda e: e[0]):
            group = {key: x for _, key, x in group}    # one instant: taken together
            if self._last_t is not None and s_ns < self._last_t:
                self.reject(f'{", ".join(group)} sample stamped {s_ns / NS_PER_S:g} s: older '
                            'than the filter (late)', 'late')
                continue
            self._core_step(s_ns, self.inputs_for(s_ns, {**group, 'cmd': inputs.get('cmd')},
                                                  group.__contains__))
        if sample_keys:
            taken = set(sample_keys)
            frame_fresh = fresh
            fresh = lambda k: k not in taken and frame_fresh(k)  # noqa: E731
        core_in = self.inputs_for(t_ns, inputs, fresh)
        self.last_ref = core_in.ref
        if sample_keys and not _has_measurement(core_in) and self._last_t is not None:
            # sample timing: the filter stays at its last sample (the next frame's samples
            # may be older than t); the estimate of frame t is predicted on a copy
            dt = (t_ns - self._last_t) / NS_PER_S
            step = copy.deepcopy(self.core).step(core_in, t, dt)
            self.last_step = step
        else:
            step = self._core_step(t_ns, core_in)
        if step.estimate is None:
            return None
        return self.estimate(t_ns, core_in.ref, step)

    def _core_step(self, t_ns: int, inputs: EstimatorInputs) -> Any:
        """The core's step to ``t_ns`` (from the last step's time), counted."""
        dt = 0.0 if self._last_t is None else (t_ns - self._last_t) / NS_PER_S
        self._last_t = t_ns
        step = self.core.step(inputs, t_ns / NS_PER_S, dt)
        self.last_step = step
        self.update_count += step.updates
        for why in step.rejections:
            self.reject(why, 'filter')
        return step

    def estimate(self, t_ns: int, ref: Any, step: Any) -> AttitudeState:
        """``adcs/attitude_estimate`` of a step."""
        est = step.estimate          # (copied: a filter may update its arrays in place)
        q_orbit_body = np.array(est.q_orbit_body, dtype=float)
        w = np.array(est.omega_body_eci_body, dtype=float)
        return AttitudeState(t_ns, att.multiply(ref.q_eci_orbit, q_orbit_body), q_orbit_body,
                             w, omega_orbit_from_eci(q_orbit_body, w, ref.omega0),
                             np.array(est.covariance, dtype=float).reshape(-1))

    def diagnostics(self, t_ns: int) -> FilterDiagnostics:
        """``adcs/estimator/diagnostics`` of the last step (built only when someone reads it)."""
        step = self.last_step
        return FilterDiagnostics(t_ns, self.algorithm, tuple(step.innovation),
                                 float(step.covariance_trace), self.update_count,
                                 self.rejected_count, self.last_rejection)


def build_estimator(entry: Any, p: Dict[str, Any], own: Dict[str, Any],
                    onboard_orbit: Dict[str, Any], onboard_field: Dict[str, Any], epoch: Any,
                    seed: int, mounts: Any, log: Log = silent) -> EstimatorComponent:
    """The estimator of registry ``entry`` from its :data:`CONTEXT_PARAMS` values ``p`` and
    its own parameter values ``own``, initialised; the onboard models from their sections."""
    reference = make_onboard_reference(onboard_orbit, onboard_field, epoch)
    ctx = {'inertia_kgm2': inertia_matrix(p['inertia_kgm2']), 'period_s': p['period_s'],
           'epoch': epoch, 'seed': seed, 'reference': reference}
    core = entry.build(own, ctx)
    core.initialise(att.normalize(p['initial_q_orbit_body']),
                    np.asarray(p['initial_omega_body_orbit_body'], dtype=float))
    return EstimatorComponent(core, entry.name, reference,
                              (p['min_field_T'], p['max_field_T']), mounts, log)
