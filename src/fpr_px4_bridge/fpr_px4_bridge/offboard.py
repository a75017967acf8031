"""Arming / offboard state machine of one bridge (ROS-free, explicit time, no I/O).

Inputs: the operator's mode (``TeleopCommand.mode``: IDLE, ARM, FLY, LAND, KILL), PX4 HEARTBEATs (armed flag,
custom mode), every other frame from PX4 (proof of life), COMMAND_ACKs, and whether a fresh setpoint exists.
Output of :meth:`OffboardStateMachine.step`: whether to stream setpoints now, which COMMAND_LONGs to send, and
log events.

States (``UavStatus.STATE_*``): IDLE -> ARMING (COMPONENT_ARM_DISARM, retried) -> WARMUP (streaming; with FLY,
after ``offboard_warmup`` >= 1 s of continuous stream: DO_SET_MODE OFFBOARD, retried until the HEARTBEAT shows
OFFBOARD, spec px4_ros_facts.md §1.4-1.5) -> OFFBOARD. LAND -> LANDING (DO_SET_MODE AUTO.LAND until the
HEARTBEAT shows it; IDLE once disarmed). KILL -> KILLED (forced disarm, optionally flight termination, latched
until IDLE). FAILSAFE: in OFFBOARD the setpoints went stale (the stream stops so that PX4's own offboard-loss
failsafe acts) or PX4 left OFFBOARD / disarmed on its own; latched until the operator changes the mode. With
the swarm guard (:mod:`fpr_px4_bridge.swarm_guard`, a :class:`~fpr_px4_bridge.swarm_guard.Verdict` passed to
:meth:`OffboardStateMachine.step`) the stale setpoints and PX4 leaving OFFBOARD lead to EMERGENCY instead:

EMERGENCY (issue 12, the swarm's emergency response; README "Emergency response"): entered from OFFBOARD on any
emergency verdict (own or a peer's). The bridge puts PX4 in Hold (DO_SET_MODE AUTO.LOITER: PX4's position
control holds this UAV where it is, and with every UAV holding, the structure keeps its shape) and keeps the
setpoint stream going while the controller delivers (PX4 ignores it in Hold; it lets OFFBOARD resume at once).
Then either the cause clears (and stays clear ``rejoin_delay``) while the operator still says FLY: WARMUP ->
OFFBOARD, the UAV rejoins without anybody landing; or it persists ``emergency_hold_time`` (or is latched: the
flight envelope) and the bridge commands AUTO.LAND (the whole swarm lands in shape, each UAV holding its x/y);
IDLE once disarmed. PX4 already in AUTO.LAND on its own (its failsafe) is left landing. The operator's LAND /
KILL / IDLE override the emergency as everywhere.
DISCONNECTED ("PX4 silent") is reported whenever no frame at all came from PX4 for ``heartbeat_timeout`` (0.45 s;
PX4 streams telemetry at >= 50 Hz but HEARTBEAT only at 1-2 Hz, so silence is judged on ANY frame from the
autopilot, not on HEARTBEATs; the next tick logs it: within 0.5 s of the last frame at 50 Hz), and until the
first HEARTBEAT; the state underneath is kept. While silent, command retries are held.

Order, ARM first and OFFBOARD after: PX4's offboard examples request OFFBOARD first and then arm; PX4 accepts
both (it takes DO_SET_MODE OFFBOARD while disarmed once a setpoint stream is present). Kept deliberately: (1) a
refused ARM (pre-flight checks, safety switch) ends the sequence with PX4 still in the pilot's mode, never left
disarmed in OFFBOARD, where a later arm from anywhere would put the controller's thrust on the motors at once;
(2) the OFFBOARD switch, the moment the FPR controller takes the thrust, comes only once PX4 reports armed and the
stream has run ``offboard_warmup`` (the stream already runs while ARMING, so PX4's proof-of-life rule is met
either way); (3) the simulator's PX4 emulator, the tests and the recorded results use this sequence.

Disarming: the bridge never disarms on its own initiative. It starts in IDLE and, when PX4 is already armed (a
scenario that starts hovering, or a bridge restarted in flight), only reports PX4's state (armed, mode) and waits
for the operator (FLY takes over the stream, LAND lands, KILL disarms). A plain DISARM is sent only on the
operator's explicit transition to IDLE from ARM, FLY or LAND, and only while PX4 reports armed within
``command_max_attempts`` × ``command_retry_interval`` of that transition (PX4 refuses it in the air unless it
thinks it has landed); KILL stays the forced disarm.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

from fpr_px4_bridge.px4_protocol import (
    FORCE_DISARM_MAGIC,
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_DO_FLIGHTTERMINATION,
    MAV_CMD_DO_SET_MODE,
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_NAMES,
    Px4AutoSubMode,
    Px4MainMode,
    Px4Mode,
    decode_custom_mode,
    is_armed,
    set_mode_params,
)
from fpr_px4_bridge.swarm_guard import Cause, Verdict

__all__ = ["BridgeState", "CommandRequest", "Decision", "LogEvent", "OffboardConfig", "OffboardStateMachine",
           "TeleopMode"]


class BridgeState(IntEnum):
    """Same values as ``fpr_msgs/UavStatus.STATE_*``."""

    DISCONNECTED = 0
    IDLE = 1
    ARMING = 2
    WARMUP = 3
    OFFBOARD = 4
    LANDING = 5
    KILLED = 6
    FAILSAFE = 7
    EMERGENCY = 8


class TeleopMode(IntEnum):
    """Same values as ``fpr_msgs/TeleopCommand.MODE_*``."""

    IDLE = 0
    ARM = 1
    FLY = 2
    LAND = 3
    KILL = 4


@dataclass(frozen=True)
class OffboardConfig:
    #: [s] no frame at all from PX4 for this long -> "PX4 silent" (DISCONNECTED), seen at the next tick: with the
    #: 50 Hz tick, reported within 0.45 + 0.02 < 0.5 s of PX4's last frame (the project's target)
    heartbeat_timeout: float = 0.45
    offboard_warmup: float = 1.2         #: [s] continuous stream before DO_SET_MODE OFFBOARD (PX4 wants > 1 s)
    command_retry_interval: float = 0.5  #: [s] between retries of an unconfirmed command
    command_max_attempts: int = 6        #: attempts of ARM / OFFBOARD / LAND before giving up (kill never gives up)
    kill_flight_termination: bool = False  #: also send DO_FLIGHTTERMINATION on KILL (PX4 needs a reboot after)
    #: [s] EMERGENCY: Hold this long waiting for the cause to clear, then AUTO.LAND (= PX4's COM_FAIL_ACT_T, 5 s,
    #: so that a UAV whose bridge died, in PX4's own Hold-then-Land failsafe, lands with the others)
    emergency_hold_time: float = 5.0
    rejoin_delay: float = 0.5            #: [s] EMERGENCY: the cause must stay clear this long before rejoining
    #: [s] an emergency within this long of the last rejoin is a flapping cause (e.g. an estimator that keeps losing
    #: its track after a restart): no more rejoins, AUTO.LAND at once, said as this UAV's own so the swarm follows
    rejoin_window: float = 10.0

    def __post_init__(self) -> None:
        if self.offboard_warmup < 1.0:
            raise ValueError("offboard_warmup must be >= 1.0 s (PX4 needs > 1 s of stream before OFFBOARD)")
        if self.heartbeat_timeout <= 0.0 or self.command_retry_interval <= 0.0 or self.command_max_attempts < 1:
            raise ValueError("heartbeat_timeout and command_retry_interval must be > 0, command_max_attempts >= 1")
        if not (0.0 <= self.emergency_hold_time < 600.0 and 0.0 <= self.rejoin_delay < 60.0
                and 0.0 <= self.rejoin_window < 3600.0):
            raise ValueError("emergency_hold_time must be in [0, 600) s, rejoin_delay in [0, 60) s and "
                             "rejoin_window in [0, 3600) s")


@dataclass(frozen=True)
class CommandRequest:
    """A COMMAND_LONG to send: MAV_CMD id, params 1-7, and a label for logs and ACK matching."""

    command: int
    params: tuple[float, float, float, float, float, float, float]
    label: str


@dataclass(frozen=True)
class LogEvent:
    level: str  #: "info", "warn" or "error"
    key: str    #: for rate limiting
    text: str


@dataclass
class Decision:
    stream: bool
    commands: list[CommandRequest] = field(default_factory=list)
    events: list[LogEvent] = field(default_factory=list)


def _params(*values: float) -> tuple[float, float, float, float, float, float, float]:
    padded = list(values) + [0.0] * (7 - len(values))
    return tuple(float(v) for v in padded)  # type: ignore[return-value]


ARM = CommandRequest(MAV_CMD_COMPONENT_ARM_DISARM, _params(1.0), "ARM")
DISARM = CommandRequest(MAV_CMD_COMPONENT_ARM_DISARM, _params(0.0), "DISARM")
FORCE_DISARM = CommandRequest(MAV_CMD_COMPONENT_ARM_DISARM, _params(0.0, FORCE_DISARM_MAGIC), "FORCE_DISARM")
SET_OFFBOARD = CommandRequest(MAV_CMD_DO_SET_MODE, _params(*set_mode_params(Px4MainMode.OFFBOARD)), "OFFBOARD")
SET_LAND = CommandRequest(MAV_CMD_DO_SET_MODE, _params(*set_mode_params(Px4MainMode.AUTO, Px4AutoSubMode.LAND)),
                          "AUTO.LAND")
SET_HOLD = CommandRequest(MAV_CMD_DO_SET_MODE,
                          _params(*set_mode_params(Px4MainMode.AUTO, Px4AutoSubMode.LOITER)), "AUTO.LOITER")
TERMINATE = CommandRequest(MAV_CMD_DO_FLIGHTTERMINATION, _params(1.0), "FLIGHT_TERMINATION")

_STREAMING_STATES = (BridgeState.ARMING, BridgeState.WARMUP, BridgeState.OFFBOARD, BridgeState.EMERGENCY)


class OffboardStateMachine:
    """See the module docstring. Times are seconds on one clock (ROS time, simulated or wall)."""

    def __init__(self, config: OffboardConfig | None = None) -> None:
        self.config = config or OffboardConfig()
        self.mode = TeleopMode.IDLE
        self._state = BridgeState.IDLE
        self._last_heartbeat: float | None = None  #: [s] last HEARTBEAT from the autopilot
        self._last_frame: float | None = None  #: [s] last frame of any kind from the autopilot
        self.armed = False
        self.px4_mode: Px4Mode = decode_custom_mode(0)
        self.custom_mode = 0
        self.custom_mode_seen = False  # a HEARTBEAT has been received
        self._was_connected = False
        self.link_was_up = False  #: the PX4 link was up (connected) once: a silence before is a start-up
        self._stream_since: float | None = None
        self._attempts: dict[str, int] = {}
        self._last_sent: dict[str, float] = {}
        self._events: list[LogEvent] = []
        self._seen_offboard = False
        self._seen_land = False
        self.offboard_requested_at: float | None = None
        #: the operator's IDLE after ARM / FLY / LAND: DISARM while PX4 is armed, until this time (None: never)
        self._disarm_until: float | None = None
        self._armed_idle_reported = False
        self._emergency_since: float | None = None  #: [s] entry into EMERGENCY
        self._emergency_landing = False  #: EMERGENCY: the hold is over, AUTO.LAND commanded
        self._clear_since: float | None = None  #: [s] EMERGENCY: the cause has been clear since
        self._rejoining = False  #: WARMUP after an EMERGENCY (a new verdict sends it back)
        self._last_rejoin: float | None = None  #: [s] the last EMERGENCY -> WARMUP (rejoin_window)
        self.emergency: Verdict | None = None  #: the verdict that holds the EMERGENCY (None outside it)
        self._verdict: Verdict | None = None  #: the guard's latest verdict (ready())
        self._join_wait_said = False  #: WARMUP joining a swarm in its emergency: said once
        self._wait_said = False  #: EMERGENCY, cause clear, waiting for a peer: said once per emergency

    # ---- inputs ----------------------------------------------------------------------------------------
    @property
    def state(self) -> BridgeState:
        """Internal state (what the bridge is doing), not masked by DISCONNECTED."""
        return self._state

    def reported_state(self, now: float) -> BridgeState:
        return self._state if self.connected(now) else BridgeState.DISCONNECTED

    def connected(self, now: float) -> bool:
        """A HEARTBEAT has been seen and the last frame from PX4 is at most ``heartbeat_timeout`` old."""
        return (self._last_heartbeat is not None and self._last_frame is not None
                and now - self._last_frame <= self.config.heartbeat_timeout)

    def link_age(self, now: float) -> float:
        """[s] since the last frame from PX4 (any message); inf before the first HEARTBEAT."""
        if self._last_heartbeat is None or self._last_frame is None:
            return float("inf")
        return max(0.0, now - self._last_frame)

    @property
    def failsafe(self) -> bool:
        return self._state == BridgeState.FAILSAFE

    def _event(self, level: str, key: str, text: str) -> None:
        self._events.append(LogEvent(level, key, text))

    def _enter(self, state: BridgeState, level: str, text: str) -> None:
        if state != self._state:
            self._event(level, f"state.{state.name}", f"{self._state.name} -> {state.name}: {text}")
            self._state = state
            self._attempts.clear()
            self._last_sent.clear()
            self._seen_offboard = False
            self._seen_land = False
            self._rejoining = False
            self._join_wait_said = self._wait_said = False
            if state != BridgeState.EMERGENCY:
                self.emergency = None
            if state == BridgeState.IDLE:
                self._last_rejoin = None  # landed: a new flight

    def _enter_emergency(self, now: float, verdict: Verdict, context: str = "", resumed: bool = False) -> None:
        """OFFBOARD (or a rejoin) -> EMERGENCY: PX4 Hold now, AUTO.LAND after emergency_hold_time (module doc).
        ``resumed``: a fault during a rejoin's warm-up, before PX4 flew the stream again: the emergency of before
        goes on (its Hold deadline too), not a new one nor a flapping cause (REPEATED) — a restarted node's
        first seconds have transients (fault runs: a restarted controller's status 0.16 s late 0.07 s into the
        rejoin landed the swarm)."""
        since_rejoin = None if self._last_rejoin is None else now - self._last_rejoin
        if resumed and self._emergency_since is not None and not verdict.latched:
            elapsed = now - self._emergency_since
            self._enter(BridgeState.EMERGENCY, "warn",
                        f"swarm emergency ({'own fault' if verdict.own else 'following the swarm'}{context}): "
                        f"{verdict.reason}; PX4 Hold again, AUTO.LAND "
                        f"{max(0.0, self.config.emergency_hold_time - elapsed):.1f} s from now unless it clears "
                        f"(the emergency of {elapsed:.1f} s ago goes on)")
            self.emergency = verdict
            self._emergency_landing = False
            self._clear_since = None
            return
        if since_rejoin is not None and since_rejoin < self.config.rejoin_window and not verdict.latched:
            verdict = Verdict(Cause.REPEATED, f"{verdict.reason}, again {since_rejoin:.1f} s after a rejoin "
                                              f"(rejoin_window {self.config.rejoin_window:g} s)", latched=True)
        source = "own fault" if verdict.own else "following the swarm"
        landing = verdict.cause is Cause.REPEATED
        self._enter(BridgeState.EMERGENCY, "error",
                    f"swarm emergency ({source}{context}): {verdict.reason}; " + (
                        "no more rejoins: AUTO.LAND now" if landing else
                        f"PX4 Hold now, AUTO.LAND after {self.config.emergency_hold_time:g} s unless it clears"))
        self.emergency = verdict
        self._emergency_since = now
        self._emergency_landing = landing
        self._clear_since = None

    def on_frame(self, now: float) -> None:
        """Any accepted frame from the PX4 autopilot at ``now`` [s] (telemetry, ACK, HEARTBEAT): proof of life."""
        if self._last_frame is None or now > self._last_frame:
            self._last_frame = now

    def on_heartbeat(self, base_mode: int, custom_mode: int, now: float) -> None:
        """A HEARTBEAT from the PX4 autopilot (also a frame: :meth:`on_frame`)."""
        self._last_heartbeat = now
        self.on_frame(now)
        armed = is_armed(base_mode)
        mode = decode_custom_mode(custom_mode)
        if mode.name != self.px4_mode.name and self.custom_mode_seen:
            self._event("info", "px4.mode", f"PX4 mode {self.px4_mode.name} -> {mode.name}")
        if armed != self.armed and self.custom_mode_seen:
            self._event("info", "px4.armed", "PX4 armed" if armed else "PX4 disarmed")
        self.armed = armed
        self.px4_mode = mode
        self.custom_mode = int(custom_mode) & 0xFFFFFFFF
        self.custom_mode_seen = True

    def on_command_ack(self, command: int, result: int, now: float) -> None:
        """A COMMAND_ACK: success is still judged from the HEARTBEAT (an ACK does not prove a mode change)."""
        if result not in (MAV_RESULT_ACCEPTED, 5):  # 5: IN_PROGRESS
            name = MAV_RESULT_NAMES.get(result, str(result))
            self._event("warn", f"ack.{command}", f"PX4 answered command {command} with {name}")

    def on_teleop(self, mode: int, now: float) -> None:
        """The operator's mode (TeleopCommand.mode); repeated values are no-ops, unknown values are refused."""
        try:
            new = TeleopMode(int(mode))
        except ValueError:
            self._event("warn", "teleop.bad", f"ignoring unknown teleop mode {mode!r}")
            return
        if new == self.mode:
            return
        self._event("info", "teleop.mode", f"teleop mode {self.mode.name} -> {new.name}")
        previous, self.mode = self.mode, new
        self._disarm_until = None
        state = self._state
        if new == TeleopMode.KILL:
            self._enter(BridgeState.KILLED, "warn", "KILL: forced disarm")
        elif state == BridgeState.KILLED and new != TeleopMode.IDLE:
            self._event("warn", "teleop.killed", f"KILLED is latched: send IDLE before {new.name}")
        elif new == TeleopMode.IDLE:
            explicit = previous in (TeleopMode.ARM, TeleopMode.FLY, TeleopMode.LAND)
            self._enter(BridgeState.IDLE, "info", "IDLE: stream stopped" + (", disarming" if explicit else ""))
            if explicit:
                cfg = self.config
                self._disarm_until = now + cfg.command_max_attempts * cfg.command_retry_interval
                self._attempts.pop(DISARM.label, None)
                self._last_sent.pop(DISARM.label, None)
        elif new == TeleopMode.LAND:
            if self.armed:
                self._enter(BridgeState.LANDING, "info", "LAND requested")
            else:
                self._enter(BridgeState.IDLE, "info", "LAND while disarmed: nothing to land")
        elif new in (TeleopMode.ARM, TeleopMode.FLY):
            if state in (BridgeState.OFFBOARD, BridgeState.EMERGENCY):
                return  # FLY -> ARM while flying keeps flying (an emergency keeps running); LAND / KILL override
            if self.armed:
                self._enter(BridgeState.WARMUP, "info", "armed: streaming")
            else:
                self._enter(BridgeState.ARMING, "info", "arming")

    # ---- commands ----------------------------------------------------------------------------------------
    def _request(self, command: CommandRequest, now: float, decision: Decision, limited: bool = True) -> bool:
        """Queue ``command`` if its retry interval has passed; False once the attempts are exhausted."""
        attempts = self._attempts.get(command.label, 0)
        if limited and attempts >= self.config.command_max_attempts:
            return False
        last = self._last_sent.get(command.label)
        if last is None or now - last >= self.config.command_retry_interval:
            if not self.connected(now):
                return True  # hold retries while PX4 is silent
            decision.commands.append(command)
            self._attempts[command.label] = attempts + 1
            self._last_sent[command.label] = now
        return True

    # ---- step ----------------------------------------------------------------------------------------------
    def step(self, now: float, setpoint_fresh: bool, verdict: Verdict | None = None) -> Decision:
        """Advance at time ``now``; ``setpoint_fresh``: a valid setpoint younger than setpoint_timeout exists;
        ``verdict``: the swarm guard's (None: no guard, the FAILSAFE behaviour of the module doc)."""
        decision = Decision(stream=False)
        self._verdict = verdict
        connected = self.connected(now)
        if connected != self._was_connected:
            if connected:
                self.link_was_up = True
                self._event("info", "link.up", f"PX4 link up: connected (mode {self.px4_mode.name})")
            elif self._last_heartbeat is not None:
                self._event("warn", "link.down",
                            f"PX4 silent / disconnected: no frame from PX4 for {self.link_age(now):.2f} s "
                            f"(heartbeat_timeout {self.config.heartbeat_timeout:g} s): DISCONNECTED")
            self._was_connected = connected
        state = self._state
        offboard = self.px4_mode.is_offboard

        if state == BridgeState.ARMING:
            if self.armed:
                self._enter(BridgeState.WARMUP, "info", "PX4 armed")
            elif not self._request(ARM, now, decision):
                self._enter(BridgeState.IDLE, "error",
                            f"arming failed after {self.config.command_max_attempts} attempts")
        elif state == BridgeState.WARMUP:
            if self._rejoining and verdict is not None and verdict.emergency:
                self._enter_emergency(now, verdict, ", again while rejoining, PX4 not yet in OFFBOARD",
                                      resumed=not offboard)
                self._emergency_step(now, connected, setpoint_fresh, verdict, decision)
            elif verdict is not None and verdict.peer_landing and self.armed:
                # joining a swarm that lands in its emergency response: land with it
                self._enter_emergency(now, Verdict(Cause.PEER, verdict.peer_landing, latched=True), " while joining")
                self._emergency_step(now, connected, setpoint_fresh, verdict, decision)
            elif self.custom_mode_seen and not self.armed and connected:
                self._enter(BridgeState.IDLE, "warn", "PX4 disarmed during warm-up")
            elif offboard and self._stream_since is not None:
                self._enter(BridgeState.OFFBOARD, "info", "PX4 reports OFFBOARD")
            elif (self.mode == TeleopMode.FLY and setpoint_fresh and self._stream_since is not None
                  and now - self._stream_since >= self.config.offboard_warmup):
                if not self._rejoining and verdict is not None and verdict.swarm_emergency:
                    # joining a flying swarm in its emergency response (a restarted bridge): OFFBOARD together
                    # with the others when they rejoin, not alone now (swarm_guard module doc, "Together")
                    if not self._join_wait_said:
                        self._join_wait_said = True
                        self._event("warn", "warmup.join_wait", f"warm-up done, not requesting OFFBOARD: "
                                    f"{verdict.swarm_emergency}; rejoining with the swarm")
                else:
                    if self.offboard_requested_at is None:
                        self.offboard_requested_at = now
                    # OFFBOARD after arming (PX4's examples: before; PX4 accepts both): a refused ARM never leaves
                    # PX4 disarmed in OFFBOARD, and the controller gets the thrust only once armed (module doc)
                    if not self._request(SET_OFFBOARD, now, decision):
                        self._enter(BridgeState.FAILSAFE, "error", f"PX4 did not enter OFFBOARD after "
                                    f"{self.config.command_max_attempts} requests")
        elif state == BridgeState.OFFBOARD:
            if connected and not self.armed:
                self._enter(BridgeState.FAILSAFE, "error", "PX4 disarmed in OFFBOARD")
            elif verdict is not None and verdict.emergency:
                self._enter_emergency(now, verdict)
                self._emergency_step(now, connected, setpoint_fresh, verdict, decision)
            elif verdict is not None and verdict.peer_landing:
                self._enter_emergency(now, Verdict(Cause.PEER, verdict.peer_landing, latched=True))
                self._emergency_step(now, connected, setpoint_fresh, verdict, decision)
            elif not setpoint_fresh:
                self._enter(BridgeState.FAILSAFE, "error",
                            "setpoints stale: stream stopped, PX4 offboard-loss failsafe takes over")
            elif connected and not offboard:
                text = f"PX4 left OFFBOARD on its own ({self.px4_mode.name})"
                if verdict is not None:
                    self._enter_emergency(now, Verdict(Cause.PX4, text))
                    self._emergency_step(now, connected, setpoint_fresh, verdict, decision)
                else:
                    self._enter(BridgeState.FAILSAFE, "error", text)
        elif state == BridgeState.EMERGENCY:
            self._emergency_step(now, connected, setpoint_fresh, verdict, decision)
        elif state == BridgeState.LANDING:
            self._seen_land = self._seen_land or self.px4_mode.is_land
            if not self.armed and connected:
                self._enter(BridgeState.IDLE, "info", "landed and disarmed")
            elif not self.px4_mode.is_land and not self._request(SET_LAND, now, decision):
                self._event("error", "land.failed", "PX4 did not enter AUTO.LAND: land it manually or KILL")
        elif state == BridgeState.KILLED:
            if self.armed or not connected:
                self._request(FORCE_DISARM, now, decision, limited=False)
                if self.config.kill_flight_termination:
                    self._request(TERMINATE, now, decision, limited=False)
        elif state == BridgeState.IDLE:
            self._idle_step(now, decision)

        decision.stream = self._state in _STREAMING_STATES and setpoint_fresh
        if decision.stream:
            if self._stream_since is None:
                self._stream_since = now
        else:
            self._stream_since = None
            if self._state not in (BridgeState.WARMUP,):
                self.offboard_requested_at = None
        decision.events = self._events
        self._events = []
        return decision

    def _emergency_step(self, now: float, connected: bool, setpoint_fresh: bool, verdict: Verdict | None,
                        decision: Decision) -> None:
        """EMERGENCY (module doc): Hold, then AUTO.LAND after emergency_hold_time, or rejoin once clear."""
        cfg = self.config
        if self.custom_mode_seen and not self.armed and connected:
            self._enter(BridgeState.IDLE, "info", "disarmed during the emergency response (landed)")
            return
        held = self.emergency or Verdict(Cause.PEER, "unknown")
        if held.cause is Cause.REPEATED:  # latched by the state machine: keep it (and land), whatever comes
            verdict = held
        active = verdict is not None and verdict.emergency
        if active:
            self.emergency = verdict
            self._clear_since = None
        elapsed = now - (self._emergency_since if self._emergency_since is not None else now)
        if not self._emergency_landing and self.px4_mode.is_land:
            self._emergency_landing = True
            self._event("warn", "emergency.px4_land", f"emergency: PX4 is landing on its own "
                        f"({self.px4_mode.name}, its failsafe): landing with it")
        if not self._emergency_landing and verdict is not None and verdict.peer_landing:
            self._emergency_landing = True
            self._event("error", "emergency.follow_land", f"emergency: {verdict.peer_landing}: AUTO.LAND with it "
                        f"now (after {elapsed:.1f} s of Hold)")
        if not active and self._clear_since is None:
            self._clear_since = now
            self._event("info", "emergency.clear", f"emergency: cause clear (was: {held.reason}); rejoining if it "
                        f"stays clear {cfg.rejoin_delay:g} s and every UAV is ready")
        # rejoin together (swarm_guard module doc): every peer ready, and this UAV too (its stream warmed up), so
        # that each leaves the emergency when the last one is ready and the OFFBOARD requests go out together
        waiting = verdict.waiting if verdict is not None else ""
        if not waiting and not self.ready(now, setpoint_fresh):
            waiting = "this UAV's setpoint stream still warming up"
        waited = now - self._clear_since if self._clear_since is not None else 0.0
        if not self._emergency_landing:
            if active and elapsed >= cfg.emergency_hold_time:
                self._emergency_landing = True
                self._event("error", "emergency.land", f"emergency: {verdict.reason} still after {elapsed:.1f} s "
                            f"(emergency_hold_time {cfg.emergency_hold_time:g} s): AUTO.LAND")
            elif not active and waiting and waited >= cfg.emergency_hold_time:
                self._emergency_landing = True
                self._event("error", "emergency.land", f"emergency: cause clear for {waited:.1f} s but {waiting} "
                            f"(emergency_hold_time {cfg.emergency_hold_time:g} s): AUTO.LAND")
            elif not active:
                if waiting and waited >= cfg.rejoin_delay and not self._wait_said:
                    self._wait_said = True
                    self._event("info", "emergency.wait", f"emergency: cause clear, {waiting}: rejoining together")
                if waited >= cfg.rejoin_delay and self.mode == TeleopMode.FLY and setpoint_fresh and not waiting:
                    self._enter(BridgeState.WARMUP, "warn", f"emergency over after {elapsed:.1f} s (was: "
                                f"{held.reason}): rejoining, OFFBOARD once the stream has run "
                                f"{cfg.offboard_warmup:g} s")
                    self._rejoining = True
                    self._last_rejoin = now
                    return
        if self._emergency_landing:
            if not self.px4_mode.is_land and not self._request(SET_LAND, now, decision):
                self._event("error", "land.failed", "PX4 did not enter AUTO.LAND: land it manually or KILL")
        elif not (self.px4_mode.is_hold or self.px4_mode.is_land) and not self._request(SET_HOLD, now, decision):
            self._emergency_landing = True
            self._event("error", "emergency.hold_failed", f"PX4 did not enter Hold after "
                        f"{cfg.command_max_attempts} requests: AUTO.LAND")

    def _idle_step(self, now: float, decision: Decision) -> None:
        """IDLE: DISARM only for the operator's explicit IDLE (module doc); an armed PX4 is otherwise reported."""
        if self._disarm_until is not None:
            if now > self._disarm_until:
                if self.armed and self.connected(now):
                    self._event("error", "disarm.failed", "PX4 is still armed after the operator's IDLE (it "
                                f"refuses to disarm in the air; mode {self.px4_mode.name}): LAND or KILL")
                self._disarm_until = None
            elif self.armed and self.custom_mode_seen:
                self._request(DISARM, now, decision)
            return
        if self.armed and self.connected(now) and self.mode == TeleopMode.IDLE:
            if not self._armed_idle_reported:
                self._armed_idle_reported = True
                self._event("warn", "px4.armed_idle",
                            f"PX4 is armed in {self.px4_mode.name} while the bridge is IDLE: not disarming, "
                            "waiting for the operator (FLY takes over, LAND lands, KILL disarms)")
        elif not self.armed:
            self._armed_idle_reported = False

    @property
    def own_emergency(self) -> bool:
        """In EMERGENCY for a cause of this UAV's own that still holds (latched, landing, or the guard's latest
        verdict): UavStatus.emergency_own, which the peers follow. Once the own cause clears the peers stop
        following, so that everybody is ready to rejoin together."""
        held = self.emergency
        if self._state != BridgeState.EMERGENCY or held is None or not held.own:
            return False
        if held.latched or self._emergency_landing:
            return True
        verdict = self._verdict
        return verdict is None or (verdict.emergency and verdict.own)

    @property
    def emergency_landing(self) -> bool:
        """The emergency response lands (AUTO.LAND commanded or PX4 landing on its own): UavStatus.emergency_landing,
        said at once so that the peers land with it (PX4's mode in the HEARTBEAT lags by up to its period)."""
        return self._state == BridgeState.EMERGENCY and self._emergency_landing

    def ready(self, now: float, setpoint_fresh: bool) -> bool:
        """UavStatus.ready: this UAV could fly OFFBOARD at once (armed, a fresh stream warmed up for
        ``offboard_warmup``, no cause of its own; in WARMUP, OFFBOARD or an EMERGENCY that is not landing): the swarm
        rejoins together (swarm_guard module doc, "Together")."""
        if self._state not in (BridgeState.WARMUP, BridgeState.OFFBOARD, BridgeState.EMERGENCY):
            return False
        if not (self.armed and setpoint_fresh and self._stream_since is not None
                and now - self._stream_since >= self.config.offboard_warmup):
            return False
        if self._state == BridgeState.EMERGENCY:
            verdict = self._verdict
            return not self._emergency_landing and not (verdict is not None and verdict.emergency and verdict.own)
        return True

    def stream_allowed(self) -> bool:
        """True when the current state streams setpoints (freshness aside)."""
        return self._state in _STREAMING_STATES
