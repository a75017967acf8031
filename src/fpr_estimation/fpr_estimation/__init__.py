"""On-board ArUco marker detection, relative-pose EKF and FPR state reconstruction."""
