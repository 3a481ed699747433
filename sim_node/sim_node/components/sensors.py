"""The simulated sensors' frame step: the truth of frame t -> the sensor's sample.

Each sensor component wraps the model its registry entry builds (:mod:`sim_node.entries`,
:mod:`sim_node.models.sensors`) with the node's random seed ``derive_seed(seed, name)``, and
stamps its samples with the frame and its ``frame_id`` (the child frame of its ``/tf_static``
mount). A missing or non-finite truth gives no sample (a warning); a magnetometer dropout a
NaN field (the ROS convention for "no data"); a horizon sensor without the Earth in view
``valid = false``. The scenario's faults change the sample's :attr:`SensorComponent.values`.

A plugin's sensor model needs no component of its own: a model with ``sample(t_ns, truth,
frame_id)`` (``truth``: ``{'state', 'env', 'wheels'}`` samples of the frame) returning its
core sample (or None), ``truth`` (the keys it reads) and ``values`` (the name of the sample's
field that faults change) runs in :class:`SensorComponent` itself.
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Tuple, Type

import numpy as np

from adcs_nodes.components.base import Log, silent
from adcs_nodes.core import attitude as att
from adcs_nodes.core import samples as s
from adcs_nodes.core.lockstep import NS_PER_S
from adcs_nodes.core.samples import all_finite
from sim_node.faults import SensorFaults, parse

_NO_COV = np.zeros(9)


def _f(a: Any) -> np.ndarray:
    return np.array(a, dtype=float)


class SensorComponent:
    """A sensor model sampled on the truth of a frame (a plugin's model directly).

    Parameters
    ----------
    model
        The sensor model (``entry.build(params, {'seed': ...})``).
    frame_id : str
        ``frame_id`` of the samples.
    log : Log
    faults : SensorFaults or None
    """

    #: The truth samples it reads: ``('state', 'env')`` or ``('wheels',)``.
    truth: Tuple[str, ...] = ('state', 'env')
    #: The sample's field that faults change.
    values = ''

    def __init__(self, model: Any, frame_id: str, log: Log = silent,
                 faults: Optional[SensorFaults] = None) -> None:
        self.model = model
        self.faults = faults
        self.frame_id = frame_id
        self.log = log
        if type(self) is SensorComponent:        # a plugin's model
            self.truth, self.values = tuple(model.truth), model.values
        cov = getattr(model, 'covariance', None)
        self.covariance = _NO_COV if cov is None else _f(cov).reshape(-1)

    def truth_ok(self, t_ns: int, what: str, *arrays: np.ndarray) -> bool:
        """True when every truth array is finite and non-zero; else warn (no sample)."""
        if all_finite(*arrays) and all(np.asarray(a).any() for a in arrays):
            return True
        self.log('warning', f't={t_ns / NS_PER_S:.3f} s: non-finite truth ({what}), no sample')
        return False

    def step(self, t_ns: int, truth: Dict[str, Any]) -> Optional[Any]:
        """The sample of frame ``t_ns`` from the truth samples, or None."""
        if any(truth.get(k) is None for k in self.truth):
            self.log('warning', f't={t_ns / NS_PER_S:.3f} s: no truth yet, no sample')
            return None
        x = self.sample(t_ns, *(truth[k] for k in self.truth))
        if x is None or self.faults is None:
            return x
        values = self.faults.apply(t_ns, self.read_values(x))   # the scenario's faults
        return None if values is None else self.with_values(x, values)

    def sample(self, t_ns: int, *truth: Any) -> Optional[Any]:
        """The sample of the truth (a plugin's model: its ``sample``)."""
        return self.model.sample(t_ns, dict(zip(self.truth, truth)), self.frame_id)

    def read_values(self, x: Any) -> np.ndarray:
        """The sample's measured values (what a fault changes)."""
        return getattr(x, self.values)

    def with_values(self, x: Any, values: np.ndarray) -> Any:
        """``x`` with its measured values replaced."""
        return x._replace(**{self.values: _f(values)})


class MagnetometerComponent(SensorComponent):
    """``sensors/magnetometer``: the truth field in the sensor frame [T]."""

    values = 'b_sensor_T'

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.dropouts = 0

    def sample(self, t_ns: int, state: s.AttitudeState,
               env: s.EnvironmentSample) -> Optional[s.MagnetometerSample]:
        if not self.truth_ok(t_ns, 'q_eci_body or b_eci', state.q_eci_body, env.b_eci_T):
            return None
        b_sensor = self.model.measure(att.to_matrix(state.q_eci_body).T @ env.b_eci_T)
        if b_sensor is None:
            # a lost sample is published as NaN (the ROS convention for "no data"), so the
            # lockstep goes on and the estimator counts it as rejected instead of waiting
            self.dropouts += 1
            self.log('debug', f't={t_ns / NS_PER_S:.3f} s: dropout ({self.dropouts})')
            b_sensor = np.full(3, np.nan)
        return s.MagnetometerSample(t_ns, self.frame_id, _f(b_sensor), self.covariance)


class GyroComponent(SensorComponent):
    """``sensors/gyro``: the measured body rate [rad/s, body axes]; the bias random walk spans
    the sim time since the previous sample."""

    values = 'omega_sensor_rad_s'

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._last_t_ns: Optional[int] = None

    def sample(self, t_ns: int, state: s.AttitudeState,
               env: s.EnvironmentSample) -> Optional[s.GyroSample]:
        omega = state.omega_body_eci_body
        if not all_finite(omega):
            self.truth_ok(t_ns, 'omega_body_eci_body', omega)   # logs the warning
            return None
        dt = 0.0 if self._last_t_ns is None else (t_ns - self._last_t_ns) / NS_PER_S
        self._last_t_ns = t_ns
        return s.GyroSample(t_ns, self.frame_id, _f(self.model.measure(omega, dt)),
                            self.covariance)


class StarTrackerComponent(SensorComponent):
    """``sensors/star_tracker``: the measured ``q_eci_body``."""

    values = 'q_eci_body'

    def sample(self, t_ns: int, state: s.AttitudeState,
               env: s.EnvironmentSample) -> Optional[s.StarTrackerSample]:
        if not self.truth_ok(t_ns, 'q_eci_body', state.q_eci_body):
            return None
        return s.StarTrackerSample(t_ns, self.frame_id, _f(self.model.measure(state.q_eci_body)),
                                   self.covariance)


class HorizonSensorComponent(SensorComponent):
    """``sensors/horizon``: roll and pitch of the body w.r.t. the orbit frame from the zenith
    ``R(q_eci_body)^T r_eci / |r_eci|``; ``valid = false`` out of view."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.invalid = 0

    def sample(self, t_ns: int, state: s.AttitudeState,
               env: s.EnvironmentSample) -> Optional[s.HorizonSample]:
        q_eci_body, r_eci = state.q_eci_body, env.r_eci_m
        if not self.truth_ok(t_ns, 'q_eci_body or r_eci', q_eci_body, r_eci):
            return None
        zenith_body = att.to_matrix(q_eci_body).T @ (r_eci / np.linalg.norm(r_eci))
        m = self.model.measure_zenith(zenith_body)
        if not m.valid:
            self.invalid += 1
        var = self.model.variance
        return s.HorizonSample(t_ns, self.frame_id, float(m.roll), float(m.pitch),
                               float(var[0]), float(var[1]), bool(m.valid))

    def read_values(self, x: s.HorizonSample) -> np.ndarray:
        return np.array([x.roll_rad, x.pitch_rad])

    def with_values(self, x: s.HorizonSample, values: np.ndarray) -> s.HorizonSample:
        return x._replace(roll_rad=float(values[0]), pitch_rad=float(values[1]),
                          valid=bool(x.valid and np.all(np.isfinite(values))))


class WheelTachometerComponent(SensorComponent):
    """``sensors/wheels``: measured wheel speeds relative to the body [rad/s]."""

    truth = ('wheels',)
    values = 'speed_rad_s'

    def sample(self, t_ns: int, wheels: s.WheelState) -> Optional[s.WheelSpeeds]:
        speed = wheels.speed_rad_s
        if not np.all(np.isfinite(speed)):
            self.log('warning', f't={t_ns / NS_PER_S:.3f} s: non-finite wheel speed, no sample')
            return None
        return s.WheelSpeeds(t_ns, self.frame_id, tuple(wheels.names),
                             np.array([float(v) for v in self.model.measure(speed)]))


#: The component of each registered sensor model, by registry name.
SENSOR_COMPONENTS: Dict[str, Type[SensorComponent]] = {
    'magnetometer': MagnetometerComponent,
    'gyro': GyroComponent,
    'star_tracker': StarTrackerComponent,
    'horizon_sensor': HorizonSensorComponent,
    'wheel_tachometer': WheelTachometerComponent,
}


def component_class(sensor: str) -> Type[SensorComponent]:
    """The component of registered sensor ``sensor`` (a plugin's model runs in the base)."""
    return SENSOR_COMPONENTS.get(sensor, SensorComponent)


def sensor_faults(sensor: str, text: str, seed: int) -> Optional[SensorFaults]:
    """The faults of a sensor from its node parameter ``faults`` (JSON; '' none), seeded from
    the scenario ``seed``; a star tracker's bias is a rotation."""
    faults = parse(text)
    return SensorFaults(faults, seed, rotation=sensor == 'star_tracker') if faults else None
