"""What each PX4 measures and reports: IMU with white noise, a gyro and an accelerometer bias (turn-on draw plus a
random walk advanced in simulation time), attitude and position in the vehicle's OWN local frame F0i (thesis §4.1:
each quadrotor's local ENU frame has an unknown yaw offset ψ0i from the world frame F0 and its origin at the
take-off position). Also the motion capture of the centralized modes (:class:`MotionCapture`) and the delay line
the simulator holds latent measurements in (:class:`DelayLine`).

Frames: F0 world ENU; F0i = F0 rotated by ψ0i about z, origin ``origin_i`` (world); body FLU. Units SI, rad.
Deterministic for a seed: one numpy Generator per UAV, spawned from the scenario seed, for the historical
white noise and constant gyro bias; the realism effects (accelerometer bias, bias random walks, motion capture)
draw from streams of their own, so the ideal profile's samples are unchanged and each effect changes only itself.

IMU model (per axis, body FLU): ``ω_m = ω + b_g + n_g``, ``f_m = f + b_a + n_a``, n ~ N(0, σ²) per sample,
``b(t_k) = b(t_{k−1}) + σ_rw √(t_k − t_{k−1}) ξ_k`` (PX4 EKF2's bias random walk, EKF2_GYR_B_NOISE /
EKF2_ACC_B_NOISE), ``b(0)`` ~ N(0, σ_b²) per UAV.
"""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from fpr_model.parameters import default_parameters
from fpr_model.rotations import quat_conjugate, quat_from_rotvec, quat_multiply, quat_to_rotmat

from fpr_sim.plant import GroundTruth
from fpr_sim.scenario import MotionCaptureConfig, Scenario, SensorConfig, per_uav

__all__ = ["DelayLine", "ImuSample", "MotionCapture", "UavSensors"]


@dataclass
class ImuSample:
    """One sample of UAV i, in its local frame F0i (ENU) and body FLU."""

    quat_local: np.ndarray  #: attitude FLU -> F0i [w,x,y,z] (with attitude noise)
    rate: np.ndarray  #: body rates [rad/s] (noise + bias)
    specific_force: np.ndarray  #: accelerometer, body [m/s²]
    position_local: np.ndarray  #: [m] in F0i
    velocity_local: np.ndarray  #: [m/s] in F0i


