"""The launcher's rclpy monitor: progress, missed frames, the recorder's state, readiness."""
from __future__ import annotations

import time
from typing import Dict


class Monitor:
    """Launcher-side rclpy node: progress from ``lockstep/status`` (content-filtered) and
    ``recorder/status``, no topic a node of the graph reads."""

    def __init__(self, epoch_ns: int, watch_ready: bool = False) -> None:
        import rclpy
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from adcs_msgs.msg import LockstepStatus
        from adcs_nodes.msgs.fields import stamp_ns
        from adcs_nodes.nodes.lockstep_node import MONITOR_NODE, MONITOR_STATUS_OF
        from adcs_nodes.nodes.runtime import make_executor

        self._rclpy = rclpy
        self._stamp_ns = stamp_ns
        self.epoch_ns = epoch_ns
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        # the nodes skip the statuses this filter would drop (LockstepNode._status_wanted)
        self.node = rclpy.create_node(MONITOR_NODE, context=self.context,
                                      start_parameter_services=False)
        self.sim_ns = 0
        self.clock_seen = False     # the lockstep has started (a node reported a frame)
        self.status: Dict[str, LockstepStatus] = {}
        self.recorder_clock_ns = -1
        self.recorder_count = 0
        self.recorder_statuses = 0        # recorder/status messages received
        self.recorder_error = ''
        self.recorder_lost = 0            # messages the middleware reported lost to the bag
        self.recorder_lost_topic = ''
        # evaluated by the writers where the middleware can; unfiltered if rclpy cannot
        status_filter = None
        try:
            from rclpy.subscription_content_filter_options import ContentFilterOptions
            status_filter = ContentFilterOptions(
                filter_expression='node = %0 OR missed_frames > 0',
                expression_parameters=[f"'{MONITOR_STATUS_OF}'"])
        except ImportError:
            pass
        try:
            self.node.create_subscription(LockstepStatus, 'lockstep/status',
                                          self._on_status_msg, 50,
                                          content_filter_options=status_filter)
        except Exception:      # a middleware that refuses the filter: take every status
            self.node.create_subscription(LockstepStatus, 'lockstep/status',
                                          self._on_status_msg, 50)
        self.node.create_subscription(LockstepStatus, 'recorder/status', self._on_rec, 10)
        #: nodes that said ``lockstep/ready`` (one process per node: the self-healing)
        self.ready: set = set()
        if watch_ready:
            from std_msgs.msg import String

            from adcs_nodes.nodes.lockstep_node import QOS_READY
            self.node.create_subscription(String, 'lockstep/ready',
                                          lambda m: self.ready.add(m.data), QOS_READY)
        # degraded-run accounting: the manager's latched status, max missed frames per node
        from rclpy.qos import DurabilityPolicy

        from adcs_msgs.msg import ControllerStatus
        self.controller_status = None
        self.max_missed: Dict[str, int] = {}
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(ControllerStatus, 'adcs/controller_status',
                                      self._on_controller_status, latched)
        self.executor = make_executor(self.context)
        self.executor.add_node(self.node)

    def _on_status_msg(self, msg) -> None:
        """``lockstep/status``: missed frames, and the sim time of the node's last frame."""
        self._on_status(msg)
        if msg.frames > 0:
            self.clock_seen = True
            self.sim_ns = max(self.sim_ns, self._stamp_ns(msg.header.stamp) - self.epoch_ns)

    def _on_status(self, msg) -> None:
        self.status[msg.node] = msg
        self.max_missed[msg.node] = max(int(msg.missed_frames),
                                        self.max_missed.get(msg.node, 0))

    def _on_controller_status(self, msg) -> None:
        self.controller_status = msg

    def _on_rec(self, msg) -> None:
        self.recorder_clock_ns = self._stamp_ns(msg.header.stamp) - self.epoch_ns
        self.recorder_count = int(msg.frames)
        self.recorder_statuses += 1
        if msg.last_missed_input.startswith('write failed: '):
            self.recorder_error = msg.last_missed_input[len('write failed: '):]
        elif msg.missed_frames > self.recorder_lost:
            self.recorder_lost = int(msg.missed_frames)
            self.recorder_lost_topic = msg.last_missed_input

    def spin(self, seconds: float) -> None:
        from rclpy.task import Future
        self.executor.spin_until_future_complete(Future(), timeout_sec=seconds)

    def wait_recorder_settled(self, deadline: float) -> bool:
        """Spin until two recorder statuses carry the same count (True) or ``deadline``."""
        seen, last = self.recorder_statuses, None
        while time.monotonic() < deadline:
            self.spin(0.1)
            if self.recorder_statuses != seen:
                seen = self.recorder_statuses
                if self.recorder_count == last:
                    return True
                last = self.recorder_count
        return False

    @property
    def missed_frames(self) -> int:
        """Missed frames of every node (the highest count each one reported)."""
        return sum(self.max_missed.values())

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.node.destroy_node()
        self.executor.shutdown()
        self._rclpy.shutdown(context=self.context)
