"""Standard per-actuator command topics: a magnetorquer or wheel driver needs only
geometry_msgs / sensor_msgs. The values are the manager's ActuatorCommand, same stamp."""
import rclpy
from geometry_msgs.msg import Vector3, Vector3Stamped
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from adcs_msgs.msg import ActuatorCommand
from adcs_nodes.nodes.actuator_topics import ActuatorTopics, wheel_names_for
from adcs_nodes.nodes.controller_manager import ControllerManagerNode
from adcs_nodes.nodes.convert import to_stamp


def test_dipole_and_wheel_torques_in_standard_types(ros_context, spin):
    node = rclpy.create_node('manager_like', context=ros_context)
    topics = ActuatorTopics(node, True, ['rw_x', 'rw_y', 'rw_z'])
    probe = rclpy.create_node('driver', context=ros_context)
    dip, wheels = [], []
    probe.create_subscription(Vector3Stamped, 'actuators/magnetorquer/command', dip.append, 10)
    probe.create_subscription(JointState, 'actuators/wheels/command', wheels.append, 10)
    assert spin([node, probe], lambda: topics.mtq_pub.get_subscription_count()
                and topics.wheel_pub.get_subscription_count())
    cmd = ActuatorCommand()
    cmd.header.stamp = to_stamp(1767225600 * 10**9 + 42 * 10**9)
    cmd.dipole_body = Vector3(x=1.5, y=-2.0, z=0.25)
    cmd.wheel_torque = [1e-3, -2e-3, 0.0]
    topics.publish(cmd)
    assert spin([node, probe], lambda: dip and wheels)
    d, w = dip[0], wheels[0]
    assert (d.vector.x, d.vector.y, d.vector.z) == (1.5, -2.0, 0.25)
    assert d.header.frame_id == 'body' and d.header.stamp == cmd.header.stamp
    assert list(w.name) == ['rw_x', 'rw_y', 'rw_z'] and list(w.effort) == [1e-3, -2e-3, 0.0]
    assert not w.position and not w.velocity and w.header.stamp == cmd.header.stamp
    probe.destroy_node()
    node.destroy_node()


def test_manager_offers_the_topics_its_spacecraft_has(ros_context):
    node = ControllerManagerNode(context=ros_context, parameter_overrides=[
        Parameter('controllers', value=['bdot']), Parameter('safe', value='bdot'),
        Parameter('max_wheel_torque_Nm', value=[0.01, 0.01]),
        Parameter('wheel_names', value=['a', 'b'])])
    pubs = dict(node.get_publisher_names_and_types_by_node(
        node.get_name(), node.get_namespace()))
    assert pubs['/actuators/magnetorquer/command'] == ['geometry_msgs/msg/Vector3Stamped']
    assert pubs['/actuators/wheels/command'] == ['sensor_msgs/msg/JointState']
    assert node.actuators.wheel_names == ['a', 'b']
    node.destroy_node()
    plain = ControllerManagerNode(context=ros_context, parameter_overrides=[
        Parameter('controllers', value=['bdot']), Parameter('safe', value='bdot')])
    assert plain.actuators.wheel_pub is None and plain.actuators.mtq_pub is not None
    plain.destroy_node()
    assert wheel_names_for(2) == ['wheel0', 'wheel1']
