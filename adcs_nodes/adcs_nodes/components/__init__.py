"""Components: the per-frame step of every node, without ROS.

A component is what a node does in one frame, minus the transport: it takes the messages of
its inputs (message objects of the generated classes, which need no ``rclpy``), converts them
to core types at its edge, calls the core (estimator, controller, manager, guidance), and
returns the messages to publish. The rclpy node is an adapter around it (subscriptions,
lockstep or live timing, lifecycle, publishing); the :class:`sim_node.engine.FrameLoop` calls
the same ``step`` directly. So a number is decided in exactly one place, and the plain,
composed and graph engines give the same series to the last bit (the parity test).

Pure Python: no ``rclpy`` import in this package (``tests/unit/test_core_purity.py``).
"""
