"""Attitude estimation cores of the flight software (pure numpy/scipy, no ROS): the onboard
reference, paper 000's magnetic filter, TRIAD, paper 004's horizon yaw, the MEKF."""
