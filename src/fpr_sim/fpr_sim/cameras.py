"""On-board cameras of the n UAVs (thesis §4.2.1, Appendix D): rendered mono8 images of the platform marker, or
emulated noisy relative poses (thesis §4.4.1, 2 cm / 2° per axis). ROS-free; uses
:mod:`fpr_sim.camera_renderer` and :mod:`fpr_model.calibration` (b_T_C and p_T_M of Table D.1).

Poses: ``p_T_b = T_p⁻¹ T_b`` from the ground truth (platform and UAV body FLU poses in F0);
``C_T_M = (b_T_C)⁻¹ (p_T_b)⁻¹ p_T_M`` (4.2).

Realism (:class:`fpr_sim.scenario.CameraConfig`): each UAV has a TRUE camera (:class:`TrueCamera`: intrinsics and
b_T_C drawn within the configured tolerances around the nominal calibration, which the estimator keeps); frames
are rendered, and emulated detections measured, through the true camera. Per-frame effects (occlusion, motion
blur, photometric changes, emulated misses) each draw a fixed number of variates per frame from a stream of their
own (seeded from the scenario seed), so switching one effect on changes no other effect's draws. With every effect
off the outputs are those of the effect-free rig, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from fpr_model.calibration import (
    CameraModel,
    EulerZxzPose,
    VisionCalibration,
    camera_T_marker_of,
    invert_transform,
    make_transform,
)
from fpr_model.rotations import quat_from_rotvec, quat_to_rotmat

from fpr_sim.camera_renderer import FrameEffects, MarkerRenderer, RenderResult, emulate_relative_pose
from fpr_sim.plant import GroundTruth
from fpr_sim.scenario import CameraConfig

__all__ = ["CameraRig", "EmulatedDetection", "TrueCamera", "draw_true_cameras", "platform_T_bodies",
           "platform_T_bodies_at"]

#: per-frame effect streams (index in SeedSequence([seed, 8, k])): one per effect, n UAVs each
_EFFECT_STREAMS = ("occlusion", "photometric", "detection")


@dataclass
class EmulatedDetection:
    """An emulated marker detection: ``camera_T_marker`` 4×4 [m] (as measured, through the true camera), and the
    ``platform_T_body`` the nominal calibration makes of it (what the estimator reconstructs with (4.2))."""

    camera_T_marker: np.ndarray
    platform_T_body: np.ndarray


@dataclass(frozen=True)
class TrueCamera:
    """The real camera of one UAV: intrinsics ``camera`` and mounting ``body_T_camera`` (4×4, m)."""

    camera: CameraModel
    body_T_camera: np.ndarray


def draw_true_cameras(config: CameraConfig, calibration: VisionCalibration, n: int, seed: int) -> list[TrueCamera]:
    """Per-UAV true cameras around the nominal ``calibration``: fx, fy × (1 + U(±intrinsics_tolerance)),
    cx, cy + U(±principal_point_tolerance) px, the Table D.1 ZXZ angles (ψ1, ϕ, ψ2) of b_T_C + U(±mounting_angle_
    tolerance) rad, its translation + U(±mounting_translation_tolerance) m per axis. Seeded (SeedSequence([seed,
    9]), one stream per UAV, 10 variates each whatever the tolerances); all tolerances 0: the nominal camera."""
    nominal, pose = calibration.camera, calibration.camera_pose
    out = []
    for stream in np.random.SeedSequence([seed, 9]).spawn(n):
        u = np.random.default_rng(stream).uniform(-1.0, 1.0, 10)
        camera = replace(nominal, fx=nominal.fx * (1.0 + config.intrinsics_tolerance * u[0]),
                         fy=nominal.fy * (1.0 + config.intrinsics_tolerance * u[1]),
                         cx=nominal.cx + config.principal_point_tolerance * u[2],
                         cy=nominal.cy + config.principal_point_tolerance * u[3])
        angles = tuple(float(a) + config.mounting_angle_tolerance * float(d) for a, d in zip(pose.euler_zxz, u[4:7],
                                                                                             strict=True))
        translation = tuple(float(x) + 100.0 * config.mounting_translation_tolerance * float(d)
                            for x, d in zip(pose.translation_cm, u[7:10], strict=True))
        true_pose = EulerZxzPose(translation, angles, pose.euler_order)  # type: ignore[arg-type]
        out.append(TrueCamera(camera, true_pose.transform))
    return out


def platform_T_bodies(truth: GroundTruth) -> list[np.ndarray]:
    """True ``p_T_bi`` (4×4, m) of every UAV from the ground truth."""
    state = truth.state
    world_T_platform = make_transform(quat_to_rotmat(state.quat), state.position)
    platform_T_world = invert_transform(world_T_platform)
    return [platform_T_world @ make_transform(quat_to_rotmat(truth.uav_quats[i]), truth.uav_positions[i])
            for i in range(len(truth.uav_quats))]


def platform_T_bodies_at(truth: GroundTruth, dt: float) -> list[np.ndarray]:
    """``p_T_bi`` extrapolated ``dt`` [s] from the ground truth at first order in the true twists: platform
    ``R_p exp(ω_p dt)`` (ω_p in Fp), ``P + v_p dt``; UAV ``R_b exp(ω_b dt)`` (ω_b body FLU), ``p_b + v_b dt``."""
    state = truth.state
    R_p = quat_to_rotmat(state.quat) @ quat_to_rotmat(quat_from_rotvec(np.asarray(state.rate) * dt))
    platform_T_world = invert_transform(make_transform(R_p, state.position + state.velocity * dt))
    out = []
    for i in range(len(truth.uav_quats)):
        R_b = quat_to_rotmat(truth.uav_quats[i]) @ quat_to_rotmat(quat_from_rotvec(truth.uav_rates[i] * dt))
        out.append(platform_T_world @ make_transform(R_b, truth.uav_positions[i] + truth.uav_velocities[i] * dt))
    return out


class CameraRig:
    """One camera per UAV, nominal calibration ``calibration`` (what camera_info and the estimator use), true cameras
    per :func:`draw_true_cameras`; deterministic for a seed. ``kernel``: where the renderers finish a frame
    (:class:`fpr_sim.camera_renderer.MarkerRenderer`; None: ``$FPR_SIM_KERNEL``), the same images either way."""

    def __init__(self, config: CameraConfig, n: int, seed: int, calibration: VisionCalibration | None = None,
                 kernel: str | None = None) -> None:
        self.config = config
        self.calibration = calibration or VisionCalibration()
        self.renderer = MarkerRenderer(self.calibration.camera, marker_size=self.calibration.marker_size,
                                       kernel=kernel)
        self.rngs = [np.random.default_rng(s) for s in np.random.SeedSequence([seed, 7]).spawn(n)]
        self.body_T_camera = self.calibration.body_T_camera
        self.platform_T_marker = self.calibration.platform_T_marker
        self.true_cameras = draw_true_cameras(config, self.calibration, n, seed)
        #: per UAV: the renderer of its true camera (the nominal renderer when the intrinsics are nominal)
        self.renderers = [self.renderer if tc.camera == self.calibration.camera else
                          MarkerRenderer(tc.camera, marker_size=self.calibration.marker_size, kernel=kernel)
                          for tc in self.true_cameras]
        self.effect_rngs = {name: [np.random.default_rng(s) for s in np.random.SeedSequence([seed, 8, k]).spawn(n)]
                            for k, name in enumerate(_EFFECT_STREAMS)}

    @property
    def calibration_error(self) -> bool:
        c = self.config
        return (c.intrinsics_tolerance > 0.0 or c.principal_point_tolerance > 0.0 or c.mounting_angle_tolerance > 0.0
                or c.mounting_translation_tolerance > 0.0)

    def camera_T_marker(self, platform_T_body: np.ndarray) -> np.ndarray:
        """``C_T_M = (b_T_C)⁻¹ (p_T_b)⁻¹ p_T_M`` (4.2) with the nominal b_T_C."""
        return camera_T_marker_of(platform_T_body, self.body_T_camera, self.platform_T_marker)

    def true_camera_T_marker(self, i: int, platform_T_body: np.ndarray) -> np.ndarray:
        """(4.2) with UAV i's TRUE b_T_C (the nominal one without calibration error: the same arithmetic)."""
        if not self.calibration_error:
            return self.camera_T_marker(platform_T_body)
        return camera_T_marker_of(platform_T_body, self.true_cameras[i].body_T_camera, self.platform_T_marker)

    # ---- rendered frames ------------------------------------------------------------------------------
    def render(self, truth: GroundTruth) -> list[RenderResult]:
        """Rendered mono8 frames of every UAV's camera (noise, blur and realism effects from the configuration),
        the state of ``truth`` at the exposure instant."""
        c = self.config
        out = []
        poses = platform_T_bodies(truth)
        half = 0.5 * c.exposure_time
        before = platform_T_bodies_at(truth, -half) if half > 0.0 else None
        after = platform_T_bodies_at(truth, half) if half > 0.0 else None
        for i, T in enumerate(poses):
            camera_T_marker = self.true_camera_T_marker(i, T)
            motion = None
            if before is not None:
                motion = self._image_motion(i, self.true_camera_T_marker(i, before[i]),
                                            self.true_camera_T_marker(i, after[i]))
            effects = self._frame_effects(i, camera_T_marker, motion)
            out.append(self.renderers[i].render(camera_T_marker, blur_sigma=c.blur_sigma, noise_sigma=c.pixel_noise,
                                                rng=self.rngs[i], effects=effects))
        return out

    def _marker_pixels(self, i: int, camera_T_marker: np.ndarray) -> np.ndarray | None:
        """The 4 marker corners (TL, TR, BR, BL) in UAV i's true image [px]; None when one is behind the camera."""
        renderer = self.renderers[i]
        points = renderer.marker_corners @ camera_T_marker[:3, :3].T + camera_T_marker[:3, 3]
        if not np.all(points[:, 2] > renderer.near_clip):
            return None
        return renderer._project(points)

    def _image_motion(self, i: int, start: np.ndarray, end: np.ndarray) -> np.ndarray | None:
        """Mean displacement [px] of the projected marker corners from ``start`` to ``end`` (C_T_M, 4×4)."""
        a, b = self._marker_pixels(i, start), self._marker_pixels(i, end)
        return None if a is None or b is None else (b - a).mean(axis=0)

    def _frame_effects(self, i: int, camera_T_marker: np.ndarray, motion: np.ndarray | None) -> FrameEffects | None:
        """This frame's draws (a fixed number per enabled effect and frame); None when no effect is enabled."""
        c = self.config
        occluding = c.occlusion_probability > 0.0
        photometric = c.contrast_variation > 0.0 or c.brightness_variation > 0.0 or c.lighting_gradient > 0.0
        if motion is None and not occluding and not photometric:
            return None
        effects = FrameEffects(motion=motion)
        if occluding:
            u = self.effect_rngs["occlusion"][i].random(4)
            corners = self._marker_pixels(i, camera_T_marker)
            if u[0] < c.occlusion_probability and corners is not None:
                effects.occluder = _occluding_band(corners, c.occlusion_width, angle=np.pi * u[1], offset=u[2] - 0.5)
                effects.occluder_factor = c.occlusion_shade * float(u[3])
        if photometric:
            z = self.effect_rngs["photometric"][i].standard_normal(4)
            effects.gain = max(0.0, 1.0 + c.contrast_variation * float(z[0]))
            effects.offset = c.brightness_variation * float(z[1])
            effects.gradient = c.lighting_gradient * z[2:4]
        return effects

    # ---- emulated detections ----------------------------------------------------------------------------
    def emulate(self, truth: GroundTruth) -> list[EmulatedDetection | None]:
        """Noisy relative poses (2 cm, 2° per axis by default) and the marker pose they imply, measured through each
        UAV's true camera (calibration bias); None for a missed detection (``detection_probability``)."""
        c = self.config
        out: list[EmulatedDetection | None] = []
        for i, T in enumerate(platform_T_bodies(truth)):
            noisy = emulate_relative_pose(T, self.rngs[i], c.position_noise, c.angle_noise)
            missed = c.detection_probability < 1.0 and \
                self.effect_rngs["detection"][i].random() >= c.detection_probability
            if missed:
                out.append(None)
            elif not self.calibration_error:
                out.append(EmulatedDetection(self.camera_T_marker(noisy), noisy))
            else:
                measured = self._measure_through_true_camera(i, self.true_camera_T_marker(i, noisy))
                implied = self.platform_T_marker @ invert_transform(measured) @ invert_transform(self.body_T_camera)
                out.append(EmulatedDetection(measured, implied))
        return out

    def _measure_through_true_camera(self, i: int, camera_T_marker: np.ndarray) -> np.ndarray:
        """The C_T_M an ArUco detector configured with the NOMINAL intrinsics gets from UAV i's true camera: the
        marker corners projected with the true intrinsics, IPPE-square PnP with the nominal ones (solution closest
        in rotation to the true pose). Unchanged when the intrinsics are nominal."""
        true_camera, nominal = self.true_cameras[i].camera, self.calibration.camera
        if true_camera == nominal:
            return camera_T_marker
        renderer = self.renderers[i]
        points = renderer.marker_corners @ camera_T_marker[:3, :3].T + camera_T_marker[:3, 3]
        if not np.all(points[:, 2] > renderer.near_clip):
            return camera_T_marker
        pixels = true_camera.project(points).reshape(-1, 1, 2)
        count, rvecs, tvecs, _ = cv2.solvePnPGeneric(renderer.marker_corners, pixels, nominal.camera_matrix,
                                                     nominal.dist_coeffs, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not count:
            return camera_T_marker
        candidates = [make_transform(cv2.Rodrigues(r)[0], np.asarray(t).reshape(3)) for r, t in zip(rvecs, tvecs,
                                                                                                   strict=True)]
        return max(candidates, key=lambda C: float(np.trace(C[:3, :3].T @ camera_T_marker[:3, :3])))


def _occluding_band(corners: np.ndarray, width: float, angle: float, offset: float) -> np.ndarray:
    """A band (4, 2) [px] across the marker of image corners ``corners`` (4, 2): ``width`` marker sides wide, at
    ``angle`` [rad] in the image, its centre line ``offset`` marker sides (in [−½, ½]) off the marker centre along
    its normal, two sides long (it crosses the whole marker)."""
    side = float(np.mean(np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)))
    direction = np.array([np.cos(angle), np.sin(angle)])
    normal = np.array([-direction[1], direction[0]])
    centre = corners.mean(axis=0) + offset * side * normal
    along, across = side * direction, 0.5 * width * side * normal
    return np.array([centre - along - across, centre + along - across, centre + along + across,
                     centre - along + across])
