"""On-board estimation pipeline of UAV i (thesis §4.2): detection -> p_T_bi (4.2) -> filter -> reconstruction.

ROS-free core of the ``pose_estimator`` node. Times are in seconds on any monotonic clock (the node uses the ROS
clock, so simulated time works). Inputs:

- :meth:`PoseEstimatorCore.on_imu`: UAV attitude in its local frame F0i and FLU body rate; runs the filter
  prediction (4.10)-(4.13) at the IMU rate;
- :meth:`PoseEstimatorCore.on_velocity`: FLU body linear velocity (for (4.23));
- :meth:`PoseEstimatorCore.on_detection`: the marker pose C_T_M; converted to p_T_bi by (4.2)-(4.3), gated, then
  used for the correction (4.16) (asynchronously, whenever a detection arrives);
- :meth:`PoseEstimatorCore.output`: the 50 Hz snapshot (filtered pose, 1-σ, reconstruction, validity).

Stale: when no detection was accepted for ``stale_timeout`` s the output is flagged invalid, prediction continues.
Re-initialisation: the first detection initialises the filter; after ``max_consecutive_rejections`` rejected
detections in a row (the filter has drifted away while the detections agree with each other) the next detection
re-initialises it. Bad inputs (NaN/inf, non-positive or huge time steps) are refused with a reason string.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from fpr_model.calibration import VisionCalibration, compose_transforms, invert_transform
from fpr_model.rotations import quat_to_rotmat, rotmat_to_euler_zyx, rotmat_to_quat

from fpr_estimation.ekf import FilterNoise, RelativePoseEKF
from fpr_estimation.gating import GateConfig, GateDecision, evaluate_gate
from fpr_estimation.mekf import RelativePoseMEKF
from fpr_estimation.reconstruction import LocalReconstruction, leg_anchor, reconstruct_local_state

__all__ = ["EstimatorConfig", "EstimatorOutput", "PoseEstimatorCore", "relative_pose_from_detection"]

FILTER_KINDS = ("ekf", "mekf")


def relative_pose_from_detection(camera_T_marker: np.ndarray, calibration: VisionCalibration) -> np.ndarray:
    """``p_T_bi = p_T_M · M_T_Ci · Ci_T_bi`` (4.2) with ``M_T_C = C_T_M⁻¹``, ``C_T_b = b_T_C⁻¹`` (4.3)."""
    return compose_transforms(calibration.platform_T_marker, invert_transform(camera_T_marker),
                              invert_transform(calibration.body_T_camera))


@dataclass(frozen=True)
class EstimatorConfig:
    uav_id: int = 1
    n: int = 3
    platform_radius: float = 0.127  #: r [m], Table B.1
    filter: str = "ekf"  #: ekf | mekf
    estimate_gyro_bias: bool = True  #: MEKF only
    noise: FilterNoise = field(default_factory=FilterNoise)
    gate: GateConfig = field(default_factory=GateConfig)
    stale_timeout: float = 0.5  #: [s]
    max_consecutive_rejections: int = 10
    max_prediction_step: float = 0.1  #: [s] longer IMU gaps are not integrated (logged by the node)

    def __post_init__(self) -> None:
        if self.filter not in FILTER_KINDS:
            raise ValueError(f"filter: expected one of {FILTER_KINDS}, got {self.filter!r}")
        if not 1 <= self.uav_id <= self.n:
            raise ValueError(f"uav_id must be in 1..{self.n}, got {self.uav_id}")
        if not (self.stale_timeout > 0.0 and self.max_prediction_step > 0.0 and self.platform_radius > 0.0):
            raise ValueError("stale_timeout, max_prediction_step and platform_radius must be positive")


@dataclass(frozen=True)
class EstimatorOutput:
    stamp: float
    position: np.ndarray  #: p_p_i [m]
    quaternion: np.ndarray  #: p_q_i [w, x, y, z]
    pose_stddev: np.ndarray  #: 1-σ of x, y, z [m] and of the body-frame rotation error [rad]
    detection_age: float  #: [s] since the last accepted detection (inf if none)
    valid: bool
    rejected_detections: int
    reconstruction: LocalReconstruction | None  #: None until an IMU attitude has been received
    body_rate: np.ndarray


def _finite(*arrays) -> bool:
    return all(np.isfinite(np.asarray(a, dtype=float)).all() for a in arrays)


class PoseEstimatorCore:
    def __init__(self, config: EstimatorConfig | None = None, calibration: VisionCalibration | None = None) -> None:
        self.config = config if config is not None else EstimatorConfig()
        self.calibration = calibration if calibration is not None else VisionCalibration()
        c = self.config
        if c.filter == "mekf":
            self.filter: RelativePoseEKF | RelativePoseMEKF = RelativePoseMEKF(c.noise, c.estimate_gyro_bias)
        else:
            self.filter = RelativePoseEKF(c.noise)
        self.anchor = leg_anchor(c.platform_radius, c.n, c.uav_id)
        self.last_imu_time: float | None = None
        self.last_accepted_time: float | None = None
        self.imu_rotation: np.ndarray | None = None
        self.body_rate = np.zeros(3)
        self.body_velocity = np.zeros(3)
        self.rejected_detections = 0
        self.accepted_detections = 0
        self.consecutive_rejections = 0
        self.last_gate: GateDecision | None = None

    # -- inputs ------------------------------------------------------------------------------------------
    def on_imu(self, stamp: float, orientation_quat: np.ndarray, body_rate: np.ndarray) -> str | None:
        """IMU sample: attitude [w, x, y, z] (FLU body -> the UAV's local ENU frame) and FLU rate [rad/s].

        Returns None, or a reason string when the sample was refused or the step skipped.
        """
        if not _finite(stamp, orientation_quat, body_rate):
            return "IMU sample with NaN/inf ignored"
        norm = float(np.linalg.norm(orientation_quat))
        if not 0.5 < norm < 1.5:
            return f"IMU orientation quaternion with norm {norm:.3g} ignored"
        self.imu_rotation = quat_to_rotmat(np.asarray(orientation_quat, dtype=float) / norm)
        self.body_rate = np.asarray(body_rate, dtype=float).copy()
        previous, self.last_imu_time = self.last_imu_time, float(stamp)
        if previous is None or not self.filter.initialized:
            return None
        dt = float(stamp) - previous
        if dt < 0.0:
            self.last_imu_time = previous
            return f"IMU stamp went back by {-dt:.3g} s; sample not integrated"
        if dt == 0.0:
            return None
        if dt > self.config.max_prediction_step:
            return f"IMU gap of {dt:.3g} s not integrated"
        self.filter.predict(self.body_rate, dt)
        return None

    def on_velocity(self, body_velocity: np.ndarray) -> str | None:
        if not _finite(body_velocity):
            return "velocity with NaN/inf ignored"
        self.body_velocity = np.asarray(body_velocity, dtype=float).copy()
        return None

    def on_detection(self, stamp: float, camera_T_marker: np.ndarray) -> GateDecision | str:
        """A marker detection C_T_M (4×4). Returns the gate decision, or a reason string if unusable."""
        if not _finite(stamp, camera_T_marker) or camera_T_marker[2, 3] <= 0.0:
            return "detection with NaN/inf or marker behind the camera ignored"
        platform_T_body = relative_pose_from_detection(camera_T_marker, self.calibration)
        return self.on_relative_pose(stamp, platform_T_body)

    def on_relative_pose(self, stamp: float, platform_T_body: np.ndarray) -> GateDecision | str:
        """A measured p_T_bi (4×4) (from (4.2), or MOCAP-emulated as in thesis §4.4.1)."""
        if not _finite(stamp, platform_T_body):
            return "relative pose with NaN/inf ignored"
        position = platform_T_body[:3, 3]
        quaternion = rotmat_to_quat(platform_T_body[:3, :3])
        if (not self.filter.initialized
                or self.consecutive_rejections >= self.config.max_consecutive_rejections):
            self.filter.initialize(position, quaternion)
            self.consecutive_rejections = 0
            self._accept(stamp)
            decision = GateDecision(True, 0.0, 0.0, 0.0)
            self.last_gate = decision
            return decision
        innovation, minimal, S = self.filter.innovation(position, quaternion)
        decision = evaluate_gate(self.config.gate, minimal, S)
        self.last_gate = decision
        if decision.accepted:
            self.filter.correct(innovation)
            self.consecutive_rejections = 0
            self._accept(stamp)
        else:
            self.rejected_detections += 1
            self.consecutive_rejections += 1
        return decision

    def _accept(self, stamp: float) -> None:
        self.accepted_detections += 1
        self.last_accepted_time = float(stamp) if self.last_accepted_time is None else max(
            self.last_accepted_time, float(stamp))

    # -- output ------------------------------------------------------------------------------------------
    def output(self, stamp: float) -> EstimatorOutput | None:
        """Snapshot at ``stamp`` [s]; None before the first accepted detection."""
        if not self.filter.initialized:
            return None
        age = float("inf") if self.last_accepted_time is None else max(float(stamp) - self.last_accepted_time, 0.0)
        position = self.filter.position
        quaternion = self.filter.quaternion
        covariance = self.filter.pose_covariance()
        stddev = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
        reconstruction = None
        if self.imu_rotation is not None:
            reconstruction = reconstruct_local_state(position, quat_to_rotmat(quaternion), self.anchor,
                                                     self.imu_rotation, self.body_velocity)
        valid = age <= self.config.stale_timeout and _finite(position, quaternion)
        return EstimatorOutput(float(stamp), position, quaternion, stddev, age, bool(valid),
                               self.rejected_detections, reconstruction, self.body_rate.copy())

    @staticmethod
    def euler_of(quaternion: np.ndarray) -> tuple[float, float, float]:
        """ZYX (roll, pitch, yaw) of a quaternion [rad] (for reports)."""
        return rotmat_to_euler_zyx(quat_to_rotmat(quaternion))
