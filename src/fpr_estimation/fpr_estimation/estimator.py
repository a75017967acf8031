"""On-board estimation pipeline of UAV i (thesis §4.2): detection -> p_T_bi (4.2) -> filter -> reconstruction.

ROS-free core of the ``pose_estimator`` node. Times are in seconds on any monotonic clock (the node uses the ROS
clock, so simulated time works). Inputs:

- :meth:`PoseEstimatorCore.on_imu`: UAV attitude in its local frame F0i and FLU body rate; runs the filter
  prediction (4.10)-(4.13) at the IMU rate;
- :meth:`PoseEstimatorCore.on_velocity`: FLU body linear velocity (for (4.23));
- :meth:`PoseEstimatorCore.on_detection`: the marker pose C_T_M; converted to p_T_bi by (4.2)-(4.3), carried from
  its capture instant to the filter's time (``latency_compensation``, :mod:`.latency`), gated, then used for the
  correction (4.16) (asynchronously, whenever a detection arrives);
- :meth:`PoseEstimatorCore.output`: the 50 Hz snapshot (filtered pose, 1-σ, reconstruction, validity).

Stale: when no detection was accepted for ``stale_timeout`` s the output is flagged invalid, prediction continues.

Safety (issue 12, DESIGN.md §5b; bounds in :class:`~fpr_estimation.gating.InputBounds`):

- implausible IMU samples (NaN/inf, non-unit quaternion, rate or specific force beyond the sensor's range, a
  stamp going back or far in the future) are refused and do not propagate the filter: the next valid sample
  integrates over the gap if it is at most ``max_prediction_step``, otherwise the gap is reported and skipped;
  a gap of ``imu_gap_reset`` or more (the IMU stream died and came back: a restarted bridge, PX4 rebooted)
  resets an initialised filter, which re-initialises from K consistent detections: its relative attitude misses
  an unknown rotation, and a filter that carried on from it flew the restarted UAV into its peers' legs;
- implausible detections (NaN/inf, behind the camera, beyond the camera range, stamped in the future) are refused;
- (re-)initialisation only from K mutually consistent detections (:class:`~fpr_estimation.gating.ConsistentRun`);
  an initialised filter is replaced only after ``min_lost_time`` s without an accepted detection: a
  self-consistent forged burst shorter than that is gated, a real loss of tracking recovers;
- state and covariance are checked for NaN/inf after every predict and correct; a filter that fails is reset and
  re-initialised from the next consistent detections (:meth:`PoseEstimatorCore.output` is None meanwhile).

Every refusal, fallback and return is queued as a :class:`GuardEvent` (:meth:`PoseEstimatorCore.take_events`);
the node logs each as one line through :class:`LogLimiter` (at most one line per kind per interval).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from fpr_model.calibration import VisionCalibration, compose_transforms, invert_transform
from fpr_model.rotations import quat_to_rotmat, rotmat_to_euler_zyx, rotmat_to_quat

from fpr_estimation.ekf import FilterNoise, RelativePoseEKF
from fpr_estimation.gating import (
    ConsistentRun,
    GateConfig,
    GateDecision,
    InputBounds,
    Refusal,
    ReinitConfig,
    check_imu_sample,
    check_marker_pose,
    evaluate_gate,
    is_rotation,
)
from fpr_estimation.latency import AttitudeHistory
from fpr_estimation.mekf import RelativePoseMEKF
from fpr_estimation.reconstruction import LocalReconstruction, leg_anchor, reconstruct_local_state

__all__ = ["EstimatorConfig", "EstimatorOutput", "GuardEvent", "LogLimiter", "PoseEstimatorCore",
           "relative_pose_from_detection"]

FILTER_KINDS = ("ekf", "mekf")
_NAN = float("nan")
#: consecutive gate rejections from which they are a warning (one is an outlier; 5 = 0.25 s at 20 Hz)
PERSISTENT_REJECTIONS = 5


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
    #: MEKF only: the platform's angular velocity as a state (:mod:`.mekf`), also used by the latency compensation
    platform_rate: bool = False
    noise: FilterNoise = field(default_factory=FilterNoise)
    gate: GateConfig = field(default_factory=GateConfig)
    bounds: InputBounds = field(default_factory=InputBounds)  #: plausibility of IMU samples and detections
    reinit: ReinitConfig = field(default_factory=ReinitConfig)  #: when detections may (re-)initialise the filter
    stale_timeout: float = 0.5  #: [s]
    max_prediction_step: float = 0.1  #: [s] longer IMU gaps are not integrated (reported)
    imu_gap_reset: float = 0.5  #: [s] an IMU gap this long resets an initialised filter (0: never)
    #: carry each detection from its capture stamp to the filter's time with the IMU attitudes (:mod:`.latency`);
    #: False: applied as if captured at arrival (the thesis's filter)
    latency_compensation: bool = True
    latency_horizon: float = 0.5  #: [s] IMU attitudes kept; an older detection is applied uncompensated (said)

    def __post_init__(self) -> None:
        if self.filter not in FILTER_KINDS:
            raise ValueError(f"filter: expected one of {FILTER_KINDS}, got {self.filter!r}")
        if not 1 <= self.uav_id <= self.n:
            raise ValueError(f"uav_id must be in 1..{self.n}, got {self.uav_id}")
        if not (self.stale_timeout > 0.0 and self.max_prediction_step > 0.0 and self.platform_radius > 0.0):
            raise ValueError("stale_timeout, max_prediction_step and platform_radius must be positive")
        if not (np.isfinite(self.latency_horizon) and self.latency_horizon > 0.0):
            raise ValueError(f"latency_horizon must be positive and finite, got {self.latency_horizon}")
        if self.imu_gap_reset != 0.0 and not self.imu_gap_reset >= self.max_prediction_step:
            raise ValueError(f"imu_gap_reset must be 0 (never) or >= max_prediction_step "
                             f"({self.max_prediction_step:g} s), got {self.imu_gap_reset}")


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


@dataclass(frozen=True)
class GuardEvent:
    """A refusal, fallback or return of the estimator, to be logged as one line.

    ``kind`` groups events for rate limiting (e.g. ``imu_rate``, ``gate``, ``reinit``); ``level`` is ``info``
    (a return to normal), ``warning`` (a refusal or fallback) or ``error`` (the filter was reset).
    """

    kind: str
    level: str
    message: str


class LogLimiter:
    """At most one line per event kind per ``interval`` [s] of the caller's clock; the next line of that kind
    says how many were suppressed in between (a clock that goes back lets the line through)."""

    def __init__(self, interval: float) -> None:
        self.interval = float(interval)
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def __call__(self, event: GuardEvent, now: float) -> str | None:
        last = self._last.get(event.kind)
        if last is not None and 0.0 <= now - last < self.interval:
            self._suppressed[event.kind] = self._suppressed.get(event.kind, 0) + 1
            return None
        self._last[event.kind] = now
        suppressed = self._suppressed.pop(event.kind, 0)
        if suppressed and last is not None:
            return f"{event.message} [{suppressed} more like this in the last {now - last:.1f} s]"
        return event.message


def _finite(*arrays) -> bool:
    return all(np.isfinite(np.asarray(a, dtype=float)).all() for a in arrays)


class PoseEstimatorCore:
    def __init__(self, config: EstimatorConfig | None = None, calibration: VisionCalibration | None = None) -> None:
        self.config = config if config is not None else EstimatorConfig()
        self.calibration = calibration if calibration is not None else VisionCalibration()
        c = self.config
        limit = c.bounds.max_marker_distance  # no relative position is known worse than the camera's range
        if c.filter == "mekf":
            self.filter: RelativePoseEKF | RelativePoseMEKF = RelativePoseMEKF(c.noise, c.estimate_gyro_bias, limit,
                                                                               c.platform_rate)
        else:
            self.filter = RelativePoseEKF(c.noise, limit)
        self.anchor = leg_anchor(c.platform_radius, c.n, c.uav_id)
        self.candidates = ConsistentRun(c.reinit)
        self.last_imu_time: float | None = None
        self.last_accepted_time: float | None = None
        self.imu_rotation: np.ndarray | None = None
        self.body_rate = np.zeros(3)
        self.body_velocity = np.zeros(3)
        self.rejected_detections = 0  #: rejected by the innovation gate
        self.accepted_detections = 0  #: used for a correction or an initialisation
        self.pending_detections = 0  #: seen while not initialised, before K consistent ones
        self.consecutive_rejections = 0
        self.initialisations = 0  #: first initialisations and re-initialisations
        self.resets = 0  #: filter resets: a non-finite state or covariance, or an IMU gap >= imu_gap_reset
        self._reset_cause = ""  #: why the last reset happened (for the not-initialised line)
        self.imu_gaps = 0  #: IMU gaps longer than max_prediction_step (not integrated)
        self.refused: dict[str, int] = {}  #: refused inputs per kind (imu_rate, detection_distance, ...)
        self.last_gate: GateDecision | None = None
        self.attitudes = AttitudeHistory(c.latency_horizon)  #: the UAV's attitudes, for the latency compensation
        self.compensated_detections = 0  #: carried from their capture stamp to the filter's time
        self.uncompensated_detections = 0  #: older than latency_horizon (applied as captured, said)
        self.last_latency = _NAN  #: [s] filter time − capture stamp of the last compensated detection
        self._refusing = {"imu": 0, "velocity": 0, "detection": 0}  # refused in a row, per input
        self._events: deque[GuardEvent] = deque(maxlen=64)
        self._was_valid = False
        self._valid_once = False

    # -- events ------------------------------------------------------------------------------------------
    def take_events(self) -> list[GuardEvent]:
        """The events queued since the last call (oldest first; at most the last 64 are kept)."""
        events = list(self._events)
        self._events.clear()
        return events

    def _emit(self, kind: str, level: str, message: str) -> None:
        self._events.append(GuardEvent(kind, level, message))

    def _refuse(self, channel: str, refusal: Refusal) -> str:
        self._refusing[channel] += 1
        self.refused[refusal.kind] = self.refused.get(refusal.kind, 0) + 1
        self._emit(refusal.kind, "warning", refusal.reason)
        return refusal.reason

    def _resume(self, channel: str, label: str) -> None:
        count = self._refusing[channel]
        if count:
            self._refusing[channel] = 0
            self._emit(f"{channel}_ok", "info", f"{label} accepted again after {count} refused")

    # -- inputs ------------------------------------------------------------------------------------------
    def on_imu(self, stamp: float, orientation_quat: np.ndarray, body_rate: np.ndarray,
               specific_force: np.ndarray | None = None, now: float | None = None) -> str | None:
        """IMU sample at ``stamp`` [s]: attitude [w, x, y, z] (FLU body -> the UAV's local ENU frame), FLU rate
        [rad/s], FLU specific force [m/s²] (None: not provided); ``now`` [s]: receive time (None: not checked).

        Returns None, or a reason string when the sample was refused or its step not integrated. A refused sample
        changes nothing: the next accepted one integrates from the last accepted stamp.
        """
        refusal = check_imu_sample(self.config.bounds, stamp, orientation_quat, body_rate, specific_force, now,
                                   self.last_imu_time)
        if refusal is not None:
            return self._refuse("imu", refusal)
        self._resume("imu", "IMU samples")
        quaternion = np.asarray(orientation_quat, dtype=float)
        quaternion = quaternion / np.linalg.norm(quaternion)
        self.imu_rotation = quat_to_rotmat(quaternion)
        self.body_rate = np.asarray(body_rate, dtype=float).copy()
        previous, self.last_imu_time = self.last_imu_time, float(stamp)
        if previous is None:
            self.attitudes.add(stamp, quaternion)
            return None
        dt = float(stamp) - previous
        if dt == 0.0:
            return None
        if dt > self.config.max_prediction_step:
            self.imu_gaps += 1
            self.candidates.clear()  # their attitudes cannot be propagated over the gap
            # nor can a detection captured before it be carried over it as the filter was not (latency): start again
            self.attitudes.clear()
            self.attitudes.add(stamp, quaternion)
            reason = (f"IMU gap of {dt:.3g} s (> max_prediction_step {self.config.max_prediction_step:g} s) not "
                      f"integrated: the relative attitude misses that rotation")
            if self.filter.initialized and 0.0 < self.config.imu_gap_reset <= dt:
                self._reset(f"an IMU gap of {dt:.3g} s (>= imu_gap_reset {self.config.imu_gap_reset:g} s)")
                reason += "; filter reset"
            self._emit("imu_gap", "warning", reason)
            return reason
        self.attitudes.add(stamp, quaternion)
        self.candidates.propagate(self.body_rate, dt)
        if self.filter.initialized:
            self.filter.predict(self.body_rate, dt)  # (4.10)-(4.13), (4.15)
            self._check_health("prediction")
        return None

    def on_velocity(self, body_velocity: np.ndarray) -> str | None:
        """FLU body linear velocity [m/s] (for (4.23)). Returns None, or why it was refused."""
        if not _finite(body_velocity):
            return self._refuse("velocity", Refusal("velocity_nan", "velocity with NaN/inf refused"))
        self._resume("velocity", "velocities")
        self.body_velocity = np.asarray(body_velocity, dtype=float).copy()
        return None

    def on_marker(self, stamp: float, position: np.ndarray, quaternion: np.ndarray,
                  capture_stamp: float | None = None) -> GateDecision | str:
        """A marker detection as a message carries it: C_t_M [m] and C_q_M [w, x, y, z] (camera optical frame)."""
        quaternion = np.asarray(quaternion, dtype=float)
        norm = float(np.linalg.norm(quaternion)) if _finite(quaternion) else _NAN
        if not abs(norm - 1.0) <= self.config.bounds.max_quaternion_norm_error:
            return self._refuse("detection", Refusal("detection_quaternion",
                                                     f"detection quaternion with norm {norm:.4g} refused"))
        camera_T_marker = np.eye(4)
        camera_T_marker[:3, :3] = quat_to_rotmat(quaternion / norm)
        camera_T_marker[:3, 3] = position
        return self.on_detection(stamp, camera_T_marker, capture_stamp)

    def on_detection(self, stamp: float, camera_T_marker: np.ndarray,
                     capture_stamp: float | None = None) -> GateDecision | str:
        """A marker detection C_T_M (4×4, m) received at ``stamp`` [s] (the filter's time), captured at
        ``capture_stamp`` [s] (None: unknown). Returns the gate decision, or a reason string if refused."""
        if not _finite(stamp):
            return self._refuse("detection", Refusal("detection_nan", "detection with a NaN/inf stamp refused"))
        refusal = check_marker_pose(self.config.bounds, np.asarray(camera_T_marker, dtype=float), capture_stamp,
                                    float(stamp))
        if refusal is not None:
            return self._refuse("detection", refusal)
        platform_T_body = relative_pose_from_detection(camera_T_marker, self.calibration)
        return self.on_relative_pose(stamp, platform_T_body, capture_stamp)

    def on_relative_pose(self, stamp: float, platform_T_body: np.ndarray,
                         capture_stamp: float | None = None) -> GateDecision | str:
        """A measured p_T_bi (4×4) (from (4.2), or MOCAP-emulated as in thesis §4.4.1) received at ``stamp`` [s],
        captured at ``capture_stamp`` [s] (None: at ``stamp``, no compensation).

        With ``latency_compensation`` the relative attitude is first carried from the capture stamp to the filter's
        time (the last IMU stamp) by the UAV's rotation in between (:mod:`.latency`; (4.10)-(4.13)'s model).

        Not initialised: the detection joins the consistent run and initialises the filter once the run holds K
        (the decision is then accepted, else not accepted with NaN errors). Initialised: gated, then the
        correction (4.14)-(4.16); a rejected detection joins the run, which re-initialises the filter only after
        ``reinit.min_lost_time`` s without an accepted detection.
        """
        platform_T_body = np.asarray(platform_T_body, dtype=float)
        if not _finite(stamp, platform_T_body):
            return self._refuse("detection", Refusal("detection_nan", "relative pose with NaN/inf refused"))
        if not is_rotation(platform_T_body[:3, :3]):
            return self._refuse("detection", Refusal("detection_rotation",
                                                     "relative pose whose orientation is not a rotation refused"))
        self._resume("detection", "detections")
        stamp = float(stamp)
        position = platform_T_body[:3, 3].copy()
        rotation = platform_T_body[:3, :3]
        if self.config.latency_compensation and capture_stamp is not None and _finite(capture_stamp):
            rotation = self._compensate_latency(float(capture_stamp), rotation)
        quaternion = rotmat_to_quat(rotation)
        if not self.filter.initialized:
            self.candidates.add(stamp, position, quaternion)
            if self.candidates.ready:
                return self._initialise(stamp, None)
            self.pending_detections += 1
            self.last_gate = GateDecision(False, _NAN, _NAN, _NAN)
            return self.last_gate
        innovation, minimal, S = self.filter.innovation(position, quaternion)
        decision = evaluate_gate(self.config.gate, minimal, S, self.lost_time(stamp))
        self.last_gate = decision
        if decision.accepted:
            try:
                self.filter.correct(innovation)  # (4.16)
            except np.linalg.LinAlgError:
                self.filter.P[:] = np.nan  # reported and reset just below
            if not self._check_health("correction"):
                self.last_gate = GateDecision(False, decision.position_error, decision.angle_error,
                                              decision.mahalanobis)
                return self.last_gate
            self.candidates.clear()
            self.consecutive_rejections = 0
            self._accept(stamp)
            return decision
        self.candidates.add(stamp, position, quaternion)
        lost = self.lost_time(stamp)
        reinit = self.config.reinit
        if self.candidates.ready and lost >= reinit.min_lost_time:
            return self._initialise(stamp, decision)
        self.rejected_detections += 1
        self.consecutive_rejections += 1
        # an isolated rejection is the gate doing its job (outliers, noise): INFO; a run of them means the filter no
        # longer follows the detections (camera calibration, a forged stream, a lock-out): WARN
        persistent = self.consecutive_rejections >= PERSISTENT_REJECTIONS
        self._emit("gate_persistent" if persistent else "gate", "warning" if persistent else "info",
                   f"detection rejected by the gate: {100 * decision.position_error:.1f} cm, "
                   f"{math.degrees(decision.angle_error):.1f} deg from the prediction (rejected "
                   f"{self.rejected_detections}; no accepted detection for {lost:.2f} s; re-initialisation needs "
                   f"{reinit.min_lost_time:g} s of that and {reinit.consistent_detections} consistent detections, "
                   f"{len(self.candidates)} now)")
        return decision

    def _compensate_latency(self, capture_stamp: float, rotation: np.ndarray) -> np.ndarray:
        """``p_R_bi(t) = p_R_bi(t_c) · Δ`` with Δ the UAV's rotation from the capture ``t_c`` to the filter's time
        ``t`` (:meth:`.AttitudeHistory.rotation_since`); the position is kept (ṗ = 0, (4.10)). With the MEKF's
        platform-rate state, the platform's rotation over ``t − t_c`` at the estimated rate is carried too:
        ``p_R_bi(t) = Exp(−w (t − t_c)) p_R_bi(t_c) Δ`` (the position still kept: the leg turns with the platform)."""
        latest = self.attitudes.latest_stamp
        if latest is None:  # no IMU attitude yet: the filter has no time of its own to carry the detection to
            return rotation
        delta = self.attitudes.rotation_since(capture_stamp)
        if delta is None:
            self.uncompensated_detections += 1
            age = latest - capture_stamp
            horizon = self.config.latency_horizon
            why = (f"more than latency_horizon {horizon:g} s" if age > horizon else
                   f"before the oldest IMU attitude kept, {latest - self.attitudes.oldest_stamp:.3f} s of history: "
                   "the IMU stream started or resumed after the capture")
            self._emit("latency", "warning",
                       f"detection captured {age:.3f} s before the filter's time ({why}): applied without latency "
                       f"compensation ({self.uncompensated_detections} so far)")
            return rotation
        self.compensated_detections += 1
        self.last_latency = max(latest - capture_stamp, 0.0)
        rotation = rotation @ delta
        if isinstance(self.filter, RelativePoseMEKF) and self.filter.estimate_platform_rate and self.filter.initialized:
            rotation = self.filter.platform_rotation(self.last_latency).T @ rotation
        return rotation

    def lost_time(self, stamp: float) -> float:
        """[s] since the last accepted detection at ``stamp`` (inf if none was ever accepted)."""
        if self.last_accepted_time is None:
            return math.inf
        return max(float(stamp) - self.last_accepted_time, 0.0)

    def _initialise(self, stamp: float, decision: GateDecision | None) -> GateDecision:
        """(Re-)initialise from the newest detection of the consistent run (P₀ = R)."""
        distance, angle, span = self.candidates.spread()
        count = len(self.candidates)
        position, quaternion = self.candidates.newest()
        lost = self.lost_time(stamp)
        was_initialised = self.filter.initialized
        self.filter.initialize(position, quaternion)
        self.candidates.clear()
        self.consecutive_rejections = 0
        self.initialisations += 1
        consistent = (f"{count} consistent detections (within {100 * distance:.1f} cm, {math.degrees(angle):.1f} deg "
                      f"over {span:.2f} s)")
        if was_initialised:
            message = f"re-initialised from {consistent} after {lost:.2f} s without an accepted detection"
        elif self.resets:
            message = f"initialised again after the reset from {consistent}"
        else:
            message = f"initialised from {consistent}"
        self._emit("init", "info", message)
        self._accept(stamp)
        if decision is None:
            decision = GateDecision(True, _NAN, _NAN, _NAN, initialised=True)
        else:
            decision = GateDecision(True, decision.position_error, decision.angle_error, decision.mahalanobis,
                                    initialised=True)
        self.last_gate = decision
        return decision

    def _check_health(self, step: str) -> bool:
        """After each predict / correct: reset the filter if its state or covariance is not finite."""
        if self.filter.is_healthy():
            return True
        self._reset(f"a non-finite state or covariance after the {step}", level="error")
        return False

    def _reset(self, cause: str, level: str = "warning") -> None:
        """Forget the filter (and the candidates): it re-initialises from K consistent detections; said once."""
        self.filter.reset()
        self.candidates.clear()
        self.resets += 1
        self._reset_cause = cause
        self._emit("reset", level,
                   f"filter reset after {cause}: local_state not published until it re-initialises from "
                   f"{self.config.reinit.consistent_detections} consistent detections")

    def _accept(self, stamp: float) -> None:
        self.accepted_detections += 1
        self.last_accepted_time = float(stamp) if self.last_accepted_time is None else max(
            self.last_accepted_time, float(stamp))

    # -- output ------------------------------------------------------------------------------------------
    def output(self, stamp: float) -> EstimatorOutput | None:
        """Snapshot at ``stamp`` [s]; None while the filter is not initialised (before K consistent detections,
        or after a reset): the node then publishes nothing, and the controller's local_state timeout applies."""
        if not self.filter.initialized:
            # before the first initialisation this is the normal start-up (INFO, issue 14); after a reset it is not
            if self.resets:
                self._emit("not_initialised", "warning",
                           f"filter reset after {self._reset_cause}: local_state not published until "
                           f"{self.config.reinit.consistent_detections} consistent detections "
                           f"({len(self.candidates)} so far); check the IMU and camera inputs")
            elif self.initialisations == 0:
                self._emit("not_initialised", "info",
                           f"waiting for the marker (start-up): local_state published after "
                           f"{self.config.reinit.consistent_detections} consistent detections "
                           f"({len(self.candidates)} so far)")
            self._was_valid = False
            return None
        age = self.lost_time(stamp)
        position = self.filter.position
        quaternion = self.filter.quaternion
        covariance = self.filter.pose_covariance()
        stddev = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
        reconstruction = None
        if self.imu_rotation is not None:
            reconstruction = reconstruct_local_state(position, quat_to_rotmat(quaternion), self.anchor,
                                                     self.imu_rotation, self.body_velocity)
        valid = bool(age <= self.config.stale_timeout and _finite(position, quaternion))
        if self._was_valid and not valid:
            self._emit("stale", "warning",
                       f"estimate stale: no accepted detection for {age:.2f} s (stale_timeout "
                       f"{self.config.stale_timeout:g} s): local_state valid = false, prediction continues")
        elif valid and not self._was_valid and self._valid_once:
            self._emit("valid", "info", f"estimate valid again: last accepted detection {age:.2f} s old")
        self._was_valid = valid
        self._valid_once = self._valid_once or valid
        return EstimatorOutput(float(stamp), position, quaternion, stddev, age, valid,
                               self.rejected_detections, reconstruction, self.body_rate.copy())

    @staticmethod
    def euler_of(quaternion: np.ndarray) -> tuple[float, float, float]:
        """ZYX (roll, pitch, yaw) of a quaternion [rad] (for reports)."""
        return rotmat_to_euler_zyx(quat_to_rotmat(quaternion))
