"""MAVLink 2 offboard attitude/thrust bridge between the FPR controller and a PX4 autopilot."""
