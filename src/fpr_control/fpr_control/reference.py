"""Desired trajectory (q^d, ν^d, ν̇^d) and desired interaction wrench τ^d_e from the teleoperation command
(thesis §4.3.1 (4.25)-(4.26); §3.4 (3.43)-(3.44)).

Decentralized (frame F_Fp): p^d = 0 (unknown position, its error is not used), q^d_p = quat(Ry(ϑ^d) Rx(ϕ^d)),
ν^d = [Fp v^d_p, pω^d_p = D(ϕ_p, ϑ_p) η̇^d, θ̇^d], ν̇^d = [Fp v̇^d_p, Ḋ η̇^d + D η̈^d, 0] with
η̇^d = [ϕ̇^d, ϑ̇^d, ψ̇^d], η̈^d = [0, 0, ψ̈^d] (4.26) and D, Ḋ of (A.78), (A.82) at the current platform roll and
pitch (Ḋ with the desired roll/pitch rates).

Centralized (frame F0, ground truth as motion capture): the command velocities are integrated into a desired
position and yaw, which start at the current pose (:class:`CentralizedReference`). No rclpy here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from fpr_model._validation import all_finite
from fpr_model.rotations import euler_rate_matrix, euler_rate_matrix_dot, euler_zyx_to_quat, rot_z


@dataclass
class TeleopReference:
    """χ_d, χ̇_d and f^d_c of one TeleopCommand (SI units, rad; velocities in F_Fp)."""

    platform_velocity: np.ndarray
    platform_acceleration: np.ndarray
    yaw_rate: float
    yaw_acceleration: float
    roll: float
    roll_rate: float
    pitch: float
    pitch_rate: float
    leg_angles: np.ndarray
    leg_rates: np.ndarray
    contact_force: float = 0.0
    mode: int = 0

    @staticmethod
    def hold(roll: float, pitch: float, leg_angles: np.ndarray) -> TeleopReference:
        """Zero velocities, the given attitude and leg angles (used before any command arrives)."""
        n = len(leg_angles)
        return TeleopReference(np.zeros(3), np.zeros(3), 0.0, 0.0, roll, 0.0, pitch, 0.0,
                               np.array(leg_angles, dtype=float), np.zeros(n))

    def stopped(self) -> TeleopReference:
        """Copy with zero velocities and accelerations (lost command stream): the configuration holds."""
        n = len(self.leg_angles)
        return TeleopReference(np.zeros(3), np.zeros(3), 0.0, 0.0, self.roll, 0.0, self.pitch, 0.0,
                               self.leg_angles.copy(), np.zeros(n), self.contact_force, self.mode)

    def is_finite(self) -> bool:
        return all_finite(self.platform_velocity, self.platform_acceleration, self.leg_angles, self.leg_rates,
                          self.yaw_rate, self.yaw_acceleration, self.roll, self.roll_rate, self.pitch,
                          self.pitch_rate, self.contact_force)


@dataclass
class DesiredTrajectory:
    """q^d (7+n), ν^d (6+n), ν̇^d (6+n) and τ^d_e (6+n) in the controller frame."""

    q: np.ndarray
    nu: np.ndarray
    nu_dot: np.ndarray
    wrench: np.ndarray


def desired_wrench(platform_rotation: np.ndarray, contact_force: float, n: int) -> np.ndarray:
    """τ^d_e = [R_p [0, 0, f^d_c]; 0_3; 0_n] (3.43)-(3.44): push f^d_c [N] along the platform normal +z_p."""
    wrench = np.zeros(6 + n)
    wrench[:3] = platform_rotation[:, 2] * contact_force
    return wrench


def angular_reference(command: TeleopReference, roll: float, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """(4.26): pω^d_p = D η̇^d, pω̇^d_p = Ḋ η̇^d + D η̈^d [rad/s, rad/s²], D at the current roll/pitch."""
    eta_rate = np.array([command.roll_rate, command.pitch_rate, command.yaw_rate])
    eta_acc = np.array([0.0, 0.0, command.yaw_acceleration])
    D = euler_rate_matrix(roll, pitch)
    D_dot = euler_rate_matrix_dot(roll, pitch, command.roll_rate, command.pitch_rate)
    return D @ eta_rate, D_dot @ eta_rate + D @ eta_acc


def decentralized_reference(command: TeleopReference, roll: float, pitch: float,
                            platform_rotation: np.ndarray) -> DesiredTrajectory:
    """(4.25)-(4.26) in F_Fp; ``roll``, ``pitch`` are the current Fp ϕ_p, Fp ϑ_p [rad] and
    ``platform_rotation`` the current F_Fp R_p (for τ^d_e)."""
    n = len(command.leg_angles)
    q_d = np.concatenate([np.zeros(3), euler_zyx_to_quat(command.roll, command.pitch, 0.0), command.leg_angles])
    omega_d, omega_dot_d = angular_reference(command, roll, pitch)
    nu_d = np.concatenate([command.platform_velocity, omega_d, command.leg_rates])
    nu_dot_d = np.concatenate([command.platform_acceleration, omega_dot_d, np.zeros(n)])
    return DesiredTrajectory(q_d, nu_d, nu_dot_d, desired_wrench(platform_rotation, command.contact_force, n))


class CentralizedReference:
    """Desired pose in F0 for the centralized variants: p^d and ψ^d integrate the commanded F_Fp velocity
    and yaw rate (``ṗ^d = Rz(ψ^d) Fp v^d``, ``ψ̇^d`` = command), starting at the pose given to :meth:`reset`."""

    def __init__(self) -> None:
        self.position: np.ndarray | None = None
        self.yaw = 0.0

    def reset(self, position: np.ndarray, yaw: float) -> None:
        self.position = np.array(position, dtype=float)
        self.yaw = float(yaw)

    @property
    def initialized(self) -> bool:
        return self.position is not None

    def step(self, command: TeleopReference, dt: float, roll: float, pitch: float,
             platform_rotation: np.ndarray) -> DesiredTrajectory:
        """Advance p^d, ψ^d by dt [s] and return (q^d, ν^d, ν̇^d, τ^d_e) in F0."""
        if self.position is None:
            raise RuntimeError("CentralizedReference.step before reset")
        yaw_rotation = rot_z(self.yaw)
        velocity = yaw_rotation @ command.platform_velocity
        v = command.platform_velocity
        e_z_cross_v = np.array([-v[1], v[0], 0.0])  # e_z × Fp v^d
        acceleration = yaw_rotation @ (command.platform_acceleration + command.yaw_rate * e_z_cross_v)
        self.position = self.position + velocity * dt
        self.yaw = math.remainder(self.yaw + command.yaw_rate * dt, 2.0 * math.pi)
        n = len(command.leg_angles)
        q_d = np.concatenate([self.position, euler_zyx_to_quat(command.roll, command.pitch, self.yaw),
                              command.leg_angles])
        omega_d, omega_dot_d = angular_reference(command, roll, pitch)
        nu_d = np.concatenate([velocity, omega_d, command.leg_rates])
        nu_dot_d = np.concatenate([acceleration, omega_dot_d, np.zeros(n)])
        return DesiredTrajectory(q_d, nu_d, nu_dot_d, desired_wrench(platform_rotation, command.contact_force, n))
