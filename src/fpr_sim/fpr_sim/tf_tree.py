"""The true TF tree of the simulated robot (ROS-free): what the simulator publishes on /tf and /tf_static.

Frames (names as in fpr_model.robot_description, whose URDF the simulator publishes on /robot_description):
``world`` (F0, ENU) -> ``platform`` (Fp at P: the platform pose) -> ``leg<i>`` (F_li at A_i, rotation
``pR_li = Rz(α_i) Rx(−π/2) Rz(θ_i)`` (2.7)-(2.8)) -> ``uav<i>/base_link`` (quadrotor i, body FLU at its CoM, its
true attitude); static: ``uav<i>/base_link`` -> ``uav<i>/camera_optical`` (the TRUE camera mounting b_T_C of that
UAV, Table D.1 with the realism's per-UAV calibration error, the frame of its images). Every transform is computed
from the ground truth and the plant's TRUE parameters (with the realism's model mismatch), so the chain
reproduces the simulated positions exactly (the leg -> UAV translation is the true tip position in F_li, l·x_li).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from fpr_model.geometry import leg_anchor_angles, platform_to_leg_rotation
from fpr_model.parameters import FprParameters
from fpr_model.rotations import quat_to_rotmat, rotmat_to_quat

__all__ = ["FrameTransform", "camera_transforms", "robot_transforms"]


@dataclass(frozen=True)
class FrameTransform:
    """``parent -> child``: the child frame's origin [m] and orientation quaternion [w, x, y, z] in the parent."""

    parent: str
    child: str
    translation: np.ndarray
    quat: np.ndarray


def robot_transforms(params: FprParameters, platform_position, platform_quat, leg_angles, uav_positions,
                     uav_quats) -> list[FrameTransform]:
    """The moving part of the tree (1 + 2n transforms) from a true state (world ENU, FLU bodies, SI)."""
    position = np.asarray(platform_position, dtype=float)
    platform_rotation = quat_to_rotmat(np.asarray(platform_quat, dtype=float))
    out = [FrameTransform("world", "platform", position, np.asarray(platform_quat, dtype=float))]
    alphas = leg_anchor_angles(params.n)
    for i, (alpha, theta) in enumerate(zip(alphas, np.asarray(leg_angles, dtype=float), strict=True)):
        anchor = params.platform_radius * np.array([np.cos(alpha), np.sin(alpha), 0.0])
        leg_rotation = platform_to_leg_rotation(alpha, theta)
        out.append(FrameTransform("platform", f"leg{i + 1}", anchor, rotmat_to_quat(leg_rotation)))
        world_to_leg = (platform_rotation @ leg_rotation).T
        tip = world_to_leg @ (np.asarray(uav_positions[i], dtype=float) - position - platform_rotation @ anchor)
        uav_rotation = world_to_leg @ quat_to_rotmat(np.asarray(uav_quats[i], dtype=float))
        out.append(FrameTransform(f"leg{i + 1}", f"uav{i + 1}/base_link", tip, rotmat_to_quat(uav_rotation)))
    return out


def camera_transforms(body_T_cameras: list[np.ndarray]) -> list[FrameTransform]:
    """The static part: ``uav<i>/base_link -> uav<i>/camera_optical`` from each UAV's 4×4 b_T_C [m]."""
    return [FrameTransform(f"uav{i + 1}/base_link", f"uav{i + 1}/camera_optical", np.asarray(T[:3, 3], dtype=float),
                           rotmat_to_quat(np.asarray(T[:3, :3], dtype=float)))
            for i, T in enumerate(body_T_cameras)]
