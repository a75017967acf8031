"""The bridge core (ROS-free): setpoints in, SET_ATTITUDE_TARGET stream out, PX4 state and telemetry back.

One :class:`Px4Bridge` per UAV. The node calls, with its ROS clock time ``now`` [s]:
- :meth:`Px4Bridge.submit_setpoint` for each ``AttitudeThrustSetpoint`` (validated; forwarded at once when
  streaming and the current stream slot is free, so the latency to the wire is then one encode + send);
- :meth:`Px4Bridge.on_teleop` for each ``/fpr/teleop`` mode;
- :meth:`Px4Bridge.tick` at ``stream_rate`` (>= 50 Hz): state machine, the stream slots (below), COMMAND_LONGs,
  the telemetry rates asked of PX4 once it is heard (``message_rates``, :mod:`fpr_px4_bridge.streams`), the 1 Hz
  HEARTBEAT (MAV_TYPE_ONBOARD_CONTROLLER);
- :meth:`Px4Bridge.poll` from its receive thread: PX4 messages -> state machine and ENU/FLU telemetry samples.

Stream rate: one SET_ATTITUDE_TARGET per stream period T = 1 / ``stream_rate`` while streaming. Time is cut into
slots of one period on a fixed grid of the clock, slot k = [k T, (k + 1) T) (an instant within 1e-6 T before a
boundary counts as after it: float rounding of the clock), so a late timer, a timer ticking at twice the rate or a
controller out of phase never shifts the slots. Each setpoint belongs to the slot of its OWN instant (its header
stamp, see below; 'now' when the stamp is unusable):

- a new setpoint goes out at once unless a setpoint of the same slot of its own instant already went out (a
  controller faster than ``stream_rate``, or jitter across a boundary) and the slot of the clock that just ended
  carried a frame: that one is held, and either a newer setpoint supersedes it or it fills the next slot of the
  clock that would otherwise end without a frame (the latest one wins);
- a slot of the clock that ends with no frame gets the latest setpoint, sent by the tick that closes it (a held
  one, or a repetition while the setpoint is younger than ``setpoint_timeout``).

So a controller publishing at ``stream_rate`` has each of its setpoints sent once, at once, and nothing else (no
doubled frames); a slower or stalled one is topped up with repetitions to ``stream_rate``; a faster one is thinned
to it. (Before issue 13 every new setpoint was sent at once AND again by the tick: twice the configured rate.)
Slots of the setpoints' own instants, not of their arrival: a setpoint that arrives after the tick of the next
period (its /clock came late) is not held, and does not make the next one wait either. (Before, a setpoint
arriving in a clock slot that already had a frame was held and sent by the next tick as that slot's frame, so
the next setpoint was held in turn: once a single setpoint arrived late, every later one left a period late — in
the simulation's lockstep, which waits for each period's setpoint before the clock moves on, each period then
waited for the lockstep watchdog: 331 timed-out periods in a 24 s fault flight.)

Setpoint time: each SET_ATTITUDE_TARGET carries in ``time_boot_ms`` the SETPOINT's own instant (the
``AttitudeThrustSetpoint`` header stamp, the controller's control instant) put on PX4's boot clock by the
telemetry's time sync (:class:`~fpr_px4_bridge.time_sync.BootTimeMapper`: ROS time = boot time + offset), computed
once when the setpoint is submitted and kept on its repetitions (a repetition is the same setpoint). Fallbacks:
the stamp is zero, not finite, or more than ``setpoint_timeout`` away from 'now' (another clock) -> 'now' is
mapped instead; the offset is not known yet (no telemetry) -> 'now' − the bridge's start (``boot_time``), the
former stamping. Real PX4 ignores ``time_boot_ms`` in SET_ATTITUDE_TARGET, so this is harmless on the robot; the
simulator's PX4 emulator uses it for its lockstep (a repetition of an old setpoint does not count as the
controller's output for a new control period, fpr_sim.simulation).

Thrust: newtons -> PX4 normalized thrust by (C.1)-(C.2) with the live battery voltage (:mod:`fpr_model.battery`),
clamped to [thrust_min, 1] (``battery_compensation``, the default: the thrust regulation of thesis Appendix C).
With ``battery_compensation`` off, f_max is taken at the fixed ``nominal_voltage`` instead, whatever PX4 reports,
as in the first Exp. I flights before the thrust regulation (thesis §3.5.1, l.5016-5020): the produced thrust then
falls as the battery sags, and the observers see a slowly growing negative z external force.
Thrust ceiling (issue 12, bounded inputs): a setpoint thrust above ``thrust_refusal_ratio`` · f_max (f_max of
(C.2) at the voltage the normalization uses right now, :meth:`Px4Bridge.max_thrust`) is REFUSED, not clamped: a
1e9 N command means the sender is broken. The refused setpoint is not stored; the last valid one keeps streaming
until it is ``setpoint_timeout`` old (then the stream stops and PX4's offboard-loss failsafe acts). Each refusal is
counted (``thrust_refusals``, and in ``rejected_setpoints`` of the status) and announced by one rate-limited
warning "setpoint thrust X N above the ceiling ... refused". A thrust in (f_max, ratio · f_max] is a controller
saturating against a sagging battery (its own f_max is a fixed number): it is flown as before at normalized 1.0
(counted in ``thrust_saturations``, one rate-limited warning), because refusing it would stop the stream of a
healthy controller at full throttle. ``thrust_refusal_ratio`` = 1.0 refuses everything above f_max. Nothing above
normalized 1.0 ever goes on MAVLink ((C.1) is clamped to [thrust_min, 1]).
The caller serializes access (one lock).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from fpr_model.battery import max_thrust, normalized_thrust
from fpr_model.rotations import quat_tilt

from fpr_px4_bridge.link import MavlinkLink
from fpr_px4_bridge.offboard import BridgeState, CommandRequest, LogEvent, OffboardConfig, OffboardStateMachine
from fpr_px4_bridge.px4_protocol import (
    MAV_AUTOPILOT_INVALID,
    MAV_CMD_SET_MESSAGE_INTERVAL,
    MAV_STATE_ACTIVE,
    MAV_TYPE_GCS,
    MAV_TYPE_ONBOARD_CONTROLLER,
    encode_set_attitude_target,
)
from fpr_px4_bridge.streams import StreamConfigurator, StreamRequest
from fpr_px4_bridge.swarm_guard import SwarmGuard, SwarmGuardConfig, Verdict
from fpr_px4_bridge.telemetry import TelemetryDecoder
from fpr_px4_bridge.time_sync import SimulationBootClock

__all__ = ["BridgeConfig", "BridgeStatus", "Px4Bridge", "SetpointResult"]

#: A battery voltage older than this is not used for the thrust normalization [s].
_VOLTAGE_MAX_AGE = 5.0
#: [stream periods] a tick or setpoint this close before a slot boundary counts as in the next slot (clock rounding).
_SLOT_EPSILON = 1e-6
#: [stream periods] a setpoint instant this close to a slot boundary re-centres the grid on the controller's phase
_GRID_MARGIN = 0.2


@dataclass(frozen=True)
class BridgeConfig:
    uav_id: int = 1                       #: i in 1..n; setpoints for other ids are refused
    target_system: int = 1                #: PX4 MAVLink system id
    target_component: int = 1             #: PX4 autopilot component id
    stream_rate: float = 50.0             #: [Hz] SET_ATTITUDE_TARGET repetition rate (>= 50)
    setpoint_timeout: float = 0.25        #: [s] a setpoint older than this is not streamed
    thrust_min: float = 0.05              #: lower clamp of the normalized thrust, in [0, 1)
    a_f: float = 8.02                     #: [N/V] (C.2) slope of this vehicle (Table C.1)
    b_f: float = -61.66                   #: [N] (C.2) offset of this vehicle (Table C.1)
    fallback_voltage: float = 12.0        #: [V] used while no (valid) battery voltage is known
    #: True: f_max (C.2) at the reported battery voltage (Appendix C thrust regulation); False: at nominal_voltage
    battery_compensation: bool = True
    #: [V] f_max voltage without battery compensation: 12.4 V, the charged 3S voltage (fpr_sim BatteryConfig)
    nominal_voltage: float = 12.4
    quaternion_tolerance: float = 1e-3    #: refuse setpoints with | |q| - 1 | above this
    #: refuse setpoints with thrust above this times f_max (C.2) at the present voltage; in [1, 2] (module doc)
    thrust_refusal_ratio: float = 1.1
    heartbeat_period: float = 1.0         #: [s] our HEARTBEAT period
    #: "estimate": PX4's time_boot_ms mapped onto the ROS clock by the telemetry's time sync (a real vehicle);
    #: "ros_time": PX4's boot clock is the ROS (simulated) clock, as for PX4 SITL in lockstep and fpr_sim's emulator
    px4_boot_clock: str = "estimate"
    offboard: OffboardConfig = OffboardConfig()
    #: the swarm guard (issue 12's emergency response): off here, on in the node (parameter ``swarm_guard``)
    guard: SwarmGuardConfig = SwarmGuardConfig(enabled=False)
    #: the telemetry rates to ask PX4 for (fpr_px4_bridge.streams): none here, DEFAULT_MESSAGE_RATES in the node
    #: (parameter ``message_rates``)
    message_rates: tuple[StreamRequest, ...] = ()

    def __post_init__(self) -> None:
        if self.px4_boot_clock not in ("estimate", "ros_time"):
            raise ValueError(f"px4_boot_clock must be 'estimate' or 'ros_time', got {self.px4_boot_clock!r}")
        if self.stream_rate < 50.0:
            raise ValueError(f"stream_rate must be >= 50 Hz, got {self.stream_rate}")
        if not 0.0 < self.setpoint_timeout < self.offboard.heartbeat_timeout + 10.0:
            raise ValueError(f"setpoint_timeout must be > 0, got {self.setpoint_timeout}")
        if not 1.0 <= self.thrust_refusal_ratio <= 2.0:
            raise ValueError(f"thrust_refusal_ratio must be in [1, 2], got {self.thrust_refusal_ratio}")
        if not 0.0 <= self.thrust_min < 1.0:
            raise ValueError(f"thrust_min must be in [0, 1), got {self.thrust_min}")
        if not all(math.isfinite(v) for v in (self.a_f, self.b_f, self.fallback_voltage, self.nominal_voltage)):
            raise ValueError("a_f, b_f, fallback_voltage and nominal_voltage must be finite")
        if self.a_f * self.fallback_voltage + self.b_f <= 0.0:
            raise ValueError("f_max at fallback_voltage must be > 0 (check a_f, b_f, fallback_voltage)")
        if not self.battery_compensation and self.a_f * self.nominal_voltage + self.b_f <= 0.0:
            raise ValueError("f_max at nominal_voltage must be > 0 (check a_f, b_f, nominal_voltage)")

    def thrust_normalization(self) -> str:
        """One line for a start-up log: how newtons become PX4's normalized thrust."""
        if self.battery_compensation:
            return (f"battery compensation on: f_max = a_f*V + b_f (a_f {self.a_f} N/V, b_f {self.b_f} N) at the "
                    f"voltage V PX4 reports (fallback {self.fallback_voltage} V)")
        f_max = self.a_f * self.nominal_voltage + self.b_f
        return (f"battery compensation OFF: fixed f_max = {f_max:.2f} N at nominal_voltage {self.nominal_voltage} V "
                "(the true thrust falls as the battery sags)")


