"""The ROS 2 distribution this process runs on, and bags that say so.

``ros_distro()``: ``$ROS_DISTRO`` when set (a sourced ROS 2 install sets it), else the
distribution of the installed ``rclpy`` (the PyPI wheels set no ``ROS_DISTRO``): rclpy's major
version is the distribution's (Humble 3, Iron 4, Jazzy 7, Kilted 9), ``'unknown'`` when
neither is known.

``stamp_distro(writer)``: the ``rosbags`` writer records ``ros_distro: rosbags`` in the bag's
metadata (``metadata.yaml`` and the ``rosbag2`` metadata record inside the MCAP file, both
written by ``Writer.close()``); called on an open writer just before ``close()``, it makes both
carry the real distribution, as ``ros2 bag record`` does. Pure Python; no rclpy import.
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


def _replace(text: str, distro: str) -> str:
    return _PATTERN.sub(lambda m: m.group(1) + distro, text)


def stamp_distro(writer: Any, distro: str = '') -> None:
    """Make ``writer.close()`` record ``distro`` (default :func:`ros_distro`) as the bag's
    ``ros_distro``. Call once, right before ``close()``; a no-op on a closed writer."""
    distro = distro or ros_distro()
    storage = getattr(writer, 'storage', None)
    if storage is None or not hasattr(storage, 'close'):
        return
    close_storage = storage.close

    def close(version: int, text: str) -> None:
        close_storage(version, _replace(text, distro))
        meta = getattr(writer, 'metapath', None)
        if meta is not None:      # written by Writer.close() after this returns
            writer.__dict__.setdefault('_adcs_distro_fix', (meta, distro))

    storage.close = close


def fix_metadata_file(writer: Any) -> None:
    """After ``close()``: rewrite ``metadata.yaml`` with the distribution chosen in
    :func:`stamp_distro` (the writer writes it last, from the unpatched text)."""
    meta, distro = writer.__dict__.pop('_adcs_distro_fix', (None, ''))
    if meta is None or not os.path.isfile(meta):
        return
    with open(meta, encoding='utf-8') as fh:
        text = fh.read()
    new = _replace(text, distro)
    if new != text:
        tmp = f'{meta}.tmp'
        with open(tmp, 'w', encoding='utf-8') as fh:
            fh.write(new)
        os.replace(tmp, meta)


def close_writer(writer: Any, distro: str = '') -> None:
    """``writer.close()`` with the real distribution in the bag's metadata (both copies).
    Errors of ``close()`` propagate unchanged."""
    stamp_distro(writer, distro)
    writer.close()
    fix_metadata_file(writer)
