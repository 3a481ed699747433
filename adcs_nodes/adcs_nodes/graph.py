"""The node graph of a scenario (nodes, parameters, topics, handshake expectations) and its
ROS 2 parameter file; every deployment starts what :func:`build_graph` returns. No rclpy."""
from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass, field
from typing import Any, Dict, List

import yaml

from adcs_nodes import inputs as input_records
from adcs_nodes import registry
from adcs_nodes.core.geomag import FIELD
from adcs_nodes.core.manager import AUTO_SEQUENCE
from adcs_nodes.core.orbit import MU_EARTH, ORBIT, R_EARTH
from adcs_nodes.scenario import default_safe
from adcs_nodes.spec import CHAIN_TIMEOUT, HOLD, PROFILE, SCHEDULE


@dataclass
class NodeSpec:
    """One node (``ros2 run package executable``, or ``module.cls`` composed), flat ROS
    ``params``, its topics; ``lockstep``: the clock master waits for it at the start."""

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
    '/tf': 'tf2_msgs/msg/TFMessage',
    '/tf_static': 'tf2_msgs/msg/TFMessage',
    '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
    'actuators/magnetorquer/command': 'geometry_msgs/msg/Vector3Stamped',
    'actuators/wheels/command': 'sensor_msgs/msg/JointState',
    'sim/environment': 'adcs_msgs/msg/Environment',
    'sim/state': 'adcs_msgs/msg/AttitudeState',
    'sim/wheels': 'adcs_msgs/msg/WheelState',
    'sim/appendages': 'adcs_msgs/msg/AppendageState',
    'sim/faults': 'diagnostic_msgs/msg/DiagnosticArray',
    'adcs/actuator_command': 'adcs_msgs/msg/ActuatorCommand',
    'lockstep/status': 'adcs_msgs/msg/LockstepStatus',
    'sensors/magnetometer': 'sensor_msgs/msg/MagneticField',
    'sensors/horizon': 'adcs_msgs/msg/HorizonSensor',
    'sensors/star_tracker': 'sensor_msgs/msg/Imu',
    'sensors/gyro': 'sensor_msgs/msg/Imu',
    'adcs/attitude_estimate': 'adcs_msgs/msg/AttitudeState',
    'adcs/estimator/diagnostics': 'adcs_msgs/msg/FilterDiagnostics',
    'adcs/controller_status': 'adcs_msgs/msg/ControllerStatus',
    'adcs/attitude_target': 'adcs_msgs/msg/AttitudeTarget',
    'sensors/wheels': 'sensor_msgs/msg/JointState',
    'adcs/security_events': 'diagnostic_msgs/msg/DiagnosticArray',
}
COMMAND_TYPE = 'adcs_msgs/msg/ActuatorCommand'


def topic_type(topic: str) -> str:
    """Message type of ``topic`` (controller command topics and sensor topics included)."""
    if topic.startswith('adcs/controllers/') and topic.endswith('/command'):
        return COMMAND_TYPE
    if topic in TOPIC_TYPES:
        return TOPIC_TYPES[topic]
    for entry in registry.entries('sensor').values():
        if entry.node and entry.node[3] == topic:
            return entry.node[4]
    raise KeyError(topic)


def _row_major(matrix) -> List[float]:
    """A 3x3 matrix as 9 values, row-major (a ROS parameter has no nested lists)."""
    return [v for row in matrix for v in (row if isinstance(row, list) else [row])]


def _rad(values) -> List[float]:
    """Degrees to radians (what is not a number is passed on: the node refuses it)."""
    return [math.radians(v) if type(v) in (int, float) else v for v in values]


def _estimator_params(sc: Dict[str, Any]) -> Dict[str, Any]:
    est = sc['estimator']
    entry = registry.get('estimator', est['algorithm'])
    inertia = _row_major(sc['spacecraft']['inertia_kgm2'])
    p: Dict[str, Any] = {
        'algorithm': est['algorithm'], 'period_s': est['period_s'], 'inertia_kgm2': inertia,
        'initial_q_orbit_body': est['initial_q_orbit_body_xyzw'],
        'initial_omega_body_orbit_body': _rad(est['initial_omega_body_orbit_body_deg_s']),
        **{prm.name: est[prm.name] for prm in entry.params}}
    p.update(_input_periods(sc, entry.inputs))
    p.update(_onboard(est))
    return p


