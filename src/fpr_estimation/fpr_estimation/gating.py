"""Innovation gate for the relative-pose filters (thesis §4.2.2: "reducing the rate of false detections"). ROS-free.

A detection is compared with the predicted relative pose before the correction (4.16). The innovation is
expressed minimally: the position difference [m] (Fp) and the rotation vector of ``q_pred^{-1} ∘ q_meas`` [rad]
(UAV body frame). Two tests, selected by ``GateConfig.mode``:

- ``"threshold"`` (default): reject when ‖δp‖ > ``max_position_error`` (10 cm) or the rotation angle
  > ``max_angle_error`` (10°);
- ``"mahalanobis"``: reject when ``νᵀ S⁻¹ ν`` exceeds ``mahalanobis_threshold`` (χ²₆ quantile; 22.46 is 99.9 %),
  S being the 6×6 innovation covariance of the filter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GateConfig", "GateDecision", "evaluate_gate"]

GATE_MODES = ("threshold", "mahalanobis", "off")


@dataclass(frozen=True)
class GateConfig:
    mode: str = "threshold"
    max_position_error: float = 0.10  #: [m]
    max_angle_error: float = float(np.radians(10.0))  #: [rad]
    mahalanobis_threshold: float = 22.46  #: χ²(6) at 99.9 %

    def __post_init__(self) -> None:
        if self.mode not in GATE_MODES:
            raise ValueError(f"gate mode: expected one of {GATE_MODES}, got {self.mode!r}")
        if not (self.max_position_error > 0.0 and self.max_angle_error > 0.0 and self.mahalanobis_threshold > 0.0):
            raise ValueError("gate thresholds must be positive")


@dataclass(frozen=True)
class GateDecision:
    accepted: bool
    position_error: float  #: ‖δp‖ [m]
    angle_error: float  #: rotation angle of the innovation [rad]
    mahalanobis: float  #: νᵀ S⁻¹ ν (NaN when S is not available)


def evaluate_gate(config: GateConfig, innovation: np.ndarray, covariance: np.ndarray | None) -> GateDecision:
    """Apply the gate to a 6-D innovation ``[δp (3), δθ (3)]`` with covariance S (6×6) or None."""
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
        accepted = position_error <= config.max_position_error and angle_error <= config.max_angle_error
    return GateDecision(accepted, position_error, angle_error, mahalanobis)
