"""Emulated relative pose of a contact target (thesis §4.4.2 Scenario II, l.7049-7068), what the simulator
publishes on ``/fpr/target`` for the approach law (4.39) (fpr_control.target_approach). ROS-free.

The thesis emulated the target's pose relative to the platform from motion capture: Fp p_t, the target position
relative to the platform centre in the flat platform frame F_Fp, and Fp ψ_t, the target's yaw relative to
F_Fp. F_Fp has its origin at the platform centre P, z up, and the platform's yaw only: with the platform
attitude R_p = Rz(ψ_p) Ry(ϑ_p) Rx(ϕ_p) (ZYX, A.72), F_Fp = Rz(ψ_p), so

    Fp p_t = Rz(ψ_p)ᵀ (p_t − P),    Fp ψ_t = wrap(ψ_t − ψ_p) ∈ (−π, π],

and the orientation sent is the rotation about z by Fp ψ_t. Noise (scenario ``target``): Gaussian, 1σ
``position_noise`` per axis of Fp p_t and ``yaw_noise`` on Fp ψ_t (the thesis's emulated MOCAP poses: 2 cm,
2°, l.6604-6608), drawn from ``SeedSequence([scenario.seed, TARGET_SEED_STREAM])``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from fpr_model.rotations import quat_to_euler_zyx

from fpr_sim.scenario import TargetConfig

__all__ = ["TARGET_FRAME", "TARGET_SEED_STREAM", "RelativeTargetPose", "TargetEmulator", "platform_yaw",
           "relative_target_pose", "wrap_angle"]

#: frame_id of /fpr/target (F_Fp), as fpr_control.target_approach expects
TARGET_FRAME = "flat_platform"
#: noise stream of the target emulation (the cameras use 7, the fan's turbulence 11)
TARGET_SEED_STREAM = 12


def wrap_angle(angle: float) -> float:
    """``angle`` [rad] wrapped to (−π, π]."""
    wrapped = math.remainder(float(angle), 2.0 * math.pi)
    return wrapped + 2.0 * math.pi if wrapped <= -math.pi else wrapped


def platform_yaw(quat) -> float:
    """ψ_p [rad]: the ZYX yaw of the platform attitude ``quat`` [w, x, y, z] (Fp → F0), A.72 / erratum E15."""
    return float(quat_to_euler_zyx(np.asarray(quat, dtype=float))[2])


@dataclass
class RelativeTargetPose:
    """The target seen from the platform, in F_Fp: ``position`` Fp p_t (3,) [m], ``yaw`` Fp ψ_t [rad] in
    (−π, π], ``quat`` [w, x, y, z] the rotation about z by ``yaw``."""

    position: np.ndarray
    yaw: float
    quat: np.ndarray


def _yaw_quat(yaw: float) -> np.ndarray:
    return np.array([math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)])


def relative_target_pose(platform_position, platform_quat, target_position, target_yaw: float) -> RelativeTargetPose:
    """Exact Fp p_t and Fp ψ_t (module doc) of a target at ``target_position`` [m] (F0) with yaw ``target_yaw``
    [rad] (F0), for a platform at ``platform_position`` [m] (F0) with attitude ``platform_quat`` [w, x, y, z]."""
    psi = platform_yaw(platform_quat)
    c, s = math.cos(psi), math.sin(psi)
    d = np.asarray(target_position, dtype=float) - np.asarray(platform_position, dtype=float)
    position = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]])  # Rz(ψ_p)ᵀ d
    yaw = wrap_angle(float(target_yaw) - psi)
    return RelativeTargetPose(position, yaw, _yaw_quat(yaw))


class TargetEmulator:
    """The noisy relative target pose of scenario ``target`` (module doc); deterministic for a seed."""

    def __init__(self, config: TargetConfig, seed: int) -> None:
        self.config = config
        self.position = np.asarray(config.position, dtype=float)
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), TARGET_SEED_STREAM]))

    def measure(self, platform_position, platform_quat) -> RelativeTargetPose:
        """One noisy sample for the platform's true pose (position [m] and attitude [w, x, y, z], F0)."""
        exact = relative_target_pose(platform_position, platform_quat, self.position, self.config.yaw)
        position = exact.position + self.rng.normal(0.0, self.config.position_noise, 3)
        yaw = wrap_angle(exact.yaw + self.rng.normal(0.0, self.config.yaw_noise))
        return RelativeTargetPose(position, yaw, _yaw_quat(yaw))