def _onboard(est: Dict[str, Any]) -> Dict[str, Any]:
    """``onboard_orbit.*`` and ``onboard_field.*``: the flight software's own models."""
    return {**ORBIT.flatten(est['onboard_orbit'], 'onboard_orbit'),
            **FIELD.flatten(est['onboard_field'], 'onboard_field')}


def flatten(prefix: str, data: Dict[str, Any], out: Dict[str, Any]) -> None:
    """Nested dict -> ``out`` with dotted keys (``orbit.altitude_km``)."""
    for key, value in data.items():
        name = f'{prefix}.{key}' if prefix else key
        if isinstance(value, dict):
            flatten(name, value, out)
        else:
            out[name] = value


def _common(sc: Dict[str, Any]) -> Dict[str, Any]:
    t = sc['timing']
    return {'epoch': sc['epoch'], 'seed': sc['seed'], 'frame_period_s': t['frame_s'],
            'timeout_s': t['timeout_s']}


def _spacecraft_params(sc: Dict[str, Any]) -> Dict[str, Any]:
    """``spacecraft.*`` of the dynamics, with the defaults that depend on other sections."""
    craft = copy.deepcopy(sc['spacecraft'])
    dist = craft['disturbance']
    if any(any(dist[k]) for k in ('aerodynamic_Nm', 'solar_pressure_Nm',
                                  'synthetic_gravity_gradient_Nm')):
        dist.setdefault('harmonic_period_s', orbital_period_s(sc['orbit']))
    if craft['wheel_error_std_Nms'] > 0.0:
        craft.setdefault('wheel_error_period_s', (sc.get('controllers') or {}).get(
            'period_s') or sc['timing']['frame_s'])
    return registry.section('spacecraft').flatten(craft, 'spacecraft')


def orbital_period_s(orbit: Dict[str, Any]) -> float:
    """Two-body period [s] of a validated ``orbit`` section (circular, or the TLE's)."""
    if orbit.get('type', 'circular') == 'circular':
        a = R_EARTH + 1e3 * float(orbit['altitude_km'])
        return 2.0 * math.pi * math.sqrt(a ** 3 / MU_EARTH)
    return 86400.0 / float(orbit['line2'][52:63])        # mean motion [rev/day]


def _world_nodes(sc: Dict[str, Any], common: Dict[str, Any], rate_factor: float,
                 max_rate: float) -> List[NodeSpec]:
    """The environment and the dynamics (the clock master; it announces every fault)."""
    dynamics = {**common, 'substeps': sc['timing']['substeps'],
                # the clock master waits longest: a fallback upstream arrives in time
                'timeout_factor': CHAIN_TIMEOUT['dynamics'],
                'rate_factor': float(rate_factor), 'lockstep_max_rate': float(max_rate),
                **_spacecraft_params(sc),
                **registry.section('initial').flatten(sc['initial'], 'initial')}
    if sc.get('faults'):
        dynamics['faults'] = json.dumps(sc['faults'], sort_keys=True)
    return [NodeSpec('environment', 'sim_node', 'environment', 'sim_node.nodes.environment',
                     'EnvironmentNode', {**common, **ORBIT.flatten(sc['orbit'], 'orbit'),
                                         **FIELD.flatten(sc['field'], 'field')},
                     publishes=['sim/environment', '/tf'], subscribes=['/clock']),
            NodeSpec('dynamics', 'sim_node', 'dynamics', 'sim_node.nodes.dynamics',
                     'DynamicsNode', dynamics, publishes=['/clock', 'sim/state', 'sim/wheels',
                                                          '/tf']
                     + (['sim/appendages'] if 'flexible' in sc['spacecraft'] else [])
                     + ['sim/faults'],     # also live faults (adcs fault): always recorded
                     subscribes=['sim/environment', 'adcs/actuator_command'])]


