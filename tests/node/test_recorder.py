"""Recorder node in process: raw recording into MCAP, latched topics, schemas, time stamps.

The truth is what the test's own publisher sent; the bag is read back with ``rosbags`` (the
bag directory, and the bare ``.mcap`` file whose embedded schemas are checked against the
type hashes that ``rosidl`` generated for the installed interfaces).
"""
import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy')

from adcs_msgs.msg import ControllerStatus, Environment, LockstepStatus  # noqa: E402
from ament_index_python.packages import get_package_share_directory  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.rosbag2 import Reader  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from adcs_nodes.nodes.recorder import OutputExistsError, RecorderNode  # noqa: E402
from adcs_nodes.bag import read_messages  # noqa: E402
from bag_digest import topic_summary  # noqa: E402
from domains import worker_domain  # noqa: E402

N = 40
T0_NS = 1_700_000_000 * 10**9
LATCHED = ControllerStatus


@pytest.fixture(scope='module')
def context():
    """Isolated rclpy context on a per-process domain, localhost discovery only."""
    from adcs_nodes.tools.run.launcher import DDS_ENV_KEYS, child_env, use_dds_env
    saved = {k: os.environ.get(k) for k in DDS_ENV_KEYS}
    use_dds_env(child_env(worker_domain(200, 15)))   # its own range: no other test
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.shutdown(context=ctx)
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


@pytest.fixture
def executor(context):
    try:
        from rclpy.experimental import EventsExecutor
        ex = EventsExecutor(context=context)
    except ImportError:
        from rclpy.executors import SingleThreadedExecutor
        ex = SingleThreadedExecutor(context=context)
    yield ex
    ex.shutdown()


def spin_until(executor, predicate, timeout=30.0, what='condition'):
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out waiting for {what}')
        executor.spin_once(timeout_sec=0.02)


def _remove(executor, *nodes) -> None:
    """End of a test: close the bag of a recorder, then remove and destroy each node."""
    for node in nodes:
        if isinstance(node, RecorderNode):
            node.close()
        executor.remove_node(node)
        node.destroy_node()


def make_environment(i: int) -> Environment:
    msg = Environment()
    t_ns = T0_NS + i * 100_000_000
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 10**9)
    msg.header.frame_id = 'eci'
    msg.r_eci.x, msg.r_eci.y, msg.r_eci.z = 7.0e6 + i, -1.5e3 * i, 1.0 / (i + 3)
    msg.v_eci.x, msg.v_eci.y, msg.v_eci.z = 1.0e-3 * i, 7.5e3, -2.0
    msg.q_eci_orbit.x, msg.q_eci_orbit.w = 0.1 * (i % 3), 0.9
    msg.omega_orbit_eci_eci.y = 1.1e-3
    msg.orbit_rate = 1.0e-3 + 1e-9 * i
    msg.argument_of_latitude = 0.01 * i
    msg.b_eci.x, msg.b_eci.y, msg.b_eci.z = 2e-5, -3e-5 * i, 4.2e-5
    msg.b_dot_eci.z = 1e-9 * i
    msg.q_eci_ecef.z, msg.q_eci_ecef.w = 0.6, 0.8
    return msg


def assert_same(ros_msg, bag_msg, path='msg'):
    """Field-by-field equality of an rclpy message and a rosbags message (exact floats)."""
    for name in ros_msg.get_fields_and_field_types():
        a, b = getattr(ros_msg, name), getattr(bag_msg, name)
        where = f'{path}.{name}'
        if hasattr(a, 'get_fields_and_field_types'):
            assert_same(a, b, where)
        elif isinstance(a, (list, tuple)) or hasattr(a, 'tolist'):
            assert list(a) == list(b), where
        else:
            assert a == b, where


def installed_hash(msgtype: str) -> str:
    pkg, _, name = msgtype.split('/')
    path = Path(get_package_share_directory(pkg)) / 'msg' / f'{name}.json'
    hashes = json.loads(path.read_text())['type_hashes']
    return next(h['hash_string'] for h in hashes if h['type_name'] == msgtype)


