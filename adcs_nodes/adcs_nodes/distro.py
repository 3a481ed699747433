"""The ROS 2 distribution this process runs on, and bags that say so.

``ros_distro()``: ``$ROS_DISTRO`` when set (a sourced ROS 2 install sets it), else the
distribution of the installed ``rclpy`` (the PyPI wheels set no ``ROS_DISTRO``): rclpy's major
version is the distribution's (Humble 3, Iron 4, Jazzy 7, Kilted 9), ``'unknown'`` when
neither is known. ``close_writer(writer)``: the ``rosbags`` writer's ``close()``, which writes
``ros_distro: rosbags`` in ``metadata.yaml`` and in the ``rosbag2`` metadata record of the MCAP
file, with the real distribution in both, as ``ros2 bag record`` does. No rclpy import.
"""
from __future__ import annotations

import os
import re
from importlib import metadata
from typing import Any

#: rclpy major version -> ROS 2 distribution (rclpy's release branches).
RCLPY_MAJOR_TO_DISTRO = {3: 'humble', 4: 'iron', 7: 'jazzy', 9: 'kilted'}
_PATTERN = re.compile(r'^(\s*ros_distro:\s*)rosbags\s*$', re.MULTILINE)


def ros_distro() -> str:
    """Lower-case distribution name (see module docstring)."""
    env = os.environ.get('ROS_DISTRO', '').strip().lower()
    if env:
        return env
    try:
        major = int(metadata.version('ros-rclpy').split('.')[0])
    except (metadata.PackageNotFoundError, ValueError):
        return 'unknown'
    return RCLPY_MAJOR_TO_DISTRO.get(major, 'unknown')


def close_writer(writer: Any, distro: str = '') -> None:
    """``writer.close()`` with ``distro`` (default :func:`ros_distro`) as the bag's
    ``ros_distro`` in both copies of the metadata. Errors of ``close()`` propagate unchanged."""
    distro = distro or ros_distro()

    def fix(text: str) -> str:
        return _PATTERN.sub(lambda m: m.group(1) + distro, text)

    storage = writer.storage
    close_storage = storage.close
    storage.close = lambda version, text: close_storage(version, fix(text))  # the MCAP record
    writer.close()
    meta = str(writer.metapath)              # written by close() from the unpatched text
    if os.path.isfile(meta):
        with open(meta, encoding='utf-8') as fh:
            text = fh.read()
        with open(meta + '.tmp', 'w', encoding='utf-8') as fh:
            fh.write(fix(text))
        os.replace(meta + '.tmp', meta)
