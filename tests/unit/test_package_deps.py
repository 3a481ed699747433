"""Every third-party import of a package is declared in its package.xml by its rosdep key.

Imports are read with ``ast`` from every Python file of the package (its module tree and its
``launch/`` directory), including imports inside functions and ``try`` blocks (optional
dependencies are dependencies too). A ROS package is recognised by its ament index entry;
a plain Python distribution must have a row in ``PIP_KEYS``. Keys must exist: in rosdistro
(the snapshot ``ROSDISTRO_KEYS``, checked against ros/rosdistro rosdep/python.yaml) or in the
project's ``ros2_ws/rosdep.yaml``, whose pip packages must be pinned in requirements.txt.
"""
import ast
import os
import re
import sys
import xml.etree.ElementTree as ET

import pytest
import yaml

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
WORKSPACE_PACKAGES = {'adcs_msgs', 'adcs_nodes', 'sim_node', 'tf2_msgs'}
#: Imports that are not dependencies: the launcher's tools use the simulator's FrameLoop (the
#: plain engine, Monte Carlo) when sim_node is installed, which itself depends on adcs_nodes
#: (a declared dependency would be a cycle); the flight software never imports it.
OPTIONAL = {('adcs_nodes', 'sim_node')}
#: ROS packages that are not in the PyPI wheels (so not in the ament index here)
NOT_IN_WHEELS = {'launch', 'launch_ros'}

#: import name -> rosdep key
PIP_KEYS = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'yaml': 'python3-yaml',
    'matplotlib': 'python3-matplotlib', 'numba': 'python3-numba',
    'rosbags': 'python3-rosbags-pip', 'ppigrf': 'python3-ppigrf-pip',
    'sgp4': 'python3-sgp4-pip', 'mcap': 'python3-mcap-pip',
    'threadpoolctl': 'python3-threadpoolctl-pip', 'distributed': 'python3-distributed-pip',
    'dask': 'python3-distributed-pip', 'skfuzzy': 'python3-scikit-fuzzy-pip',
}
#: keys defined in ros/rosdistro rosdep/python.yaml (looked up at commit 8468e88, 2026-08)
ROSDISTRO_KEYS = {'python3-numpy', 'python3-scipy', 'python3-yaml', 'python3-matplotlib',
                  'python3-numba', 'python3-rosbags-pip', 'python3-pytest',
                  'python3-pytest-timeout', 'python3-hypothesis'}


def _ros_packages():
    found = set(WORKSPACE_PACKAGES) | NOT_IN_WHEELS
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        index = os.path.join(prefix, 'share', 'ament_index', 'resource_index', 'packages')
        if os.path.isdir(index):
            found.update(os.listdir(index))
    return found


def _imports(package):
    pkg_dir = os.path.join(ROOT, package)
    out = {}
    for sub in (package, 'launch'):
        for dirpath, _, files in os.walk(os.path.join(pkg_dir, sub)):
            for name in files:
                if not name.endswith('.py'):
                    continue
                path = os.path.join(dirpath, name)
                with open(path, encoding='utf-8') as fh:
                    tree = ast.parse(fh.read(), path)
                for node in ast.walk(tree):
                    if isinstance(node, ast.Import):
                        mods = [a.name for a in node.names]
                    elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                        mods = [node.module]
                    else:
                        continue
                    for mod in mods:
                        out.setdefault(mod.split('.')[0], os.path.relpath(path, ROOT))
    return out


def _declared(package):
    tree = ET.parse(os.path.join(ROOT, package, 'package.xml'))
    return {el.text.strip() for el in tree.getroot()
            if el.tag.endswith('depend') and el.text}


def _project_keys():
    with open(os.path.join(ROOT, 'ros2_ws', 'rosdep.yaml'), encoding='utf-8') as fh:
        return yaml.safe_load(fh)


@pytest.mark.parametrize('package', ['adcs_nodes', 'sim_node'])
def test_every_third_party_import_is_declared(package):
    if not os.environ.get('AMENT_PREFIX_PATH'):
        pytest.skip('needs the workspace environment (ros2_ws/run.sh) to know ROS packages')
    ros = _ros_packages()
    declared = _declared(package)
    missing, unknown = [], []
    for mod, where in sorted(_imports(package).items()):
        if mod in sys.stdlib_module_names or mod == package or mod == '__future__':
            continue
        if (package, mod) in OPTIONAL:
            continue
        key = PIP_KEYS.get(mod, mod if mod in ros else None)
        if key is None:
            unknown.append(f'{mod} ({where})')
        elif key not in declared:
            missing.append(f'{key} (import {mod} in {where})')
    assert not unknown, f'{package}: no rosdep key known for: {unknown} (add to PIP_KEYS)'
    assert not missing, f'{package}/package.xml lacks: {missing}'


@pytest.mark.parametrize('package', ['adcs_nodes', 'sim_node'])
def test_every_declared_key_resolves(package):
    project = _project_keys()
    ros = _ros_packages()
    bad = [k for k in _declared(package)
           if k not in ROSDISTRO_KEYS and k not in project and k not in ros]
    assert not bad, f'{package}: keys neither in rosdistro nor ros2_ws/rosdep.yaml: {bad}'


def test_project_keys_are_pinned_pip_packages():
    with open(os.path.join(ROOT, 'ros2_ws', 'requirements.txt'), encoding='utf-8') as fh:
        pinned = {re.split(r'[=<>\s]', line.strip())[0].lower()
                  for line in fh if line.strip() and not line.startswith('#')}
    for key, rule in _project_keys().items():
        assert key.endswith('-pip'), key
        for platform in ('debian', 'ubuntu'):
            for pkg in rule[platform]['pip']['packages']:
                assert pkg.lower() in pinned, f'{key}: {pkg} not pinned in requirements.txt'
