"""The thesis's motion-capture fallback for lost or false marker detections (§4.4.2, l.6823-6830). ROS-free.

In the thesis's Scenarios I and II (Tables 4.6-4.8) the onboard ArUco detections were supervised from the motion
capture: "Emulating the relative pose p_T_bi with the same noises presented in Section 4.4.1 if the detection is
lost for more than 0.5 s (corresponding to 10 control iterations) or a false detection is identified (with
translation error > 10 cm or rotation error > 10°). This is required for safety reasons as the detection failure
will inevitably cause instabilities and crashes". :class:`DetectionFallback` does the same for n UAVs:

- a detection whose relative pose ``p_T_bi`` (4.2) is within ``max_position_error`` / ``max_angle_error`` of the
  motion capture's at its capture stamp passes unchanged;
- a false one (farther) is replaced by an emulated detection: the motion capture's ``p_T_bi`` at that stamp with
  the §4.4.1 noise (``position_noise`` per axis, ``angle_noise`` per axis, Gaussian, seeded);
- while no detection has passed for more than ``lost_timeout``, emulated detections of the latest motion-capture
  sample are given at ``rate`` (the camera's 20 Hz), until a real one passes again.

An emulated detection is a marker pose ``C_T_M`` as a camera would report it, built with the NOMINAL calibration
(Table D.1, the one the estimators use), so that (4.2) in the estimator gives back the emulated ``p_T_bi``:
``C_T_M = (b_T_C)⁻¹ (p_T_bi)⁻¹ p_T_M`` (fpr_model.calibration.camera_T_marker_of). Frames: ``p_T_bi`` is the UAV
body (FLU) in the platform frame Fp, from
the motion capture's platform and UAV poses in F0 (``p_T_bi = 0_T_p⁻¹ · 0_T_bi``); metres, radians, seconds of the
stamps' clock.

This is a ground-truth component of the experiment set-up, as the thesis's was: the real robot has no such
supervisor unless a motion-capture system is there.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from fpr_estimation.estimator import relative_pose_from_detection
from fpr_model.calibration import VisionCalibration, camera_T_marker_of, invert_transform, make_transform
from fpr_model.rotations import quat_from_rotvec, quat_to_rotmat

__all__ = ["DetectionFallback", "FallbackConfig", "FallbackDecision"]


@dataclass(frozen=True)
class FallbackConfig:
    lost_timeout: float = 0.5  #: [s] no passed detection for longer: emulated ones (l.6825-6826)
    max_position_error: float = 0.10  #: [m] a detection farther from the motion capture is false (l.6827)
    max_angle_error: float = math.radians(10.0)  #: [rad] (l.6827-6828)
    position_noise: float = 0.02  #: [m] 1-σ per axis of an emulated p_p_i (§4.4.1: 2 cm)
    angle_noise: float = math.radians(2.0)  #: [rad] 1-σ per axis of an emulated p_q_i (§4.4.1: 2°)
    rate: float = 20.0  #: [Hz] emulated detections while lost (the cameras' rate)
    history: float = 0.5  #: [s] motion-capture samples kept (to compare a detection at its capture stamp)

    def __post_init__(self) -> None:
        for name in ("lost_timeout", "max_position_error", "max_angle_error", "rate", "history"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"detection fallback {name}: must be positive and finite, got {value}")
        for name in ("position_noise", "angle_noise"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"detection fallback {name}: must be >= 0 and finite, got {value}")


@dataclass(frozen=True)
class FallbackDecision:
    camera_T_marker: np.ndarray  #: C_T_M to publish (the detection's own, or an emulated one)
    emulated: bool
    reason: str  #: "" (passed), "false detection: ..." or "no motion capture"


def _pose(position, quat) -> np.ndarray:
    q = np.asarray(quat, dtype=float)
    return make_transform(quat_to_rotmat(q / np.linalg.norm(q)), position)


def _angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """[rad] angle of ``R_aᵀ R_b``."""
    return float(math.acos(max(-1.0, min(1.0, 0.5 * (float(np.trace(R_a.T @ R_b)) - 1.0)))))


class DetectionFallback:
    """The supervisor of n UAVs' detections (see the module doc). Feed the motion capture with :meth:`on_mocap`,
    every detection with :meth:`on_detection`, and call :meth:`due` at least at ``rate``."""

    def __init__(self, n: int, config: FallbackConfig | None = None, calibration: VisionCalibration | None = None,
                 seed: int = 0) -> None:
        self.n = int(n)
        self.config = config if config is not None else FallbackConfig()
        self.calibration = calibration if calibration is not None else VisionCalibration()
        self._rng = [np.random.default_rng([int(seed), 4044, uav]) for uav in range(1, self.n + 1)]
        self._mocap: deque[tuple[float, list[np.ndarray]]] = deque()
        self._last_passed: list[float | None] = [None] * self.n
        self._next_emulated = [-math.inf] * self.n
        self.lost = [False] * self.n  #: per UAV: emulating because no detection passed for lost_timeout
        self.passed = [0] * self.n
        self.false_detections = [0] * self.n
        self.emulated = [0] * self.n  #: emulated detections given (false ones replaced + while lost)

    # -- motion capture ---------------------------------------------------------------------------------------
    def on_mocap(self, stamp: float, platform_position, platform_quat, uav_positions, uav_quats) -> str | None:
        """One motion-capture sample at ``stamp`` [s]: poses in F0 (positions [m], unit quaternions [w, x, y, z]).
        Returns None, or why the sample was refused (the previous samples stand)."""
        stamp = float(stamp)
        if len(uav_positions) != self.n or len(uav_quats) != self.n:
            return f"motion capture with {len(uav_positions)} UAV poses, {len(uav_quats)} attitudes, expected {self.n}"
        values = [platform_position, platform_quat, *uav_positions, *uav_quats]
        if not all(np.isfinite(np.asarray(v, dtype=float)).all() for v in values) or not np.isfinite(stamp):
            return "motion capture with NaN/inf"
        if not all(abs(float(np.linalg.norm(q)) - 1.0) <= 0.01 for q in (platform_quat, *uav_quats)):
            return "motion capture with a non-unit quaternion"
        if self._mocap and stamp <= self._mocap[-1][0]:
            return None  # not newer than the last sample: nothing to add
        world_T_platform_inv = invert_transform(_pose(platform_position, platform_quat))
        relative = [world_T_platform_inv @ _pose(p, q) for p, q in zip(uav_positions, uav_quats, strict=True)]
        self._mocap.append((stamp, relative))
        while len(self._mocap) > 1 and self._mocap[0][0] < stamp - self.config.history:
            self._mocap.popleft()
        return None

    def mocap_relative_pose(self, uav: int, stamp: float) -> tuple[float, np.ndarray] | None:
        """(sample stamp, ``p_T_bi``) of the motion-capture sample nearest ``stamp`` for UAV ``uav`` (1-based)."""
        if not self._mocap:
            return None
        best = min(self._mocap, key=lambda sample: abs(sample[0] - stamp))
        return best[0], best[1][uav - 1]

    # -- detections -------------------------------------------------------------------------------------------
    def _emulate(self, uav: int, platform_T_body: np.ndarray) -> np.ndarray:
        """``C_T_M`` of ``p_T_bi`` with the §4.4.1 noise."""
        rng, c = self._rng[uav - 1], self.config
        noisy = platform_T_body.copy()
        noisy[:3, 3] += rng.normal(0.0, c.position_noise, 3)
        noisy[:3, :3] = platform_T_body[:3, :3] @ quat_to_rotmat(quat_from_rotvec(rng.normal(0.0, c.angle_noise, 3)))
        self.emulated[uav - 1] += 1
        c = self.calibration
        return camera_T_marker_of(noisy, c.body_T_camera, c.platform_T_marker)

    def on_detection(self, uav: int, stamp: float, camera_T_marker: np.ndarray) -> FallbackDecision:
        """A detection of UAV ``uav`` captured at ``stamp`` [s]: passed, or replaced when false (see the module doc).
        Without motion capture yet it passes (nothing to compare with)."""
        index = uav - 1
        camera_T_marker = np.asarray(camera_T_marker, dtype=float)
        reference = self.mocap_relative_pose(uav, stamp)
        if reference is None:
            self._passed(index, stamp)
            return FallbackDecision(camera_T_marker, False, "no motion capture")
        measured = relative_pose_from_detection(camera_T_marker, self.calibration) \
            if np.isfinite(camera_T_marker).all() else None
        truth = reference[1]
        if measured is not None:
            distance = float(np.linalg.norm(measured[:3, 3] - truth[:3, 3]))
            angle = _angle(measured[:3, :3], truth[:3, :3])
            if distance <= self.config.max_position_error and angle <= self.config.max_angle_error:
                self._passed(index, stamp)
                return FallbackDecision(camera_T_marker, False, "")
            reason = f"false detection: {100 * distance:.1f} cm, {math.degrees(angle):.1f} deg from the motion capture"
        else:
            reason = "false detection: not finite"
        self.false_detections[index] += 1
        return FallbackDecision(self._emulate(uav, truth), True, reason)

    def _passed(self, index: int, stamp: float) -> None:
        self.passed[index] += 1
        last = self._last_passed[index]
        self._last_passed[index] = stamp if last is None else max(last, stamp)

    def due(self, uav: int, now: float) -> tuple[float, np.ndarray] | None:
        """While UAV ``uav``'s detections are lost (none passed for ``lost_timeout`` s; counted from the first call
        when none ever did): (capture stamp, ``C_T_M``) of an emulated detection of the latest motion capture, at
        most one per 1/``rate`` s; else None."""
        index = uav - 1
        if self._last_passed[index] is None:
            self._last_passed[index] = float(now)  # the start: lost_timeout of grace, as after a detection
        self.lost[index] = now - self._last_passed[index] > self.config.lost_timeout
        if not self.lost[index] or now < self._next_emulated[index] or not self._mocap:
            return None
        period = 1.0 / self.config.rate  # on a fixed grid from the first one (a caller's tick does not drift it)
        following = self._next_emulated[index] + period
        self._next_emulated[index] = following if now - period < following else now + period - 1e-9
        stamp, relative = self._mocap[-1]
        return stamp, self._emulate(uav, relative[index])

    def lost_for(self, uav: int, now: float) -> float:
        """[s] since UAV ``uav``'s last passed detection (0 before any call)."""
        last = self._last_passed[uav - 1]
        return 0.0 if last is None else max(0.0, float(now) - last)

