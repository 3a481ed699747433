"""What the node adapters share: a component's log callback on the node's logger."""
from __future__ import annotations

from typing import Any, Callable


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
