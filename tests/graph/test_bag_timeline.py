"""A bag's timeline and QoS, as Foxglove and ``ros2 bag play`` meet them (issue 37, items 1-3).

paper000_control runs 600 s in each engine (plain, composed, graph) with ``--record``. Each bag
is read with the independent ``mcap`` reader and decoded from its embedded ``ros2msg`` schemas
by ``mcap-ros2-support`` (neither rosbags, rclpy nor the project's bag module), and its
``metadata.yaml`` with a YAML parser. Truth: the scenario (epoch, frame, run length) and each
message's own stamp.

* every message's log time is its header stamp (``rosgraph_msgs/Clock``: its clock;
  ``tf2_msgs/TFMessage``: its transforms' stamps); a message without any stamp is logged at
  a ``/clock`` of the bag;
* ``metadata.yaml``: starting time = the scenario's epoch, duration = 600 s +- one frame;
* every topic has its offered QoS; the latched ones (``/tf_static``,
  ``adcs/controller_status``) transient local, the others volatile; the plain engine's bag
  says what the graph's publishers offered.
"""
import os
from datetime import datetime

import pytest
import yaml

from adcs_launch import SCENARIOS, adcs

mcap_reader = pytest.importorskip('mcap.reader')
mcap_ros2 = pytest.importorskip('mcap_ros2.decoder')

SCENARIO = os.path.join(SCENARIOS, 'paper000_control.yaml')
DURATION_S = 600
ENGINES = ('plain', 'composed', 'graph')
LATCHED = {'/tf_static', '/adcs/controller_status'}
TRANSIENT_LOCAL, VOLATILE = 1, 2      # rmw durability policy values in metadata.yaml


@pytest.fixture(scope='module')
def scenario():
    with open(SCENARIO) as fh:
        sc = yaml.safe_load(fh)
    epoch = datetime.fromisoformat(sc['epoch'].replace('Z', '+00:00'))
    return int(epoch.timestamp()) * 10**9, int(sc['timing']['frame_s'] * 1e9)


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """``{engine: bag directory}`` of the three 600 s runs."""
    tmp = tmp_path_factory.mktemp('timeline')
    out = {}
    for engine in ENGINES:
        out[engine] = tmp / engine
        adcs('run', SCENARIO, '--engine', engine, '--duration', str(DURATION_S),
             '--record', str(out[engine]), '--quiet')
    return out


def _metadata(bag):
    with open(bag / 'metadata.yaml') as fh:
        return yaml.safe_load(fh)['rosbag2_bagfile_information']


def _ns(stamp):
    return stamp.sec * 10**9 + stamp.nanosec


def _own_stamps(msg):
    """The stamps a message carries itself (empty: none)."""
    if hasattr(msg, 'header'):
        return {_ns(msg.header.stamp)}
    if hasattr(msg, 'clock'):
        return {_ns(msg.clock)}
    return {_ns(t.header.stamp) for t in getattr(msg, 'transforms', ())}


def _log_times(bag):
    """``{topic: [(log time, own stamps)]}`` of every message, decoded from the schemas."""
    mcap, = bag.glob('*.mcap')
    out = {}
    with open(mcap, 'rb') as fh:
        reader = mcap_reader.make_reader(fh, decoder_factories=[mcap_ros2.DecoderFactory()])
        for _, channel, message, msg in reader.iter_decoded_messages(log_time_order=False):
            out.setdefault(channel.topic, []).append((message.log_time, _own_stamps(msg)))
    return out


@pytest.mark.parametrize('engine', ENGINES)
def test_every_log_time_is_the_message_stamp(bags, engine):
    got = _log_times(bags[engine])
    clocks = {t for t, _ in got['/clock']}
    assert len(clocks) == len(got['/clock']) > DURATION_S / 2   # 2 s frames
    if engine != 'plain':
        assert {'/tf_static', '/tf', '/diagnostics'} <= set(got)
    wrong = {}
    for topic, items in got.items():
        for log_ns, stamps in items:
            ok = stamps == {log_ns} if stamps else log_ns in clocks
            if not ok:
                wrong.setdefault(topic, (log_ns, sorted(stamps)))
    assert not wrong, f'{engine}: log time != stamp (first per topic): {wrong}'


@pytest.mark.parametrize('engine', ENGINES)
def test_duration_is_the_runs(bags, engine, scenario):
    epoch_ns, frame_ns = scenario
    meta = _metadata(bags[engine])
    assert meta['starting_time']['nanoseconds_since_epoch'] == epoch_ns
    assert abs(meta['duration']['nanoseconds'] - DURATION_S * 10**9) <= frame_ns


@pytest.mark.parametrize('engine', ENGINES)
def test_each_topic_offers_its_qos_latched_ones_transient_local(bags, engine):
    meta = _metadata(bags[engine])
    topics = {t['topic_metadata']['name']: yaml.safe_load(
        t['topic_metadata']['offered_qos_profiles']) for t in meta['topics_with_message_count']}
    assert '/adcs/controller_status' in topics
    for topic, profiles in topics.items():
        assert profiles, f'{engine}: {topic} has no offered QoS'
        want = TRANSIENT_LOCAL if topic in LATCHED else VOLATILE
        assert {p['durability'] for p in profiles} == {want}, (engine, topic)
        assert {p['reliability'] for p in profiles} == {1}, (engine, topic)   # reliable


def test_plain_bag_offers_what_the_graphs_publishers_offer(bags):
    def profiles(engine):
        return {t['topic_metadata']['name']: t['topic_metadata']['offered_qos_profiles']
                for t in _metadata(bags[engine])['topics_with_message_count']}
    plain, graph = profiles('plain'), profiles('graph')
    assert set(plain) <= set(graph)
    for topic, text in plain.items():
        assert yaml.safe_load(text)[0] in yaml.safe_load(graph[topic]), topic
