"""Target-approach law (4.39) of thesis §4.4.2 Scenario II (contact with a board), run at the ground station.

The thesis's hybrid scheme (l.7049-7078): the platform's x/y velocity and yaw rate in the flat platform frame
F_Fp come from the proportional law

    Fp v^d_p,x = λ_p · Fp p_t,x,    Fp v^d_p,y = λ_p · Fp p_t,y,    Fp ψ̇^d_p = λ_ψ · Fp ψ_t        (4.39)

with λ_p = 0.4 1/s and λ_ψ = 0.25 1/s, where Fp p_t is the target's position relative to the platform centre in
F_Fp [m] and Fp ψ_t its relative yaw [rad]; the z velocity and the desired contact force stay with the human
operator, roll, pitch and the legs at the teleoperation values. In the thesis the relative pose was emulated
from motion capture (a stand-in for a platform camera); here it arrives as a pose (``/fpr/target``) and this
module turns it into the three channel targets that :class:`fpr_control.teleop_filter.TeleopFilter` then
low-pass filters like the sticks (so χ̇_d stays consistent).

Additions that are ours, not the thesis's:

- clamping to the teleop mapping's limits of the replaced channels. The x/y velocity is scaled as a vector
  (its direction, towards the target, is kept); the yaw rate is clipped;
- a freshness rule: the last accepted target is used for ``timeout`` seconds after it was received
  (receive time, the ground station's clock), and a refused message drops it at once (the estimator's
  garbage is not flown on for another ``timeout``);
- refusal of non-finite values, a non-unit quaternion, a position farther than ``max_distance`` and a frame
  other than ``flat_platform``.

No rclpy in this module.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from fpr_model.rotations import quat_to_euler_zyx

from fpr_control.teleop_filter import TeleopConfig

#: frame_id the target pose must carry (F_Fp: origin at the platform centre, z up, yaw of the platform).
TARGET_FRAME = "flat_platform"
#: Channels of :class:`fpr_control.teleop_filter.TeleopFilter` that (4.39) replaces.
APPROACH_CHANNELS = ("velocity_x", "velocity_y", "yaw_rate")


@dataclass(frozen=True)
class TargetApproachConfig:
    """Gains (thesis values by default), freshness and plausibility rules, output limits.

    ``lambda_p``, ``lambda_psi`` [1/s]; ``timeout`` [s]; ``max_distance`` [m] (norm of the relative position);
    ``velocity_x_limits``, ``velocity_y_limits`` [m/s] and ``yaw_rate_limits`` [rad/s] as (minimum, maximum).
    """

    lambda_p: float = 0.4
    lambda_psi: float = 0.25
    timeout: float = 0.5
    max_distance: float = 100.0
    velocity_x_limits: tuple[float, float] = (-math.inf, math.inf)
    velocity_y_limits: tuple[float, float] = (-math.inf, math.inf)
    yaw_rate_limits: tuple[float, float] = (-math.inf, math.inf)

    def __post_init__(self) -> None:
        for name in ("lambda_p", "lambda_psi"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if not (math.isfinite(self.timeout) and self.timeout > 0.0):
            raise ValueError(f"timeout must be finite and > 0, got {self.timeout}")
        if not self.max_distance > 0.0:
            raise ValueError(f"max_distance must be > 0, got {self.max_distance}")
        for name in ("velocity_x_limits", "velocity_y_limits", "yaw_rate_limits"):
            low, high = getattr(self, name)
            if not low <= high:
                raise ValueError(f"{name}: minimum {low} > maximum {high}")


def approach_config_from_teleop(teleop: TeleopConfig, lambda_p: float = 0.4, lambda_psi: float = 0.25,
                                timeout: float = 0.5, max_distance: float = 100.0) -> TargetApproachConfig:
    """:class:`TargetApproachConfig` whose output limits are the mapping's limits of the replaced channels."""
    channels = teleop.channels

    def limits(name: str) -> tuple[float, float]:
        return channels[name].minimum, channels[name].maximum

    return TargetApproachConfig(lambda_p, lambda_psi, timeout, max_distance, limits("velocity_x"),
                                limits("velocity_y"), limits("yaw_rate"))


@dataclass(frozen=True)
class ApproachCommand:
    """Channel targets from (4.39), in F_Fp: Fp v^d_p,x, Fp v^d_p,y [m/s] and Fp ψ̇^d_p [rad/s]."""

    velocity_x: float
    velocity_y: float
    yaw_rate: float

    def as_targets(self) -> dict[str, float]:
        """The form :meth:`fpr_control.teleop_filter.TeleopFilter.step` takes (``external``)."""
        return {"velocity_x": self.velocity_x, "velocity_y": self.velocity_y, "yaw_rate": self.yaw_rate}


def approach_law(relative_position_xy: Sequence[float], relative_yaw: float, lambda_p: float,
                 lambda_psi: float) -> tuple[float, float, float]:
    """(4.39), unclamped: ``Fp v^d_p,x/y = λ_p · Fp p_t,x/y``, ``Fp ψ̇^d_p = λ_ψ · Fp ψ_t``.

    ``relative_position_xy`` = (x, y) of the target minus the platform centre in F_Fp [m]; ``relative_yaw`` =
    Fp ψ_t [rad], the target's yaw relative to F_Fp; gains [1/s]. Returns (v_x [m/s], v_y [m/s], ψ̇ [rad/s]) in
    F_Fp.
    """
    x, y = float(relative_position_xy[0]), float(relative_position_xy[1])
    return lambda_p * x, lambda_p * y, lambda_psi * float(relative_yaw)


