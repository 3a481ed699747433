"""A fake magnetometer on sim time, as ``ros2 topic pub -s -r 10 /sensors/magnetometer
sensor_msgs/msg/MagneticField "{header: auto, magnetic_field: {...}}"`` is one: a node with
``use_sim_time``, the default QoS (reliable, volatile), ``header: auto`` stamped from its sim
clock, a timer on that clock. Like the CLI in the run of issue 37 (its publisher appeared only
once the world ran), it publishes only once its clock has started. Prints one line per sample.
"""
import sys

import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from sensor_msgs.msg import MagneticField


def main() -> int:
    rate = float(sys.argv[1])
    rclpy.init()
    node = rclpy.create_node('fake_magnetometer', parameter_overrides=[
        Parameter('use_sim_time', value=True)])
    while rclpy.ok() and node.get_clock().now().nanoseconds == 0:
        rclpy.spin_once(node, timeout_sec=0.1)         # waits for a clock
    pub = node.create_publisher(MagneticField, '/sensors/magnetometer', QoSProfile(depth=10))
    msg = MagneticField()
    msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = 2e-5, -1e-5, 3e-5

    def tick() -> None:
        msg.header.stamp = node.get_clock().now().to_msg()
        pub.publish(msg)
        print('published', msg.header.stamp.sec, msg.header.stamp.nanosec, flush=True)
    tick()
    node.create_timer(1.0 / rate, tick)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