@dataclass(frozen=True)
class SetpointResult:
    accepted: bool
    sent: bool
    reason: str = ""


@dataclass(frozen=True)
class BridgeStatus:
    """The content of ``fpr_msgs/UavStatus`` (without header)."""

    uav_id: int
    state: int
    connected: bool
    armed: bool
    offboard: bool
    failsafe: bool
    px4_custom_mode: int
    mode_name: str
    battery_voltage: float
    battery_remaining: float
    link_age: float
    setpoint_rate: float
    rx_garbage: int
    rejected_setpoints: int
    thrust_refusals: int = 0  #: of rejected_setpoints: thrust above the ceiling
    thrust_saturations: int = 0  #: setpoints in (f_max, ceiling]: flown at normalized 1.0
    emergency: bool = False  #: in the swarm's emergency response (state EMERGENCY)
    emergency_own: bool = False  #: ... for a cause of this UAV's own (the peers follow it)
    emergency_reason: str = ""
    ready: bool = False  #: could fly OFFBOARD at once (the swarm rejoins together; UavStatus.ready)
    emergency_landing: bool = False  #: the emergency response lands (UavStatus.emergency_landing)


@dataclass
class _Setpoint:
    q_enu_flu: np.ndarray
    thrust_newton: float
    received: float
    time_boot_ms: int  #: the setpoint's own instant on PX4's boot clock (see the module doc)
    instant: float  #: [s] the setpoint's own instant on the local clock (its stamp; its arrival if unusable)


