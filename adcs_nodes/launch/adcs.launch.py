"""Standard ROS 2 launch file of the ADCS graph, built from the same description as `adcs run`.

    ros2 launch adcs_nodes adcs.launch.py scenario:=paper000_estimation.yaml \
        [duration:=600] [record:=/tmp/bag]

``scenario``: an installed scenario (``share/adcs_nodes/scenarios``) or a path. The nodes and
their parameters come from ``adcs_nodes.graph`` (see ``adcs_nodes.tools.run.launch_graph``);
the parameter file is written to a private temporary file, removed when the launch shuts
down. The launch ends when the clock master (``dynamics``) exits at the end of the scenario;
each node gets the time it needs to stop after SIGINT (``sigterm_timeout``: the recorder
closes its bag) before launch escalates to SIGTERM.
"""
import atexit
import os
import tempfile

from launch import LaunchDescription
from launch.actions import (DeclareLaunchArgument, LogInfo, OpaqueFunction,
                            RegisterEventHandler, Shutdown)
from launch.event_handlers import OnShutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from adcs_nodes.tools.run.launch_graph import CLOCK_MASTER, launch_graph, stop_timeouts
from adcs_nodes.tools.run.launcher import profile_env


def _remove(path):
    """Remove the launch's temporary parameter file (once; a second call does nothing)."""
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass


def _graph(context, *args, **kwargs):
    scenario = LaunchConfiguration('scenario').perform(context)
    duration = LaunchConfiguration('duration').perform(context)
    record = LaunchConfiguration('record').perform(context)
    nodes, params = launch_graph(scenario, float(duration) if duration else None,
                                 record or None)
    fd, params_path = tempfile.mkstemp(prefix='adcs-', suffix='.params.yaml')
    with os.fdopen(fd, 'w', encoding='utf-8') as fh:     # mkstemp: mode 0600
        fh.write(params)
    # removed when the launch shuts down (end of the scenario, Ctrl-C, SIGTERM), and at the
    # latest when the launch process exits
    atexit.register(_remove, params_path)
    actions = [LogInfo(msg=f'adcs: {scenario}: {len(nodes)} nodes, parameters in '
                           f'{params_path} (removed at shutdown)'),
               RegisterEventHandler(OnShutdown(
                   on_shutdown=lambda event, context: _remove(params_path)))]
    # the project's Fast DDS profile, as `adcs run` (unless the user set a profiles file)
    env = profile_env(os.environ)
    for n in nodes:
        extra = {'on_exit': Shutdown(reason='end of the scenario')} \
            if n.name == CLOCK_MASTER else {}
        if env:
            extra['additional_env'] = env
        term, kill = stop_timeouts(n)
        actions.append(Node(package=n.package, executable=n.executable, name=n.name,
                            parameters=[params_path], output='screen',
                            sigterm_timeout=str(term), sigkill_timeout=str(kill), **extra))
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
