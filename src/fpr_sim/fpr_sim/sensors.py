"""What each PX4 measures and reports: IMU with noise and a constant gyro bias, attitude and position in the
vehicle's OWN local frame F0i (thesis §4.1: each quadrotor's local ENU frame has an unknown yaw offset ψ0i from
the world frame F0 and its origin at the take-off position).

Frames: F0 world ENU; F0i = F0 rotated by ψ0i about z, origin ``origin_i`` (world); body FLU. Units SI, rad.
Deterministic for a seed: one numpy Generator per UAV, spawned from the scenario seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from fpr_model.rotations import quat_from_rotvec, quat_multiply, quat_to_rotmat

from fpr_sim.scenario import Scenario, SensorConfig, per_uav

__all__ = ["ImuSample", "UavSensors"]


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

    def __init__(self, scenario: Scenario, origins: np.ndarray) -> None:
        self.config: SensorConfig = scenario.sensors
        n = scenario.n
        seeds = np.random.SeedSequence(scenario.seed).spawn(n)
        self.rngs = [np.random.default_rng(s) for s in seeds]
        self.gyro_bias = np.array([rng.normal(0.0, self.config.gyro_bias, 3) for rng in self.rngs])
        self.yaw_offsets = np.array([float(per_uav(scenario.px4.yaw_offsets, i)) for i in range(n)])
        self.origins = np.array(origins, dtype=float)
        half = 0.5 * self.yaw_offsets
        #: q_{F0i <- F0}: rotation by −ψ0i about z
        self.world_to_local = np.stack([np.cos(half), np.zeros(n), np.zeros(n), -np.sin(half)], axis=1)
        self.world_to_local_R = quat_to_rotmat(self.world_to_local)

    def sample(self, i: int, quat_world: np.ndarray, rate: np.ndarray, specific_force: np.ndarray,
               position_world: np.ndarray, velocity_world: np.ndarray) -> ImuSample:
        """Noisy measurement of UAV i (0-based) from its true state (world ENU, body FLU)."""
        c = self.config
        rng = self.rngs[i]
        noise_rot = quat_from_rotvec(rng.normal(0.0, c.attitude_noise, 3))
        quat_local = quat_multiply(quat_multiply(self.world_to_local[i], quat_world), noise_rot)
        R = self.world_to_local_R[i]
        return ImuSample(
            quat_local=quat_local / np.linalg.norm(quat_local),
            rate=rate + self.gyro_bias[i] + rng.normal(0.0, c.gyro_noise, 3),
            specific_force=specific_force + rng.normal(0.0, c.accel_noise, 3),
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
