"""Core sample <-> message, every topic kind (``adcs_nodes.msgs.convert``): bit-exact both ways.

For random samples (NaN, inf, -0.0, subnormals, the largest doubles, empty and long
sequences, non-ASCII names): ``to_core(to_msg(x))`` is ``x`` field by field, bit for bit (the
bytes of every float), and a message read into a sample and made a message again encodes to
the same CDR bytes. Every topic the engines publish has a converter, found by
``adcs_nodes.inputs.converter`` (the record's for an input's topic).
"""
import dataclasses
import struct

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from adcs_nodes.core import samples as s
from adcs_nodes.graph import TOPIC_TYPES
from adcs_nodes.inputs import INPUTS, converter
from adcs_nodes.msgs import convert as c
from adcs_nodes.msgs.cdr import codec

EPOCH_NS = 1767225600 * 10**9
SPECIAL = [0.0, -0.0, float('nan'), float('inf'), -float('inf'), 5e-324, 1.7976931348623157e308]
FLOATS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from(SPECIAL))
TEXT = st.text(st.characters(blacklist_categories=('Cs',), blacklist_characters='\0'),
               max_size=12)


def arrays(n=None):
    size = st.integers(0, 7) if n is None else st.just(n)
    return size.flatmap(lambda k: st.lists(FLOATS, min_size=k, max_size=k)).map(
        lambda v: np.array(v, dtype=float))


def vec(n):
    return arrays(n)


T_NS = st.integers(0, 10**15)
#: One strategy per (converter, core type): the fields in the order of the dataclass.
CASES = {
    'CLOCK': st.builds(s.Tick, T_NS),
    'ENVIRONMENT': st.builds(s.EnvironmentSample, T_NS, vec(3), vec(3), vec(4), vec(3), FLOATS,
                             FLOATS, vec(3), vec(3), vec(4)),
    'ATTITUDE_STATE': st.builds(s.AttitudeState, T_NS, vec(4), vec(4), vec(3), vec(3), vec(36)),
    'FAULTS': st.builds(s.FaultEvents, T_NS, st.lists(st.builds(
        s.FaultEvent, st.integers(0, 99), st.booleans(), TEXT, TEXT, TEXT,
        st.lists(st.tuples(TEXT, TEXT), max_size=3).map(tuple)), max_size=3).map(tuple)),
    'WHEEL_STATE': st.integers(0, 4).flatmap(lambda n: st.builds(
        s.WheelState, T_NS, st.lists(TEXT, min_size=n, max_size=n).map(tuple), vec(n),
        vec(n), vec(n), vec(3))),
    'APPENDAGES': st.builds(s.AppendageState, T_NS, arrays(), arrays(), arrays()),
    'MAGNETOMETER': st.builds(s.MagnetometerSample, T_NS, TEXT, vec(3), vec(9)),
    'GYRO': st.builds(s.GyroSample, T_NS, TEXT, vec(3), vec(9)),
    'STAR_TRACKER': st.builds(s.StarTrackerSample, T_NS, TEXT, vec(4), vec(9)),
    'HORIZON': st.builds(s.HorizonSample, T_NS, TEXT, FLOATS, FLOATS, FLOATS, FLOATS,
                         st.booleans()),
    'WHEEL_SPEEDS': st.builds(s.WheelSpeeds, T_NS, TEXT, st.lists(TEXT, max_size=4).map(tuple),
                              arrays()),
    'DIAGNOSTICS': st.builds(s.FilterDiagnostics, T_NS, TEXT,
                             st.lists(FLOATS, max_size=6).map(tuple), FLOATS,
                             st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1), TEXT),
    'TARGET': st.builds(s.AttitudeTarget, T_NS, TEXT, vec(4), vec(3), vec(3), FLOATS, TEXT),
    'COMMAND': st.builds(s.ActuatorCommand, T_NS, vec(3), arrays(), vec(3), TEXT),
    'MAGNETORQUER_COMMAND': st.builds(s.MagnetorquerCommand, T_NS, vec(3)),
    'WHEEL_COMMAND': st.builds(s.WheelCommand, T_NS, st.lists(TEXT, max_size=4).map(tuple),
                               st.lists(FLOATS, max_size=4).map(tuple)),
    'CONTROLLER_STATUS': st.builds(s.ControllerStatus, T_NS, TEXT,
                                   st.lists(TEXT, max_size=4).map(tuple), TEXT,
                                   st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1), TEXT),
}


def bits(value):
    """A value as comparable bits: arrays and floats by their bytes, containers item-wise."""
    if isinstance(value, np.ndarray):
        return ('array', value.dtype.str, value.shape, value.tobytes())
    if isinstance(value, float):
        return ('float', struct.pack('<d', value))
    if isinstance(value, (tuple, list)):
        return tuple(bits(v) for v in value)
    if dataclasses.is_dataclass(value):
        return (type(value).__name__,) + tuple(
            bits(getattr(value, f.name)) for f in dataclasses.fields(value))
    return value


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_every_converter_round_trips_bit_for_bit(data):
    for name, strategy in CASES.items():
        conv = getattr(c, name)
        x = data.draw(strategy, label=name)
        msg = conv.to_msg(x, EPOCH_NS)
        assert bits(conv.to_core(msg, EPOCH_NS)) == bits(x), name
        encode = codec(type(msg)).encode
        again = conv.to_msg(conv.to_core(codec(type(msg)).decode(encode(msg)), EPOCH_NS),
                            EPOCH_NS)
        assert encode(again) == encode(msg), name


@settings(max_examples=5, deadline=None)
@given(data=st.data())
def test_every_topic_of_the_graph_has_its_converter(data):
    """Each data topic's converter makes the topic's message type (records first)."""
    topics = [t for t in TOPIC_TYPES if t not in ('/tf', '/tf_static', '/diagnostics',
                                                  'lockstep/status', 'adcs/security_events')]
    topics += ['adcs/controllers/mpi/command'] + [r.topic for r in INPUTS]
    for topic in topics:
        conv = converter(topic)
        name = next(n for n in CASES if getattr(c, n) is conv)
        x = data.draw(CASES[name], label=topic)
        msg = conv.to_msg(x, EPOCH_NS)
        want = TOPIC_TYPES.get(topic) or next(r.msg_type for r in INPUTS if r.topic == topic) \
            if not topic.startswith('adcs/controllers/') else 'adcs_msgs/msg/ActuatorCommand'
        pkg, _, cls = want.split('/')
        assert type(msg).__module__.startswith(pkg + '.msg') and type(msg).__name__ == cls, topic
    assert converter('/sim/state') is c.ATTITUDE_STATE      # a resolved name is the same topic


def test_a_record_whose_converter_cannot_be_loaded_says_so():
    import pytest

    from adcs_nodes.inputs import Input
    bad = Input('nowhere', 'nowhere', 'sensors/nowhere', 'std_msgs/msg/String', None,
                'nowhere_period_s', 1.0, 'adcs_nodes.msgs.convert:NO_SUCH')
    with pytest.raises(ValueError, match="converter 'adcs_nodes.msgs.convert:NO_SUCH' cannot"):
        bad.converter()
