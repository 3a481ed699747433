"""Standard per-actuator command topics: a magnetorquer or wheel driver needs only
geometry_msgs / sensor_msgs. The values are the manager's ActuatorCommand, same stamp."""
import numpy as np
import rclpy
from geometry_msgs.msg import Vector3Stamped
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from adcs_msgs.msg import ActuatorCommand
from adcs_nodes.components.manager import actuator_commands, wheel_names_for
from adcs_nodes.core.samples import ActuatorCommand as Command
from adcs_nodes.msgs.convert import COMMAND
from adcs_nodes.nodes.controller_manager import ControllerManagerNode

EPOCH_NS = 1767225600 * 10**9


def test_dipole_and_wheel_torques_in_standard_types(ros_context, spin):
    """The manager node publishes the per-actuator topics of its command when a driver
    subscribes: the dipole (body frame) and the wheel torques by name, the command's stamp."""
    node = ControllerManagerNode(context=ros_context, parameter_overrides=[
        Parameter('controllers', value=['bdot']), Parameter('safe', value='bdot'),
        Parameter('max_wheel_torque_Nm', value=[0.01, 0.01, 0.01]),
        Parameter('wheel_names', value=['rw_x', 'rw_y', 'rw_z'])])
    probe = rclpy.create_node('driver', context=ros_context)
    dip, wheels, cmds = [], [], []
    probe.create_subscription(Vector3Stamped, 'actuators/magnetorquer/command', dip.append, 10)
    probe.create_subscription(JointState, 'actuators/wheels/command', wheels.append, 10)
    probe.create_subscription(ActuatorCommand, 'adcs/actuator_command', cmds.append, 10)
    assert spin([node, probe], lambda: all(
        p.get_subscription_count() for p in node.actuator_pubs.values()))
    node.on_frame(42 * 10**9, {'bdot': None}, [])        # no command: zero, stamped 42 s
    assert spin([node, probe], lambda: dip and wheels and cmds)
    d, w, c = dip[0], wheels[0], cmds[0]
    assert (d.vector.x, d.vector.y, d.vector.z) == (c.dipole_body.x, c.dipole_body.y,
                                                    c.dipole_body.z)
    assert d.header.frame_id == 'body' and d.header.stamp == c.header.stamp
    assert c.header.stamp.sec == EPOCH_NS // 10**9 + 42
    assert list(w.name) == ['rw_x', 'rw_y', 'rw_z'] and list(w.effort) == [0.0, 0.0, 0.0]
    assert not w.position and not w.velocity and w.header.stamp == c.header.stamp
    probe.destroy_node()
    node.destroy_node()


def test_actuator_commands_carry_the_command_values():
    cmd = Command(42, np.array([1.5, -2.0, 0.25]), np.array([1e-3, -2e-3, 0.0]), np.zeros(3),
                  'mpi')
    (t1, mtq), (t2, wheels) = actuator_commands(cmd, ['rw_x', 'rw_y', 'rw_z'])
    assert (t1, t2) == ('actuators/magnetorquer/command', 'actuators/wheels/command')
    assert mtq.t_ns == wheels.t_ns == 42 and list(mtq.dipole_body_Am2) == [1.5, -2.0, 0.25]
    assert wheels.names == ('rw_x', 'rw_y', 'rw_z') and wheels.torque_Nm == (1e-3, -2e-3, 0.0)
    # a command without wheel torques (a magnetic law) drives every wheel with zero
    (_, _), (_, none) = actuator_commands(COMMAND.to_core(COMMAND.to_msg(
        Command(42, np.ones(3), np.zeros(0), np.zeros(3), 'bdot'), EPOCH_NS), EPOCH_NS),
        ['a', 'b'])
    assert none.torque_Nm == (0.0, 0.0)
    assert [t for t, _ in actuator_commands(cmd, [])] == ['actuators/magnetorquer/command']


def test_manager_offers_the_topics_its_spacecraft_has(ros_context):
    node = ControllerManagerNode(context=ros_context, parameter_overrides=[
        Parameter('controllers', value=['bdot']), Parameter('safe', value='bdot'),
        Parameter('max_wheel_torque_Nm', value=[0.01, 0.01]),
        Parameter('wheel_names', value=['a', 'b'])])
    pubs = dict(node.get_publisher_names_and_types_by_node(
        node.get_name(), node.get_namespace()))
    assert pubs['/actuators/magnetorquer/command'] == ['geometry_msgs/msg/Vector3Stamped']
    assert pubs['/actuators/wheels/command'] == ['sensor_msgs/msg/JointState']
    assert node.wheel_names == ['a', 'b']
    node.destroy_node()
    plain = ControllerManagerNode(context=ros_context, parameter_overrides=[
        Parameter('controllers', value=['bdot']), Parameter('safe', value='bdot')])
    assert list(plain.actuator_pubs) == ['actuators/magnetorquer/command']
    plain.destroy_node()
    assert wheel_names_for(2) == ['wheel0', 'wheel1']
