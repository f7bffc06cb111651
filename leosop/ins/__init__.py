"""Inertial navigation: truth trajectories and ideal IMU data, IMU errors,
real IMU log readers, the strapdown mechanization, alignment and error models.
"""
