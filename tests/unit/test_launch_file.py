"""The standard ROS 2 launch file describes the same nodes and parameters as `adcs run`.

``launch`` and ``launch_ros`` are not on PyPI, so they are replaced by stubs that record what
the launch file asks for; the file is loaded from the source tree (and, when built, from the
installed share directory). Not tried here: ``ros2 launch`` itself (needs a ROS 2 install).
"""
import ast
import importlib.util
import os
import sys
import types

import pytest
import yaml

from adcs_nodes.tools.graph import params_file_text
from adcs_nodes.tools.launch_graph import scenario_path
from adcs_nodes.tools.launcher import Launcher, child_env
from adcs_nodes.tools.scenario import load_scenario

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LAUNCH_FILE = os.path.join(ROOT, 'adcs_nodes', 'launch', 'adcs.launch.py')


class _Recorder:
    """Stub of a launch action: keeps its arguments."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class _LaunchConfiguration:
    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context[self.name]


@pytest.fixture
def launch_stubs(monkeypatch):
    kinds = {}
    for name in ('LaunchDescription', 'DeclareLaunchArgument', 'LogInfo', 'OpaqueFunction',
                 'Shutdown', 'Node'):
        kinds[name] = type(name, (_Recorder,), {})
    launch = types.ModuleType('launch')
    launch.LaunchDescription = kinds['LaunchDescription']
    actions = types.ModuleType('launch.actions')
    for name in ('DeclareLaunchArgument', 'LogInfo', 'OpaqueFunction', 'Shutdown'):
        setattr(actions, name, kinds[name])
    subs = types.ModuleType('launch.substitutions')
    subs.LaunchConfiguration = _LaunchConfiguration
    ros = types.ModuleType('launch_ros')
    ros_actions = types.ModuleType('launch_ros.actions')
    ros_actions.Node = kinds['Node']
    for mod in (launch, actions, subs, ros, ros_actions):
        monkeypatch.setitem(sys.modules, mod.__name__, mod)
    return kinds


def _load(path):
    spec = importlib.util.spec_from_file_location('adcs_launch_file', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _expand(module, kinds, **arguments):
    desc = module.generate_launch_description()
    assert isinstance(desc, kinds['LaunchDescription'])
    entities = desc.args[0]
    declared = {e.args[0]: e.kwargs['default_value'] for e in entities
                if isinstance(e, kinds['DeclareLaunchArgument'])}
    assert set(declared) == {'scenario', 'duration', 'record'}
    context = {**declared, **arguments}
    opaque = [e for e in entities if isinstance(e, kinds['OpaqueFunction'])]
    assert len(opaque) == 1
    return [a for a in opaque[0].kwargs['function'](context)
            if isinstance(a, kinds['Node'])]


def _entry_points(package):
    with open(os.path.join(ROOT, package, 'setup.py'), encoding='utf-8') as fh:
        tree = ast.parse(fh.read())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                if isinstance(key, ast.Constant) and key.value == 'console_scripts':
                    return {ast.literal_eval(v).split('=')[0].strip() for v in value.elts}
    return set()


@pytest.mark.parametrize('scenario', ['paper000_control.yaml', 'paper000_estimation.yaml'])
def test_launch_file_starts_what_adcs_run_starts(launch_stubs, tmp_path, scenario,
                                                 monkeypatch):
    path = os.path.join(ROOT, 'scenarios', scenario)
    bag = str(tmp_path / 'bag')
    for key in ('FASTDDS_DEFAULT_PROFILES_FILE', 'FASTRTPS_DEFAULT_PROFILES_FILE'):
        monkeypatch.delenv(key, raising=False)
    nodes = _expand(_load(LAUNCH_FILE), launch_stubs, scenario=path, duration='120',
                    record=bag)
    run = Launcher(load_scenario(path), duration_s=120.0, record=bag, progress=False)
    assert [(n.kwargs['name'], n.kwargs['package'], n.kwargs['executable']) for n in nodes] \
        == [(n.name, n.package, n.executable) for n in run.nodes]
    params_files = {n.kwargs['parameters'][0] for n in nodes}
    assert len(params_files) == 1
    params_path = params_files.pop()
    try:
        assert oct(os.stat(params_path).st_mode & 0o777) == '0o600'
        with open(params_path, encoding='utf-8') as fh:
            launched = yaml.safe_load(fh)
    finally:
        os.unlink(params_path)
    expected = yaml.safe_load(params_file_text(run.nodes))
    # the launcher's own bookkeeping file (read by `adcs run` only)
    expected['/dynamics']['ros__parameters'].pop('result_file')
    assert launched == expected
    dyn = next(n for n in nodes if n.kwargs['name'] == 'dynamics')
    assert isinstance(dyn.kwargs['on_exit'], launch_stubs['Shutdown'])   # end of scenario
    for n in nodes:                        # every executable exists for `ros2 run`
        assert n.kwargs['executable'] in _entry_points(n.kwargs['package']), n.kwargs
        # the Fast DDS profile, as `adcs run` gives it (child_env)
        assert n.kwargs['additional_env'] == {
            'FASTDDS_DEFAULT_PROFILES_FILE': child_env(0)['FASTDDS_DEFAULT_PROFILES_FILE']}
    # a profiles file of the user's own wins
    monkeypatch.setenv('FASTDDS_DEFAULT_PROFILES_FILE', str(tmp_path / 'mine.xml'))
    nodes = _expand(_load(LAUNCH_FILE), launch_stubs, scenario=path, duration='120', record='')
    for params_path in {n.kwargs['parameters'][0] for n in nodes}:
        os.unlink(params_path)
    assert all('additional_env' not in n.kwargs for n in nodes)


def test_default_arguments_use_an_installed_scenario(launch_stubs):
    share = pytest.importorskip('ament_index_python.packages')
    try:
        installed = share.get_package_share_directory('adcs_nodes')
    except share.PackageNotFoundError:
        pytest.skip('adcs_nodes not built')
    launch_file = os.path.join(installed, 'launch', 'adcs.launch.py')
    assert os.path.isfile(launch_file), 'launch file not installed (setup.py data_files)'
    assert os.path.isfile(os.path.join(installed, 'scenarios', 'free_tumble.yaml'))
    nodes = _expand(_load(launch_file), launch_stubs)       # scenario:=free_tumble.yaml
    assert {n.kwargs['name'] for n in nodes} == {'environment', 'dynamics'}
    with pytest.raises(ValueError, match='not found'):
        scenario_path('no_such_scenario')
