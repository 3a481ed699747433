"""Engine parity through every fault combination (issue 38 item 1): the plain engine and the
composed one (every node in this process, messages passed in process, the world running
ahead of a consumer that stopped waiting for a dead producer) give the same series on every
data topic, to the bit, for faults drawn at random: kinds, targets, overlaps and times, on
short runs of the demo mission (every sensor, the MEKF, four controllers, wheels and rods).

The named example is the issue's: two overlapping star-tracker bias steps make the MEKF
refuse 10 samples and restart, then the star tracker is silent and stuck; the composed
engine used the returning sample when it came before the estimator counted its third miss.
20 examples in ``make test``, 200 in ``make test-long``.
"""
import importlib
import os

import pytest
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from adcs_nodes.graph import params_file_text, topic_type
from adcs_nodes.inputs import converter
from adcs_nodes.msgs.cdr import codec
from adcs_nodes.scenario import load_scenario
from adcs_nodes.tools.run.compose import InProcessBus, drive_lifecycle, overrides_for

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

DURATION_S = 24.0
NOT_DATA = ('/clock', '/tf', '/tf_static', '/diagnostics', '/adcs/security_events',
            '/adcs/controller_status', '/lockstep/status')
SENSORS = {'magnetometer': 2e-6, 'gyro': 1e-3, 'star_tracker': 1e-2, 'horizon_sensor': 5e-2,
           'wheel_tachometer': 1.0}          # a step or noise of this size, sensor units
#: Nodes a ``node_killed`` fault strikes here. Not the controller manager: with it gone the world
#: no longer waits for a command and runs up to the throttle ahead of the slowest node, which
#: the clock master's end-of-run wait (one timeout) may not see finish (a separate question,
#: tests/graph/test_node_killed_graph.py covers that kill on its own).
NODES = ('estimator', 'guidance', 'magnetic_controller', 'mpi_controller', 'fuzzy_controller',
         'magnetometer', 'star_tracker', 'gyro')


def _timed(kind, target, **params):
    return st.builds(lambda at, dur: {'at_s': float(at), 'kind': kind, 'target': target,
                                      'params': {**params, 'duration_s': float(dur)}},
                     st.integers(0, 18), st.sampled_from([0, 1, 3, 5, 10]))


FAULT = st.one_of(
    st.sampled_from(sorted(SENSORS)).flatmap(lambda s: st.one_of(
        *(_timed(k, s) for k in ('dropout', 'nan', 'stuck')),
        _timed('bias_step', s, bias=[SENSORS[s], -SENSORS[s], 0.5 * SENSORS[s]]),
        _timed('noise_burst', s, std=[SENSORS[s]] * 3))),
    st.sampled_from(['wheel_x', 'wheel_y', 'wheel_z']).flatmap(lambda w: st.one_of(
        _timed('wheel_stuck', w), _timed('wheel_torque_lost', w, fraction=0.25))),
    st.sampled_from(['x', 'y', 'z']).flatmap(lambda a: _timed('coil_open', a)),
    st.builds(lambda at, node: {'at_s': float(at), 'kind': 'node_killed', 'target': node},
              st.integers(1, 18), st.sampled_from(NODES)))


def issue_38_faults(t0):
    """The issue's combination from ``t0``: two overlapping star-tracker bias steps (the MEKF
    refuses 10 samples and restarts at t0 + 9 s), the star tracker silent 10-15 s after t0 and
    stuck 11-21 s after t0."""
    def at(dt, kind, **params):
        return {'at_s': t0 + dt, 'kind': kind, 'target': 'star_tracker', 'params': params}
    return [at(0.0, 'bias_step', bias=[0.01, 0.0, 0.0], duration_s=15.0),
            at(1.0, 'bias_step', bias=[0.0, 0.01, 0.0], duration_s=15.0),
            at(10.0, 'dropout', duration_s=5.0), at(11.0, 'stuck', duration_s=10.0)]


