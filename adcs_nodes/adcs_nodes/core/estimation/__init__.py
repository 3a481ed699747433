"""Attitude estimation cores of the flight software (pure numpy/scipy, no ROS).

Modules
-------
:mod:`.onboard`
    The flight software's own reference: orbit state and geomagnetic field in the ORBIT frame.
:mod:`.magnetic_filter`
    Magnetometer-only attitude, rate and disturbance estimator of paper 000 (Lebedev,
    Tkachenko, Shtepa), equations (33)-(39).
:mod:`.triad`
    Classic two-vector TRIAD attitude.
:mod:`.horizon_yaw`
    Yaw from an Earth (horizon) sensor's roll and pitch plus a magnetometer, paper 004
    (Ryzhkov, Holembiovskyi) formula (3), and TRIAD on the same two vectors.
"""
from adcs_nodes.core.estimation.horizon_yaw import (attitude_from_horizon_and_yaw,
                                                    triad_from_horizon_and_field,
                                                    yaw_from_horizon_and_field)
from adcs_nodes.core.estimation.magnetic_filter import MagneticFilter, linearised_matrices
from adcs_nodes.core.estimation.onboard import (OnboardReference, OnboardState,
                                                b_orbit_direct_dipole, make_onboard_reference)
from adcs_nodes.core.estimation.triad import triad

__all__ = [
    'MagneticFilter', 'OnboardReference', 'OnboardState', 'attitude_from_horizon_and_yaw',
    'b_orbit_direct_dipole', 'linearised_matrices', 'make_onboard_reference', 'triad',
    'triad_from_horizon_and_field', 'yaw_from_horizon_and_field',
]
