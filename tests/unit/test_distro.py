"""Bags name the real ROS 2 distribution (not rosbags' placeholder), in metadata.yaml and in
the rosbag2 metadata record inside the MCAP file (read back with the independent mcap reader).
"""
import importlib.metadata

import pytest
import yaml
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from adcs_nodes.distro import RCLPY_MAJOR_TO_DISTRO, close_writer, ros_distro

mcap_reader = pytest.importorskip('mcap.reader')


def test_distro_from_environment_else_from_rclpy(monkeypatch):
    monkeypatch.setenv('ROS_DISTRO', 'Jazzy')
    assert ros_distro() == 'jazzy'
    monkeypatch.delenv('ROS_DISTRO')
    try:
        major = int(importlib.metadata.version('ros-rclpy').split('.')[0])
    except importlib.metadata.PackageNotFoundError:
        assert ros_distro() == 'unknown'
    else:
        assert ros_distro() == RCLPY_MAJOR_TO_DISTRO.get(major, 'unknown')
        if major == 9:      # the pinned wheels (ros-rclpy 9.1.x) are Kilted's
            assert ros_distro() == 'kilted'


def test_bag_metadata_names_the_distro(tmp_path):
    store = get_typestore(Stores.ROS2_KILTED)
    out = tmp_path / 'bag'
    writer = Writer(out, version=8, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    conn = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=store)
    msg = store.types['std_msgs/msg/String'](data='hello')
    writer.write(conn, 42, store.serialize_cdr(msg, 'std_msgs/msg/String'))
    close_writer(writer, 'kilted')
    meta = yaml.safe_load((out / 'metadata.yaml').read_text())
    assert meta['rosbag2_bagfile_information']['ros_distro'] == 'kilted'
    mcap_file = next(out.glob('*.mcap'))
    with open(mcap_file, 'rb') as fh:
        records = list(mcap_reader.make_reader(fh).iter_metadata())
    embedded = yaml.safe_load(records[0].metadata['serialized_metadata'])
    assert records[0].name == 'rosbag2' and embedded['ros_distro'] == 'kilted'
    with open(mcap_file, 'rb') as fh:       # the file is still a valid MCAP with its message
        assert [m.log_time for _, _, m in mcap_reader.make_reader(fh).iter_messages()] == [42]