def limit_planar_velocity(vx: float, vy: float, x_limits: tuple[float, float],
                          y_limits: tuple[float, float]) -> tuple[float, float]:
    """Scale the F_Fp velocity (vx, vy) [m/s] by one factor in [0, 1] so that each component is within its
    (minimum, maximum): the direction towards the target is kept. Limits that exclude 0 cannot be met by
    scaling; the components are then clipped as well."""
    factor = 1.0
    for value, (low, high) in ((vx, x_limits), (vy, y_limits)):
        if value > high and high >= 0.0:
            factor = min(factor, high / value)
        elif value < low and low <= 0.0:
            factor = min(factor, low / value)
    vx, vy = vx * factor, vy * factor
    return min(max(vx, x_limits[0]), x_limits[1]), min(max(vy, y_limits[0]), y_limits[1])


def relative_yaw_from_quaternion(w: float, x: float, y: float, z: float) -> float:
    """Fp ψ_t [rad] in (−π, π]: the ZYX yaw of the target orientation in F_Fp (A.72 with erratum E15,
    ``atan2(2(q0q3 + q1q2), q0² + q1² − q2² − q3²)``). The interface sends a rotation about z by ψ_t; any tilt
    is ignored (it is not used by (4.39))."""
    return float(quat_to_euler_zyx(np.array([w, x, y, z], dtype=float))[2])


def validate_target(position: Sequence[float], orientation: Sequence[float], frame_id: str,
                    max_distance: float) -> str | None:
    """Reason to refuse a target pose, or None. ``position`` (x, y, z) [m] and ``orientation`` (w, x, y, z) in
    F_Fp; ``frame_id`` must be :data:`TARGET_FRAME`."""
    if frame_id != TARGET_FRAME:
        return f"frame_id {frame_id!r}, expected {TARGET_FRAME!r}"
    p = np.asarray(position, dtype=float)
    q = np.asarray(orientation, dtype=float)
    if p.shape != (3,) or q.shape != (4,):
        return "position needs 3 values and orientation 4"
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
        return "NaN or inf in the target pose"
    distance = float(np.linalg.norm(p))
    if distance > max_distance:
        return f"target {distance:.1f} m away (> {max_distance:.0f} m): implausible"
    norm = float(np.linalg.norm(q))
    if not 0.5 < norm < 1.5:
        return f"orientation is not a unit quaternion (norm {norm:.3g})"
    return None


@dataclass(frozen=True)
class RelativeTarget:
    """An accepted target: Fp p_t (x, y, z) [m], Fp ψ_t [rad], received at ``time`` [s]."""

    position: np.ndarray
    yaw: float
    time: float


class TargetApproach:
    """Target poses in, (4.39) channel targets out. Call :meth:`receive` for each pose message and
    :meth:`command` once per teleop tick; :meth:`take_reports` returns the one-off log lines (the target
    became usable, or stopped being usable and why)."""

    def __init__(self, config: TargetApproachConfig) -> None:
        self.config = config
        self.target: RelativeTarget | None = None
        self._usable = False  # as of the last command()
        self._lost_reason = "no target received"
        self._reports: list[tuple[str, str]] = []

    def receive(self, t: float, position: Sequence[float], orientation: Sequence[float],
                frame_id: str = TARGET_FRAME) -> str | None:
        """Take a target pose at time t [s] (see :func:`validate_target`). Returns the refusal reason; a
        refused pose also drops the held target (back to the sticks at the next :meth:`command`)."""
        reason = validate_target(position, orientation, frame_id, self.config.max_distance)
        if reason is not None:
            self.target = None
            self._lost_reason = f"refused ({reason})"
            return reason
        w, x, y, z = (float(v) for v in orientation)
        self.target = RelativeTarget(np.array(position, dtype=float), relative_yaw_from_quaternion(w, x, y, z),
                                     float(t))
        return None

    def fresh(self, t: float) -> bool:
        """A target was accepted no more than ``timeout`` s before t [s] (and nothing refused since). A target
        stamped after t (the clock went back, e.g. a restarted simulation) is not fresh."""
        return self.target is not None and 0.0 <= t - self.target.time <= self.config.timeout

    def command(self, t: float) -> ApproachCommand | None:
        """(4.39) at time t [s] from the held target, clamped to the limits; None without a fresh target."""
        usable = self.fresh(t)
        if not usable and self.target is not None:
            age = t - self.target.time
            self._lost_reason = (f"stale (none for {age:.2f} s > {self.config.timeout:g} s)" if age >= 0.0
                                 else "stale (received after now: the clock went back)")
        if usable != self._usable:
            if usable:
                p, yaw = self.target.position, self.target.yaw
                self._reports.append(("info",
                    f"target approach: /fpr/target at x {p[0]:+.2f} m, y {p[1]:+.2f} m, yaw "
                    f"{math.degrees(yaw):+.1f} deg: x/y velocity and yaw rate from (4.39) while flying"))
            else:
                self._reports.append(("warning", f"target approach: /fpr/target {self._lost_reason}: x/y "
                                      "velocity and yaw rate back to the sticks"))
            self._usable = usable
        if not usable:
            return None
        cfg = self.config
        vx, vy, yaw_rate = approach_law(self.target.position[:2], self.target.yaw, cfg.lambda_p, cfg.lambda_psi)
        vx, vy = limit_planar_velocity(vx, vy, cfg.velocity_x_limits, cfg.velocity_y_limits)
        yaw_rate = min(max(yaw_rate, cfg.yaw_rate_limits[0]), cfg.yaw_rate_limits[1])
        return ApproachCommand(vx, vy, yaw_rate)

    def take_reports(self) -> list[tuple[str, str]]:
        """One-off notices since the last call, for a log: (level "info" | "warning", text)."""
        reports, self._reports = self._reports, []
        return reports
