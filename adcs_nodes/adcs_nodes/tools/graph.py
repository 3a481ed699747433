"""The node graph of a scenario: which nodes run, their parameters and their topics.

The launcher and the composed runner both start what :func:`build_graph` returns, so the two
deployments run exactly the same nodes with the same parameters. The graph also yields each
node's start-handshake expectations (how many DDS endpoints must be matched, see
``adcs_nodes.nodes.lockstep_node``) and the ROS 2 parameter file.

Pure Python; no rclpy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List

import yaml


@dataclass
class NodeSpec:
    """One node of the graph.

    Attributes
    ----------
    name : str
        Node name (also the process name shown by the launcher).
    package, executable : str
        For ``ros2 run package executable``.
    module, cls : str
        Python module and class (composed mode builds the class in-process).
    params : dict
        ROS parameters (flat; dotted names for sections).
    publishes, subscribes : list of str
        Topics, for the handshake expectations and the recorder.
    lockstep : bool
        Takes part in the start handshake (the clock master waits for it).
    """

    name: str
    package: str
    executable: str
    module: str
    cls: str
    params: Dict[str, Any] = field(default_factory=dict)
    publishes: List[str] = field(default_factory=list)
    subscribes: List[str] = field(default_factory=list)
    lockstep: bool = True


#: Message type of every topic the graph can carry (the recorder subscribes by type).
TOPIC_TYPES = {
    '/clock': 'rosgraph_msgs/msg/Clock',
    'sim/environment': 'adcs_msgs/msg/Environment',
    'sim/state': 'adcs_msgs/msg/AttitudeState',
    'sim/wheels': 'adcs_msgs/msg/WheelState',
    'adcs/actuator_command': 'adcs_msgs/msg/ActuatorCommand',
    'lockstep/status': 'adcs_msgs/msg/LockstepStatus',
}


def _flatten(prefix: str, data: Dict[str, Any], out: Dict[str, Any]) -> None:
    for key, value in data.items():
        name = f'{prefix}.{key}' if prefix else key
        if isinstance(value, dict):
            _flatten(name, value, out)
        else:
            out[name] = value


def _common(sc: Dict[str, Any]) -> Dict[str, Any]:
    t = sc['timing']
    return {'epoch': sc['epoch'], 'seed': int(sc['seed']), 'frame_period_s': t['frame_s'],
            'timeout_s': t['timeout_s']}


def _spacecraft_params(sc: Dict[str, Any]) -> Dict[str, Any]:
    s = sc['spacecraft']
    p: Dict[str, Any] = {
        'inertia_kgm2': [float(v) for row in s['inertia_kgm2'] for v in row],
        'gravity_gradient': bool(s['gravity_gradient']),
        'constant_torque_Nm': s['disturbance']['constant_torque_Nm'],
        'random_std_Nm': s['disturbance']['random_std_Nm'],
        'random_period_s': s['disturbance']['random_period_s'],
    }
    if 'magnetorquer' in s:
        p['max_dipole_Am2'] = s['magnetorquer']['max_dipole_Am2']
    wheels = s.get('wheels') or []
    if wheels:
        p['wheel_names'] = [w['name'] for w in wheels]
        p['wheel_axes'] = [float(c) for w in wheels for c in w['axis']]
        p['wheel_max_torque_Nm'] = [w['max_torque_Nm'] for w in wheels]
        p['wheel_max_momentum_Nms'] = [w['max_momentum_Nms'] for w in wheels]
        p['wheel_inertia_kgm2'] = [w['inertia_kgm2'] for w in wheels]
        p['wheel_h0_Nms'] = [w['h0_Nms'] for w in wheels]
    return {f'spacecraft.{k}': v for k, v in p.items()}


def _initial_params(sc: Dict[str, Any]) -> Dict[str, Any]:
    init = sc['initial']
    p: Dict[str, Any] = {}
    if 'q_orbit_body_wxyz' in init:
        w, x, y, z = init['q_orbit_body_wxyz']
        p['q_orbit_body'] = [x, y, z, w]
    elif 'q_orbit_body_xyzw' in init:
        p['q_orbit_body'] = list(init['q_orbit_body_xyzw'])
    if 'omega_body_eci_body_deg_s' in init:
        p['omega_body_eci_body'] = [math.radians(v) for v in init['omega_body_eci_body_deg_s']]
    elif 'omega_body_orbit_body_deg_s' in init:
        p['omega_body_orbit_body'] = [math.radians(v)
                                      for v in init['omega_body_orbit_body_deg_s']]
    return {f'initial.{k}': v for k, v in p.items()}


def build_graph(sc: Dict[str, Any], duration_s: float, real_time: bool = False,
                rate_factor: float = 1.0, record: bool = False) -> List[NodeSpec]:
    """Node specs of a validated scenario (see :func:`adcs_nodes.tools.scenario.load_scenario`)."""
    common = _common(sc)
    common['real_time'] = bool(real_time)
    env_params = dict(common)
    _flatten('orbit', sc['orbit'], env_params)
    _flatten('field', sc['field'], env_params)
    nodes = [
        NodeSpec('environment', 'sim_node', 'environment', 'sim_node.nodes.environment',
                 'EnvironmentNode', env_params, publishes=['sim/environment'],
                 subscribes=['/clock']),
        NodeSpec('dynamics', 'sim_node', 'dynamics', 'sim_node.nodes.dynamics', 'DynamicsNode',
                 {**common, 'duration_s': float(duration_s),
                  'substeps': int(sc['timing']['substeps']),
                  'rate_factor': float(rate_factor), **_spacecraft_params(sc),
                  **_initial_params(sc)},
                 publishes=['/clock', 'sim/state', 'sim/wheels'],
                 subscribes=['sim/environment', 'adcs/actuator_command']),
    ]
    if record:
        topics = list(sc['record']['topics']) or sorted(
            {t for n in nodes for t in n.publishes} | {'lockstep/status'})
        nodes.append(NodeSpec(
            'recorder', 'adcs_nodes', 'recorder', 'adcs_nodes.nodes.recorder', 'RecorderNode',
            {'topics': [f'{t}={TOPIC_TYPES[t]}' if t in TOPIC_TYPES else t for t in topics]},
            publishes=[], subscribes=topics, lockstep=True))
    _add_handshake(nodes)
    return nodes


def _add_handshake(nodes: List[NodeSpec]) -> None:
    """Fill each node's ``expected_matches`` and the clock master's ``wait_for_nodes``."""
    for node in nodes:
        exp = []
        for topic in node.publishes:
            n = sum(topic in other.subscribes for other in nodes if other is not node)
            if n:
                exp.append(f'pub:{topic}={n}')
        for topic in node.subscribes:
            n = sum(topic in other.publishes for other in nodes if other is not node)
            if n:
                exp.append(f'sub:{topic}={n}')
        if exp:
            node.params['expected_matches'] = exp
    master = next(n for n in nodes if n.name == 'dynamics')
    others = [n.name for n in nodes if n.lockstep and n is not master]
    if others:  # (an empty list has no type in a ROS parameter file)
        master.params['wait_for_nodes'] = others


def params_file_text(nodes: List[NodeSpec]) -> str:
    """ROS 2 parameter file (``--params-file``) for every node of the graph."""
    doc = {f'/{n.name}': {'ros__parameters': _nest(n.params)} for n in nodes}
    return yaml.safe_dump(doc, sort_keys=True, default_flow_style=None)


def _nest(flat: Dict[str, Any]) -> Dict[str, Any]:
    out: Dict[str, Any] = {}
    for key, value in flat.items():
        parts = key.split('.')
        cur = out
        for p in parts[:-1]:
            cur = cur.setdefault(p, {})
        cur[parts[-1]] = value
    return out
