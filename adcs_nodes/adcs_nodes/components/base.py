"""What every component shares: the run's epoch, a log callback, the mount table of the
sensors (``/tf_static`` in a graph, the scenario in the FrameLoop) and the flat parameters."""
from __future__ import annotations

from datetime import datetime, timezone
from typing import Any, Callable, Dict, Optional, Sequence

import numpy as np

from adcs_nodes.core import attitude as att
from adcs_nodes.core.lockstep import NS_PER_S

#: Epoch of a node started without one (ISO-8601 UTC).
DEFAULT_EPOCH = '2026-01-01T00:00:00Z'

#: ``log(level, text)`` with level ``'debug' | 'info' | 'warning' | 'error'``.
Log = Callable[[str, str], None]


def silent(level: str, text: str) -> None:
    """A log that drops everything (a component built without a node)."""


def parse_epoch(text: str) -> datetime:
    """ISO-8601 UTC text (``2026-01-01T00:00:00Z``) -> aware ``datetime``; ValueError if bad."""
    try:
        dt = datetime.fromisoformat(str(text).replace('Z', '+00:00'))
    except ValueError as exc:
        raise ValueError(f'epoch {text!r} is not an ISO-8601 date-time') from exc
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=timezone.utc)
    return dt.astimezone(timezone.utc)


def epoch_to_ns(epoch: datetime) -> int:
    """Aware datetime -> integer ns since the Unix epoch (exact to the microsecond)."""
    delta = epoch - datetime(1970, 1, 1, tzinfo=timezone.utc)
    return (delta.days * 86400 + delta.seconds) * NS_PER_S + delta.microseconds * 1000


class Mounts:
    """Sensor mounts ``q_body_sensor`` (scalar last) by the samples' ``frame_id``.

    The FrameLoop fills it from the sensors' parameters (what their nodes put on
    ``/tf_static``); a node wraps its ``MountTable``, which fills it from ``/tf_static``.
    """

    def __init__(self, mounts: Optional[Dict[str, Sequence[float]]] = None) -> None:
        self._q: Dict[str, np.ndarray] = {}
        for frame, q in (mounts or {}).items():
            self.set(frame, q)

    def set(self, frame_id: str, q_body_sensor: Sequence[float]) -> None:
        """Record the mount of ``frame_id`` (normalised)."""
        self._q[str(frame_id)] = att.normalize(np.asarray(q_body_sensor, dtype=float))

    def lookup(self, frame_id: str) -> Optional[np.ndarray]:
        """``q_body_sensor`` of ``frame_id`` (``body`` itself: identity), or None if unknown."""
        if frame_id in ('', 'body'):
            return np.array([0.0, 0.0, 0.0, 1.0])
        return self._q.get(frame_id)


def covariance_to_body(covariance: Sequence[float],
                       q_body_sensor: Sequence[float]) -> Optional[np.ndarray]:
    """A sample's 3x3 covariance (row-major, sensor axes) in body axes, or ``None``.

    ``C_body = R C_sensor R^T`` with ``R = R(q_body_sensor)``. ``None`` when the sample
    gives none, by the ``sensor_msgs`` conventions: all zeros ("unknown"), ``covariance[0]
    = -1`` ("not provided"), or anything not finite, not symmetric or not positive
    semi-definite.
    """
    c = np.asarray(covariance, dtype=float).reshape(-1)
    q = np.asarray(q_body_sensor, dtype=float)
    key = (c.tobytes(), q.tobytes())          # a sensor's covariance rarely changes
    if key in _COVARIANCE_BODY:
        got = _COVARIANCE_BODY[key]
        return None if got is None else got.copy()
    if len(_COVARIANCE_BODY) >= 64:
        _COVARIANCE_BODY.clear()
    got = _COVARIANCE_BODY[key] = _covariance_to_body(c, q)
    return None if got is None else got.copy()


#: Results of :func:`covariance_to_body` by the bytes of its arguments (a pure function).
_COVARIANCE_BODY: Dict[tuple, Optional[np.ndarray]] = {}


def _covariance_to_body(c: np.ndarray, q_body_sensor: np.ndarray) -> Optional[np.ndarray]:
    if c.size != 9 or not np.all(np.isfinite(c)) or c[0] == -1.0 or not np.any(c):
        return None
    c = c.reshape(3, 3)
    if not np.allclose(c, c.T, rtol=1e-9, atol=0.0) or np.linalg.eigvalsh(c)[0] < \
            -1e-12 * max(float(np.abs(c).max()), 1e-300):
        return None
    r = att.to_matrix(att.normalize(np.asarray(q_body_sensor, dtype=float)))
    return r @ c @ r.T


# ---------------------------------------------------------------------- flat parameters
def param_value(spec: Any, params: Dict[str, Any]) -> Any:
    """The value of parameter ``spec`` in the flat node parameters ``params``, validated as
    the node declares it (:meth:`adcs_nodes.core.spec.Param.from_ros`); else the default."""
    if spec.name not in params or params[spec.name] is None:
        return spec.default if spec.default is None else spec.validate(spec.default)
    return spec.from_ros(params[spec.name])


def param_values(specs: Sequence[Any], params: Dict[str, Any]) -> Dict[str, Any]:
    """``{name: value}`` of every spec (:func:`param_value`)."""
    return {s.name: param_value(s, params) for s in specs}
