"""Synthetic FPR scenes for tests and benchmarks: true UAV poses relative to the platform. ROS-free.

The UAV attitude follows the thesis's setpoint rule (3.36)-(3.38): body z along the thrust direction, body x at
the yaw constant β from the leg (3.37). The thrust direction is taken as the world vertical tilted towards the
platform by ``tilt`` rad (the hover attitude: the compressed leg pushes the UAV outwards; a quasi-static estimate
from Table B.1 gives ≈ 5° at θ = 45° and ≈ 1.5° at θ = 75°, see :func:`hover_tilt`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from fpr_model.calibration import make_transform
from fpr_model.geometry import desired_uav_rotation, inverse_geometric_model, make_configuration
from fpr_model.parameters import FprParameters
from fpr_model.rotations import euler_zyx_to_quat, quat_to_rotmat

__all__ = ["SimulatedSequence", "hover_tilt", "simulate_sequence", "uav_pose_in_platform", "uav_world_rotation"]


def hover_tilt(params: FprParameters, leg_angle: float) -> float:
    """Quasi-static inward tilt of a hovering UAV [rad] for a flat platform and equal leg angles.

    Moment balance of leg i about its revolute axis, with the leg tip carrying the platform share
    ``F_z = (m_p/n + m_l) g``: the radial tip force is ``F_r = −cot θ (F_z − m_l g s_l/l)``; the thrust is
    ``m_b g ẑ − F`` so ``tilt = atan(|F_r| / (m_b g + F_z))``. An estimate for building test scenes only.
    """
    g = params.gravity
    f_z = (params.platform_mass / params.n + params.leg_mass) * g
    f_r = (f_z - params.leg_mass * g * params.leg_com[0] / params.leg_length) / np.tan(leg_angle)
    m_b = float(np.mean(params.uav_masses))
    return float(np.arctan2(abs(f_r), m_b * g + f_z))


def uav_world_rotation(leg_direction: np.ndarray, thrust_direction: np.ndarray, beta: float) -> np.ndarray:
    """``R_i^d = [x, z × x, z]`` (3.38) with ``z = thrust_direction``, ``x = AxisAngle(z, β − π/2)(l × z)`` (3.37)."""
    return desired_uav_rotation(thrust_direction, leg_direction, beta)


def uav_pose_in_platform(params: FprParameters, leg_angles, platform_roll: float = 0.0,
                         platform_pitch: float = 0.0, platform_yaw: float = 0.0,
                         tilt: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """True ``p_T_bi`` (n, 4, 4), the world rotations R_i (n, 3, 3) and the platform rotation R_p (3, 3).

    Platform at the origin with ZYX angles (roll, pitch, yaw); UAV positions from the IGM (2.5)-(2.9);
    attitudes from (3.37)-(3.38) with the thrust tilted towards the platform by ``tilt`` (default
    :func:`hover_tilt` of the mean leg angle).
    """
    leg_angles = np.asarray(leg_angles, dtype=float)
    quat_p = euler_zyx_to_quat(platform_roll, platform_pitch, platform_yaw)
    q = make_configuration(np.zeros(3), quat_p, leg_angles)
    positions = inverse_geometric_model(params, q)
    R_p = quat_to_rotmat(quat_p)
    if tilt is None:
        tilt = hover_tilt(params, float(np.mean(leg_angles)))
    poses = np.zeros((params.n, 4, 4))
    rotations = np.zeros((params.n, 3, 3))
    for i in range(params.n):
        alpha = 2.0 * np.pi * i / params.n
        anchor = R_p @ (params.platform_radius * np.array([np.cos(alpha), np.sin(alpha), 0.0]))
        leg = positions[i] - anchor
        leg /= np.linalg.norm(leg)
        inward = -leg.copy()
        inward[2] = 0.0
        inward /= np.linalg.norm(inward)
        thrust = np.array([0.0, 0.0, 1.0]) * np.cos(tilt) + inward * np.sin(tilt)
        rotations[i] = uav_world_rotation(leg, thrust, params.joint_offset_angle)
        poses[i] = make_transform(R_p.T @ rotations[i], R_p.T @ positions[i])
    return poses, rotations, R_p


# --------------------------------------------------------------------------------------------------------
# Simulated estimation sequence (true relative pose, gyro, detections)
# --------------------------------------------------------------------------------------------------------
@dataclass
class SimulatedSequence:
    """A relative-pose run: truth sampled at the IMU rate, gyro samples, and detections.

    imu_times (N,), true_positions (N, 3), true_quats (N, 4), gyro (N, 3) [rad/s, FLU];
    detection_times (M,), detection_poses (M, 4, 4) noisy p_T_b, detection_is_outlier (M,) bool.
    """

    imu_times: np.ndarray
    true_positions: np.ndarray
    true_quats: np.ndarray
    gyro: np.ndarray
    detection_times: np.ndarray
    detection_poses: np.ndarray
    detection_is_outlier: np.ndarray
    gyro_bias: np.ndarray


def simulate_sequence(duration: float = 60.0, seed: int = 0, imu_rate: float = 200.0,
                      detection_rate: float = 20.0, position_sigma: float = 0.02,
                      angle_sigma: float = float(np.radians(2.0)), drop_rate: float = 0.10,
                      outlier_rate: float = 0.02, outlier_offset: float = 0.20,
                      gyro_noise: float = 0.005, gyro_bias_max: float = 0.02,
                      initial_pose: np.ndarray | None = None) -> SimulatedSequence:
    """Smooth true relative motion around ``initial_pose`` (default: UAV 1 at θ = 60°, flat platform):
    position sinusoids of a few cm (leg angles and platform moving), body rate a sum of sinusoids
    (≈ 0.3 rad/s) integrated exactly; gyro = rate + constant bias (|b_k| ≤ gyro_bias_max) + white noise;
    detections at ``detection_rate`` with Gaussian noise (σ per axis), ``drop_rate`` dropped and
    ``outlier_rate`` replaced by a pose ``outlier_offset`` m away in a random direction."""
    from fpr_model.parameters import default_parameters
    from fpr_model.rotations import quat_from_rotvec, quat_multiply, rotmat_to_quat

    rng = np.random.default_rng(seed)
    if initial_pose is None:
        initial_pose = uav_pose_in_platform(default_parameters(), [np.radians(60.0)] * 3)[0][0]
    n_imu = int(round(duration * imu_rate)) + 1
    times = np.arange(n_imu) / imu_rate
    # Position: the leg angle and the platform move a little (a few cm, periods of seconds).
    amplitude = np.array([0.04, 0.03, 0.05])
    frequency = rng.uniform(0.1, 0.3, 3)
    phase = rng.uniform(0.0, 2.0 * np.pi, 3)
    positions = initial_pose[:3, 3] + amplitude * np.sin(2.0 * np.pi * frequency * times[:, None] + phase)
    # Body rate: sums of sinusoids, bounded attitude excursions.
    rate_amp = rng.uniform(0.15, 0.3, (2, 3))
    rate_freq = rng.uniform(0.2, 1.0, (2, 3))
    rate_phase = rng.uniform(0.0, 2.0 * np.pi, (2, 3))
    rates = sum(rate_amp[k] * np.sin(2.0 * np.pi * rate_freq[k] * times[:, None] + rate_phase[k])
                for k in range(2))
    quats = np.zeros((n_imu, 4))
    quats[0] = rotmat_to_quat(initial_pose[:3, :3])
    dt = 1.0 / imu_rate
    for k in range(1, n_imu):
        # midpoint rate over the step (the true motion is smooth)
        mid = 0.5 * (rates[k - 1] + rates[k])
        q = quat_multiply(quats[k - 1], quat_from_rotvec(mid * dt))
        quats[k] = q / np.linalg.norm(q)
    bias = rng.uniform(-gyro_bias_max, gyro_bias_max, 3)
    gyro = rates + bias + rng.normal(0.0, gyro_noise, rates.shape)
    # Detections.
    step = int(round(imu_rate / detection_rate))
    det_times, det_poses, det_outlier = [], [], []
    for k in range(step, n_imu, step):
        if rng.random() < drop_rate:
            continue
        position = positions[k] + rng.normal(0.0, position_sigma, 3)
        rotation = quat_to_rotmat(quat_multiply(quats[k], quat_from_rotvec(rng.normal(0.0, angle_sigma, 3))))
        outlier = bool(rng.random() < outlier_rate)
        if outlier:
            direction = rng.normal(size=3)
            position = positions[k] + outlier_offset * direction / np.linalg.norm(direction)
        det_times.append(times[k])
        det_poses.append(make_transform(rotation, position))
        det_outlier.append(outlier)
    return SimulatedSequence(times, positions, quats, gyro, np.array(det_times), np.array(det_poses),
                             np.array(det_outlier, dtype=bool), bias)
