"""Components: the per-frame step of every node on core samples (:mod:`adcs_nodes.core.samples`),
without ROS. A node is an adapter around one (message -> sample through its input records, the
step, sample -> message); the FrameLoop (:mod:`sim_node.engine`) calls the same step, so a
number is decided in one place and the three engines give the same series (the parity test).
"""
