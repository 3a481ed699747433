"""tf for the ADCS graph: ``/tf`` and ``/tf_static`` (``tf2_msgs/TFMessage``) as tf2 expects them.

Frames and who publishes them: ``docs/topics.md``, "Frames" (``eci -> orbit -> body`` truth
from dynamics, ``eci -> body_estimate`` from the estimator, ``eci -> ecef`` from the
environment, the sensor mounts ``body -> <sensor>`` on ``/tf_static``). A ``TransformStamped``
``parent -> child`` carries ``q_parent_child`` (``child`` components into ``parent``, the
project's convention and tf2's) and the child's origin in the parent frame [m].

Sensor mounts are defined once, by whoever publishes the sensor's samples (the simulated sensor
node from its ``q_body_sensor`` parameter, or a driver / ``static_transform_publisher``), and
read from ``/tf_static`` by every consumer through :class:`MountTable`, keyed by the sample's
``header.frame_id``.

Standalone (a mount for a real driver, on a machine without ``tf2_ros``)::

    python -m adcs_nodes.nodes.tf body magnetometer QX QY QZ QW

publishes ``body -> magnetometer`` on ``/tf_static`` and keeps it latched until Ctrl-C.
"""
from __future__ import annotations

import sys
from typing import Any, Dict, Iterable, List, Optional, Sequence

import numpy as np
from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage

from adcs_nodes.components.base import Mounts
from adcs_nodes.core import attitude as att
from adcs_nodes.msgs.fields import quat, to_quat, to_vec3
from adcs_nodes.nodes.adapter import QOS_DATA, QOS_LATCHED, QOS_READY

#: tf2_ros's QoS: ``/tf``, ``/tf_static`` (latched) and a ``/tf_static`` reader (depth 100)
QOS_TF, QOS_TF_STATIC, QOS_TF_STATIC_READER = QOS_DATA, QOS_LATCHED, QOS_READY

BODY = 'body'
BODY_ESTIMATE = 'body_estimate'
ECI, ECEF, ORBIT = 'eci', 'ecef', 'orbit'


def transform(parent: str, child: str, q_parent_child: Sequence[float], stamp: Any,
              translation: Optional[Sequence[float]] = None) -> TransformStamped:
    """One ``TransformStamped`` ``parent -> child`` at ``stamp``: ``q_parent_child`` (4,)
    takes ``child`` components into ``parent`` (normalised here); ``translation`` (3,) [m] the
    child origin in ``parent`` (zero when omitted)."""
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id = parent
    t.child_frame_id = child
    t.transform.rotation = to_quat(att.normalize(np.asarray(q_parent_child, dtype=float)))
    if translation is not None:
        t.transform.translation = to_vec3(translation)
    return t


def truth_transforms(stamp: Any, r_eci: Sequence[float], q_eci_orbit: Sequence[float],
                     q_orbit_body: Sequence[float]) -> List[TransformStamped]:
    """``eci -> orbit`` (at the spacecraft position ``r_eci`` [m]) and ``orbit -> body``."""
    return [transform(ECI, ORBIT, q_eci_orbit, stamp, r_eci),
            transform(ORBIT, BODY, q_orbit_body, stamp)]


def estimate_transforms(stamp: Any, r_eci: Sequence[float],
                        q_eci_body: Sequence[float]) -> List[TransformStamped]:
    """``eci -> body_estimate`` at the onboard orbit position ``r_eci`` [m]."""
    return [transform(ECI, BODY_ESTIMATE, q_eci_body, stamp, r_eci)]


def earth_transforms(stamp: Any, q_eci_ecef: Sequence[float]) -> List[TransformStamped]:
    """``eci -> ecef`` (same origin, Earth rotation)."""
    return [transform(ECI, ECEF, q_eci_ecef, stamp)]


def mount_transforms(stamp: Any, mounts: Dict[str, Sequence[float]]) -> List[TransformStamped]:
    """``body -> <sensor frame>`` for every ``{frame_id: q_body_sensor}`` (zero lever arm).

    ASSUMPTION: sensor positions on the body are not modelled (no paper gives them and no
    measurement here depends on them), so the translation is zero.
    """
    return [transform(BODY, frame, q, stamp) for frame, q in sorted(mounts.items())]


