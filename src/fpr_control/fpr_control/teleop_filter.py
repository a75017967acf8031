"""Ground teleoperation core: gamepad (sensor_msgs/Joy arrays) -> filtered command χ_d, χ̇_d (thesis §4.3.1).

χ = [Fp v_p (3), Fp ψ̇_p, Fp ϑ_p, Fp ϕ_p, θ_l] (4.25). The operator sets the platform velocity and yaw rate
(flat platform frame F_Fp, m/s and rad/s) and the *values* of roll, pitch and a common leg angle (rad), plus the
desired contact force f^d_c (N, (3.43)). Each channel goes through: dead zone -> scaling (absolute value or
integrated rate) -> clamping to its limits -> first-order low-pass ``τ ẏ = x − y``. The filter output is χ_d
and its derivative ``(x − y)/τ`` is χ̇_d (4.25)-(4.26).

Start from the robot (``start_from_robot``): while the robot is not flying (modes IDLE and ARM, before FLY),
the configuration channels do not take the operator's input: roll and pitch stay at their configured initial
values (0: the robot rests level) and the common leg angle follows the robot's measured one (the mean of the
UAVs' reported θ_i, :mod:`fpr_control.teleop_start`), each with the filter state set to the target, so
χ̇_d = 0 there. Once FLY is engaged the operator's inputs take over from those values (same channel modes).
Without a measured leg angle the leg channel keeps the configured initial value (or the last measured one)
and the operator's input as before.

External targets (``external`` of :meth:`TeleopFilter.step`): a higher-level law may set the targets of some
channels in place of the operator's input, e.g. the target-approach law (4.39)
(:mod:`fpr_control.target_approach`) for the x/y velocity and the yaw rate. They are used only in FLY with a
live joystick (the operator supervises: a silent joystick still zeroes every velocity), clamped to the channel's
limits and low-pass filtered like the sticks, so χ̇_d stays consistent; the other channels keep the operator's
input. When the external targets stop, an ``absolute`` channel returns to the stick value and a ``rate``
channel integrates the operator's input from the last external target.

The exact gamepad layout of the thesis Fig. 4.5 is lost in the text extraction; the default layout lives in
``config/teleop.yaml`` and is documented there. No rclpy in this module.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

MODE_IDLE, MODE_ARM, MODE_FLY, MODE_LAND, MODE_KILL = 0, 1, 2, 3, 4
MODE_NAMES = {MODE_IDLE: "idle", MODE_ARM: "arm", MODE_FLY: "fly", MODE_LAND: "land", MODE_KILL: "kill"}

#: Channel names in the order of :class:`TeleopOutput`'s vector form.
CHANNELS = ("velocity_x", "velocity_y", "velocity_z", "yaw_rate", "roll", "pitch", "leg_angle", "contact_force")
#: Channels zeroed when the joystick falls silent (the others hold their value).
RATE_CHANNELS = ("velocity_x", "velocity_y", "velocity_z", "yaw_rate")
#: Configuration channels held at the robot's resting configuration before FLY (``start_from_robot``).
ATTITUDE_CHANNELS = ("roll", "pitch")
#: Modes in which the robot is not flown by the controllers: the start configuration is tracked there.
GROUND_MODES = (MODE_IDLE, MODE_ARM)
#: Where the common leg-angle command came from (:attr:`TeleopFilter.leg_source`).
LEG_SOURCE_CONFIGURED = "configured initial value"
LEG_SOURCE_INFO = "mean of the UAVs' reported leg angles (/fpr/info)"
LEG_SOURCE_INFO_STALE = "last mean of the UAVs' reported leg angles (/fpr/info now stale)"


@dataclass(frozen=True)
class ChannelConfig:
    """One command channel.

    Input ``u`` = ``axis value − center`` (with ``axis >= 0``) or ``button[plus] − button[minus]``
    (with ``buttons = (plus, minus)``), after the dead zone. ``mode = "absolute"``: target = initial + scale·u;
    ``mode = "rate"``: target += scale·u·dt (scale per second). Target clamped to [minimum, maximum].
    Units: m/s, rad/s, rad or N according to the channel.
    """

    axis: int = -1
    buttons: tuple[int, int] | None = None
    mode: str = "absolute"
    scale: float = 1.0
    center: float = 0.0
    dead_zone: float = 0.05
    initial: float = 0.0
    minimum: float = -math.inf
    maximum: float = math.inf

    def __post_init__(self) -> None:
        if self.mode not in ("absolute", "rate"):
            raise ValueError(f"channel mode must be 'absolute' or 'rate', got {self.mode!r}")
        if self.axis < 0 and self.buttons is None:
            raise ValueError("a channel needs an axis index >= 0 or a (plus, minus) button pair")
        if not self.minimum <= self.initial <= self.maximum:
            raise ValueError(f"initial {self.initial} outside [{self.minimum}, {self.maximum}]")
        if not 0.0 <= self.dead_zone < 1.0:
            raise ValueError(f"dead_zone must be in [0, 1), got {self.dead_zone}")


@dataclass(frozen=True)
class ButtonConfig:
    """Button indices for the flight-mode commands (rising edges)."""

    arm: int = 0
    land: int = 1
    fly: int = 2
    kill: int = 6


@dataclass(frozen=True)
class TeleopConfig:
    """Whole mapping. ``expected_axes`` and ``min_buttons`` validate incoming Joy arrays."""

    channels: dict[str, ChannelConfig]
    buttons: ButtonConfig = field(default_factory=ButtonConfig)
    time_constant: float = 0.3
    expected_axes: int = 8
    min_buttons: int = 7
    joy_timeout: float = 0.5
    n: int = 3

    def __post_init__(self) -> None:
        missing = [name for name in CHANNELS if name not in self.channels]
        if missing:
            raise ValueError(f"teleop mapping lacks channels {missing}")
        if self.time_constant <= 0.0:
            raise ValueError("time_constant must be > 0")
        for name, channel in self.channels.items():
            if channel.axis >= self.expected_axes:
                raise ValueError(f"channel {name}: axis {channel.axis} >= expected_axes {self.expected_axes}")


@dataclass
class TeleopOutput:
    """χ_d, χ̇_d and the flight mode (one TeleopCommand)."""

    mode: int
    platform_velocity: np.ndarray  # Fp v^d_p [m/s]
    platform_acceleration: np.ndarray  # Fp v̇^d_p [m/s²]
    yaw_rate: float
    yaw_acceleration: float
    roll: float
    roll_rate: float
    pitch: float
    pitch_rate: float
    leg_angles: np.ndarray  # (n,) rad
    leg_rates: np.ndarray  # (n,) rad/s
    contact_force: float  # f^d_c [N]
    joy_stale: bool
    external_channels: tuple[str, ...] = ()  # channels whose target came from ``external`` in this step


def apply_dead_zone(value: float, dead_zone: float) -> float:
    """Dead zone with rescaling: 0 inside ``|v| <= dz``, then linear, reaching ±1 at |v| = 1 (no jump).
    Inputs measured from a rest value of ±1 (triggers) span up to 2 and map up to about 2."""
    magnitude = abs(value)
    if magnitude <= dead_zone:
        return 0.0
    return math.copysign((magnitude - dead_zone) / (1.0 - dead_zone), value)


class TeleopFilter:
    """Joy arrays -> :class:`TeleopOutput`. Call :meth:`joy` for each Joy message and :meth:`step` at the
    publishing rate (50 Hz). ``leg_range`` (optional) returns the feasible (min, max) leg angle [rad] for the
    current roll and pitch; the commanded leg angle is clamped into it in addition to the static limits.
    ``start_from_robot``: before FLY, hold roll/pitch at their initial values and follow the measured leg
    angle given to :meth:`step` (module doc)."""

    def __init__(self, config: TeleopConfig,
                 leg_range: Callable[[float, float], tuple[float, float]] | None = None,
                 start_from_robot: bool = False) -> None:
        self.config = config
        self.leg_range = leg_range
        self.start_from_robot = start_from_robot
        #: origin of the current leg-angle target (LEG_SOURCE_*), as of the last step before FLY
        self.leg_source = LEG_SOURCE_CONFIGURED
        self._reports: list[str] = []
        self._targets = {name: config.channels[name].initial for name in CHANNELS}
        self._filtered = dict(self._targets)
        self._axes = np.zeros(config.expected_axes)
        self._buttons = np.zeros(config.min_buttons, dtype=int)
        self._previous_buttons = np.zeros(config.min_buttons, dtype=int)
        self._last_joy_time: float | None = None
        self._pending_edges: list[int] = []
        self.mode = MODE_IDLE

    # ---------------------------------------------------------------------------------------------
    def validate_joy(self, axes: Sequence[float], buttons: Sequence[int]) -> str | None:
        """Reason to reject a Joy message, or None if it is usable."""
        if len(axes) != self.config.expected_axes:
            return f"Joy has {len(axes)} axes, expected {self.config.expected_axes}"
        if len(buttons) < self.config.min_buttons:
            return f"Joy has {len(buttons)} buttons, expected at least {self.config.min_buttons}"
        if not np.all(np.isfinite(np.asarray(axes, dtype=float))):
            return "Joy axes contain NaN or inf"
        return None

    def joy(self, t: float, axes: Sequence[float], buttons: Sequence[int]) -> str | None:
        """Take a Joy sample at time t [s]. Returns the rejection reason (the sample is then ignored)."""
        reason = self.validate_joy(axes, buttons)
        if reason is not None:
            return reason
        self._axes = np.clip(np.asarray(axes, dtype=float), -1.0, 1.0)
        new_buttons = np.asarray(buttons, dtype=int)[: self.config.min_buttons]
        rising = (new_buttons != 0) & (self._previous_buttons == 0)
        self._pending_edges.extend(int(i) for i in np.flatnonzero(rising))
        self._previous_buttons = new_buttons
        self._buttons = new_buttons
        self._last_joy_time = t
        return None

    def joy_stale(self, t: float) -> bool:
        """True when no valid Joy arrived for ``joy_timeout`` s (or never)."""
        return self._last_joy_time is None or t - self._last_joy_time > self.config.joy_timeout

    # ---------------------------------------------------------------------------------------------
    def _update_mode(self) -> None:
        b = self.config.buttons
        for index in self._pending_edges:
            if index == b.kill:
                self.mode = MODE_KILL
            elif index == b.arm and self.mode in (MODE_IDLE, MODE_LAND, MODE_KILL):
                self.mode = MODE_ARM
            elif index == b.fly and self.mode in (MODE_ARM, MODE_LAND):
                self.mode = MODE_FLY
            elif index == b.land and self.mode in (MODE_ARM, MODE_FLY):
                self.mode = MODE_LAND
        self._pending_edges.clear()

    def _channel_input(self, channel: ChannelConfig) -> float:
        if channel.buttons is not None:
            plus, minus = channel.buttons
            value = float(self._buttons[plus] != 0) if plus < len(self._buttons) else 0.0
            value -= float(self._buttons[minus] != 0) if minus < len(self._buttons) else 0.0
            return value
        return apply_dead_zone(float(self._axes[channel.axis]) - channel.center, channel.dead_zone)

    def _limits(self, name: str) -> tuple[float, float]:
        channel = self.config.channels[name]
        low, high = channel.minimum, channel.maximum
        if name == "leg_angle" and self.leg_range is not None:
            try:
                feasible_low, feasible_high = self.leg_range(self._targets["roll"], self._targets["pitch"])
            except (ValueError, ArithmeticError):
                feasible_low, feasible_high = low, high
            if math.isfinite(feasible_low) and math.isfinite(feasible_high) and feasible_low <= feasible_high:
                new_low, new_high = max(low, feasible_low), min(high, feasible_high)
                if new_low <= new_high:
                    low, high = new_low, new_high
        return low, high

    def step(self, t: float, dt: float, measured_leg_angle: float | None = None,
             external: Mapping[str, float] | None = None) -> TeleopOutput:
        """Advance targets and filters by dt [s] at time t [s] and return χ_d, χ̇_d (4.25)-(4.26).
        ``measured_leg_angle`` [rad]: the robot's current common leg angle (None: unknown), used before FLY
        when ``start_from_robot`` is set; non-finite values count as unknown. ``external``: channel name ->
        target (channel units) replacing the operator's input for that channel, in FLY with a live joystick
        only (module doc); non-finite values and unknown names are ignored."""
        previous_mode = self.mode
        self._update_mode()
        stale = self.joy_stale(t)
        used_external: dict[str, float] = {}
        if external and self.mode == MODE_FLY and not stale:
            used_external = {name: float(value) for name, value in external.items()
                             if name in self._targets and math.isfinite(value)}
        on_ground = self.start_from_robot and self.mode in GROUND_MODES
        if measured_leg_angle is not None and not math.isfinite(measured_leg_angle):
            measured_leg_angle = None
        follow_legs = on_ground and measured_leg_angle is not None
        held = ATTITUDE_CHANNELS + ("leg_angle",) if follow_legs else ATTITUDE_CHANNELS
        for name in CHANNELS:
            channel = self.config.channels[name]
            u = 0.0 if stale else self._channel_input(channel)
            if name in used_external:
                target = used_external[name]
            elif on_ground and name in ATTITUDE_CHANNELS:
                target = channel.initial  # the robot rests level (configured initial: 0)
            elif follow_legs and name == "leg_angle":
                target = measured_leg_angle
            elif channel.mode == "absolute":
                if stale and name not in RATE_CHANNELS:
                    target = self._targets[name]  # hold the last value
                else:
                    target = channel.initial + channel.scale * u
            else:
                target = self._targets[name] + channel.scale * u * dt
            low, high = self._limits(name)
            self._targets[name] = min(max(target, low), high)
        tau = self.config.time_constant
        alpha = 1.0 - math.exp(-dt / tau) if dt > 0.0 else 0.0
        rates = {}
        for name in CHANNELS:
            if on_ground and name in held:
                self._filtered[name] = self._targets[name]  # start configuration: χ_d = target, χ̇_d = 0
            else:
                self._filtered[name] += alpha * (self._targets[name] - self._filtered[name])
            rates[name] = (self._targets[name] - self._filtered[name]) / tau
        if on_ground:
            self._update_leg_source(follow_legs)
        if self.mode == MODE_FLY and previous_mode in GROUND_MODES:
            source = self.leg_source if self.start_from_robot else "initial_legs_from_info off"
            self._reports.append(f"FLY: common leg angle starts at {math.degrees(self._targets['leg_angle']):.1f} "
                                 f"deg ({source})")
        f, n = self._filtered, self.config.n
        return TeleopOutput(
            mode=self.mode,
            platform_velocity=np.array([f["velocity_x"], f["velocity_y"], f["velocity_z"]]),
            platform_acceleration=np.array([rates["velocity_x"], rates["velocity_y"], rates["velocity_z"]]),
            yaw_rate=f["yaw_rate"],
            yaw_acceleration=rates["yaw_rate"],
            roll=f["roll"],
            roll_rate=rates["roll"],
            pitch=f["pitch"],
            pitch_rate=rates["pitch"],
            leg_angles=np.full(n, f["leg_angle"]),
            leg_rates=np.full(n, rates["leg_angle"]),
            contact_force=f["contact_force"],
            joy_stale=stale,
            external_channels=tuple(name for name in CHANNELS if name in used_external),
        )

    def _update_leg_source(self, followed: bool) -> None:
        if followed:
            source = LEG_SOURCE_INFO
        elif self.leg_source == LEG_SOURCE_CONFIGURED:
            source = LEG_SOURCE_CONFIGURED
        else:
            source = LEG_SOURCE_INFO_STALE
        if source != self.leg_source:
            self._reports.append(f"leg angle command: {source}, "
                                 f"{math.degrees(self._targets['leg_angle']):.1f} deg")
            self.leg_source = source

    def take_reports(self) -> list[str]:
        """One-off notices since the last call (the leg-angle source changed; FLY engaged from it), for a log."""
        reports, self._reports = self._reports, []
        return reports

    @property
    def targets(self) -> dict[str, float]:
        """Current (clamped, unfiltered) channel targets."""
        return dict(self._targets)


def config_from_dict(d: dict, n: int = 3) -> TeleopConfig:
    """Build a :class:`TeleopConfig` from the YAML structure of ``config/teleop.yaml`` (angles in degrees
    where the key ends in ``_deg``)."""
    channels = {}
    for name in CHANNELS:
        raw = dict(d["channels"][name])
        for key in list(raw):
            if key.endswith("_deg"):
                raw[key[:-4]] = math.radians(float(raw.pop(key)))
        if "buttons" in raw and raw["buttons"] is not None:
            raw["buttons"] = tuple(int(b) for b in raw["buttons"])
        channels[name] = ChannelConfig(**raw)
    buttons = ButtonConfig(**d.get("buttons", {}))
    return TeleopConfig(
        channels=channels,
        buttons=buttons,
        time_constant=float(d.get("time_constant", 0.3)),
        expected_axes=int(d.get("expected_axes", 8)),
        min_buttons=int(d.get("min_buttons", 7)),
        joy_timeout=float(d.get("joy_timeout", 0.5)),
        n=n,
    )
