"""Multiplicative (error-state) EKF of the relative pose: the thesis's suggested improvement (§4.2.2, Markley 2003).

Same measurement and process hypotheses as :mod:`fpr_estimation.ekf` ((4.5)-(4.7): ṗ = 0, relative attitude
driven by the UAV body rate), but the attitude error is a 3-vector in the body frame,
``q_true = q ∘ exp(δθ/2)``, so the quaternion stays unit and the covariance is 6×6 (9×9 with the optional gyro
bias ``b``: ``ω_true = ω_meas − b``).

- Prediction: ``q ← q ∘ exp((ω − b) T_s)`` (exact for a constant rate), error transition
  ``F = [[I, 0, 0], [0, exp(−[(ω − b) T_s]×), −I T_s], [0, 0, I]]``, ``P' = F P Fᵀ + Q T_s``.
- Correction with ``ν = [p_m − p, log(q^{-1} ∘ q_m)]`` and H = [I₆, 0]: ``K = P'Hᵀ(H P' Hᵀ + R)⁻¹``,
  ``δx = K ν``, ``p += δp``, ``q ← q ∘ exp(δθ/2)``, ``b += δb``, ``P = (I − K H) P'``.
- Robustness (issue 12): variances capped after each prediction (:func:`~fpr_estimation.ekf.limit_variances`),
  :meth:`RelativePoseMEKF.is_healthy` after each step, :meth:`RelativePoseMEKF.reset` on failure.
"""

from __future__ import annotations

import numpy as np
from fpr_model.rotations import quat_from_rotvec, quat_multiply, quat_normalize, quat_to_rotmat, quat_to_rotvec

from fpr_estimation.ekf import FilterNoise, limit_variances

__all__ = ["RelativePoseMEKF"]


class RelativePoseMEKF:
    """Error-state EKF; ``estimate_gyro_bias`` adds a 3-D gyro bias to the state."""

    name = "mekf"

    def __init__(self, noise: FilterNoise | None = None, estimate_gyro_bias: bool = True,
                 position_sigma_limit: float = 2.0) -> None:
        """``position_sigma_limit`` [m]: cap of the 1-σ of each position axis (see
        :func:`~fpr_estimation.ekf.limit_variances`)."""
        self.noise = noise if noise is not None else FilterNoise()
        self.estimate_gyro_bias = bool(estimate_gyro_bias)
        n = self.noise
        self.dim = 9 if self.estimate_gyro_bias else 6
        self._R = np.diag([n.measurement_position_sigma ** 2] * 3 + [n.measurement_angle_sigma ** 2] * 3)
        density = [n.position_random_walk ** 2] * 3 + [n.attitude_random_walk ** 2] * 3
        if self.estimate_gyro_bias:
            density += [n.gyro_bias_random_walk ** 2] * 3
        self._q_density = np.array(density)
        # Variance caps: position from the camera range, attitude error at π², gyro bias at (1 rad/s)².
        self._variance_limit = np.array([float(position_sigma_limit) ** 2] * 3 + [np.pi ** 2] * 3
                                        + [1.0] * (self.dim - 6))
        self.reset()

    def reset(self) -> None:
        """Back to "not initialised" (after a non-finite state): the next :meth:`initialize` starts again."""
        self.p = np.zeros(3)
        self.q = np.array([1.0, 0.0, 0.0, 0.0])
        self.gyro_bias = np.zeros(3)
        self.P = np.eye(self.dim)
        self.initialized = False

    def is_healthy(self) -> bool:
        """State and covariance finite, variances non-negative (checked after every predict and correct)."""
        return bool(np.isfinite(self.p).all() and np.isfinite(self.q).all() and np.isfinite(self.gyro_bias).all()
                    and np.isfinite(self.P).all() and (np.diag(self.P) >= 0.0).all())

    @property
    def position(self) -> np.ndarray:
        return self.p.copy()

    @property
    def quaternion(self) -> np.ndarray:
        return self.q.copy()

    def pose_covariance(self) -> np.ndarray:
        return self.P[:6, :6].copy()

    def initialize(self, position: np.ndarray, quaternion: np.ndarray) -> None:
        self.p = np.asarray(position, dtype=float).copy()
        self.q = quat_normalize(quaternion)
        self.P = np.zeros((self.dim, self.dim))
        self.P[:6, :6] = self._R
        if self.estimate_gyro_bias:
            self.P[6:, 6:] = np.eye(3) * self.noise.initial_gyro_bias_sigma ** 2
            self.gyro_bias = np.zeros(3)
        self.initialized = True

    def predict(self, body_rate: np.ndarray, dt: float) -> None:
        rate = np.asarray(body_rate, dtype=float) - self.gyro_bias
        step = quat_from_rotvec(rate * dt)
        q = quat_multiply(self.q, step)
        self.q = q / np.sqrt(q @ q)
        rotation_back = quat_to_rotmat(step).T  # exp(−[ω T_s]×)
        P = self.P
        P[3:6, :] = rotation_back @ P[3:6, :]
        P[:, 3:6] = P[:, 3:6] @ rotation_back.T
        if self.estimate_gyro_bias:
            # δθ_k += −T_s δb: F = I + E with E[3:6, 6:9] = −T_s I (applied after the rotation block).
            P[3:6, :] -= dt * P[6:9, :]
            P[:, 3:6] -= dt * P[:, 6:9]
        P[np.diag_indices(self.dim)] += self._q_density * dt
        limit_variances(P, self._variance_limit)

    def innovation(self, position: np.ndarray, quaternion: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Returns (the 6-D innovation used by :meth:`correct`, the same for the gate, its covariance S)."""
        q_conj = self.q * np.array([1.0, -1.0, -1.0, -1.0])
        nu = np.concatenate([np.asarray(position, dtype=float) - self.p,
                             quat_to_rotvec(quat_multiply(q_conj, np.asarray(quaternion, dtype=float)))])
        S = self.P[:6, :6] + self._R
        return nu, nu, S

    def correct(self, innovation: np.ndarray) -> None:
        S = self.P[:6, :6] + self._R
        PHt = self.P[:, :6]
        K = np.linalg.solve(S.T, PHt.T).T
        dx = K @ innovation
        self.p = self.p + dx[:3]
        q = quat_multiply(self.q, quat_from_rotvec(dx[3:6]))
        self.q = q / np.linalg.norm(q)
        if self.estimate_gyro_bias:
            self.gyro_bias = self.gyro_bias + dx[6:9]
        self.P = self.P - K @ self.P[:6, :]
        self.P = 0.5 * (self.P + self.P.T)
