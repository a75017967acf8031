"""The Flying Parallel Robot as a ROS-free Python library.

Parameters, rotations and frames, geometry, kinematics, dynamics, wrench feasibility.
"""