class Px4Bridge:
    """See the module docstring."""

    def __init__(self, config: BridgeConfig, link: MavlinkLink, boot_time: float = 0.0) -> None:
        self.config = config
        self.link = link
        self.machine = OffboardStateMachine(config.offboard)
        self.guard = SwarmGuard(config.guard)
        self.streams = StreamConfigurator(config.message_rates, config.offboard.command_retry_interval,
                                          config.offboard.command_max_attempts)
        self.verdict: Verdict | None = None  #: the guard's latest (None: guard off)
        self.telemetry = TelemetryDecoder(SimulationBootClock() if config.px4_boot_clock == "ros_time" else None)
        self.boot_time = boot_time  # local time that our time_boot_ms counts from
        self._setpoint: _Setpoint | None = None
        self._setpoint_unsent = False  #: the latest setpoint has not been transmitted yet
        self._slot: int | None = None  #: index k of the current stream slot [k T, (k + 1) T)
        self._slot_used = False  #: a SET_ATTITUDE_TARGET was sent in the current slot
        self._sent_instant: float | None = None  #: [s] own instant of the newest setpoint sent (not repeated)
        self._grid_offset = 0.0  #: [s] slot k = [offset + k T, offset + (k + 1) T), centred on the controller
        self._last_heartbeat_sent = -math.inf
        self._sent_times: deque[float] = deque()
        self.rejected_setpoints = 0
        self.setpoints_sent = 0
        self.repetitions_sent = 0  #: SET_ATTITUDE_TARGETs that repeated an already sent setpoint (slot top-ups)
        self.voltage_fallbacks = 0
        self.stamp_fallbacks = 0  #: setpoints whose header stamp could not be used (not 0, but invalid)
        self.thrust_refusals = 0  #: setpoints refused for a thrust above the ceiling (module doc)
        self.thrust_saturations = 0  #: setpoints in (f_max, ceiling], flown at normalized thrust 1.0
        self._pending_events: list[LogEvent] = []

    # ---- events --------------------------------------------------------------------------------------------
    def _event(self, level: str, key: str, text: str) -> None:
        self._pending_events.append(LogEvent(level, key, text))

    def take_events(self) -> list[LogEvent]:
        events, self._pending_events = self._pending_events, []
        return events

    # ---- setpoints -----------------------------------------------------------------------------------------
    def _validate(self, q_enu_flu, thrust_newton: float, uav_id: int,
                  now: float) -> tuple[np.ndarray | None, str]:
        if int(uav_id) != self.config.uav_id:
            return None, f"setpoint for uav_id {uav_id} refused by the bridge of uav {self.config.uav_id}"
        q = np.asarray(q_enu_flu, dtype=float)
        if q.shape != (4,) or not np.isfinite(q).all():
            return None, f"setpoint attitude not finite: {q.tolist()}"
        norm = math.sqrt(float(q @ q))
        if abs(norm - 1.0) > self.config.quaternion_tolerance:
            return None, f"setpoint attitude not a unit quaternion (norm {norm:.6g})"
        thrust = float(thrust_newton)
        if not math.isfinite(thrust) or thrust < 0.0:
            return None, f"setpoint thrust must be finite and >= 0 N, got {thrust}"
        f_max, voltage = self.max_thrust(now)
        ceiling = self.config.thrust_refusal_ratio * f_max
        if thrust > ceiling:
            self.thrust_refusals += 1
            return None, (f"setpoint thrust {thrust:.6g} N above the ceiling {ceiling:.2f} N "
                          f"({self.config.thrust_refusal_ratio:g} x f_max {f_max:.2f} N (C.2) at {voltage:.2f} V): "
                          "refused, the sender is broken; the last valid setpoint streams until setpoint_timeout")
        if thrust > f_max:
            self.thrust_saturations += 1
            self._event("warn", "setpoint.saturated", f"setpoint thrust {thrust:.3f} N above f_max {f_max:.2f} N "
                        f"(C.2) at {voltage:.2f} V (within the ceiling {ceiling:.2f} N): flown at full thrust 1.0")
        return q / norm, ""

    def submit_setpoint(self, q_enu_flu, thrust_newton: float, uav_id: int, now: float,
                        stamp: float = 0.0) -> SetpointResult:
        """A new setpoint (``q`` ``[w, x, y, z]`` body FLU -> local ENU, thrust [N]) with its own instant ``stamp``
        [s] on the local clock (header stamp; 0: none, 'now' is used); refused ones are never sent."""
        q, reason = self._validate(q_enu_flu, thrust_newton, uav_id, now)
        if q is None:
            self.rejected_setpoints += 1
            self._event("warn", "setpoint.refused", reason + " (not forwarded)")
            return SetpointResult(accepted=False, sent=False, reason=reason)
        streaming = self.machine.stream_allowed()
        instant = self._setpoint_instant(stamp, now)
        self._centre_grid(instant, now)
        closing_empty = self._slot is not None and not self._slot_used
        # a new slot opened by a setpoint: the closing one, if empty, gets this setpoint (below), not a repetition
        opened = self._open_slot(now, stream=False)
        self._setpoint = _Setpoint(q_enu_flu=q, thrust_newton=float(thrust_newton), received=now,
                                   time_boot_ms=self._time_boot_ms(instant, now), instant=instant)
        self._setpoint_unsent = True
        new_slot = self._sent_instant is None or self._slot_of(instant) != self._slot_of(self._sent_instant)
        sent = False
        if streaming and (new_slot or (opened and closing_empty)):
            sent = self._transmit(now)  # else held: superseded, or the frame of a slot that would have none
        return SetpointResult(accepted=True, sent=sent)

    def _slot_of(self, instant: float) -> int:
        """Stream slot index k of ``instant`` [s]: [offset + k T, offset + (k + 1) T) (module doc)."""
        return math.floor((instant - self._grid_offset) * self.config.stream_rate + _SLOT_EPSILON)

    def _centre_grid(self, instant: float, now: float) -> None:
        """Put the slot boundaries halfway between the controller's instants (module doc): on the first setpoint,
        and whenever one comes within ``_GRID_MARGIN`` periods of a boundary (a controller (re)started with
        another phase). The current slot of the clock carries over to the moved grid."""
        rate = self.config.stream_rate
        position = ((instant - self._grid_offset) * rate) % 1.0
        if self._sent_instant is not None and _GRID_MARGIN <= position <= 1.0 - _GRID_MARGIN:
            return
        period = 1.0 / rate
        self._grid_offset = math.fmod(instant, period) - 0.5 * period
        if self._slot is not None:
            self._slot = self._slot_of(now)

    def _setpoint_instant(self, stamp: float, now: float) -> float:
        """A setpoint's own instant [s, local clock]: its ``stamp``, or ``now`` when the stamp is zero (none), not
        finite or more than ``setpoint_timeout`` away from ``now`` (another clock: counted and said)."""
        try:
            stamp = float(stamp)
        except (TypeError, ValueError):
            stamp = math.nan
        if math.isfinite(stamp) and stamp > 0.0 and abs(now - stamp) <= self.config.setpoint_timeout:
            return stamp
        if stamp != 0.0 and now > 0.0:  # now 0: no /clock yet (use_sim_time), every stamp is ahead: nominal
            self.stamp_fallbacks += 1
            self._event("warn", "setpoint.stamp", f"setpoint stamp {stamp} s unusable at {now:.3f} s "
                        "(not finite, or another clock): SET_ATTITUDE_TARGET stamped with 'now'")
        return now

    def _time_boot_ms(self, instant: float, now: float) -> int:
        """``time_boot_ms`` of a local-clock ``instant`` [s] submitted at ``now`` (module doc)."""
        boot = self.telemetry.mapper.to_boot(instant)
        if boot is None or boot < 0.0:
            boot = now - self.boot_time  # no time sync yet: the bridge's own clock since its start
        return int(round(max(0.0, boot) * 1000.0)) & 0xFFFFFFFF

    def setpoint_time_boot_ms(self, stamp: float, now: float) -> int:
        """``time_boot_ms`` of a setpoint stamped ``stamp`` [s, local clock] submitted at ``now`` (module doc)."""
        return self._time_boot_ms(self._setpoint_instant(stamp, now), now)

    def setpoint_fresh(self, now: float) -> bool:
        sp = self._setpoint
        return sp is not None and now - sp.received <= self.config.setpoint_timeout

    def battery_voltage(self, now: float) -> float:
        battery = self.telemetry.battery
        if battery is None or not math.isfinite(battery.voltage) or now - battery.stamp > _VOLTAGE_MAX_AGE:
            return math.nan
        return battery.voltage

    def max_thrust(self, now: float) -> tuple[float, float]:
        """(f_max [N], V [V]): f_max = a_f·V + b_f (C.2) at the voltage :meth:`normalized_thrust` uses now (the
        live one, or ``fallback_voltage`` when unknown or outside the model; ``nominal_voltage`` without battery
        compensation)."""
        cfg = self.config
        voltage = cfg.nominal_voltage if not cfg.battery_compensation else self.battery_voltage(now)
        if not math.isfinite(voltage) or max_thrust(voltage, cfg.a_f, cfg.b_f) <= 0.0:
            voltage = cfg.fallback_voltage
        return max_thrust(voltage, cfg.a_f, cfg.b_f), voltage

    def normalized_thrust(self, thrust_newton: float, now: float) -> float:
        """(C.1)-(C.2) with the live voltage; the fallback voltage when it is unknown or outside the model. Without
        battery compensation (config) the fixed ``nominal_voltage``: independent of what PX4 reports."""
        cfg = self.config
        if not cfg.battery_compensation:
            return normalized_thrust(thrust_newton, cfg.nominal_voltage, cfg.a_f, cfg.b_f, cfg.thrust_min)
        voltage = self.battery_voltage(now)
        if math.isfinite(voltage):
            try:
                return normalized_thrust(thrust_newton, voltage, cfg.a_f, cfg.b_f, cfg.thrust_min)
            except ValueError as error:
                self.voltage_fallbacks += 1
                self._event("warn", "thrust.voltage", f"{error}; using fallback_voltage {cfg.fallback_voltage} V")
        return normalized_thrust(thrust_newton, cfg.fallback_voltage, cfg.a_f, cfg.b_f, cfg.thrust_min)

    def _send_setpoint(self, now: float) -> bool:
        sp = self._setpoint
        if sp is None:
            return False
        cfg = self.config
        thrust = self.normalized_thrust(sp.thrust_newton, now)
        msg = encode_set_attitude_target(self.link.mav, sp.time_boot_ms, cfg.target_system, cfg.target_component,
                                         sp.q_enu_flu, thrust)
        if not self.link.send(msg):
            return False
        self.setpoints_sent += 1
        self._sent_times.append(now)
        return True

    def _transmit(self, now: float) -> bool:
        """Send the latest setpoint as the current slot's frame (first transmission or repetition)."""
        repetition = not self._setpoint_unsent
        if not self._send_setpoint(now):
            return False
        self._slot_used = True
        if self._setpoint_unsent and self._setpoint is not None:
            self._sent_instant = self._setpoint.instant
        self._setpoint_unsent = False
        self.repetitions_sent += int(repetition)
        return True

    def _open_slot(self, now: float, stream: bool) -> bool:
        """Open the clock slot of ``now`` [s] if it is a new one (module doc): first fill the closing slot if it
        carried no frame (``stream``: the state machine streams and a fresh setpoint exists) with the latest
        setpoint (a held one, or a repetition). True if opened."""
        slot = self._slot_of(now)
        if self._slot is not None and slot <= self._slot:
            return False  # same slot: timer jitter, a caller ticking faster than stream_rate, a second setpoint
        if stream and self._slot is not None and not self._slot_used:
            self._transmit(now)  # the closing slot's frame: a held setpoint or a repetition
        self._slot = slot
        self._slot_used = False
        return True

    def _stream_slots(self, now: float, stream: bool) -> None:
        """The tick's part of the stream-rate rule (module doc): at a clock-slot boundary, fill the closing slot if
        it has no frame and open the next one. ``stream``: the state machine streams now (a fresh setpoint
        exists). Times [s]."""
        self._open_slot(now, stream)

    def setpoint_rate(self, now: float) -> float:
        """Measured SET_ATTITUDE_TARGET output rate over the last second [Hz]."""
        times = self._sent_times
        while times and now - times[0] > 1.0:
            times.popleft()
        return float(len(times))

    # ---- operator and periodic work ----------------------------------------------------------------------
    def on_teleop(self, mode: int, now: float) -> None:
        self.machine.on_teleop(mode, now)

    def tick(self, now: float) -> list[LogEvent]:
        """Periodic step at ``stream_rate`` (time ``now`` [s]): state machine, stream slots, commands, HEARTBEAT."""
        fresh = self.setpoint_fresh(now)
        self.verdict = None
        if self.config.guard.enabled:
            self._feed_guard_from_telemetry(now)
            flying = self.machine.state in (BridgeState.OFFBOARD, BridgeState.EMERGENCY, BridgeState.WARMUP) and \
                self.machine.armed
            self.verdict = self.guard.evaluate(now, fresh, flying)
            if not self.machine.armed:
                self.guard.reset_latch()
        decision = self.machine.step(now, fresh, self.verdict)
        self._stream_slots(now, decision.stream)
        cfg = self.config
        for command in decision.commands:
            self._send_command(command)
            self._event("info", f"command.{command.label}", f"sent {command.label} (MAV_CMD {command.command})")
        for command in self.streams.step(now, self.machine.connected(now)):
            self._send_command(command)  # the stream configurator logs one line when done
        self._pending_events.extend(self.streams.take_events())
        if now - self._last_heartbeat_sent >= cfg.heartbeat_period or now < self._last_heartbeat_sent:
            self._last_heartbeat_sent = now
            self.link.send(self.link.mav.heartbeat_encode(
                type=MAV_TYPE_ONBOARD_CONTROLLER, autopilot=MAV_AUTOPILOT_INVALID, base_mode=0, custom_mode=0,
                system_status=MAV_STATE_ACTIVE))
        return decision.events + self.take_events()

    def _send_command(self, command: CommandRequest) -> None:
        cfg = self.config
        self.link.send(self.link.mav.command_long_encode(
            target_system=cfg.target_system, target_component=cfg.target_component,
            command=command.command, confirmation=0,
            param1=command.params[0], param2=command.params[1], param3=command.params[2],
            param4=command.params[3], param5=command.params[4], param6=command.params[5],
            param7=command.params[6]))

    def _feed_guard_from_telemetry(self, now: float) -> None:
        """The envelope inputs of the swarm guard: PX4's local position (height, climb rate, horizontal position)
        and the tilt."""
        position = self.telemetry.local_position
        attitude = self.telemetry.attitude
        if position is None or attitude is None or now - position.stamp > 0.5:
            return
        tilt = math.degrees(quat_tilt(attitude))
        self.guard.on_local_position(position.height, position.climb_rate, tilt, self.machine.armed,
                                     not self.machine.armed, now, position.north, position.east)

    # ---- reception -----------------------------------------------------------------------------------------
    def handle_message(self, msg, now: float):
        """Dispatch one accepted MAVLink message; return a telemetry sample for the node to publish, or None."""
        if msg.get_srcSystem() != self.config.target_system:
            return None
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if msg.autopilot == MAV_AUTOPILOT_INVALID or msg.type in (MAV_TYPE_GCS, MAV_TYPE_ONBOARD_CONTROLLER):
                return None  # another component of the vehicle, not the autopilot
            self.machine.on_heartbeat(msg.base_mode, msg.custom_mode, now)
            return None
        if msg.get_srcComponent() == self.config.target_component:
            self.machine.on_frame(now)  # any frame from the autopilot proves it alive (PX4-silence rule)
        if kind == "COMMAND_ACK":
            if msg.command == MAV_CMD_SET_MESSAGE_INTERVAL:
                if msg.get_srcComponent() == self.config.target_component:  # the autopilot's streams, not a camera's
                    self.streams.on_command_ack(msg.result, now)
            else:
                self.machine.on_command_ack(msg.command, msg.result, now)
            return None
        try:
            return self.telemetry.decode(msg, now)
        except (ValueError, TypeError, AttributeError, IndexError) as error:
            self._event("warn", "telemetry.bad", f"dropping malformed {kind}: {error}")
            return None

    def poll(self, now: float, timeout: float = 0.0) -> list:
        """Receive what is pending on the link (waiting up to ``timeout``); return the telemetry samples."""
        samples = []
        for msg in self.link.receive(timeout):
            sample = self.handle_message(msg, now)
            if sample is not None:
                samples.append(sample)
        return samples

    # ---- status --------------------------------------------------------------------------------------------
    def status(self, now: float) -> BridgeStatus:
        machine = self.machine
        battery = self.telemetry.battery
        return BridgeStatus(
            uav_id=self.config.uav_id,
            state=int(machine.reported_state(now)),
            connected=machine.connected(now),
            armed=machine.armed,
            offboard=machine.px4_mode.is_offboard,
            failsafe=machine.failsafe,
            px4_custom_mode=machine.custom_mode,
            mode_name=machine.px4_mode.name if machine.custom_mode_seen else "",
            battery_voltage=battery.voltage if battery is not None else math.nan,
            battery_remaining=battery.remaining if battery is not None else math.nan,
            link_age=machine.link_age(now),
            setpoint_rate=self.setpoint_rate(now),
            rx_garbage=self.link.counters.rx_rejected,
            rejected_setpoints=self.rejected_setpoints,
            thrust_refusals=self.thrust_refusals,
            thrust_saturations=self.thrust_saturations,
            emergency=machine.state == BridgeState.EMERGENCY,
            emergency_own=machine.own_emergency,
            emergency_reason=machine.emergency.reason if machine.emergency is not None else "",
            ready=machine.ready(now, self.setpoint_fresh(now)),
            emergency_landing=machine.emergency_landing,
        )

    @property
    def state(self) -> BridgeState:
        return self.machine.state
