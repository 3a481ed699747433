"""controller_manager services live under the project's namespace (``/adcs/...``), never under
ros2_control's ``/controller_manager/switch_controller`` names (other types: the two could not
share a graph). A client on the documented name gets the answers the manager core gives."""
import rclpy
from rclpy.parameter import Parameter

from adcs_msgs.srv import ListControllers, SwitchController
from adcs_nodes.nodes.controller_manager import ControllerManagerNode


def _call(spin, nodes, client, request):
    future = client.call_async(request)
    assert spin(nodes, future.done, timeout=10.0), 'service did not answer'
    return future.result()


def test_services_under_adcs_namespace(ros_context, spin):
    node = ControllerManagerNode(context=ros_context, parameter_overrides=[
        Parameter('controllers', value=['magnetic', 'bdot']), Parameter('safe', value='bdot'),
        Parameter('period_s', value=2.0), Parameter('frame_period_s', value=2.0)])
    probe = rclpy.create_node('probe', context=ros_context)
    switch = probe.create_client(SwitchController, '/adcs/switch_controller')
    listing = probe.create_client(ListControllers, '/adcs/list_controllers')
    nodes = [node, probe]
    assert spin(nodes, lambda: switch.service_is_ready() and listing.service_is_ready())
    served = {name for name, _ in node.get_service_names_and_types_by_node(
        node.get_name(), node.get_namespace())}
    assert {'/adcs/switch_controller', '/adcs/list_controllers'} <= served
    assert not any(s.startswith('/controller_manager/') and 'controller' in s.split('/')[-1]
                   for s in served), served

    res = _call(spin, nodes, listing, ListControllers.Request())
    assert list(res.names) == ['magnetic', 'bdot'] and res.safe == 'bdot'
    res = _call(spin, nodes, switch, SwitchController.Request(name='nonexistent'))
    assert not res.success and 'magnetic' in res.message
    res = _call(spin, nodes, switch, SwitchController.Request(name='magnetic'))
    assert res.success
    probe.destroy_node()
    node.destroy_node()
