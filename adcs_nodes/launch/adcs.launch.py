"""Standard ROS 2 launch file of the ADCS graph, built from the same description as `adcs run`.

    ros2 launch adcs_nodes adcs.launch.py scenario:=paper000_estimation.yaml \
        [duration:=600] [record:=/tmp/bag]

``scenario``: an installed scenario (``share/adcs_nodes/scenarios``) or a path. The nodes and
their parameters come from ``adcs_nodes.tools.graph`` (see ``adcs_nodes.tools.launch_graph``);
the parameter file is written to a private temporary file. The launch ends when the clock
master (``dynamics``) exits at the end of the scenario.
"""
import os
import tempfile

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, LogInfo, OpaqueFunction, Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from adcs_nodes.tools.launch_graph import CLOCK_MASTER, launch_graph
from adcs_nodes.tools.launcher import profile_env


def _graph(context, *args, **kwargs):
    scenario = LaunchConfiguration('scenario').perform(context)
    duration = LaunchConfiguration('duration').perform(context)
    record = LaunchConfiguration('record').perform(context)
    nodes, params = launch_graph(scenario, float(duration) if duration else None,
                                 record or None)
    fd, params_path = tempfile.mkstemp(prefix='adcs-', suffix='.params.yaml')
    with os.fdopen(fd, 'w', encoding='utf-8') as fh:     # mkstemp: mode 0600
        fh.write(params)
    actions = [LogInfo(msg=f'adcs: {scenario}: {len(nodes)} nodes, parameters in '
                           f'{params_path}')]
    # the project's Fast DDS profile, as `adcs run` (unless the user set a profiles file)
    env = profile_env(os.environ)
    for n in nodes:
        extra = {'on_exit': Shutdown(reason='end of the scenario')} \
            if n.name == CLOCK_MASTER else {}
        if env:
            extra['additional_env'] = env
        actions.append(Node(package=n.package, executable=n.executable, name=n.name,
                            parameters=[params_path], output='screen', **extra))
    return actions


def generate_launch_description():
    """Arguments ``scenario``, ``duration``, ``record``; the nodes of the scenario's graph."""
    return LaunchDescription([
        DeclareLaunchArgument('scenario', default_value='free_tumble.yaml',
                              description='installed scenario name or path to a YAML file'),
        DeclareLaunchArgument('duration', default_value='',
                              description="simulated seconds (default: the scenario's)"),
        DeclareLaunchArgument('record', default_value='',
                              description='record every topic to this bag directory'),
        OpaqueFunction(function=_graph),
    ])
