"""Innovation gate for the relative-pose filters (thesis §4.2.2: "reducing the rate of false detections"). ROS-free.

A detection is compared with the predicted relative pose before the correction (4.16). The innovation is
expressed minimally: the position difference [m] (Fp) and the rotation vector of ``q_pred^{-1} ∘ q_meas`` [rad]
(UAV body frame). Two tests, selected by ``GateConfig.mode``:

- ``"threshold"`` (default): reject when ‖δp‖ > ``max_position_error`` (10 cm) or the rotation angle
  > ``max_angle_error`` (10°);
- ``"mahalanobis"``: reject when ``νᵀ S⁻¹ ν`` exceeds ``mahalanobis_threshold`` (χ²₆ quantile; 22.46 is 99.9 %),
  S being the 6×6 innovation covariance of the filter.

Input guards (issue 12, DESIGN.md §5b), applied before anything reaches the filter:

- :func:`check_imu_sample`: NaN/inf, |‖q‖ − 1| > ``max_quaternion_norm_error`` (0.01), ‖ω‖ > ``max_body_rate``
  (35 rad/s, PX4 gyro range), ‖f‖ > ``max_specific_force`` (16 g), a stamp more than ``max_stamp_future`` (0.2 s)
  after the receive time or earlier than the previous accepted one;
- :func:`check_marker_pose`: NaN/inf, not a rotation, marker behind the camera, farther than
  ``max_marker_distance`` (2 m), capture stamp more than ``max_stamp_future`` after the receive time.

(Re-)initialisation (:class:`ReinitConfig`, :class:`ConsistentRun`): only from K (4) consecutive detections,
pairwise within ``position_tolerance`` (10 cm) and ``angle_tolerance`` (10°) after the IMU-propagated rotation,
spanning at most ``window`` (0.3 s); an initialised filter additionally only after ``min_lost_time`` (1.5 s)
without an accepted detection. A single outlier, or a burst that disagrees with itself, never initialises; a
self-consistent forged burst shorter than ``min_lost_time`` while the filter tracks is gated like any outlier.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from fpr_model.rotations import quat_angle, quat_from_rotvec, quat_multiply, quat_normalize

__all__ = ["ConsistentRun", "GateConfig", "GateDecision", "InputBounds", "ReinitConfig", "Refusal",
           "check_imu_sample", "check_marker_pose", "evaluate_gate", "is_rotation"]

GATE_MODES = ("threshold", "mahalanobis", "off")


@dataclass(frozen=True)
class GateConfig:
    """Innovation gate of the marker detections. ``threshold``: ‖δp‖ and the innovation's rotation angle each below
    a bound that **grows with the time since the last accepted detection** (``lost`` [s]): ``max_position_error +
    position_error_rate·lost``, capped at ``position_error_limit`` (likewise the angle). The relative position of the
    EKF (4.9)-(4.16) is a random walk, so while detections are rejected the prediction stands still while the UAV
    moves against the platform (a leg change at 10 °/s moves the UAV ~0.17 m/s): a fixed bound then rejects every
    later detection — a lock-out the adversarial simulator showed (issue 11, Table 4.2 seed 21: 1.4 s of rejections
    of good detections, a re-initialisation mid-motion, the robot flipped). The growth is the threshold analogue of
    the Mahalanobis gate's growing covariance. The rates and caps are small enough that a consistent forged stream
    20 cm / 20° off stays out for the whole second issue 12's test gives it (bound 18 cm / 16° after 1 s).
    ``mahalanobis``: νᵀ S⁻¹ ν below the χ²(6) threshold. ``off``: everything accepted."""

    mode: str = "threshold"
    max_position_error: float = 0.10  #: [m] bound right after an accepted detection
    max_angle_error: float = float(np.radians(10.0))  #: [rad]
    mahalanobis_threshold: float = 22.46  #: χ²(6) at 99.9 %
    position_error_rate: float = 0.08  #: [m/s] growth of the position bound per second without an accepted detection
    angle_error_rate: float = float(np.radians(6.0))  #: [rad/s]
    position_error_limit: float = 0.18  #: [m] the position bound's cap
    angle_error_limit: float = float(np.radians(16.0))  #: [rad]

    def __post_init__(self) -> None:
        if self.mode not in GATE_MODES:
            raise ValueError(f"gate mode: expected one of {GATE_MODES}, got {self.mode!r}")
        if not (self.max_position_error > 0.0 and self.max_angle_error > 0.0 and self.mahalanobis_threshold > 0.0):
            raise ValueError("gate thresholds must be positive")
        if not (self.position_error_rate >= 0.0 and self.angle_error_rate >= 0.0
                and self.position_error_limit >= self.max_position_error
                and self.angle_error_limit >= self.max_angle_error):
            raise ValueError("gate growth rates must be >= 0 and the limits >= the base bounds")

    def bounds(self, lost: float) -> tuple[float, float]:
        """(position [m], angle [rad]) bounds of the threshold gate ``lost`` s after the last accepted detection."""
        lost = max(float(lost), 0.0) if np.isfinite(lost) else 0.0
        return (min(self.max_position_error + self.position_error_rate * lost, self.position_error_limit),
                min(self.max_angle_error + self.angle_error_rate * lost, self.angle_error_limit))


@dataclass(frozen=True)
class GateDecision:
    accepted: bool
    position_error: float  #: ‖δp‖ [m]
    angle_error: float  #: rotation angle of the innovation [rad]
    mahalanobis: float  #: νᵀ S⁻¹ ν (NaN when S is not available)
    initialised: bool = False  #: this detection (re-)initialised the filter (the errors are then those to the old
    #: prediction, NaN when there was none)


def evaluate_gate(config: GateConfig, innovation: np.ndarray, covariance: np.ndarray | None,
                  lost: float = 0.0) -> GateDecision:
    """Apply the gate to a 6-D innovation ``[δp (3), δθ (3)]`` with covariance S (6×6) or None, ``lost`` s after the
    last accepted detection (the threshold gate's bounds grow with it, :meth:`GateConfig.bounds`)."""
    position_error = float(np.linalg.norm(innovation[:3]))
    angle_error = float(np.linalg.norm(innovation[3:]))
    mahalanobis = float("nan")
    if covariance is not None:
        try:
            mahalanobis = float(innovation @ np.linalg.solve(covariance, innovation))
        except np.linalg.LinAlgError:
            mahalanobis = float("inf")
    if config.mode == "off":
        accepted = True
    elif config.mode == "mahalanobis":
        accepted = bool(np.isfinite(mahalanobis) and mahalanobis <= config.mahalanobis_threshold)
    else:
        position_bound, angle_bound = config.bounds(lost)
        accepted = position_error <= position_bound and angle_error <= angle_bound
    return GateDecision(accepted, position_error, angle_error, mahalanobis)


# -- input plausibility (issue 12) -------------------------------------------------------------------------------

STANDARD_GRAVITY = 9.80665  #: [m/s²]


@dataclass(frozen=True)
class InputBounds:
    """Physical plausibility bounds on the estimator's inputs (DESIGN.md §5b). SI units.

    The IMU bounds are the measurement ranges of PX4 flight-controller IMUs (gyro ±2000 °/s ≈ 35 rad/s,
    accelerometer ±16 g): a larger value cannot come from the sensor. The marker bound is the camera's useful range
    on this robot (camera to marker ≈ 1 m through a 1.043 m leg, Table B.1).
    """

    max_body_rate: float = 35.0  #: [rad/s] ‖ω‖ (FLU body rate)
    max_specific_force: float = 16.0 * STANDARD_GRAVITY  #: [m/s²] ‖f‖ (FLU specific force, +g at rest)
    max_quaternion_norm_error: float = 0.01  #: |‖q‖ − 1| of the IMU attitude quaternion
    max_stamp_future: float = 0.2  #: [s] a stamp later than the receive time by more is refused
    max_marker_distance: float = 2.0  #: [m] ‖C_t_M‖, camera to marker

    def __post_init__(self) -> None:
        for name in ("max_body_rate", "max_specific_force", "max_quaternion_norm_error", "max_stamp_future",
                     "max_marker_distance"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"{name}: must be positive and finite, got {value}")


@dataclass(frozen=True)
class Refusal:
    """Why an input was refused: ``kind`` names the bound (the key of the rate-limited log line)."""

    kind: str
    reason: str


def _finite(*arrays) -> bool:
    return all(np.isfinite(np.asarray(a, dtype=float)).all() for a in arrays)


def check_imu_sample(bounds: InputBounds, stamp: float, orientation_quat: np.ndarray, body_rate: np.ndarray,
                     specific_force: np.ndarray | None = None, now: float | None = None,
                     last_stamp: float | None = None) -> Refusal | None:
    """Plausibility of one IMU sample: stamp [s], attitude [w, x, y, z], FLU rate [rad/s], FLU specific force
    [m/s²] (None: not provided); ``now`` is the receive time and ``last_stamp`` the previous accepted stamp [s]
    (None: not checked). Returns None, or the first bound violated."""
    if not _finite(stamp, orientation_quat, body_rate) or (specific_force is not None and not _finite(
            specific_force)):
        return Refusal("imu_nan", "IMU sample with NaN/inf refused")
    norm = float(np.linalg.norm(orientation_quat))
    if abs(norm - 1.0) > bounds.max_quaternion_norm_error:
        return Refusal("imu_quaternion", f"IMU attitude quaternion with norm {norm:.4g} refused "
                                         f"(|norm - 1| > {bounds.max_quaternion_norm_error:g})")
    rate = float(np.linalg.norm(body_rate))
    if rate > bounds.max_body_rate:
        return Refusal("imu_rate", f"IMU body rate {rate:.4g} rad/s refused (gyro range {bounds.max_body_rate:g} "
                                   f"rad/s)")
    if specific_force is not None:
        force = float(np.linalg.norm(specific_force))
        if force > bounds.max_specific_force:
            return Refusal("imu_force", f"IMU specific force {force:.4g} m/s^2 refused (accelerometer range "
                                        f"{bounds.max_specific_force:.4g} m/s^2)")
    if now is not None and stamp > now + bounds.max_stamp_future:
        return Refusal("imu_stamp", f"IMU stamp {stamp - now:.3g} s in the future refused "
                                    f"(> {bounds.max_stamp_future:g} s)")
    if last_stamp is not None and stamp < last_stamp:
        return Refusal("imu_stamp", f"IMU stamp went back by {last_stamp - stamp:.3g} s: sample refused")
    return None


def check_marker_pose(bounds: InputBounds, camera_T_marker: np.ndarray, capture_stamp: float | None = None,
                      now: float | None = None) -> Refusal | None:
    """Plausibility of a marker detection C_T_M (4×4, camera optical frame, m) captured at ``capture_stamp`` and
    received at ``now`` [s] (either None: the stamp is not checked)."""
    if not _finite(camera_T_marker) or (capture_stamp is not None and not _finite(capture_stamp)):
        return Refusal("detection_nan", "detection with NaN/inf refused")
    if not is_rotation(camera_T_marker[:3, :3]):
        return Refusal("detection_rotation", "detection whose orientation is not a rotation refused")
    if camera_T_marker[2, 3] <= 0.0:
        return Refusal("detection_behind", "detection with the marker behind the camera refused")
    distance = float(np.linalg.norm(camera_T_marker[:3, 3]))
    if distance > bounds.max_marker_distance:
        return Refusal("detection_distance", f"detection {distance:.3g} m from the camera refused "
                                             f"(range {bounds.max_marker_distance:g} m)")
    if capture_stamp is not None and now is not None and capture_stamp > now + bounds.max_stamp_future:
        return Refusal("detection_stamp", f"detection stamped {capture_stamp - now:.3g} s in the future refused "
                                          f"(> {bounds.max_stamp_future:g} s)")
    return None


def is_rotation(R: np.ndarray, tolerance: float = 1e-3) -> bool:
    """True for a proper rotation matrix (‖RᵀR − I‖∞ ≤ tolerance, det R > 0)."""
    R = np.asarray(R, dtype=float)
    return bool(np.abs(R.T @ R - np.eye(3)).max() <= tolerance and np.linalg.det(R) > 0.0)


# -- re-initialisation on consistent detections (issue 12) -------------------------------------------------------

@dataclass(frozen=True)
class ReinitConfig:
    """When the filter may (re-)initialise from detections instead of gating them (see :class:`ConsistentRun`).

    - not initialised (start, or after a non-finite state): on ``consistent_detections`` (K) consecutive
      detections, pairwise consistent, spanning at most ``window``;
    - initialised: the same K, and only once no detection was accepted for ``min_lost_time`` — a healthy filter
      is never replaced by a burst shorter than that (its detections are gated as usual).
    """

    consistent_detections: int = 4  #: K
    window: float = 0.3  #: [s] the K detections span at most this
    position_tolerance: float = 0.10  #: [m] pairwise ‖p_a − p_b‖ (Fp)
    angle_tolerance: float = float(np.radians(10.0))  #: [rad] pairwise angle, after the IMU-propagated rotation
    min_lost_time: float = 1.5  #: [s] without an accepted detection before an initialised filter is replaced

    def __post_init__(self) -> None:
        if self.consistent_detections < 1:
            raise ValueError(f"consistent_detections must be >= 1, got {self.consistent_detections}")
        for name in ("window", "position_tolerance", "angle_tolerance", "min_lost_time"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"reinit {name}: must be positive and finite, got {value}")


@dataclass
class _Candidate:
    stamp: float
    position: np.ndarray
    quaternion: np.ndarray  #: propagated with the IMU to the latest IMU time


class ConsistentRun:
    """The latest run of mutually consistent detections of p_T_bi (candidates for a (re-)initialisation).

    Each candidate's attitude is propagated with the UAV body rate like the filter's prediction ((4.5)-(4.8):
    ``q ← q ∘ exp(ω T_s)``, position constant), so candidates taken while the UAV turns stay comparable. A new
    candidate drops the ones older than ``window`` and every one up to the newest it disagrees with (more than
    ``position_tolerance`` apart, or an angle of ``q_a⁻¹ ∘ q_b`` above ``angle_tolerance``): the run is always
    pairwise consistent (a common propagation leaves pairwise angles unchanged), and :attr:`ready` once it holds K.
    """

    def __init__(self, config: ReinitConfig | None = None) -> None:
        self.config = config if config is not None else ReinitConfig()
        self._run: list[_Candidate] = []

    def __len__(self) -> int:
        return len(self._run)

    @property
    def ready(self) -> bool:
        return len(self._run) >= self.config.consistent_detections

    def clear(self) -> None:
        self._run.clear()

    def propagate(self, body_rate: np.ndarray, dt: float) -> None:
        """Rotate every candidate's attitude by the FLU body rate ω [rad/s] over dt [s]."""
        if not self._run:
            return
        step = quat_from_rotvec(np.asarray(body_rate, dtype=float) * dt)
        for candidate in self._run:
            candidate.quaternion = quat_normalize(quat_multiply(candidate.quaternion, step))

    def _consistent(self, a: _Candidate, b: _Candidate) -> bool:
        if np.linalg.norm(a.position - b.position) > self.config.position_tolerance:
            return False
        return quat_angle(a.quaternion, b.quaternion) <= self.config.angle_tolerance

    def add(self, stamp: float, position: np.ndarray, quaternion: np.ndarray) -> None:
        """A detection p_p_i [m], p_q_i [w, x, y, z] at ``stamp`` [s] (a stamp earlier than the run restarts it)."""
        new = _Candidate(float(stamp), np.asarray(position, dtype=float).copy(), quat_normalize(quaternion))
        run = [c for c in self._run if new.stamp - self.config.window <= c.stamp <= new.stamp]
        for index in range(len(run) - 1, -1, -1):
            if not self._consistent(run[index], new):
                run = run[index + 1:]
                break
        run.append(new)
        self._run = run[-self.config.consistent_detections:]

    def newest(self) -> tuple[np.ndarray, np.ndarray]:
        """(position, quaternion) of the newest candidate, propagated to the latest IMU time."""
        last = self._run[-1]
        return last.position.copy(), last.quaternion.copy()

    def spread(self) -> tuple[float, float, float]:
        """Largest pairwise position distance [m] and angle [rad] of the run, and its time span [s]."""
        distance = angle = 0.0
        for i, a in enumerate(self._run):
            for b in self._run[i + 1:]:
                distance = max(distance, float(np.linalg.norm(a.position - b.position)))
                angle = max(angle, quat_angle(a.quaternion, b.quaternion))
        span = self._run[-1].stamp - self._run[0].stamp if self._run else 0.0
        return distance, angle, span


