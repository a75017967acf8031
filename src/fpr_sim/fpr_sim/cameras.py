"""On-board cameras of the n UAVs (thesis §4.2.1, Appendix D): rendered mono8 images of the platform marker, or
emulated noisy relative poses (thesis §4.4.1, 2 cm / 2° per axis). ROS-free; uses
:mod:`fpr_sim.camera_renderer` and :mod:`fpr_model.calibration` (b_T_C and p_T_M of Table D.1).

Poses: ``p_T_b = T_p⁻¹ T_b`` from the ground truth (platform and UAV body FLU poses in F0);
``C_T_M = (b_T_C)⁻¹ (p_T_b)⁻¹ p_T_M`` (4.2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from fpr_model.calibration import VisionCalibration, invert_transform, make_transform
from fpr_model.rotations import quat_to_rotmat

from fpr_sim.camera_renderer import MarkerRenderer, RenderResult, emulate_relative_pose
from fpr_sim.plant import GroundTruth
from fpr_sim.scenario import CameraConfig

__all__ = ["CameraRig", "EmulatedDetection", "platform_T_bodies"]


@dataclass
class EmulatedDetection:
    """An emulated marker detection: ``camera_T_marker`` 4×4 [m] (noisy), and the noisy ``platform_T_body``."""

    camera_T_marker: np.ndarray
    platform_T_body: np.ndarray


def platform_T_bodies(truth: GroundTruth) -> list[np.ndarray]:
    """True ``p_T_bi`` (4×4, m) of every UAV from the ground truth."""
    state = truth.state
    world_T_platform = make_transform(quat_to_rotmat(state.quat), state.position)
    platform_T_world = invert_transform(world_T_platform)
    return [platform_T_world @ make_transform(quat_to_rotmat(truth.uav_quats[i]), truth.uav_positions[i])
            for i in range(len(truth.uav_quats))]


class CameraRig:
    """One camera per UAV, same calibration; deterministic for a seed."""

    def __init__(self, config: CameraConfig, n: int, seed: int, calibration: VisionCalibration | None = None) -> None:
        self.config = config
        self.calibration = calibration or VisionCalibration()
        self.renderer = MarkerRenderer(self.calibration.camera, marker_size=self.calibration.marker_size)
        self.rngs = [np.random.default_rng(s) for s in np.random.SeedSequence([seed, 7]).spawn(n)]
        self.body_T_camera = self.calibration.body_T_camera
        self.platform_T_marker = self.calibration.platform_T_marker

    def camera_T_marker(self, platform_T_body: np.ndarray) -> np.ndarray:
        """``C_T_M = (b_T_C)⁻¹ (p_T_b)⁻¹ p_T_M`` (4.2)."""
        return invert_transform(self.body_T_camera) @ invert_transform(platform_T_body) @ self.platform_T_marker

    def render(self, truth: GroundTruth) -> list[RenderResult]:
        """Rendered mono8 frames of every UAV's camera (noise and blur from the configuration)."""
        return [self.renderer.render(self.camera_T_marker(T), blur_sigma=self.config.blur_sigma,
                                     noise_sigma=self.config.pixel_noise, rng=self.rngs[i])
                for i, T in enumerate(platform_T_bodies(truth))]

    def emulate(self, truth: GroundTruth) -> list[EmulatedDetection]:
        """Noisy relative poses (2 cm, 2° per axis by default) and the marker pose they imply."""
        out = []
        for i, T in enumerate(platform_T_bodies(truth)):
            noisy = emulate_relative_pose(T, self.rngs[i], self.config.position_noise, self.config.angle_noise)
            out.append(EmulatedDetection(self.camera_T_marker(noisy), noisy))
        return out
