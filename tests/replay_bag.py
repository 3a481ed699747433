"""A small rosbag2 MCAP bag for the replay tests (node and unit tier): three magnetometer
samples and /clock ticks 10 s apart, written out of stamp order. Written with rosbags only."""
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

EPOCH_NS = 1767225600 * 10**9


def write_small_bag(out):
    """Write the bag to directory ``out`` (must not exist); returns its path as text."""
    store = get_typestore(Stores.ROS2_KILTED)
    w = Writer(out, version=8, storage_plugin=StoragePlugin.MCAP)
    w.open()
    mag = w.add_connection('/sensors/magnetometer', 'sensor_msgs/msg/MagneticField',
                           typestore=store)
    clock = w.add_connection('/clock', 'rosgraph_msgs/msg/Clock', typestore=store)
    Time = store.types['builtin_interfaces/msg/Time']
    Header = store.types['std_msgs/msg/Header']
    Vector3 = store.types['geometry_msgs/msg/Vector3']
    MagneticField = store.types['sensor_msgs/msg/MagneticField']
    for k in (2, 0, 1):                  # written out of stamp order
        t = EPOCH_NS + k * 10 * 10**9
        m = MagneticField(header=Header(stamp=Time(sec=t // 10**9, nanosec=t % 10**9),
                                        frame_id='magnetometer'),
                          magnetic_field=Vector3(x=1e-5 * k, y=2e-5, z=-3e-5),
                          magnetic_field_covariance=np.zeros(9))
        w.write(mag, t, store.serialize_cdr(m, 'sensor_msgs/msg/MagneticField'))
        c = store.types['rosgraph_msgs/msg/Clock'](clock=Time(sec=t // 10**9, nanosec=0))
        w.write(clock, t, store.serialize_cdr(c, 'rosgraph_msgs/msg/Clock'))
    w.close()
    return str(out)
