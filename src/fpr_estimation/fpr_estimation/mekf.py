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

Optional platform-rate state (``platform_rate``, not in the thesis): the hypotheses of (4.5)-(4.7) leave the
platform's own rotation to the process noise, so in a swing of the platform (0.3-0.7 rad/s) the filter lags the
relative attitude by its time constant. With ``platform_rate`` the platform's angular velocity ``w`` (in Fp, rad/s)
is a state, a first-order Gauss-Markov process (time constant τ_w, so that it decays to 0 without detections), and
the relative attitude turns with it: ``q̇ = ½ q ∘ [0, ω − b − R(q)ᵀ w]`` (R(q) = p_R_bi; p_R_bi = R_pᵀ R_bi with
Ṙ_p = R_p [w]×). The position keeps ṗ = 0: the UAV hangs on its leg, whose anchor turns with the platform, so
p_p_i changes with the leg angle only, not with w. The error transition adds ``∂δθ̇/∂δw = −R(q)ᵀ`` and keeps
``∂δθ̇/∂δθ = −[ω − b]×`` (the ``−[R(q)ᵀ w]×`` of the nominal rate cancels against the error's own rotation of
``R(q)ᵀ w``). :meth:`RelativePoseMEKF.platform_rotation` gives the platform's rotation over an interval, which the
estimator's latency compensation adds to the UAV's own.
"""

from __future__ import annotations

import numpy as np
from fpr_model.rotations import (
    quat_from_rotvec,
    quat_multiply,
    quat_normalize,
    quat_to_rotmat,
    quat_to_rotvec,
)

from fpr_estimation.ekf import FilterNoise, limit_variances

__all__ = ["RelativePoseMEKF"]


class RelativePoseMEKF:
    """Error-state EKF; ``estimate_gyro_bias`` adds a 3-D gyro bias to the state."""

    name = "mekf"

    def __init__(self, noise: FilterNoise | None = None, estimate_gyro_bias: bool = True,
                 position_sigma_limit: float = 2.0, platform_rate: bool = False) -> None:
        """``position_sigma_limit`` [m]: cap of the 1-σ of each position axis (see
        :func:`~fpr_estimation.ekf.limit_variances`); ``platform_rate``: add the platform's angular velocity to the
        state (module doc)."""
        self.noise = noise if noise is not None else FilterNoise()
        self.estimate_gyro_bias = bool(estimate_gyro_bias)
        self.estimate_platform_rate = bool(platform_rate)
        n = self.noise
        self.dim = 6 + 3 * self.estimate_gyro_bias + 3 * self.estimate_platform_rate
        self._rate_index = self.dim - 3 if self.estimate_platform_rate else None  #: first index of w in the state
        self._R = np.diag([n.measurement_position_sigma ** 2] * 3 + [n.measurement_angle_sigma ** 2] * 3)
        density = [n.position_random_walk ** 2] * 3 + [n.attitude_random_walk ** 2] * 3
        limits = [float(position_sigma_limit) ** 2] * 3 + [np.pi ** 2] * 3
        if self.estimate_gyro_bias:
            density += [n.gyro_bias_random_walk ** 2] * 3
            limits += [1.0] * 3  # (1 rad/s)²
        if self.estimate_platform_rate:
            density += [n.platform_rate_random_walk ** 2] * 3
            limits += [9.0] * 3  # (3 rad/s)²: beyond any flown swing
        self._q_density = np.array(density)
        # Variance caps: position from the camera range, attitude error at π², gyro bias at (1 rad/s)², rate (3 rad/s)².
        self._variance_limit = np.array(limits)
        self.reset()

    def reset(self) -> None:
        """Back to "not initialised" (after a non-finite state): the next :meth:`initialize` starts again."""
        self.p = np.zeros(3)
        self.q = np.array([1.0, 0.0, 0.0, 0.0])
        self.gyro_bias = np.zeros(3)
        self.platform_rate = np.zeros(3)  #: w [rad/s] in Fp (stays 0 without the platform-rate state)
        self.P = np.eye(self.dim)
        self.initialized = False

    def is_healthy(self) -> bool:
        """State and covariance finite, variances non-negative (checked after every predict and correct)."""
        return bool(np.isfinite(self.p).all() and np.isfinite(self.q).all() and np.isfinite(self.gyro_bias).all()
                    and np.isfinite(self.platform_rate).all() and np.isfinite(self.P).all()
                    and (np.diag(self.P) >= 0.0).all())

    def platform_rotation(self, interval: float) -> np.ndarray:
        """``Exp([w]× Δt)``: the platform's rotation (in Fp) over ``interval`` [s] at the estimated rate (the
        identity without the platform-rate state). The relative attitude of Δt ago is carried to now by its
        transpose on the left: ``p_R_bi(t) = Exp(−w Δt) p_R_bi(t − Δt) Δ_bi``."""
        if not self.estimate_platform_rate:
            return np.eye(3)
        return quat_to_rotmat(quat_from_rotvec(self.platform_rate * float(interval)))

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
            self.P[6:9, 6:9] = np.eye(3) * self.noise.initial_gyro_bias_sigma ** 2
            self.gyro_bias = np.zeros(3)
        if self._rate_index is not None:
            r = self._rate_index
            self.P[r:r + 3, r:r + 3] = np.eye(3) * self.noise.initial_platform_rate_sigma ** 2
            self.platform_rate = np.zeros(3)
        self.initialized = True

    def predict(self, body_rate: np.ndarray, dt: float) -> None:
        if self._rate_index is not None:
            self._predict_with_platform_rate(np.asarray(body_rate, dtype=float), float(dt))
            return
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
        if self._rate_index is not None:
            self.platform_rate = self.platform_rate + dx[self._rate_index:self._rate_index + 3]
        self.P = self.P - K @ self.P[:6, :]
        self.P = 0.5 * (self.P + self.P.T)

    def error_transition(self, body_rate: np.ndarray, dt: float) -> np.ndarray:
        """F of the platform-rate prediction (module doc) at the current state: ``δx_k = F δx_{k−1}`` over ``dt``
        with ``δx = [δp, δθ, (δb), δw]`` (dim ≤ 12). Only with the platform-rate state."""
        if self._rate_index is None:
            raise ValueError("error_transition: the filter has no platform-rate state")
        return self._transition(np.asarray(body_rate, dtype=float) - self.gyro_bias, quat_to_rotmat(self.q).T,
                                float(np.exp(-dt / self.noise.platform_rate_time_constant)), dt)

    def _transition(self, gyro: np.ndarray, body_R_platform: np.ndarray, decay: float, dt: float) -> np.ndarray:
        """F from the bias-corrected gyro ``ω − b``, ``R(q)ᵀ`` and the rate's decay ``exp(−T_s / τ_w)``."""
        r = self._rate_index
        F = np.eye(self.dim)
        F[3:6, 3:6] = quat_to_rotmat(quat_from_rotvec(gyro * dt)).T  # exp(−[(ω − b) T_s]×)
        F[3:6, r:r + 3] = -body_R_platform * dt  # ∂δθ̇/∂δw = −R(q)ᵀ
        if self.estimate_gyro_bias:
            F[3:6, 6:9] = -np.eye(3) * dt
        F[r:r + 3, r:r + 3] = np.eye(3) * decay
        return F

    def _predict_with_platform_rate(self, body_rate: np.ndarray, dt: float) -> None:
        """The prediction with the platform-rate state (module doc): nominal state, then ``P' = F P Fᵀ + Q T_s``
        with the full error transition F (:meth:`error_transition`)."""
        gyro = body_rate - self.gyro_bias
        body_R_platform = quat_to_rotmat(self.q).T  # R(q)ᵀ
        decay = float(np.exp(-dt / self.noise.platform_rate_time_constant))
        F = self._transition(gyro, body_R_platform, decay, dt)
        q = quat_multiply(self.q, quat_from_rotvec((gyro - body_R_platform @ self.platform_rate) * dt))
        self.q = q / np.sqrt(q @ q)
        self.platform_rate = self.platform_rate * decay
        P = F @ self.P @ F.T
        P[np.diag_indices(self.dim)] += self._q_density * dt
        limit_variances(P, self._variance_limit)
        self.P = P
