"""Robot state reconstruction on UAV i from its relative pose and its own IMU (thesis §4.2.3, (4.17)-(4.23), (4.38)).

Frames: Fp platform body frame; F_Fi the UAV's flat frame (z up, the UAV's yaw); F_Fp the platform's flat frame
(z up, the platform's yaw, zero roll/pitch); F0i the UAV's own local ENU frame, whose yaw offset from the world
is unknown (§4.2.3). Nothing here depends on that offset: only the IMU's roll and pitch are used, and a
rotation about the world z changes neither (ZYX: ``Rz(δ) Rz(ψ) Ry(ϑ) Rx(ϕ)``).
Units: metres, radians, m/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from fpr_model._math import cross3
from fpr_model.geometry import leg_anchor_angles
from fpr_model.rotations import euler_zyx_to_rotmat, rotmat_to_euler_zyx, rotmat_to_quat

__all__ = [
    "LocalReconstruction",
    "flat_rotation",
    "leg_anchor",
    "leg_angle",
    "platform_roll_pitch_flat",
    "reconstruct_local_state",
]


def leg_anchor(platform_radius: float, n: int, uav_id: int) -> np.ndarray:
    """``p_p_Ai = r·[cos α_i, sin α_i, 0]`` in Fp [m], α_i = 2π(i−1)/n ((2.7), erratum E1); uav_id = i (1-based)."""
    if not 1 <= int(uav_id) <= int(n):
        raise ValueError(f"uav_id must be in 1..{n}, got {uav_id}")
    alpha = leg_anchor_angles(int(n))[int(uav_id) - 1]
    return platform_radius * np.array([np.cos(alpha), np.sin(alpha), 0.0])


def leg_angle(relative_position: np.ndarray, anchor: np.ndarray) -> float:
    """θ_i (4.17)-(4.18): angle between ``p_r_AiBi = p_p_i − p_p_Ai`` and ``p_p_Ai`` [rad].

    Evaluated as atan2(‖a × b‖, a·b), the same angle as the thesis's acos, accurate near 0.
    """
    leg = np.asarray(relative_position, dtype=float) - anchor  # (4.17)
    # a × b on plain floats: np.cross's operations (same bits), without its ~10 µs of per-call overhead
    normal = np.array(cross3(leg.tolist(), np.asarray(anchor, dtype=float).tolist()))
    return float(np.arctan2(np.linalg.norm(normal), leg @ anchor))


def flat_rotation(roll: float, pitch: float) -> np.ndarray:
    """``Ry(ϑ) Rx(ϕ)`` (4.19): an attitude in its flat frame (yaw = 0)."""
    return euler_zyx_to_rotmat(roll, pitch, 0.0)


def platform_roll_pitch_flat(uav_roll: float, uav_pitch: float, platform_R_uav: np.ndarray) -> tuple[float, float]:
    """Platform roll and pitch in F_Fp from the UAV's IMU roll/pitch and ``p_R_i`` (4.19)-(4.21).

    ``Fi_R_p = Ry(ϑ_i) Rx(ϕ_i) · p_R_iᵀ`` (4.20); ``ϕ_p = atan2(R32, R33)``, ``ϑ_p = −asin(R31)`` (4.21).
    """
    R = flat_rotation(uav_roll, uav_pitch) @ np.asarray(platform_R_uav, dtype=float).T
    roll = float(np.arctan2(R[2, 1], R[2, 2]))
    pitch = float(-np.arcsin(np.clip(R[2, 0], -1.0, 1.0)))
    return roll, pitch


@dataclass(frozen=True)
class LocalReconstruction:
    """What UAV i reconstructs (fpr_msgs/LocalState fields)."""

    leg_angle: float  #: θ_i [rad] (4.18)
    platform_roll: float  #: Fp ϕ_p [rad] (4.21)
    platform_pitch: float  #: Fp ϑ_p [rad] (4.21)
    uav_attitude_flat: np.ndarray  #: Fp q_i [w, x, y, z] (4.22)
    uav_velocity_flat: np.ndarray  #: Fp v_i [m/s] (4.23)
    relative_yaw: float  #: p ψ_i [rad], ZYX yaw of p_R_i, for (4.38)
    uav_yaw: float  #: 0i ψ_i [rad], the UAV's own IMU yaw, for (4.38)


def reconstruct_local_state(relative_position: np.ndarray, platform_R_uav: np.ndarray, anchor: np.ndarray,
                            imu_R_uav: np.ndarray, body_velocity: np.ndarray) -> LocalReconstruction:
    """(4.17)-(4.23) on UAV i.

    relative_position: p_p_i [m]; platform_R_uav: p_R_i; anchor: p_p_Ai [m]; imu_R_uav: the UAV attitude in its
    own local frame F0i (body FLU -> ENU, any yaw offset); body_velocity: bi_v_i [m/s] in FLU.
    """
    roll_i, pitch_i, yaw_i = rotmat_to_euler_zyx(imu_R_uav)
    roll_p, pitch_p = platform_roll_pitch_flat(roll_i, pitch_i, platform_R_uav)
    flat_R_uav = flat_rotation(roll_p, pitch_p) @ platform_R_uav  # Fp_R_i of Fp_T_bi = Fp_T_p p_T_bi (4.22)
    _, _, relative_yaw = rotmat_to_euler_zyx(platform_R_uav)
    return LocalReconstruction(
        leg_angle=leg_angle(relative_position, anchor),
        platform_roll=roll_p,
        platform_pitch=pitch_p,
        uav_attitude_flat=rotmat_to_quat(flat_R_uav),
        uav_velocity_flat=flat_R_uav @ np.asarray(body_velocity, dtype=float),  # (4.23)
        relative_yaw=relative_yaw,
        uav_yaw=yaw_i,
    )