def test_records_every_message_latched_and_schemas(context, executor, tmp_path):
    talker = Node('talker', context=context)
    env_pub = talker.create_publisher(Environment, 'sim/environment', 100)
    str_pub = talker.create_publisher(String, 'chatter', 100)
    clock_pub = talker.create_publisher(Clock, '/clock', 10)
    latched_qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                             reliability=ReliabilityPolicy.RELIABLE)
    status_pub = talker.create_publisher(LATCHED, 'adcs/controller_status', latched_qos)
    latched = LATCHED(active='magnetic', available=['bdot', 'magnetic'], mode='point',
                      switch_count=3, missed_frames=1, last_fault='stale')
    latched.header.stamp.sec = 1_700_000_000
    status_pub.publish(latched)  # before the recorder exists
    statuses = []
    talker.create_subscription(LockstepStatus, 'recorder/status', statuses.append, 10)
    executor.add_node(talker)

    bag = tmp_path / 'bag'
    recorder = RecorderNode(context=context, parameter_overrides=[
        Parameter('output', value=str(bag)), Parameter('discovery_period_s', value=0.1)])
    executor.add_node(recorder)
    try:
        spin_until(executor, lambda: (env_pub.get_subscription_count() > 0
                                      and str_pub.get_subscription_count() > 0
                                      and clock_pub.get_subscription_count() > 0
                                      and status_pub.get_subscription_count() > 0),
                   what='recorder subscriptions')
        spin_until(executor, lambda: recorder.counts.get('/adcs/controller_status') == 1,
                   what='latched message')
        sent_env = [make_environment(i) for i in range(N)]
        sent_str = [String(data=f'message {i} \u00e9') for i in range(N)]
        for env, text in zip(sent_env, sent_str):
            env_pub.publish(env)
            str_pub.publish(text)
        clock = Clock()
        clock.clock.sec, clock.clock.nanosec = 1_700_000_123, 456
        clock_pub.publish(clock)
        spin_until(executor, lambda: (recorder.counts.get('/sim/environment') == N
                                      and recorder.counts.get('/chatter') == N
                                      and recorder.counts.get('/clock') == 1),
                   what='all messages recorded')
        # + the latched lockstep/ready of the recorder itself (no expectations: ready at once)
        spin_until(executor, lambda: recorder.counts.get('/lockstep/ready') == 1,
                   what='own lockstep/ready')
        spin_until(executor, lambda: statuses and statuses[-1].frames == 2 * N + 3,
                   what='recorder/status')
        assert statuses[-1].node == 'recorder'
        assert (statuses[-1].header.stamp.sec, statuses[-1].header.stamp.nanosec) == (
            1_700_000_123, 456)
        assert statuses[-1].missed_frames == 0
        assert '/recorder/status' not in recorder.topics
        assert '/rosout' not in recorder.topics
    finally:
        _remove(executor, recorder, talker)

    # contents, order and counts
    got = {}
    for topic, _, msg in read_messages(bag):
        got.setdefault(topic, []).append(msg)
    assert len(got['/sim/environment']) == N
    for i, (sent, rec) in enumerate(zip(sent_env, got['/sim/environment'])):
        assert_same(sent, rec, f'environment[{i}]')
    assert [m.data for m in got['/chatter']] == [m.data for m in sent_str]
    assert len(got['/adcs/controller_status']) == 1
    assert_same(latched, got['/adcs/controller_status'][0], 'controller_status')
    summary = topic_summary(bag)
    assert summary['/sim/environment'][:2] == ('adcs_msgs/msg/Environment', N)
    assert summary['/chatter'][:2] == ('std_msgs/msg/String', N)
    assert set(summary) == {'/sim/environment', '/chatter', '/clock', '/adcs/controller_status',
                            '/lockstep/ready'}
    assert [m.data for m in got['/lockstep/ready']] == ['recorder']

    # metadata.yaml carries the RIHS01 hashes of the installed interfaces
    with Reader(bag) as reader:
        for conn in reader.connections:
            assert conn.digest == installed_hash(conn.msgtype), conn.topic
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
        assert qos['/adcs/controller_status'][0].durability.name == 'TRANSIENT_LOCAL'
        assert qos['/chatter'][0].durability.name == 'VOLATILE'

    # the bare MCAP file alone (no metadata.yaml, no default types) embeds complete schemas:
    # the types rebuilt from them hash to the installed interfaces' RIHS01
    mcap_files = list(bag.glob('*.mcap'))
    assert len(mcap_files) == 1
    with AnyReader([mcap_files[0]]) as reader:
        assert {c.topic for c in reader.connections} == set(summary)
        for conn in reader.connections:
            assert conn.msgdef.data.strip(), conn.topic
            assert reader.typestore.hash_rihs01(conn.msgtype) == installed_hash(conn.msgtype)
        env_def = next(c for c in reader.connections if c.topic == '/sim/environment')
        assert env_def.msgdef.data.startswith('std_msgs/Header header\n')
        assert 'MSG: geometry_msgs/Vector3' in env_def.msgdef.data
        assert len(list(reader.messages())) == 2 * N + 3
    raw = mcap_files[0].read_bytes()
    assert raw.startswith(b'\x89MCAP0\r\n') and raw.endswith(b'\x89MCAP0\r\n')
    assert b'ros2msg' in raw and b'adcs_msgs/msg/ControllerStatus' in raw
    assert 'version: 8' in (bag / 'metadata.yaml').read_text()