def build_graph(sc: Dict[str, Any], duration_s: float, real_time: bool = False,
                rate_factor: float = 1.0, record: bool = False,
                max_rate: float = 0.0) -> List[NodeSpec]:
    """Node specs of a validated scenario; ``max_rate``: sim s per wall s at most (0: none)."""
    common = _common(sc)
    common['real_time'] = bool(real_time)
    common['duration_s'] = duration_s          # every node knows its last frame
    nodes = _world_nodes(sc, common, rate_factor, max_rate)
    flight = {**common, 'timing_mode': 'lockstep'}
    # nodes that build registry components load the plugins (an empty list has no type)
    plugins = {'plugins': sc['plugins']} if sc.get('plugins') else {}
    for key, cfg in sc['sensors'].items():
        if cfg.get('external'):
            continue       # a real driver publishes this topic (the launcher says so)
        package, module, cls, topic, _ = registry.get('sensor', key).node
        inputs = ['sim/wheels'] if key == 'wheel_tachometer' else ['sim/state',
                                                                   'sim/environment']
        mine = [f for f in sc.get('faults', []) if f['target'] == key
                and 'sensor' in registry.get('fault', f['kind']).targets]
        nodes.append(NodeSpec(key, package, module.rsplit('.', 1)[1], module, cls,
                              {**common, **plugins,
                               **{k: v for k, v in cfg.items() if k != 'external'},
                               'timeout_factor': CHAIN_TIMEOUT['sensor'],
                               **({'faults': json.dumps(mine, sort_keys=True)} if mine else {})},
                              publishes=[topic, '/tf_static'], subscribes=['/clock'] + inputs))
    if 'estimator' in sc:
        entry = registry.get('estimator', sc['estimator']['algorithm'])
        subs = ['/clock', '/tf_static'] + [input_records.get(i).topic for i in entry.inputs]
        nodes.append(NodeSpec('estimator', 'adcs_nodes', 'estimator',
                              'adcs_nodes.nodes.estimator', 'EstimatorNode',
                              {**flight, **plugins, **_estimator_params(sc),
                               **_mounts(sc, entry.inputs),
                               **_sample_timing(sc, entry.inputs, real_time)},
                              publishes=['adcs/attitude_estimate',
                                         'adcs/estimator/diagnostics', '/tf'],
                              subscribes=subs))
    if 'controllers' in sc:
        nodes += _control_nodes(sc, flight, plugins)
        dyn = next(n for n in nodes if n.name == 'dynamics')
        dyn.params['command_period_s'] = sc['controllers']['period_s']
    for node in nodes:      # every LockstepNode publishes /diagnostics once per sim second
        node.publishes.append('/diagnostics')
    for f in sc.get('faults', []):      # a node_killed fault: the node stops at at_s
        if f['kind'] == 'node_killed':
            node = next(n for n in nodes if n.name == f['target'])
            at = float(f['at_s'])
            node.params['killed_at_s'] = min(at, node.params.get('killed_at_s', at))
    _add_publisher_guard(nodes)
    if record:
        topics = list(sc['record']['topics']) or sorted(
            {t for n in nodes for t in n.publishes} | {'lockstep/status'})
        nodes.append(NodeSpec(
            'recorder', 'adcs_nodes', 'recorder', 'adcs_nodes.nodes.recorder', 'RecorderNode',
            {'topics': [f'{t}={topic_type(t)}' for t in topics],
             'status_period_s': 0.1},           # its progress, for the clock's flow control
            publishes=[], subscribes=topics, lockstep=True))
    _add_handshake(nodes)
    return nodes


def _mounts(sc: Dict[str, Any], names) -> Dict[str, Any]:
    """``expected_mounts`` of a consumer: its simulated mounted sensors' frames."""
    frames = []
    for name in names:
        rec = input_records.get(name)
        cfg = sc['sensors'].get(rec.sensor) if rec.sensor else None
        if rec.mounted and cfg is not None and not cfg.get('external'):
            frames.append(rec.sensor)        # a sensor node's frame_id is its name
    return {'expected_mounts': frames} if frames else {}


def _sample_timing(sc: Dict[str, Any], names, real_time: bool) -> Dict[str, Any]:
    """``external_inputs`` of a consumer, taken in sample timing (never awaited): a driver's,
    or every sensor's in real-time mode (DESIGN section 6)."""
    keys = []
    for name in names:
        rec = input_records.get(name)
        cfg = sc['sensors'].get(rec.sensor) if rec.sensor else None
        if cfg is not None and (cfg.get('external') or real_time):
            keys.append(rec.key)
    return {'external_inputs': keys} if keys else {}