def demo_scenario(tmp_path, faults, timeout_s=0.4):
    """The demo mission with ``faults`` and a short input timeout, validated; its file."""
    with open(os.path.join(ROOT, 'scenarios', 'demo_mission.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['faults'] = faults
    sc['timing']['timeout_s'] = timeout_s
    sc.pop('record', None)
    path = tmp_path / 'faults.yaml'
    path.write_text(yaml.safe_dump(sc))
    return load_scenario(str(path)), str(path)


def log_misses(sync, name, log):
    """Record ``(node, frame, missing inputs)`` of every miss ``sync`` counts into ``log``."""
    record = sync.record_misses

    def recorded(t_ns):
        log.add((name, int(t_ns), tuple(sorted(sync.missing(t_ns)))))
        return record(t_ns)
    sync.record_misses = recorded


def plain_series(sc, duration_s, misses):
    """Every topic's CDR bytes in order of the plain engine's run (what its bag holds); its
    consumers' misses into ``misses``."""
    from sim_node.engine import FrameLoop
    loop = FrameLoop.from_scenario(sc, duration_s)
    for c in loop.consumers:
        log_misses(c.sync, c.name, misses)
    out = {}
    for frame in loop.run():
        for topic, x in frame.outputs:
            msg = converter(topic).to_msg(x, loop.epoch_ns)
            out.setdefault('/' + topic.lstrip('/'), []).append(codec(type(msg)).encode(msg))
    return out


def composed_series(sc, duration_s, spin, tmp_path, misses):
    """Every data topic's CDR bytes in order of a composed run in this process; every node's
    misses (the world's too) into ``misses``. Each run has a context (a DDS participant) of its
    own, as a composed process has: nodes re-created under the same names in one participant
    were sometimes not listed in its graph under load, and the handshake waited for them."""
    import rclpy

    from adcs_nodes.nodes.runtime import make_executor
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        return _composed_run(sc, duration_s, ctx, spin, tmp_path, misses, make_executor)
    finally:
        rclpy.shutdown(context=ctx)


def _composed_run(sc, duration_s, ctx, spin, tmp_path, misses, make_executor):
    from rclpy.node import Node

    from adcs_nodes.tools.run.launcher import Launcher
    launcher = Launcher(sc, duration_s=duration_s, compose=True, progress=False,
                        run_dir=str(tmp_path), log=lambda *a, **k: None)
    doc = yaml.safe_load(params_file_text(launcher.nodes))
    nodes = [getattr(importlib.import_module(n.module), n.cls)(
        n.name, context=ctx, parameter_overrides=overrides_for(doc, n.name))
        for n in launcher.nodes]
    assert drive_lifecycle(nodes) == ''
    for node in nodes:
        if getattr(node, 'sync', None) is not None:
            log_misses(node.sync, node.get_name(), misses)
    collector = Node('collector', context=ctx)
    out = {}
    topics = sorted({t for n in launcher.nodes for t in n.publishes})
    for topic in topics:
        name = '/' + topic.lstrip('/')
        if name in NOT_DATA:
            continue
        pkg, _, cls = topic_type(topic).split('/')
        cls = getattr(importlib.import_module(f'{pkg}.msg'), cls)
        collector.create_subscription(cls, name, lambda m, n=name: out.setdefault(
            n, []).append(codec(type(m)).encode(m)), 1000)
    InProcessBus(nodes + [collector])
    master = next(n for n in nodes if n.get_name() == 'dynamics')
    try:     # the composed runner's executor (an EventsExecutor)
        assert spin(nodes + [collector], lambda: master.done, timeout=300.0,
                    executor=make_executor(ctx))
        spin(nodes + [collector], lambda: False, timeout=0.2,      # the last deliveries
             executor=make_executor(ctx))
    finally:
        for n in nodes + [collector]:
            n.destroy_node()
    return out


def check_parity(faults, spin, tmp_path, duration_s=DURATION_S, attempts=3):
    """The composed run's series equal the plain run's, and so do the inputs each consumer
    missed. A composed run in which an input timed out that the plain run did not miss (its
    producer was late by more than a timeout of wall time: the machine's load, not the rule)
    is run again, up to ``attempts`` times."""
    sc, _ = demo_scenario(tmp_path, faults)
    killed = {f['target']: round(f['at_s'] * 1e9) for f in faults if f['kind'] == 'node_killed'}

    def alive(log):            # (a killed node may count the miss of the frame it stops at)
        return {m for m in log if m[1] < killed.get(m[0], 2 ** 62)}
    expected = set()
    plain = {t: v for t, v in plain_series(sc, duration_s, expected).items()
             if t not in NOT_DATA}
    expected = alive(expected)
    for attempt in range(attempts):
        misses, run_dir = set(), tmp_path / f'composed{attempt}'
        run_dir.mkdir()
        composed = composed_series(sc, duration_s, spin, run_dir, misses)
        misses = alive(misses)
        if misses <= expected:
            break
    else:
        pytest.fail(f'in every composed run inputs timed out that the plain run did not miss '
                    f'(the load, or a rule that differs): {sorted(misses - expected)[:5]}')
    assert misses == expected
    assert sorted(composed) == sorted(plain)
    differ = [t for t in plain if plain[t] != composed[t]]
    assert not differ, {t: (len(plain[t]), len(composed[t])) for t in differ}


# beside the parallel tests: a composed run with a miss the plain run has not (the load) is
# run again (check_parity, attempts)
@pytest.mark.parametrize('examples', [
    pytest.param(20, marks=pytest.mark.timeout(1200)),
    pytest.param(200, marks=[pytest.mark.long, pytest.mark.timeout(10800)])])
def test_plain_and_composed_agree_through_random_faults(examples, ros_context, spin,
                                                        tmp_path_factory):
    @settings(max_examples=examples, deadline=None, derandomize=examples == 20,
              suppress_health_check=list(HealthCheck))
    @given(faults=st.lists(FAULT, min_size=1, max_size=4))
    @example(faults=issue_38_faults(2.0))
    def check(faults):
        check_parity(faults, spin, tmp_path_factory.mktemp('run'))   # (ros_context: the domain)
    check()
