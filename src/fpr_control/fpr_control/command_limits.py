"""The controller's own limits on the teleoperation command (issue 12, "bounded inputs"). No rclpy here.

Every controller checks each ``/fpr/teleop`` command (:class:`fpr_control.reference.TeleopReference`, χ_d and χ̇_d
of (4.25)-(4.26), velocities in F_Fp) against its own limits, whoever published it. The teleop node's limits
only bound what that node sends, so a second publisher, a broken ground station or a fault injector is not
limited by them. Each field is checked as follows (defaults in :class:`CommandLimits`):

- inside its limit: passed unchanged;
- slightly outside: CLAMPED to the limit. "Slightly" means up to ``refuse_ratio`` (2) times the limit for a
  symmetric limit |x| ≤ L, and inside the legs' joint stops [10°, 92°] for the leg angles. A stick a little past
  a limit, or a ground station configured a little wider, is then flown at the limit. Vectors (the platform
  velocity and acceleration in F_Fp) are scaled to the limit, so their direction is kept;
- beyond that: the whole command is REFUSED and the controller keeps the last valid command. A value this far out
  means the sender is broken: 1e9, legs at 150°, roll at 80°. Clamping it would fly a command nobody meant
  (full tilt, full speed), so refusing it is safer. If refusals go on, the last valid command ages and the node's
  ``teleop_timeout`` stops every velocity.

The mode must be one of ``TeleopCommand.MODE_*`` (0..4), otherwise the command is refused.

Default limits: the widest any shipped teleop mapping sends (fpr_control config/teleop.yaml, fpr_experiments
config/mappings/teleop_tilt30.yaml), with headroom for the teleop's low-pass derivatives χ̇_d.

- legs [15°, 80°]: the teleop's range, which includes the thesis experiments' 30°-75°;
- |roll|, |pitch| ≤ 30°: teleop_tilt30, which the Exp. IV inclined push flies at 25° pitch;
- |Fp v^d| ≤ 1 m/s: teleop 0.5 / 0.5 / 0.3 m/s gives a norm of 0.77;
- |ψ̇^d| ≤ 1 rad/s: teleop 0.5;
- |ϕ̇^d|, |ϑ̇^d|, |θ̇^d| ≤ 1 rad/s: the teleop's rate channels move at 5-10°/s, and a leg target clipped into
  the feasible range steps by at most ~20° over τ = 0.3 s;
- |Fp v̇^d| ≤ 6 m/s²: a full stick reversal on all three axes, (1, 1, 0.6) m/s / 0.3 s, gives a norm of 5.1;
- |ψ̈^d| ≤ 5 rad/s²;
- f^d_c in [0, 15] N (teleop 0-10 N). It is clamped inside [−15, 30] N and refused outside.

The command carries no position, so there is no workspace box.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from fpr_control.reference import TeleopReference

#: TeleopCommand.MODE_IDLE .. MODE_KILL
TELEOP_MODES = (0, 1, 2, 3, 4)


@dataclass(frozen=True)
class CommandLimits:
    """Limits of the teleoperation command. Angles in rad, SI units. Velocities are in F_Fp."""

    leg_angle_min: float = math.radians(15.0)  #: θ^d lower limit [rad]
    leg_angle_max: float = math.radians(80.0)  #: θ^d upper limit [rad]
    leg_stop_min: float = math.radians(10.0)  #: joint stop: θ^d below this is refused [rad]
    leg_stop_max: float = math.radians(92.0)  #: joint stop: θ^d above this is refused [rad]
    max_tilt: float = math.radians(30.0)  #: |ϕ^d|, |ϑ^d| [rad]
    max_speed: float = 1.0  #: |Fp v^d_p| [m/s]
    max_yaw_rate: float = 1.0  #: |ψ̇^d| [rad/s]
    max_tilt_rate: float = 1.0  #: |ϕ̇^d|, |ϑ̇^d| [rad/s]
    max_leg_rate: float = 1.0  #: |θ̇^d_i| [rad/s]
    max_acceleration: float = 6.0  #: |Fp v̇^d_p| [m/s²]
    max_yaw_acceleration: float = 5.0  #: |ψ̈^d| [rad/s²]
    max_contact_force: float = 15.0  #: f^d_c in [0, this] [N]
    refuse_ratio: float = 2.0  #: beyond this times a symmetric limit the command is refused (clamped below)

    def __post_init__(self) -> None:
        if not 0.0 <= self.leg_stop_min <= self.leg_angle_min < self.leg_angle_max <= self.leg_stop_max <= math.pi:
            raise ValueError("need 0 <= leg_stop_min <= leg_angle_min < leg_angle_max <= leg_stop_max <= pi")
        positive = (self.max_tilt, self.max_speed, self.max_yaw_rate, self.max_tilt_rate, self.max_leg_rate,
                    self.max_acceleration, self.max_yaw_acceleration, self.max_contact_force)
        if not all(math.isfinite(v) and v > 0.0 for v in positive):
            raise ValueError("command limits must be finite and > 0")
        if not self.max_tilt < 0.5 * math.pi:
            raise ValueError("max_tilt must be < 90 deg")
        if not 1.0 <= self.refuse_ratio <= 10.0:
            raise ValueError(f"refuse_ratio must be in [1, 10], got {self.refuse_ratio}")


@dataclass
class BoundedCommand:
    """The result of :func:`bound_command`. ``command`` is None when the command was refused (``refused`` says
    why). ``clamped`` lists what was clamped (empty: the command passes unchanged)."""

    command: TeleopReference | None
    refused: str | None = None
    clamped: list[str] = field(default_factory=list)


def _deg(value: float) -> str:
    return f"{math.degrees(value):.1f} deg"


class _Checker:
    def __init__(self, limits: CommandLimits) -> None:
        self.limits = limits
        self.clamped: list[str] = []

    def scalar(self, name: str, value: float, limit: float, unit: str = "") -> float:
        """Symmetric limit |value| ≤ limit: pass, clamp up to refuse_ratio·limit, refuse beyond (raises)."""
        show = _deg if unit == "deg" else (lambda v: f"{v:.3g} {unit}".rstrip())
        if abs(value) <= limit:
            return value
        if abs(value) > self.limits.refuse_ratio * limit:
            raise _Refused(f"{name} {show(value)} beyond {self.limits.refuse_ratio:g} x its limit {show(limit)}")
        clamped = math.copysign(limit, value)
        self.clamped.append(f"{name} {show(value)} -> {show(clamped)}")
        return clamped

    def vector(self, name: str, value: np.ndarray, limit: float, unit: str) -> np.ndarray:
        norm = float(np.linalg.norm(value))
        if norm <= limit:
            return value
        if norm > self.limits.refuse_ratio * limit:
            raise _Refused(f"|{name}| {norm:.3g} {unit} beyond {self.limits.refuse_ratio:g} x its limit "
                           f"{limit:g} {unit}")
        self.clamped.append(f"|{name}| {norm:.3g} -> {limit:g} {unit}")
        return value * (limit / norm)


class _Refused(Exception):
    pass


def bound_command(command: TeleopReference, limits: CommandLimits) -> BoundedCommand:
    """Check a finite teleoperation command against ``limits`` (module doc): pass, clamp or refuse.

    The caller has already checked that the command is finite and has n leg angles."""
    if int(command.mode) not in TELEOP_MODES:
        return BoundedCommand(None, f"mode {command.mode} is not a TeleopCommand.MODE_* (0..4)")
    check = _Checker(limits)
    try:
        legs = np.array(command.leg_angles, dtype=float)
        for i, leg in enumerate(legs):
            if not limits.leg_stop_min <= leg <= limits.leg_stop_max:
                raise _Refused(f"leg angle {i + 1} {_deg(leg)} outside the joint stops "
                               f"[{_deg(limits.leg_stop_min)}, {_deg(limits.leg_stop_max)}]")
            if not limits.leg_angle_min <= leg <= limits.leg_angle_max:
                legs[i] = min(max(leg, limits.leg_angle_min), limits.leg_angle_max)
                check.clamped.append(f"leg angle {i + 1} {_deg(leg)} -> {_deg(legs[i])}")
        roll = check.scalar("roll", command.roll, limits.max_tilt, "deg")
        pitch = check.scalar("pitch", command.pitch, limits.max_tilt, "deg")
        velocity = check.vector("platform velocity", np.asarray(command.platform_velocity, float),
                                limits.max_speed, "m/s")
        acceleration = check.vector("platform acceleration", np.asarray(command.platform_acceleration, float),
                                    limits.max_acceleration, "m/s^2")
        yaw_rate = check.scalar("yaw rate", command.yaw_rate, limits.max_yaw_rate, "rad/s")
        yaw_acceleration = check.scalar("yaw acceleration", command.yaw_acceleration, limits.max_yaw_acceleration,
                                        "rad/s^2")
        roll_rate = check.scalar("roll rate", command.roll_rate, limits.max_tilt_rate, "rad/s")
        pitch_rate = check.scalar("pitch rate", command.pitch_rate, limits.max_tilt_rate, "rad/s")
        leg_rates = np.array([check.scalar(f"leg rate {i + 1}", float(r), limits.max_leg_rate, "rad/s")
                              for i, r in enumerate(command.leg_rates)])
        force = command.contact_force
        f_max = limits.max_contact_force
        if not -f_max <= force <= limits.refuse_ratio * f_max:
            raise _Refused(f"contact force {force:.3g} N outside [{-f_max:g}, {limits.refuse_ratio * f_max:g}] N")
        if not 0.0 <= force <= f_max:
            clipped = min(max(force, 0.0), f_max)
            check.clamped.append(f"contact force {force:.3g} N -> {clipped:g} N")
            force = clipped
    except _Refused as refusal:
        return BoundedCommand(None, str(refusal))
    if not check.clamped:
        return BoundedCommand(command)
    bounded = replace(command, platform_velocity=velocity, platform_acceleration=acceleration, yaw_rate=yaw_rate,
                      yaw_acceleration=yaw_acceleration, roll=roll, roll_rate=roll_rate, pitch=pitch,
                      pitch_rate=pitch_rate, leg_angles=legs, leg_rates=leg_rates, contact_force=force)
    return BoundedCommand(bounded, None, check.clamped)