def _mount(t_ns: int):
    """A latched ``/tf_static`` mount stamped ``t_ns`` (what the mounts node publishes)."""
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage
    tf = TransformStamped()
    tf.header.stamp.sec, tf.header.stamp.nanosec = divmod(t_ns, 10**9)
    tf.header.frame_id, tf.child_frame_id, tf.transform.rotation.w = 'body', 'magnetometer', 1.0
    return TFMessage(transforms=[tf])


def test_log_time_is_the_stamp_unstamped_at_the_clock(context, executor, tmp_path):
    """A bag's timeline is the simulation's (DESIGN section 8; issue 37, items 1 and 2).

    Log time = the message's own stamp: the latched ``/tf_static`` mount that arrives before
    any ``/clock`` publisher exists, an Environment one frame ahead of ``/clock``. An unstamped
    String: at its receive time while no ``/clock`` publisher exists, held until the first
    ``/clock`` once one does, then at the latest ``/clock``. Unlisted topics are not recorded.
    """
    from adcs_nodes.nodes.tf import QOS_TF_STATIC
    talker = Node('talker2', context=context)
    tf_pub = talker.create_publisher(_mount(0).__class__, '/tf_static', QOS_TF_STATIC)
    tf_pub.publish(_mount(T0_NS))                  # latched, before the recorder exists
    env_pub = talker.create_publisher(Environment, 'env_only', 100)
    str_pub = talker.create_publisher(String, 'chatter', 100)
    other_pub = talker.create_publisher(String, 'not_listed', 10)
    executor.add_node(talker)
    bag = tmp_path / 'simbag'
    recorder = RecorderNode(context=context, parameter_overrides=[
        Parameter('output', value=str(bag)), Parameter('discovery_period_s', value=0.1),
        Parameter('topics', value=['env_only', 'chatter', '/tf_static', '/clock'])])
    executor.add_node(recorder)

    def counts(topic):
        return recorder.counts.get(topic)

    try:
        spin_until(executor, lambda: (counts('/tf_static') == 1
                                      and str_pub.get_subscription_count() > 0),
                   what='the mount recorded, chatter subscribed')
        wall_before = time.time_ns()
        str_pub.publish(String(data='no simulation yet'))
        spin_until(executor, lambda: counts('/chatter') == 1, what='first chatter')
        wall_after = time.time_ns()
        clock_pub = talker.create_publisher(Clock, '/clock', 10)
        spin_until(executor, lambda: (clock_pub.get_subscription_count() > 0
                                      and env_pub.get_subscription_count() > 0),
                   what='clock and env subscribed')
        str_pub.publish(String(data='before the first clock'))
        env_pub.publish(make_environment(0))
        env_pub.publish(make_environment(1))
        other_pub.publish(String(data='ignored'))
        spin_until(executor, lambda: counts('/env_only') == 2, what='2 environments')
        assert counts('/chatter') == 1                  # the second one is held
        clock_pub.publish(_clock(T0_NS))
        spin_until(executor, lambda: counts('/clock') == 1 and counts('/chatter') == 2,
                   what='first clock, held chatter written')
        env_pub.publish(make_environment(3))           # ahead of /clock
        str_pub.publish(String(data='after the first clock'))
        spin_until(executor, lambda: counts('/env_only') == 3 and counts('/chatter') == 3,
                   what='3rd environment and chatter')
        assert sorted(recorder.topics) == ['/chatter', '/clock', '/env_only', '/tf_static']
    finally:
        _remove(executor, recorder, talker)
    got, chatter = {}, {}
    for topic, t_ns, msg in read_messages(bag):     # in log-time order
        got.setdefault(topic, []).append(t_ns)
        if topic == '/chatter':
            chatter[msg.data] = t_ns
    assert got['/tf_static'] == [T0_NS]
    assert got['/env_only'] == [T0_NS, T0_NS + 100_000_000, T0_NS + 300_000_000]
    assert got['/clock'] == [T0_NS]
    assert wall_before <= chatter.pop('no simulation yet') <= wall_after
    assert chatter == {'before the first clock': T0_NS, 'after the first clock': T0_NS}


