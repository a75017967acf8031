"""Decentralized FPR controllers (C, NC, impedance) with wrench observers, and the ground teleoperation path."""