class TfPublisher:
    """Publisher of ``/tf`` (or the latched ``/tf_static``) for one node.

    Created in the node's constructor, so the start handshake of a lockstep node (its
    ``publisher`` method) covers it and a recorder sees the first transform.
    """

    def __init__(self, node: Any, static: bool = False) -> None:
        topic, qos = ('/tf_static', QOS_TF_STATIC) if static else ('/tf', QOS_TF)
        make = getattr(node, 'publisher', None)
        self.pub = (make(TFMessage, topic, qos) if make is not None
                    else node.create_publisher(TFMessage, topic, qos))
        self.static = static
        self._static_sent: Dict[str, TransformStamped] = {}
        # the rcl call, without rclpy's `with handle` guard (0.09 us against 0.47 us; asked
        # every frame; a destroyed publisher raises RCLError either way)
        self._subscription_count = self.pub.handle.get_subscription_count

    def send(self, transforms: Iterable[TransformStamped]) -> None:
        """Publish ``transforms`` in one message. On ``/tf_static`` every call re-publishes
        all transforms sent so far (the latched message is the whole set, as tf2 does)."""
        transforms = list(transforms)
        if self.static:
            for t in transforms:
                self._static_sent[t.child_frame_id] = t
            transforms = list(self._static_sent.values())
        self.pub.publish(TFMessage(transforms=transforms))

    def wanted(self) -> bool:
        """True when building transforms is worth it: ``/tf`` with a matched subscription (a
        recorder recording it, a tf2 listener, RViz), or ``/tf_static`` (latched, always).
        Nobody reads ``/tf`` in a bench run; building it was about 7 % of a composed frame."""
        return self.static or self._subscription_count() > 0


class MountTable(Mounts):
    """The sensor mounts read from ``/tf_static`` (``body -> frame``, finite and non-zero
    ones), looked up by the samples' ``frame_id`` (:class:`Mounts`: identity for ``''`` or
    ``body``; ``None`` for a mount not known yet: the consumer rejects the sample)."""

    def __init__(self, node: Any) -> None:
        super().__init__()
        make = getattr(node, 'subscription', None)
        if make is not None:
            make(TFMessage, '/tf_static', self.on_message, QOS_TF_STATIC_READER)
        else:
            node.create_subscription(TFMessage, '/tf_static', self.on_message,
                                     QOS_TF_STATIC_READER)

    def on_message(self, msg: TFMessage) -> None:
        """Store every ``body -> X`` rotation of a ``/tf_static`` message."""
        for t in msg.transforms:
            q = quat(t.transform.rotation)
            if t.header.frame_id == BODY and t.child_frame_id and np.all(np.isfinite(q)) \
                    and np.linalg.norm(q) > 0.5:
                self.set(t.child_frame_id, q)

    def frames(self) -> List[str]:
        """Sensor frames with a known mount."""
        return sorted(self._q)

    def missing(self, expected: List[str]) -> List[str]:
        """The ``expected`` frames whose mount has not arrived yet (for the start handshake:
        matched ``/tf_static`` endpoints do not mean the latched message was delivered)."""
        return [f'/tf_static mount body -> {f}' for f in expected
                if f and self.lookup(f) is None]


def main(argv: Optional[List[str]] = None) -> int:
    """``python -m adcs_nodes.nodes.tf PARENT CHILD QX QY QZ QW [X Y Z]``: one static transform."""
    import rclpy
    from rclpy.utilities import remove_ros_args

    from adcs_nodes.nodes import runtime
    args = remove_ros_args(sys.argv if argv is None else argv)[1:]
    if len(args) not in (6, 9):
        print('usage: python -m adcs_nodes.nodes.tf PARENT CHILD QX QY QZ QW [X Y Z]',
              file=sys.stderr)
        return 2
    try:
        values = [float(v) for v in args[2:]]
    except ValueError:
        print(f'not numbers: {args[2:]}', file=sys.stderr)
        return 2
    q = np.asarray(values[:4])
    if not np.all(np.isfinite(values)) or np.linalg.norm(q) < 0.5:
        print('the quaternion must be finite and non-zero [x, y, z, w]', file=sys.stderr)
        return 2
    rclpy.init(args=argv)
    try:
        node = rclpy.create_node('static_mount_' + args[1].replace('/', '_'))
        pub = TfPublisher(node, static=True)
        pub.send([transform(args[0], args[1], q, node.get_clock().now().to_msg(),
                            values[4:] or None)])
        node.get_logger().info(f'/tf_static: {args[0]} -> {args[1]} q_xyzw={q.tolist()}')
        runtime.spin_nodes([node])
    finally:
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