class UavSensors:
    """Sensors of all n UAVs (see the module doc)."""

    def __init__(self, scenario: Scenario, origins: np.ndarray, gravity: float | None = None) -> None:
        """``gravity`` [m/s²]: the plant's (None: Table B.1's, fpr_model.parameters)."""
        self.config: SensorConfig = scenario.sensors
        n = scenario.n
        seeds = np.random.SeedSequence(scenario.seed).spawn(n)
        self.rngs = [np.random.default_rng(s) for s in seeds]
        self.gyro_bias = np.array([rng.normal(0.0, self.config.gyro_bias, 3) for rng in self.rngs])
        bias_seeds = np.random.SeedSequence([scenario.seed, 11]).spawn(n)
        #: per UAV: the accelerometer-bias / random-walk stream (apart from the white noise: the ideal stays intact)
        self.bias_rngs = [np.random.default_rng(s) for s in bias_seeds]
        self.accel_bias = np.array([rng.normal(0.0, self.config.accel_bias, 3) if self.config.accel_bias > 0.0
                                    else np.zeros(3) for rng in self.bias_rngs])
        self._bias_time = np.full(n, np.nan)  # [s] instant each UAV's bias was last advanced to
        misalignment_seeds = np.random.SeedSequence([scenario.seed, 17]).spawn(n)
        #: [rad] per UAV: the IMU frame's constant tilt off the thrust axis (body x, y; SensorConfig.imu_misalignment)
        self.imu_misalignment = np.array([
            np.random.default_rng(s).normal(0.0, self.config.imu_misalignment, 3) * np.array([1.0, 1.0, 0.0])
            if self.config.imu_misalignment > 0.0 else np.zeros(3) for s in misalignment_seeds])
        #: per UAV: R(μ_i), IMU frame -> thrust-axis body frame (None: no misalignment)
        self._misalignment_R = ([quat_to_rotmat(quat_from_rotvec(m)) for m in self.imu_misalignment]
                                if self.config.imu_misalignment > 0.0 else None)
        #: per UAV: (exp(δ_i), exp(−δ_i)) of the present attitude-estimate error, or None until computed (a cache: δ_i
        #: changes only with the accelerometer bias; PX4's 250 Hz loop and every sample use it)
        self._estimate_quats: list[tuple[np.ndarray, np.ndarray] | None] = [None] * n
        #: [m/s²] what the accelerometer reads at rest (the plant's gravity)
        self.gravity = float(default_parameters(n).gravity if gravity is None else gravity)
        self.yaw_offsets = np.array([float(per_uav(scenario.px4.yaw_offsets, i)) for i in range(n)])
        self.origins = np.array(origins, dtype=float)
        half = 0.5 * self.yaw_offsets
        #: q_{F0i <- F0}: rotation by −ψ0i about z
        self.world_to_local = np.stack([np.cos(half), np.zeros(n), np.zeros(n), -np.sin(half)], axis=1)
        self.world_to_local_R = quat_to_rotmat(self.world_to_local)

    def advance_biases(self, i: int, t: float) -> None:
        """Random walk of UAV i's gyro and accelerometer biases from their last instant to ``t`` [s] (simulation
        time): ``b += σ_rw √Δt ξ`` (exact for a Wiener process whatever the sampling rate). No-op at 0 densities."""
        c = self.config
        previous, self._bias_time[i] = self._bias_time[i], t
        if not (c.gyro_bias_random_walk > 0.0 or c.accel_bias_random_walk > 0.0) or not np.isfinite(previous):
            return
        dt = t - previous
        if dt <= 0.0:
            return
        xi = self.bias_rngs[i].standard_normal(6)
        self.gyro_bias[i] += c.gyro_bias_random_walk * np.sqrt(dt) * xi[:3]
        self.accel_bias[i] += c.accel_bias_random_walk * np.sqrt(dt) * xi[3:]
        if c.tilt_from_accel_bias > 0.0:
            self._estimate_quats[i] = None  # δ_i follows the accelerometer bias

    def attitude_estimate_error(self, i: int) -> np.ndarray | None:
        """δ_i [rad] (rotation vector in the thrust-axis body frame FLU of the plant) of the attitude UAV i's PX4
        controls and reports, q̂ = q ∘ exp(δ): its IMU frame's misalignment (``imu_misalignment``, constant) plus
        the tilt that the unestimated share ``tilt_from_accel_bias`` of the current accelerometer bias implies (at
        rest the accelerometer reads g û_b + b, û_b the vertical in the body frame; aligning the estimated vertical
        with it tilts the estimate by (b_y, −b_x, 0) / g, first order). None when both are off."""
        c = self.config
        if c.tilt_from_accel_bias <= 0.0 and c.imu_misalignment <= 0.0:
            return None
        bx, by, _ = self.accel_bias[i]
        share = c.tilt_from_accel_bias
        return self.imu_misalignment[i] + np.array([share * by / self.gravity, -share * bx / self.gravity, 0.0])

    def attitude_estimate_quats(self, i: int) -> tuple[np.ndarray, np.ndarray] | None:
        """(exp(δ_i), exp(−δ_i)) as unit quaternions [w, x, y, z] of :meth:`attitude_estimate_error` (None when it is
        off), computed once per value of δ_i."""
        cached = self._estimate_quats[i]
        if cached is None:
            error = self.attitude_estimate_error(i)
            if error is None:
                return None
            forward = quat_from_rotvec(error)
            cached = self._estimate_quats[i] = (forward, quat_conjugate(forward))  # exp(−δ) = conj(exp(δ)), exactly
        return cached

    def sample(self, i: int, quat_world: np.ndarray, rate: np.ndarray, specific_force: np.ndarray,
               position_world: np.ndarray, velocity_world: np.ndarray, t: float | None = None) -> ImuSample:
        """Noisy measurement of UAV i (0-based) from its true state (world ENU, body FLU) at ``t`` [s] (simulation
        time; advances the bias random walk, None: biases as they are)."""
        c = self.config
        if t is not None:
            self.advance_biases(i, float(t))
        rng = self.rngs[i]
        noise_rot = quat_from_rotvec(rng.normal(0.0, c.attitude_noise, 3))
        estimate = self.attitude_estimate_quats(i)
        if estimate is not None:  # PX4 reports its estimate q̂ = q ∘ exp(δ)
            quat_world = quat_multiply(quat_world, estimate[0])
            quat_world = quat_world / np.linalg.norm(quat_world)
        if self._misalignment_R is not None:  # the IMU measures in its own frame: R(μ)ᵀ (body -> IMU)
            rate = self._misalignment_R[i].T @ rate
            specific_force = self._misalignment_R[i].T @ specific_force
        quat_local = quat_multiply(quat_multiply(self.world_to_local[i], quat_world), noise_rot)
        R = self.world_to_local_R[i]
        return ImuSample(
            quat_local=quat_local / np.linalg.norm(quat_local),
            rate=rate + self.gyro_bias[i] + rng.normal(0.0, c.gyro_noise, 3),
            specific_force=specific_force + rng.normal(0.0, c.accel_noise, 3) + self.accel_bias[i],
            position_local=R @ (position_world - self.origins[i]) + rng.normal(0.0, c.position_noise, 3),
            velocity_local=R @ velocity_world + rng.normal(0.0, c.velocity_noise, 3),
        )

    def to_world_attitude(self, i: int, quat_local: np.ndarray) -> np.ndarray:
        """An attitude commanded in F0i expressed in F0: ``q_F0 = q_{F0<-F0i} ∘ q_F0i``."""
        inverse = self.world_to_local[i] * np.array([1.0, -1.0, -1.0, -1.0])
        return quat_multiply(inverse, quat_local)

    def world_to_local_quat(self, i: int, quat_world: np.ndarray) -> np.ndarray:
        """An attitude in F0 expressed in F0i: ``q_F0i = q_{F0i<-F0} ∘ q_F0``."""
        return quat_multiply(self.world_to_local[i], quat_world)


