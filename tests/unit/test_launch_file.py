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

from adcs_nodes.graph import params_file_text
from adcs_nodes.tools.run.launch_graph import scenario_path
from adcs_nodes.tools.run.launcher import Launcher, child_env
from adcs_nodes.scenario import load_scenario

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
                 'Shutdown', 'Node', 'RegisterEventHandler', 'OnShutdown'):
        kinds[name] = type(name, (_Recorder,), {})
    launch = types.ModuleType('launch')
    launch.LaunchDescription = kinds['LaunchDescription']
    actions = types.ModuleType('launch.actions')
    for name in ('DeclareLaunchArgument', 'LogInfo', 'OpaqueFunction', 'Shutdown',
                 'RegisterEventHandler'):
        setattr(actions, name, kinds[name])
    handlers = types.ModuleType('launch.event_handlers')
    handlers.OnShutdown = kinds['OnShutdown']
    subs = types.ModuleType('launch.substitutions')
    subs.LaunchConfiguration = _LaunchConfiguration
    ros = types.ModuleType('launch_ros')
    ros_actions = types.ModuleType('launch_ros.actions')
    ros_actions.Node = kinds['Node']
    for mod in (launch, actions, handlers, subs, ros, ros_actions):
        monkeypatch.setitem(sys.modules, mod.__name__, mod)
    return kinds


def _load(path):
    spec = importlib.util.spec_from_file_location('adcs_launch_file', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _actions(module, kinds, **arguments):
    """Every action the launch file's OpaqueFunction returns for ``arguments``."""
    desc = module.generate_launch_description()
    entities = desc.args[0]
    declared = {e.args[0]: e.kwargs['default_value'] for e in entities
                if isinstance(e, kinds['DeclareLaunchArgument'])}
    opaque = [e for e in entities if isinstance(e, kinds['OpaqueFunction'])]
    return opaque[0].kwargs['function']({**declared, **arguments})


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


# ---------------------------------------------------------------------- stopping (issue 22)
def _shutdown_handlers(actions, kinds):
    return [a.args[0].kwargs['on_shutdown'] for a in actions
            if isinstance(a, kinds['RegisterEventHandler'])
            and isinstance(a.args[0], kinds['OnShutdown'])]


def _params_files():
    import glob
    import tempfile
    return set(glob.glob(os.path.join(tempfile.gettempdir(), 'adcs-*.params.yaml')))


def test_launch_file_removes_its_parameter_file_at_shutdown(launch_stubs, tmp_path,
                                                            monkeypatch):
    """Each launch wrote a parameter file to the temporary directory and left it there
    (defect 8): it is removed when the launch shuts down (``OnShutdown``), and nothing else
    is left in the temporary directory (this test's own: another worker's launch may write
    its file to the shared one meanwhile)."""
    import tempfile
    own_tmp = tmp_path / 'tmp'
    own_tmp.mkdir()
    monkeypatch.setattr(tempfile, 'tempdir', str(own_tmp))
    before = _params_files()
    path = os.path.join(ROOT, 'scenarios', 'paper000_control.yaml')
    actions = _actions(_load(LAUNCH_FILE), launch_stubs, scenario=path, duration='60',
                       record=str(tmp_path / 'bag'))
    nodes = [a for a in actions if isinstance(a, launch_stubs['Node'])]
    params_path = nodes[0].kwargs['parameters'][0]
    assert os.path.isfile(params_path)          # the nodes read it when they start
    handlers = _shutdown_handlers(actions, launch_stubs)
    assert handlers, 'no OnShutdown handler: the parameter file is never removed'
    for handler in handlers:
        handler(None, {})
    assert not os.path.exists(params_path)
    for handler in handlers:                     # a second shutdown event is harmless
        handler(None, {})
    assert _params_files() - before == set()


def _constants(path):
    """Module-level numeric constants of a source file (read: the unit tier imports no
    rclpy, and adcs_nodes.nodes.runtime does)."""
    with open(path, encoding='utf-8') as fh:
        tree = ast.parse(fh.read())
    return {t.id: ast.literal_eval(node.value) for node in tree.body
            if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant)
            for t in node.targets if isinstance(t, ast.Name)}


