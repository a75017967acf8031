"""Quadrotor setpoints from the thrust vectors (thesis §3.3.2 (3.36)-(3.38), §4.3.4 (4.38)).

The controller computes thrust vectors f_i [N] in its world frame F (F0 centralized, F_Fp decentralized).
For its own UAV it turns f_i into a thrust magnitude and a desired attitude R^d_i (body FLU -> F), with the
body x axis at the constant angle β from the leg (propeller/leg clearance, (3.37), spec §1.7), then
re-expresses the yaw in the UAV's own local frame F0i (4.38). The attitude rule itself is
:func:`fpr_model.geometry.desired_uav_rotation` (shared with the simulator). Saturations: thrust ≤ f_max, tilt of z^d_i
from the vertical ≤ max_tilt. No rclpy here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from fpr_model.rotations import (
    euler_zyx_to_quat,
    rotmat_to_euler_zyx,
)


@dataclass(frozen=True)
class SaturatedThrust:
    """Thrust vector after the saturations, with flags."""

    vector: np.ndarray  # (3,) in F [N]
    thrust_saturated: bool
    tilt_saturated: bool


def saturate_thrust_vector(thrust_vector: np.ndarray, max_thrust: float, max_tilt: float) -> SaturatedThrust:
    """Clip the direction to ``angle(f, +z) ≤ max_tilt`` [rad] (rotating it toward +z in its vertical plane,
    magnitude kept), then the magnitude to ``[0, max_thrust]`` [N]. A zero or non-finite vector gives 0.
    Evaluated on plain floats (one 3-vector)."""
    fx, fy, fz = np.asarray(thrust_vector, dtype=float).tolist()
    magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
    if not math.isfinite(magnitude) or magnitude < 1e-9:
        return SaturatedThrust(np.zeros(3), False, False)
    direction = (fx / magnitude, fy / magnitude, fz / magnitude)
    tilt_saturated = False
    if direction[2] < math.cos(max_tilt):
        h_norm = math.hypot(direction[0], direction[1])
        azimuth = (direction[0] / h_norm, direction[1] / h_norm) if h_norm > 1e-12 else (1.0, 0.0)
        direction = (azimuth[0] * math.sin(max_tilt), azimuth[1] * math.sin(max_tilt), math.cos(max_tilt))
        tilt_saturated = True
    thrust_saturated = magnitude > max_thrust
    magnitude = min(magnitude, max_thrust)
    return SaturatedThrust(np.array([direction[0] * magnitude, direction[1] * magnitude, direction[2] * magnitude]),
                           thrust_saturated, tilt_saturated)


def local_frame_attitude(rotation_in_frame: np.ndarray, uav_yaw_in_frame: float, uav_yaw_local: float) -> np.ndarray:
    """(4.38): attitude R^d (body -> controller frame F) re-expressed in the UAV's local frame F0i, as a unit
    quaternion [w, x, y, z]. Roll and pitch are kept; ``ψ^d_0i = ψ_0i + (ψ^d_F − ψ_F)`` with ψ_F the UAV's
    current yaw in F (pψ_i for F = F_Fp, thesis: pψ_i = Fpψ_i) and ψ_0i its yaw from its own IMU [rad]."""
    roll, pitch, yaw = rotmat_to_euler_zyx(rotation_in_frame)
    yaw_local = uav_yaw_local + (yaw - uav_yaw_in_frame)
    yaw_local = math.atan2(math.sin(yaw_local), math.cos(yaw_local))
    quat = euler_zyx_to_quat(roll, pitch, yaw_local)
    return quat / np.linalg.norm(quat)


def hover_thrust_share(total_mass: float, gravity: float, n: int) -> float:
    """Thrust per UAV holding the robot's weight equally, m_tot g / n [N] (safe fallback magnitude)."""
    return total_mass * gravity / n