def _input_periods(sc: Dict[str, Any], names) -> Dict[str, float]:
    """The producer periods of inputs ``names`` in this scenario, by period parameter."""
    ctrl = sc.get('controllers') or {}
    producers = {
        'estimate': (sc.get('estimator') or {}).get('period_s'),
        'target': (sc.get('guidance') or {}).get('period_s') or ctrl.get('period_s'),
        'actuator_command': ctrl.get('period_s')}
    out = {}
    for name in names:
        rec = input_records.get(name)
        period = (sc['sensors'].get(rec.sensor, {}).get('period_s') if rec.sensor
                  else producers.get(name))
        if period is not None:
            out[rec.period_param] = period
    return out


def _spacecraft_context(sc: Dict[str, Any]) -> Dict[str, Any]:
    """What every controller node knows of the spacecraft (``CONTEXT_PARAMS`` of the node)."""
    craft = sc['spacecraft']
    wheels = craft.get('wheels') or []
    p: Dict[str, Any] = {
        'inertia_kgm2': _row_major(craft['inertia_kgm2']),
        'max_dipole_Am2': craft['magnetorquer']['max_dipole_Am2']
        if 'magnetorquer' in craft else [0.0, 0.0, 0.0]}    # zero: no magnetorquer
    if wheels:
        p['wheel_axes_body'] = [c for w in wheels for c in w['axis']]
        p['wheel_max_torque_Nm'] = [w['max_torque_Nm'] for w in wheels]
        p['wheel_max_momentum_Nms'] = [w['max_momentum_Nms'] for w in wheels]
        p['wheel_inertia_kgm2'] = [w['inertia_kgm2'] for w in wheels]
    return p


def _guidance_node(sc: Dict[str, Any], flight: Dict[str, Any]) -> NodeSpec:
    """The guidance node: the scenario's profile (default: hold the orbital frame)."""
    g = sc.get('guidance') or {}
    period = g.get('period_s')
    params = {**flight, 'period_s': sc['controllers']['period_s'] if period is None else period,
              'frame': g.get('frame', 'orbit'),
              'controllers': [k for k in sc['controllers'] if k != 'period_s'],
              **PROFILE.to_columns(g.get('profile') or HOLD, 'profile_')}
    if g.get('euler312_profile'):
        params['euler312_profile'] = json.dumps(g['euler312_profile'])
    return NodeSpec('guidance', 'adcs_nodes', 'guidance', 'adcs_nodes.nodes.guidance',
                    'GuidanceNode', params, publishes=['adcs/attitude_target'],
                    # the slew action follows the estimate and the applied command
                    subscribes=['/clock', 'adcs/attitude_estimate', 'adcs/actuator_command'])


