"""What the node adapters share: their QoS profiles, a component's log callback on the node's
logger."""
from __future__ import annotations

from typing import Any, Callable

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
