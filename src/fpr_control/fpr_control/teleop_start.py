"""Where the teleoperation starts: the robot's actual common leg angle, from the UAVs' information vectors.

Each controller broadcasts ζ_i = [θ_i, Fp v_i, Fp q_i, f^d_t,i] on /fpr/info (4.31), (4.36), also while the
robot rests on the ground. Before the operator engages FLY, the teleop sets its common leg-angle command θ^d_l
of χ_d (4.25) to the mean of the UAVs' reported θ_i, so arming does not command a configuration change
(:meth:`fpr_control.teleop_filter.TeleopFilter.step` takes the value this module gives).

:class:`ReportedLegAngles` keeps the newest valid θ_i per UAV with its receive time; :meth:`ReportedLegAngles.update`
(called at the teleop rate) averages the fresh ones over the UAVs and smooths that mean with a first-order
filter (time constant ``smoothing``), because each on-board estimate jitters by about ±1° (camera noise).
Angles in rad, times in s (the node's clock). No rclpy here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class ReportedLegAnglesConfig:
    """``timeout``: a θ_i older than this is not used; ``smoothing``: time constant of the average (0: none)."""

    n: int
    timeout: float = 0.5
    smoothing: float = 1.0

    def __post_init__(self) -> None:
        if self.n < 1:
            raise ValueError(f"n must be >= 1, got {self.n}")
        if not self.timeout > 0.0:
            raise ValueError(f"timeout must be > 0, got {self.timeout}")
        if not self.smoothing >= 0.0:
            raise ValueError(f"smoothing must be >= 0, got {self.smoothing}")


@dataclass(frozen=True)
class LegAngleEstimate:
    """Smoothed mean of the fresh reported leg angles [rad] and how many UAVs were fresh at the last update."""

    leg_angle: float
    uav_count: int


class ReportedLegAngles:
    """Newest θ_i per UAV i (1-based) from /fpr/info and their smoothed mean."""

    def __init__(self, config: ReportedLegAnglesConfig) -> None:
        self.config = config
        self._angles: dict[int, float] = {}
        self._times: dict[int, float] = {}
        self._smoothed: float | None = None

    def receive(self, uav_id: int, leg_angle: float, valid: bool, t: float) -> str | None:
        """Store θ_i received at time t. A vector marked invalid by its sender is skipped silently (its age
        grows, as in the controllers); returns the reason when the vector is malformed, else None."""
        if not valid:
            return None
        if not 1 <= uav_id <= self.config.n:
            return f"uav_id {uav_id} outside 1..{self.config.n}"
        if not math.isfinite(leg_angle) or not 0.0 < leg_angle < 0.5 * math.pi:
            return f"leg angle {leg_angle} of uav {uav_id} not in (0, pi/2) rad"
        self._angles[uav_id] = float(leg_angle)
        self._times[uav_id] = t
        return None

    def fresh_mean(self, t: float) -> tuple[float, int] | None:
        """Unsmoothed mean [rad] of the θ_i received within ``timeout`` s of time t, with their count; None if
        none."""
        fresh = [angle for uav_id, angle in self._angles.items()
                 if abs(t - self._times[uav_id]) <= self.config.timeout]  # abs: a clock jumping back
        if not fresh:
            return None
        return sum(fresh) / len(fresh), len(fresh)

    def update(self, t: float, dt: float) -> LegAngleEstimate | None:
        """Advance the average by dt [s] at time t [s]. None (and the average restarts later) while no UAV's
        θ_i is fresh."""
        mean = self.fresh_mean(t)
        if mean is None:
            self._smoothed = None
            return None
        value, count = mean
        if self._smoothed is None or self.config.smoothing == 0.0:
            self._smoothed = value
        else:
            alpha = 1.0 - math.exp(-max(dt, 0.0) / self.config.smoothing)
            self._smoothed += alpha * (value - self._smoothed)
        return LegAngleEstimate(self._smoothed, count)
