"""Simulator node replacing the FPR hardware: plant, PX4 autopilot emulators over MAVLink 2, cameras."""
