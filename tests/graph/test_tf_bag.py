"""A recorded bag carries /tf and /tf_static that tf2, RViz and Foxglove understand.

The bag is opened with the independent ``mcap`` reader (not rosbags, not the project's bag
module); CDR payloads are decoded by rclpy's own deserialiser with the types the schemas
name. Rotations are composed with scipy. Checks:

* ``eci -> orbit -> body`` composes to the recorded truth ``sim/state`` ``q_eci_body``, and
  ``orbit -> body`` is its ``q_orbit_body``; the ``eci -> orbit`` translation is ``r_eci``;
* ``eci -> body_estimate`` is the recorded estimate's ``q_eci_body``;
* ``eci -> ecef`` is ``sim/environment``'s ``q_eci_ecef``;
* ``/tf_static`` holds the scenario's magnetometer mount (a 90 deg yaw here), and the recorded
  magnetometer samples rotated by it equal the truth body field within the sensor noise;
* the type hash of ``tf2_msgs/msg/TFMessage`` in the bag is the upstream one.
"""
import importlib
import os

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from adcs_launch import SCENARIOS, adcs

mcap_reader = pytest.importorskip('mcap.reader')
from rclpy.serialization import deserialize_message  # noqa: E402

MOUNT = [0.0, 0.0, 0.5 ** 0.5, 0.5 ** 0.5]     # body -> magnetometer: 90 deg about z


def get_message(name):
    """Generated Python class of ``pkg/msg/Name`` (what rosidl_runtime_py does)."""
    pkg, _, cls = name.split('/')
    return getattr(importlib.import_module(f'{pkg}.msg'), cls)


def _read(path):
    """``{topic: [(msg, schema_name, log_time)]}`` of every message, via the mcap reader."""
    out = {}
    schemas = {}
    with open(path, 'rb') as fh:
        reader = mcap_reader.make_reader(fh)
        for schema, channel, message in reader.iter_messages():
            schemas[channel.topic] = schema
            cls = get_message(schema.name)
            out.setdefault(channel.topic, []).append(deserialize_message(message.data, cls))
    return out, schemas


def _stamp(msg):
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def _rot(q):
    return Rotation.from_quat([q.x, q.y, q.z, q.w])


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('tf')
    with open(os.path.join(SCENARIOS, 'paper000_estimation.yaml')) as fh:
        sc = yaml.safe_load(fh)
    mag = sc['sensors']['magnetometer']
    mag.update(q_body_sensor_xyzw=MOUNT, misalignment_deg=[0.0, 0.0, 0.0],
               bias_T=[0.0, 0.0, 0.0])
    scenario = tmp / 'tf.yaml'
    scenario.write_text(yaml.safe_dump(sc))
    out = str(tmp / 'bag')
    adcs('run', str(scenario), '--record', out, '--duration', '100', '--quiet')
    mcaps = [f for f in os.listdir(out) if f.endswith('.mcap')]
    assert len(mcaps) == 1
    return _read(os.path.join(out, mcaps[0]))


def test_truth_and_estimate_transforms_compose_to_the_recorded_attitude(bag):
    msgs, schemas = bag
    assert schemas['/tf'].name == 'tf2_msgs/msg/TFMessage'
    tf = {}
    for m in msgs['/tf']:
        for t in m.transforms:
            tf[(t.header.frame_id, t.child_frame_id, _stamp(t))] = t.transform
    states = msgs['/sim/state']
    envs = {_stamp(e): e for e in msgs['/sim/environment']}
    assert len(states) >= 50
    for s in states:
        k = _stamp(s)
        eci_orbit, orbit_body = tf[('eci', 'orbit', k)], tf[('orbit', 'body', k)]
        composed = _rot(eci_orbit.rotation) * _rot(orbit_body.rotation)
        assert (composed.inv() * _rot(s.q_eci_body)).magnitude() < 1e-9
        assert (_rot(orbit_body.rotation).inv() * _rot(s.q_orbit_body)).magnitude() < 1e-9
        e = envs[k]
        r = eci_orbit.translation
        assert np.allclose([r.x, r.y, r.z], [e.r_eci.x, e.r_eci.y, e.r_eci.z], rtol=0, atol=1e-6)
        ecef = tf[('eci', 'ecef', k)]
        assert (_rot(ecef.rotation).inv() * _rot(e.q_eci_ecef)).magnitude() < 1e-9
    estimates = msgs['/adcs/attitude_estimate']
    assert len(estimates) >= 40
    for m in estimates:
        est = tf[('eci', 'body_estimate', _stamp(m))]
        assert (_rot(est.rotation).inv() * _rot(m.q_eci_body)).magnitude() < 1e-9


def test_static_mount_is_the_one_the_sensor_model_uses(bag):
    msgs, _ = bag
    mounts = {t.child_frame_id: t for m in msgs['/tf_static'] for t in m.transforms
              if t.header.frame_id == 'body'}
    assert set(mounts) == {'magnetometer'}
    q = mounts['magnetometer'].transform.rotation
    assert np.allclose([q.x, q.y, q.z, q.w], MOUNT, atol=1e-12)
    states = {_stamp(s): s for s in msgs['/sim/state']}
    envs = {_stamp(e): e for e in msgs['/sim/environment']}
    errors = []
    for m in msgs['/sensors/magnetometer']:
        assert m.header.frame_id == 'magnetometer'
        k = _stamp(m)
        b_eci = envs[k].b_eci
        b_body = _rot(states[k].q_eci_body).inv().apply([b_eci.x, b_eci.y, b_eci.z])
        f = m.magnetic_field
        errors.append(_rot(q).apply([f.x, f.y, f.z]) - b_body)
    # noise std 375/25/65 nT in sensor axes + 20 nT LSB: 5 sigma of the largest is ~1.9 uT;
    # the wrong mount (identity) would give errors of the field size, ~20-50 uT
    assert len(errors) >= 10
    assert np.max(np.abs(errors)) < 2.0e-6


def test_diagnostics_recorded(bag):
    """/diagnostics is in the bag: the estimator reports its counters once per frame of 2 s
    (one status per sim second at most), level OK when nothing was rejected."""
    msgs, schemas = bag
    assert schemas['/diagnostics'].name == 'diagnostic_msgs/msg/DiagnosticArray'
    est = [m.status[0] for m in msgs['/diagnostics'] if m.status[0].name == 'estimator']
    stamps = [_stamp(m) for m in msgs['/diagnostics'] if m.status[0].name == 'estimator']
    assert len(est) >= 40 and stamps == sorted(set(stamps))
    values = {kv.key: kv.value for kv in est[-1].values}
    assert int(values['update_count']) >= 9 and values['rejected_count'] == '0'
    assert est[-1].level == est[-1].OK
