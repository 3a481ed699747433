"""The magnetometer covariance to body axes (``adcs_nodes.components.base.covariance_to_body``):
rotated as ``R C R^T`` (scipy's rotation, the truth), and the ROS conventions (all zeros:
unknown; -1 first: not provided) give None."""
import numpy as np
from scipy.spatial.transform import Rotation

from adcs_nodes.components import base as tf


def test_covariance_to_body_rotates_and_follows_the_ros_conventions():
    q = Rotation.from_euler('zyx', [90.0, 20.0, -30.0], degrees=True).as_quat()
    c_sensor = np.diag([375e-9, 25e-9, 65e-9]) ** 2
    c_body = tf.covariance_to_body(c_sensor.reshape(-1), q)
    r = Rotation.from_quat(q).as_matrix()
    assert np.allclose(c_body, r @ c_sensor @ r.T, rtol=1e-12, atol=0.0)
    assert tf.covariance_to_body([0.0] * 9, q) is None                  # unknown
    assert tf.covariance_to_body([-1.0] + [0.0] * 8, q) is None         # not provided
    assert tf.covariance_to_body([np.nan] * 9, q) is None
    assert tf.covariance_to_body([1.0, 2.0, 0, 0, 1.0, 0, 0, 0, 1.0], q) is None   # asymmetric
    assert tf.covariance_to_body([1.0] * 4, q) is None                  # wrong size