def _control_nodes(sc: Dict[str, Any], flight: Dict[str, Any],
                   plugins: Dict[str, Any]) -> List[NodeSpec]:
    """Guidance, one node per configured controller (any registered one), the manager."""
    ctrl = sc['controllers']
    est_period = sc['estimator']['period_s'] if 'estimator' in sc else 0.0
    craft = _spacecraft_context(sc)
    limits = craft['max_dipole_Am2']
    wheels = sc['spacecraft'].get('wheels') or []
    names = [k for k in ctrl if k != 'period_s']
    entries = {n: registry.get('controller', n) for n in names}
    shared = {**flight, **craft, 'period_s': ctrl['period_s']}
    nodes = []
    nodes.append(_guidance_node(sc, flight))     # targets, and the adcs/slew action
    for name, entry in entries.items():
        params = {**shared, **plugins, 'controller': name, **ctrl[name],
                  **_mounts(sc, entry.inputs),
                  **_sample_timing(sc, entry.inputs, flight['real_time']),
                  'timeout_factor': CHAIN_TIMEOUT['controller']}
        params.update(_input_periods(sc, entry.inputs))
        if {'estimate', 'magnetometer'} <= set(entry.inputs):
            params.update(_onboard(sc['estimator']))
        subs = ['/clock'] + [input_records.get(i).topic for i in entry.inputs]
        if any(input_records.get(i).mounted for i in entry.inputs):
            subs.append('/tf_static')
        nodes.append(NodeSpec(f'{name}_controller', 'adcs_nodes', 'controller',
                              'adcs_nodes.nodes.controller', 'ControllerNode', params,
                              publishes=[f'adcs/controllers/{name}/command'], subscribes=subs))
    man = sc.get('manager') or {'safe': default_safe(names),
                                'initial': '', 'stale_after_s': 0.0, 'schedule': []}
    users = [n for n, e in entries.items() if 'estimate' in e.inputs]
    watch_estimate = est_period > 0 and (users or 'auto' in man)
    mparams: Dict[str, Any] = {
        **flight, 'controllers': names, 'safe': man['safe'], 'initial': man['initial'],
        'timeout_factor': CHAIN_TIMEOUT['manager'],
        'period_s': ctrl['period_s'], 'controller_period_s': ctrl['period_s'],
        # the manager watches the estimate: stale -> the safe controller (which needs none)
        'estimator_period_s': est_period if watch_estimate else 0.0,
        'estimate_users': users or [''],
        # real time: nodes take the latest values, so a command may be a frame old
        'stale_after_s': man['stale_after_s'] or (1.5 * ctrl['period_s'] if flight['real_time']
                                                  else 0.0),
        'max_dipole_Am2': limits,
        'max_torque_Nm': sc['spacecraft']['ideal_torque']['max_torque_Nm']
        if 'ideal_torque' in sc['spacecraft'] else [0.0, 0.0, 0.0]}
    if wheels:
        mparams['max_wheel_torque_Nm'] = [w['max_torque_Nm'] for w in wheels]
        mparams['wheel_names'] = [w['name'] for w in wheels]
    if man.get('fallback'):
        mparams['fallback'] = man['fallback']
    if man['schedule']:
        mparams.update(SCHEDULE.to_columns(man['schedule'], 'schedule_'))
    if 'auto' in man:
        mparams.update(AUTO_SEQUENCE.flatten(man['auto'], 'auto'))
    subs = ['/clock'] + [f'adcs/controllers/{n}/command' for n in names]
    if watch_estimate:
        subs.append('adcs/attitude_estimate')
    nodes.append(NodeSpec('controller_manager', 'adcs_nodes', 'controller_manager',
                          'adcs_nodes.nodes.controller_manager', 'ControllerManagerNode',
                          mparams, publishes=['adcs/actuator_command', 'adcs/controller_status',
                                              'actuators/magnetorquer/command']
                          + (['actuators/wheels/command'] if wheels else []),
                          subscribes=subs))
    return nodes


#: Consumers that accept each input only from its producer (``docs/security.md``).
GUARDED_NODES = ('dynamics', 'controller_manager')
#: Where a guarded node reports refused messages (recorded with the graph's topics).
SECURITY_EVENTS = 'adcs/security_events'


def _add_publisher_guard(nodes: List[NodeSpec]) -> None:
    """``expected_publishers`` (``<topic>=<node>``) of the guarded nodes' one-producer topics."""
    for node in nodes:
        if node.name not in GUARDED_NODES:
            continue
        exp = []
        for topic in node.subscribes:
            producers = [o.name for o in nodes if o is not node and topic in o.publishes]
            if topic not in ('/clock', '/tf', '/tf_static') and len(producers) == 1:
                exp.append(f'{topic}={producers[0]}')
        if exp:
            node.params['expected_publishers'] = exp
            node.publishes.append(SECURITY_EVENTS)


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


class _NoAliasDumper(yaml.SafeDumper):
    """The rcl parameter-file parser knows no YAML anchors/aliases: write every value out."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


def params_file_text(nodes: List[NodeSpec]) -> str:
    """ROS 2 parameter file of the graph (an empty list, untyped there, is left out)."""
    doc = {f'/{n.name}': {'ros__parameters': _nest({k: v for k, v in n.params.items()
                                                    if not (isinstance(v, list) and not v)})}
           for n in nodes}
    return yaml.dump(doc, Dumper=_NoAliasDumper, sort_keys=True, default_flow_style=None)


def _nest(flat: Dict[str, Any]) -> Dict[str, Any]:
    out: Dict[str, Any] = {}
    for key, value in flat.items():
        parts = key.split('.')
        cur = out
        for p in parts[:-1]:
            cur = cur.setdefault(p, {})
        cur[parts[-1]] = value
    return out