class DelayLine:
    """Items held until their publication time (simulation time [s]): :meth:`push` ``(due, item)``, :meth:`pop_due`
    returns every item due at ``t`` in due order (ties in push order). Latency of cameras and motion capture."""

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, Any]] = []
        self._order = itertools.count()

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, due: float, item: Any) -> None:
        heapq.heappush(self._heap, (float(due), next(self._order), item))

    def pop_due(self, t: float, tolerance: float = 1e-9) -> list[Any]:
        out = []
        while self._heap and self._heap[0][0] <= t + tolerance:
            out.append(heapq.heappop(self._heap)[2])
        return out


class MotionCapture:
    """Motion capture (Vicon / Qualisys / OptiTrack-like) of the whole robot for the centralized modes: see
    :class:`fpr_sim.scenario.MotionCaptureConfig`. :meth:`measure` gives the frame captured now (a noisy copy of the
    ground truth, same instant) or None for a missed frame; disabled, the exact truth. Seeded: one stream for the
    dropouts and one for the noise (so a dropout probability does not change the noise of the frames kept)."""

    def __init__(self, config: MotionCaptureConfig, seed: int) -> None:
        self.config = config
        drop_seed, noise_seed = np.random.SeedSequence([seed, 13]).spawn(2)
        self._drop_rng = np.random.default_rng(drop_seed)
        self._noise_rng = np.random.default_rng(noise_seed)

    @property
    def latency(self) -> float:
        """[s] capture to publication (0 when disabled)."""
        return self.config.latency if self.config.enabled else 0.0

    def measure(self, truth: GroundTruth) -> GroundTruth | None:
        """The motion-capture frame of ``truth`` (world ENU, Fp / body FLU as in GroundTruth); None: dropped."""
        c = self.config
        if not c.enabled:
            return truth
        if c.dropout_probability > 0.0 and self._drop_rng.random() < c.dropout_probability:
            return None
        rng, s = self._noise_rng, truth.state
        n = len(truth.uav_quats)
        # the draws in their historical order (one stream: the same frames as drawing field by field); the n + 1
        # attitude perturbations are then evaluated together
        position = s.position + rng.normal(0.0, c.position_noise, 3)
        platform_rotvec = rng.normal(0.0, c.attitude_noise, 3)
        leg_angles = s.leg_angles + rng.normal(0.0, c.leg_angle_noise, n)
        velocity = s.velocity + rng.normal(0.0, c.velocity_noise, 3)
        rate = s.rate + rng.normal(0.0, c.rate_noise, 3)
        leg_rates = s.leg_rates + rng.normal(0.0, c.rate_noise, n)
        uav_rotvecs = rng.normal(0.0, c.attitude_noise, (n, 3))  # = n draws of 3, UAV after UAV
        uav_positions = truth.uav_positions + rng.normal(0.0, c.position_noise, (n, 3))
        uav_velocities = truth.uav_velocities + rng.normal(0.0, c.velocity_noise, (n, 3))
        quats = _perturb(np.vstack([s.quat, truth.uav_quats]), np.vstack([platform_rotvec, uav_rotvecs]))
        state = replace(s, position=position, quat=quats[0], leg_angles=leg_angles, velocity=velocity, rate=rate,
                        leg_rates=leg_rates)
        return replace(truth, state=state, uav_positions=uav_positions, uav_quats=quats[1:],
                       uav_velocities=uav_velocities)


def _perturb(quats: np.ndarray, rotvecs: np.ndarray) -> np.ndarray:
    """``q ∘ exp(δ)``: small rotations δ (3,) or (m, 3) [rad] about the body axes of the attitudes ``quats`` (4,) or
    (m, 4), renormalised (each row by its own norm, as one quaternion at a time)."""
    out = quat_multiply(quats, quat_from_rotvec(rotvecs))
    if out.ndim == 1:
        return out / np.linalg.norm(out)
    return np.array([row / np.linalg.norm(row) for row in out])
