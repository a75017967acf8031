"""The Flying Parallel Robot as a ROS-free Python library: parameters, rotations and frames, geometry, kinematics, dynamics, wrench feasibility."""