def test_a_clock_from_zero_is_a_clock(context, executor, tmp_path):
    """A simulator whose ``/clock`` starts at 0 (Gazebo): that /clock is logged at 0 and an
    unstamped message after it at 0, not held for a later clock."""
    talker, clock_pub, chat_pub, _ = _talker(context, executor, 'zero')
    bag = tmp_path / 'zero'
    recorder = RecorderNode(context=context, parameter_overrides=[
        Parameter('output', value=str(bag)), Parameter('discovery_period_s', value=0.1),
        Parameter('topics', value=['/clock', 'zero_chatter'])])
    executor.add_node(recorder)
    try:
        spin_until(executor, lambda: (clock_pub.get_subscription_count() > 0
                                      and chat_pub.get_subscription_count() > 0),
                   what='recorder subscriptions')
        clock_pub.publish(_clock(0))
        spin_until(executor, lambda: recorder.counts.get('/clock') == 1, what='clock 0')
        chat_pub.publish(String(data='at zero'))
        spin_until(executor, lambda: recorder.counts.get('/zero_chatter') == 1, what='chatter')
    finally:
        _remove(executor, recorder, talker)
    got = sorted((topic, t) for topic, t, _ in read_messages(bag))
    assert got == [('/clock', 0), ('/zero_chatter', 0)]


def test_existing_output_is_an_error(context, tmp_path):
    out = tmp_path / 'exists'
    out.mkdir()
    (out / 'keep.txt').write_text('precious')
    with pytest.raises(OutputExistsError, match='exists already') as info:
        RecorderNode(context=context, parameter_overrides=[Parameter('output', value=str(out))])
    assert isinstance(info.value, ValueError)  # the runtime reports it as a config error
    assert [p.name for p in out.iterdir()] == ['keep.txt']
    assert (out / 'keep.txt').read_text() == 'precious'


