"""Relative-pose EKF of thesis §4.2.2, (4.4)-(4.16). ROS-free.

State (4.4): ``x = [p_p_i (3), p_q_i (4)]``, the UAV body (FLU) position [m] and attitude quaternion
``[w, x, y, z]`` in the platform frame Fp (``p_R_i`` maps body to platform coordinates).

Prediction (4.10)-(4.13) at the gyro rate, with the hypotheses of the thesis (ṗ = 0; the relative attitude moves
with the UAV's body rate ``bi_ω_i`` only):
``q_k = (I₄ + Ω(ω) T_s) q_{k−1}``, ``Ω(ω) = ½ [[0, −ωᵀ], [ω, −[ω]×]]`` (4.8) (= ½·Q̄([0, ω]), the right
product matrix (A.54)), ``F = blockdiag(I₃, I₄ + Ω T_s)`` (4.13), ``P' = F P Fᵀ + Q`` (4.15).
Correction (4.14)-(4.16): direct measurement ``h(x) = x``, H = I₇, ``K = P'(P' + R)⁻¹``, ``x = x' + K(z − x')``,
``P = (I − K) P'``, asynchronous (whenever a detection arrives). The measured quaternion is sign-aligned with the
prediction first (q and −q are one attitude); the quaternion is renormalised after every step, as in the thesis.

Noise (from YAML): Q = diag(σ_p² T_s I₃, σ_q² T_s I₄) with random-walk densities; R = diag(σ_pm² I₃, σ_qm² I₄),
σ_qm = ½·(angle σ) since a small rotation δθ changes the quaternion by ≈ δθ/2.

Robustness (issue 12): the variances are capped at the state's physical range after each prediction
(:func:`limit_variances`), and :meth:`RelativePoseEKF.is_healthy` checks state and covariance for NaN/inf after
each step; the estimator resets a filter that fails it (:meth:`RelativePoseEKF.reset`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from fpr_model.rotations import quat_multiply, quat_normalize, quat_right_matrix, quat_to_rotvec

__all__ = ["FilterNoise", "RelativePoseEKF", "limit_variances", "quaternion_to_body_error_jacobian"]


@dataclass(frozen=True)
class FilterNoise:
    """Process and measurement noise (SI). Densities are per √s; measurement sigmas per axis."""

    position_random_walk: float = 0.05  #: [m/√s] unmodelled relative motion (leg angles, platform)
    attitude_random_walk: float = 0.1  #: [rad/√s] gyro noise + platform rotation (README "Tuning")
    gyro_bias_random_walk: float = 0.002  #: [rad/s/√s] (MEKF with bias estimation only)
    initial_gyro_bias_sigma: float = 0.02  #: [rad/s] (MEKF with bias estimation only)
    measurement_position_sigma: float = 0.02  #: [m] per axis
    measurement_angle_sigma: float = float(np.radians(2.0))  #: [rad] per axis
    #: MEKF with the platform-rate state only: density of its Gauss-Markov process [rad/s/√s], its time constant
    #: [s] and its initial 1-σ [rad/s] (steady-state 1-σ = density · √(τ/2))
    platform_rate_random_walk: float = 1.0
    platform_rate_time_constant: float = 1.0
    initial_platform_rate_sigma: float = 0.3

    def __post_init__(self) -> None:
        for name in ("position_random_walk", "attitude_random_walk", "gyro_bias_random_walk",
                     "initial_gyro_bias_sigma", "measurement_position_sigma", "measurement_angle_sigma",
                     "platform_rate_random_walk", "platform_rate_time_constant", "initial_platform_rate_sigma"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"{name}: must be positive and finite, got {value}")


def limit_variances(P: np.ndarray, limit: np.ndarray) -> None:
    """Cap the variances of P in place at ``limit`` by the congruence ``P ← D P D``, ``D = diag(min(1, √(limit /
    P_kk)))``: P stays symmetric positive semi-definite and correlations are kept. The prediction (4.15) without
    corrections grows P without bound (and (I₄ + Ω T_s) is not orthogonal, so the quaternion block grows
    geometrically); an uncertainty beyond the physical range of the state carries no information."""
    diagonal = np.diag(P)
    if not (diagonal > limit).any() or not np.isfinite(diagonal).all():  # non-finite: for is_healthy() to report
        return
    scale = np.sqrt(np.minimum(1.0, limit / np.maximum(diagonal, np.finfo(float).tiny)))
    P *= scale[:, None]
    P *= scale[None, :]


def quaternion_to_body_error_jacobian(q: np.ndarray) -> np.ndarray:
    """G (3×4) with ``δθ_body ≈ G δq`` at the unit quaternion q: ``δθ = 2·vec(q̄ ∘ δq)``, from (A.83)."""
    w, x, y, z = q
    return 2.0 * np.array([[-x, w, z, -y], [-y, -z, w, x], [-z, y, -x, w]])


class RelativePoseEKF:
    """The additive quaternion EKF (4.9)-(4.16). Call :meth:`initialize` first."""

    name = "ekf"

    def __init__(self, noise: FilterNoise | None = None, position_sigma_limit: float = 2.0) -> None:
        """``position_sigma_limit`` [m]: cap of the 1-σ of each position axis (see :func:`limit_variances`)."""
        self.noise = noise if noise is not None else FilterNoise()
        n = self.noise
        self._R = np.diag([n.measurement_position_sigma ** 2] * 3 + [(0.5 * n.measurement_angle_sigma) ** 2] * 4)
        self._q_density = np.array([n.position_random_walk ** 2] * 3 + [(0.5 * n.attitude_random_walk) ** 2] * 4)
        # Variance caps: position from the camera range, quaternion components (|q_k| <= 1) at 1.
        self._variance_limit = np.array([float(position_sigma_limit) ** 2] * 3 + [1.0] * 4)
        self.reset()

    def reset(self) -> None:
        """Back to "not initialised" (after a non-finite state): the next :meth:`initialize` starts again."""
        self.x = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
        self.P = np.eye(7)
        self.initialized = False

    def is_healthy(self) -> bool:
        """State and covariance finite, variances non-negative (checked after every predict and correct)."""
        return bool(np.isfinite(self.x).all() and np.isfinite(self.P).all() and (np.diag(self.P) >= 0.0).all())

    # -- state access ------------------------------------------------------------------------------------
    @property
    def position(self) -> np.ndarray:
        return self.x[:3].copy()

    @property
    def quaternion(self) -> np.ndarray:
        return self.x[3:].copy()

    def pose_covariance(self) -> np.ndarray:
        """6×6 covariance of ``[p, δθ_body]`` (quaternion block mapped by :func:`quaternion_to_body_error_jacobian`)."""
        G = np.zeros((6, 7))
        G[:3, :3] = np.eye(3)
        G[3:, 3:] = quaternion_to_body_error_jacobian(self.x[3:])
        return G @ self.P @ G.T

    # -- filter ------------------------------------------------------------------------------------------
    def initialize(self, position: np.ndarray, quaternion: np.ndarray) -> None:
        """Start from a measurement, with P₀ = R (the measurement's own uncertainty)."""
        self.x = np.concatenate([np.asarray(position, dtype=float), quat_normalize(quaternion)])
        self.P = self._R.copy()
        self.initialized = True

    def predict(self, body_rate: np.ndarray, dt: float) -> None:
        """(4.10)-(4.13), (4.15): one prediction step with the UAV body rate ω [rad/s] (FLU) over dt [s]."""
        omega_matrix = 0.5 * quat_right_matrix(np.array([0.0, body_rate[0], body_rate[1], body_rate[2]]))
        transition = np.eye(4) + omega_matrix * dt  # I + Ω(ω) T_s  (4.11)
        q = transition @ self.x[3:]
        self.x[3:] = q / np.sqrt(q @ q)  # normalisation (thesis §4.2.2)
        P = self.P
        # F = blockdiag(I3, transition) (4.13): P' = F P Fᵀ + Q (4.15)
        P[3:, :] = transition @ P[3:, :]
        P[:, 3:] = P[:, 3:] @ transition.T
        P[np.diag_indices(7)] += self._q_density * dt
        limit_variances(P, self._variance_limit)

    def innovation(self, position: np.ndarray, quaternion: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Returns (7-D innovation z − h(x') with the sign-aligned quaternion, 6-D minimal innovation
        ``[δp, δθ_body]``, its 6×6 covariance S)."""
        quaternion = np.asarray(quaternion, dtype=float)
        if quaternion @ self.x[3:] < 0.0:
            quaternion = -quaternion
        innovation7 = np.concatenate([np.asarray(position, dtype=float) - self.x[:3], quaternion - self.x[3:]])
        q_pred_conj = self.x[3:] * np.array([1.0, -1.0, -1.0, -1.0])
        rotvec = quat_to_rotvec(quat_multiply(q_pred_conj, quaternion))
        G = np.zeros((6, 7))
        G[:3, :3] = np.eye(3)
        G[3:, 3:] = quaternion_to_body_error_jacobian(self.x[3:])
        S6 = G @ (self.P + self._R) @ G.T
        return innovation7, np.concatenate([innovation7[:3], rotvec]), S6

    def correct(self, innovation7: np.ndarray) -> None:
        """(4.16) with H = I₇ (4.14): K = P'(P' + R)⁻¹, x = x' + K ν, P = (I − K) P'; then normalisation."""
        S = self.P + self._R
        K = np.linalg.solve(S.T, self.P.T).T  # P S⁻¹ (S symmetric)
        self.x = self.x + K @ innovation7
        self.x[3:] /= np.linalg.norm(self.x[3:])
        self.P = (np.eye(7) - K) @ self.P
        self.P = 0.5 * (self.P + self.P.T)
