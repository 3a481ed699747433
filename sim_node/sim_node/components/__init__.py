"""The simulated world's components (environment, dynamics, sensors): each node's frame step
without ROS, called by its node and by the FrameLoop (:mod:`sim_node.engine`). No rclpy."""