def test_handshake_typed_topics_and_clock_log_time(context, executor, tmp_path):
    """``lockstep/ready`` only once the expected publishers matched; without use_sim_time the
    log time is the latest /clock; /clock is subscribed once (one DDS match per topic)."""
    talker = Node('talker3', context=context)
    ready = []
    talker.create_subscription(String, 'lockstep/ready', lambda m: ready.append(m.data),
                               QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                          durability=DurabilityPolicy.TRANSIENT_LOCAL))
    clock_pub = talker.create_publisher(Clock, '/clock', 10)
    executor.add_node(talker)
    bag = tmp_path / 'hsbag'
    recorder = RecorderNode(context=context, parameter_overrides=[
        Parameter('output', value=str(bag)),
        Parameter('topics', value=['hs=std_msgs/msg/String', '/clock']),
        Parameter('expected_matches', value=['sub:hs=1', 'sub:/clock=1'])])
    executor.add_node(recorder)
    try:
        spin_until(executor, lambda: '/clock' in recorder.topics, what='/clock subscription')
        deadline = time.monotonic() + 0.3
        spin_until(executor, lambda: time.monotonic() > deadline, what='idle')
        assert not recorder.ready and ready == []  # no publisher on hs yet
        hs_pub = talker.create_publisher(String, 'hs', 10)
        spin_until(executor, lambda: 'recorder' in ready, what='lockstep/ready')
        assert recorder.ready and recorder.unmatched() == []
        clock_subs = [i for i in talker.get_subscriptions_info_by_topic('/clock')
                      if i.node_name == 'recorder']
        assert len(clock_subs) == 1
        spin_until(executor, lambda: clock_pub.get_subscription_count() > 0, what='clock match')
        clock = Clock()
        clock.clock.sec = 1_900_000_000
        clock_pub.publish(clock)
        spin_until(executor, lambda: recorder.counts.get('/clock') == 1, what='clock recorded')
        hs_pub.publish(String(data='after clock'))
        spin_until(executor, lambda: recorder.counts.get('/hs') == 1, what='hs recorded')
    finally:
        _remove(executor, recorder, talker)
    got = [(topic, t) for topic, t, _ in read_messages(bag)]
    assert got == [('/clock', 1_900_000_000 * 10**9), ('/hs', 1_900_000_000 * 10**9)]


# ---------------------------------------------------------------------- crash safety
def _clock(t_ns: int) -> Clock:
    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = divmod(t_ns, 10**9)
    return msg


def _talker(context, executor, name: str):
    """A node ``<name>_talker`` publishing ``/clock`` and ``<name>_chatter``, collecting
    ``recorder/status``: ``(node, clock_pub, chatter_pub, statuses)``."""
    talker = Node(f'{name}_talker', context=context)
    clock_pub = talker.create_publisher(Clock, '/clock', 100)
    chat_pub = talker.create_publisher(String, f'{name}_chatter', 100)
    statuses = []
    talker.create_subscription(LockstepStatus, 'recorder/status', statuses.append, 10)
    executor.add_node(talker)
    return talker, clock_pub, chat_pub, statuses


def _wait_proc(proc, timeout: float) -> None:
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        raise AssertionError('recorder process did not exit')