def test_every_node_gets_the_time_it_needs_to_stop(launch_stubs, tmp_path):
    """``sigterm_timeout`` of each node: launch escalates to SIGTERM only past it. A node
    exits within 2 s of SIGINT (tests/node/test_shutdown.py); it may wait for its last
    samples to be acknowledged and for rclpy's teardown, the recorder closes its bag."""
    from adcs_nodes.tools.run import launch_graph as lg
    runtime = _constants(os.path.join(ROOT, 'adcs_nodes', 'adcs_nodes', 'nodes', 'runtime.py'))
    assert lg.NODE_SIGTERM_TIMEOUT_S >= \
        runtime['FLUSH_BUDGET_S'] + runtime['TEARDOWN_BUDGET_S'] + runtime['HANG_S']
    assert lg.RECORDER_SIGTERM_TIMEOUT_S > lg.NODE_SIGTERM_TIMEOUT_S
    path = os.path.join(ROOT, 'scenarios', 'paper000_control.yaml')
    actions = _actions(_load(LAUNCH_FILE), launch_stubs, scenario=path, duration='60',
                       record=str(tmp_path / 'bag'))
    try:
        nodes = [a for a in actions if isinstance(a, launch_stubs['Node'])]
        for n in nodes:
            term = lg.RECORDER_SIGTERM_TIMEOUT_S if n.kwargs['name'] == 'recorder' \
                else lg.NODE_SIGTERM_TIMEOUT_S
            assert float(n.kwargs['sigterm_timeout']) == term, n.kwargs['name']
            assert float(n.kwargs['sigkill_timeout']) == lg.SIGKILL_TIMEOUT_S
        assert {n.kwargs['name'] for n in nodes} >= {'recorder', 'dynamics', 'estimator'}
    finally:
        for handler in _shutdown_handlers(actions, launch_stubs):
            handler(None, {})


@pytest.mark.alone
def test_interrupted_launch_leaves_no_process_behind(launch_stubs, tmp_path):
    """Ctrl-C during ``ros2 launch``, emulated on the launch file's own actions: each node's
    installed executable started as launch_ros starts it (``--ros-args -r __node:=NAME
    --params-file FILE``, the action's environment); then launch's stop: the shutdown
    handlers, SIGINT to every node, SIGTERM after its ``sigterm_timeout``, SIGKILL after
    ``sigkill_timeout``. Every node must be gone after the SIGINT alone (no escalation),
    nothing left behind, and the parameter file removed."""
    import glob
    import signal
    import subprocess
    import time

    share = pytest.importorskip('ament_index_python.packages')
    from domains import worker_domain
    path = os.path.join(ROOT, 'scenarios', 'free_tumble.yaml')
    bag = str(tmp_path / 'bag')
    actions = _actions(_load(LAUNCH_FILE), launch_stubs, scenario=path, duration='100000',
                       record=bag)
    nodes = [a for a in actions if isinstance(a, launch_stubs['Node'])]
    params_path = nodes[0].kwargs['parameters'][0]
    env = child_env(worker_domain(120, 30, 3))
    procs, stops = {}, {}
    try:
        for n in nodes:
            kw = n.kwargs
            try:
                prefix = share.get_package_prefix(kw['package'])
            except share.PackageNotFoundError:
                pytest.skip(f'{kw["package"]} not built')
            exe = os.path.join(prefix, 'lib', kw['package'], kw['executable'])
            with open(tmp_path / f'{kw["name"]}.log', 'w') as log:
                procs[kw['name']] = subprocess.Popen(
                    [exe, '--ros-args', '-r', f'__node:={kw["name"]}', '--params-file',
                     kw['parameters'][0]], env={**env, **kw.get('additional_env', {})},
                    stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
            stops[kw['name']] = (float(kw.get('sigterm_timeout', 5.0)),   # (launch's
                                 float(kw.get('sigkill_timeout', 5.0)))   # defaults)
        deadline = time.monotonic() + 180.0
        while time.monotonic() < deadline:       # running: the bag grows
            files = glob.glob(os.path.join(bag, '*.mcap'))
            if files and os.path.getsize(files[0]) > 30_000:
                break
            assert all(p.poll() is None for p in procs.values()), 'a node ended early'
            time.sleep(0.2)
        else:
            pytest.fail('the launched graph did not start recording within 180 s')
        # launch's stop: OnShutdown handlers, then SIGINT, SIGTERM, SIGKILL
        for handler in _shutdown_handlers(actions, launch_stubs):
            handler(None, {})
        t0 = time.monotonic()
        for p in procs.values():
            p.send_signal(signal.SIGINT)
        escalated = []
        for name, p in procs.items():
            term, kill = stops[name]
            try:
                p.wait(timeout=max(0.0, t0 + term - time.monotonic()))
                continue
            except subprocess.TimeoutExpired:
                escalated.append(f'{name}: SIGTERM')
                p.send_signal(signal.SIGTERM)
            try:
                p.wait(timeout=kill)
            except subprocess.TimeoutExpired:
                escalated.append(f'{name}: SIGKILL')
                p.kill()
                p.wait()
        assert escalated == []
        # exit code 0, or 1 when faulthandler ended a teardown that hung in Fast DDS
        # (runtime.TEARDOWN_BUDGET_S; its stacks in the log)
        assert all(p.returncode == 0 or (p.returncode == 1 and 'Timeout (' in (
            tmp_path / f'{k}.log').read_text()) for k, p in procs.items()), \
            {k: p.returncode for k, p in procs.items()}
        assert not os.path.exists(params_path)
        assert os.path.isfile(os.path.join(bag, 'metadata.yaml'))   # the bag was closed
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait()
        for handler in _shutdown_handlers(actions, launch_stubs):
            handler(None, {})
