"""What the node adapters share: their QoS profiles, a component's log callback on the node's
logger, and the conversion of a frame's input messages to core samples (once per message)."""
from __future__ import annotations

from typing import Any, Callable, Dict, Iterable

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def _qos(depth: int, latched: bool) -> QoSProfile:
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                      history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.TRANSIENT_LOCAL
                      if latched else DurabilityPolicy.VOLATILE)


#: Reliable, keep last 100, volatile: lockstep data (deep enough that no frame is lost),
#: ``/diagnostics`` and the status topics (a recorder may lag 40 frames), ``/tf`` (tf2_ros
#: ``DynamicBroadcasterQoS``).
QOS_DATA = _qos(100, False)
#: The same, transient local: ``lockstep/ready``; a ``/tf_static`` reader (tf2's static
#: listener: TFMessage has no key, so with depth 1 two sensors' mounts overwrite each other).
QOS_READY = _qos(100, True)
#: Latched, depth 1: status-like topics, ``/tf_static`` (tf2_ros ``StaticBroadcasterQoS``).
QOS_LATCHED = _qos(1, True)


def node_log(node: Any) -> Callable[[str, str], None]:
    """``log(level, text)`` of a component, written to ``node``'s logger.

    (rclpy refuses one call site logging at two severities, so each level has its own.)
    """
    logger = node.get_logger()

    def log(level: str, text: str) -> None:
        if level == 'error':
            logger.error(text)
        elif level == 'warning':
            logger.warning(text)
        elif level == 'info':
            logger.info(text)
        else:
            logger.debug(text)
    return log


class ToCore:
    """A node's input messages -> core samples, by input key: ``converters`` ``{key:
    to_core(msg, epoch_ns)}`` (the input records', :mod:`adcs_nodes.msgs.convert`). A message
    held over several frames is converted once."""

    def __init__(self, converters: Dict[str, Callable[[Any, int], Any]], epoch_ns: int) -> None:
        self.converters = dict(converters)
        self.epoch_ns = int(epoch_ns)
        self._last: Dict[str, tuple] = {}

    def one(self, key: str, msg: Any) -> Any:
        """The sample of ``msg`` (input ``key``; None for None)."""
        if msg is None:
            return None
        last = self._last.get(key)
        if last is not None and last[0] is msg:
            return last[1]
        x = self.converters[key](msg, self.epoch_ns)
        self._last[key] = (msg, x)
        return x

    def __call__(self, msgs: Dict[str, Any]) -> Dict[str, Any]:
        """``{key: sample or None}`` of a frame's ``{key: message or None}``."""
        return {k: self.one(k, m) for k, m in msgs.items()}


def records_to_core(names: Iterable[str], epoch_ns: int) -> ToCore:
    """:class:`ToCore` of the input records ``names`` (:mod:`adcs_nodes.inputs`)."""
    from adcs_nodes import inputs
    return ToCore({rec.key: rec.converter().to_core for rec in map(inputs.get, names)},
                  epoch_ns)