def test_sigkill_keeps_everything_but_the_last_seconds(context, executor, tmp_path):
    """A recorder killed with SIGKILL leaves a bag that reads back (recovery of the unfinished
    MCAP) with every message logged more than ``flush_sim_s`` before its last one.

    The truth is what this test published. Only the sim-time rule writes chunks here (the wall
    clock rule is disabled with a huge ``flush_period_s``). Phase 1 (clocks 0..18 s, chatter)
    is fully received before phase 2 (clocks 18.5..20 s) is published, so every phase-1
    message is logged at <= 18 s = last log time - 2 s: all of it must survive the kill.
    """
    talker, clock_pub, chat_pub, statuses = _talker(context, executor, 'crash')
    bag = tmp_path / 'killed'
    proc = subprocess.Popen(
        [sys.executable, '-m', 'adcs_nodes.nodes.recorder', '--ros-args',
         '-p', f'output:={bag}', '-p', 'discovery_period_s:=0.1', '-p', 'flush_sim_s:=2.0',
         '-p', 'flush_period_s:=1000.0', '-p', 'fsync_period_s:=1000.0',
         '-p', 'status_period_s:=0.1',
         '-p', 'exclude:=[/rosout, /parameter_events, /lockstep/ready]'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
    phase1 = list(range(37))        # clocks 0 .. 18 s
    phase2 = list(range(37, 41))    # clocks 18.5 .. 20 s
    try:
        # its own lockstep/ready is excluded: an unstamped message held until the first clock
        # would make "phase 1 written" below count one message early
        spin_until(executor, lambda: (clock_pub.get_subscription_count() > 0
                                      and chat_pub.get_subscription_count() > 0
                                      and statuses), timeout=60.0, what='recorder subscribed')
        written0 = statuses[-1].frames

        def publish(steps):
            for i in steps:
                clock_pub.publish(_clock(T0_NS + i * 500_000_000))
                chat_pub.publish(String(data=f'm{i}'))

        publish(phase1)
        spin_until(executor, lambda: statuses[-1].frames >= written0 + 2 * len(phase1),
                   timeout=60.0, what='phase 1 written')
        publish(phase2)
        spin_until(executor, lambda: statuses[-1].frames >= written0 + 2 * (len(phase1)
                                                                            + len(phase2)),
                   timeout=60.0, what='phase 2 written')
        os.kill(proc.pid, signal.SIGKILL)
        _wait_proc(proc, 10.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        _remove(executor, talker)
    assert not (bag / 'metadata.yaml').exists()   # really unfinished
    got = {}
    for topic, t_ns, msg in read_messages(bag):
        got.setdefault(topic, []).append((t_ns, msg))
    chatter = [m.data for _, m in got['/crash_chatter']]
    sent = [f'm{i}' for i in phase1 + phase2]
    assert chatter == sent[:len(chatter)]                 # in order, no gap, nothing invented
    assert len(chatter) >= len(phase1), chatter
    clocks = [t for t, _ in got['/clock']]
    assert clocks[:len(phase1)] == [T0_NS + i * 500_000_000 for i in phase1]
    last = max(t for items in got.values() for t, _ in items)
    assert last >= T0_NS + 18 * 10**9


class _FullDisk:
    """Stands for the bag's file object once the disk is full: every write fails (ENOSPC)."""

    def __init__(self, real) -> None:
        self.real = real
        self.attempts = 0

    def write(self, data) -> int:
        self.attempts += 1
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def flush(self) -> None:
        pass

    def fileno(self) -> int:
        return self.real.fileno()

    def tell(self) -> int:
        return self.real.tell()

    def close(self) -> None:
        self.real.close()


def test_disk_full_stops_recording_keeps_the_data(context, executor, tmp_path):
    """ENOSPC while writing: no exception out of the callbacks, the node reports 'disk full'
    (status and exit code) and stops; the bag keeps every chunk written before."""
    from adcs_nodes.nodes.recorder import EXIT_WRITE_FAILED, WRITE_FAILED_PREFIX

    talker, clock_pub, chat_pub, statuses = _talker(context, executor, 'full')
    bag = tmp_path / 'full'
    recorder = RecorderNode(context=context, parameter_overrides=[
        Parameter('output', value=str(bag)), Parameter('discovery_period_s', value=0.1),
        Parameter('flush_sim_s', value=1.0), Parameter('flush_period_s', value=1000.0)])
    executor.add_node(recorder)
    try:
        spin_until(executor, lambda: (clock_pub.get_subscription_count() > 0
                                      and chat_pub.get_subscription_count() > 0),
                   what='recorder subscriptions')
        for i in range(10):
            clock_pub.publish(_clock(T0_NS + i * 10**9))
            chat_pub.publish(String(data=f'before {i}'))
        spin_until(executor, lambda: recorder.counts.get('/full_chatter') == 10,
                   what='10 messages')
        recorder.flush()
        full = _FullDisk(recorder._writer.storage.bio)
        recorder._writer.storage.bio = full
        for i in range(10, 20):
            clock_pub.publish(_clock(T0_NS + i * 10**9))
            chat_pub.publish(String(data=f'after {i}'))
        spin_until(executor, lambda: recorder.done, what='recorder stops on ENOSPC')
        spin_until(executor, lambda: any(s.last_missed_input.startswith(WRITE_FAILED_PREFIX)
                                         for s in statuses), what='status says it')
        assert full.attempts >= 1
        assert recorder.exit_code == EXIT_WRITE_FAILED
        assert not recorder.is_open
        assert 'disk full' in recorder.write_error
        recorder.close()   # idempotent, no exception
    finally:
        _remove(executor, recorder, talker)
    chatter = [m.data for topic, _, m in read_messages(bag) if topic == '/full_chatter']
    assert chatter == [f'before {i}' for i in range(10)]
