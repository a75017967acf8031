"""One emulated PX4 autopilot per UAV, speaking MAVLink 2 over UDP on 127.0.0.1 as PX4 SITL does. ROS-free.

UDP like PX4 SITL instance k = i − 1 (its MAVLink "onboard" link, the one MAVROS/MAVSDK use): it binds its own
local port ``127.0.0.1:local_port`` (default 14580 + i − 1) and SENDS from the start (HEARTBEAT, telemetry) to the
remote port ``127.0.0.1:remote_port`` (default 14540 + i − 1), where the offboard computer (fpr_px4_bridge, MAVROS,
MAVSDK) listens; afterwards it replies to the address of whoever sent it the last valid frame. ``local_port`` 0
binds an ephemeral port (tests); ``remote_port`` 0 sends nothing until someone talks first. The receive buffer is
enlarged (``SO_RCVBUF`` 1 MiB, capped by net.core.rmem_max): a loopback UDP socket drops datagrams once its
buffer is full, so :meth:`Px4Emulator.poll` must be called continuously (the simulation does, at 250 Hz).
Behaviour (spec px4_ros_facts.md §1.3-§1.5):

- HEARTBEAT as MAV_TYPE_QUADROTOR / MAV_AUTOPILOT_PX4, ``base_mode`` with CUSTOM_MODE_ENABLED (+ SAFETY_ARMED,
  + AUTO|GUIDED|STABILIZE in OFFBOARD/AUTO), ``custom_mode`` = PX4 main/sub mode (fpr_px4_bridge.px4_protocol);
- COMMAND_LONG ARM/DISARM (400), DO_SET_MODE (176), DO_FLIGHTTERMINATION (185) answered with COMMAND_ACK.
  Arming and OFFBOARD need a healthy setpoint stream (gaps < 1/offboard_min_rate for >= offboard_warmup s),
  else TEMPORARILY_REJECTED; in-flight disarm needs the force magic 21196; other commands UNSUPPORTED;
- SET_ATTITUDE_TARGET (NED/FRD quaternion, normalized thrust, type_mask honoured: ATTITUDE_IGNORE -> body rate
  mode, THROTTLE_IGNORE keeps the thrust, yaw rate feed-forward unless bit 4). Each valid message is offboard
  proof of life; a NaN/inf or non-unit quaternion or NaN thrust is rejected (previous setpoint kept, counted);
  thrust is clamped to [0, 1]; messages for another system id are ignored;
- setpoint time (for the simulator's lockstep only; real PX4 ignores ``time_boot_ms`` in SET_ATTITUDE_TARGET):
  ``time_boot_ms`` is read as the setpoint's own instant on this PX4's boot clock (fpr_px4_bridge puts the
  controller's stamp there, and keeps it on its repetitions). :attr:`Px4Emulator.setpoint_time_ms` is the
  instant of the latest setpoint; a message with the same ``time_boot_ms`` as the one before is a repetition
  (counted, still proof of life). (Different, not just later: the sender's boot-time mapping may shift by a few
  ms when its time-sync estimate moves.) ``time_boot_ms`` = 0 means "no time given" (scripted pymavlink
  clients): the message is stamped with its arrival time, i.e. every such message is new, as before this rule.
  :attr:`Px4Emulator.setpoint_latency` keeps the age of each new stamped setpoint on arrival (simulation time −
  its ``time_boot_ms``);
- offboard loss: no setpoint for COM_OF_LOSS_T (1 s) in OFFBOARD -> failsafe: AUTO.LOITER (level attitude,
  last thrust) for ``failsafe_hold_time``, then AUTO.LAND (level, reduced thrust) and disarm once landed;
- outside OFFBOARD (PX4 parameters emulated, :class:`~fpr_sim.scenario.Px4Config` field in brackets), with no
  RC (the FPR flies without one: COM_RCL_EXCEPT excepts OFFBOARD from the RC-loss failsafe):

  * land detector: "landed" = the vehicle's landing gear touches the ground (the plant's contact; PX4's
    MulticopterLandDetector also looks at the thrust and the vertical speed, which this does not model);
  * landed outside OFFBOARD: the motors run at IDLE (normalized thrust 0, the actuator minimum: PWM_MAIN_MIN
    spins the rotors without lift). PX4's position / altitude controllers (POSCTL, ALTCTL) keep a landed vehicle
    at idle until a take-off is asked with the throttle stick, MANUAL/STABILIZED take the throttle from the
    stick, the navigator's LOITER/LAND do not take off: without RC none of them lifts the vehicle. Arming
    before OFFBOARD (fpr_px4_bridge arms, then switches ~1.2 s later) therefore leaves the robot on the ground;
    the offboard setpoints streamed meanwhile are ignored as PX4 does outside OFFBOARD;
  * COM_DISARM_PRFLT (``disarm_preflight_timeout``, 10 s): armed and not taken off (the land detector never
    said airborne) for that long since arming -> auto-disarm, in every mode (PX4 Commander::checkForAutoDisarm);
  * COM_DISARM_LAND (``land_disarm_delay``, 2 s): in AUTO.LAND, landed that long -> disarm; after a take-off,
    landed that long in any mode but OFFBOARD -> disarm (not in OFFBOARD: there PX4's land detector also needs
    a low thrust setpoint, which the gear-contact detector here cannot tell);
  * RC loss (COM_RC_LOSS_T = ``rc_loss_timeout``, 0.5 s): airborne in a mode that needs RC (MANUAL,
    STABILIZED, ALTCTL, POSCTL, ACRO) that long -> failsafe, NAV_RCL_ACT: PX4's default Return needs a global
    position an indoor FPR does not have and falls back to Land, emulated as the offboard-loss chain: hold
    (AUTO.LOITER, ``failsafe_hold_time``, standing in for COM_FAIL_ACT_T) then AUTO.LAND. Until then, and in
    these modes in the air, the emulator flies level with the last thrust (it has no position controller);
- AUTO.LAND (commanded, or the end of a failsafe) is PX4's per-vehicle land: each UAV descends LEVEL at
  ``land_descent_thrust_ratio`` of its last thrust, at idle once its gear touches, and disarms COM_DISARM_LAND
  later. It cannot land an FPR gracefully: the legs are held at their angle by the inward (horizontal)
  components of the tilted thrusts, which level UAVs no longer produce, so the legs splay (fold towards flat)
  while the robot sinks. From 2 m with legs at 60° the robot reaches the ground with the legs on their lower
  joint stop (10°, scenario ``joint_stops``) and comes to rest there (test_px4_emulator.py). Operators should
  descend under the FPR controllers (OFFBOARD) to near the ground and land / disarm there; LAND is a last resort;
- telemetry from simulation time: ATTITUDE_QUATERNION, ATTITUDE, HIGHRES_IMU, LOCAL_POSITION_NED (own frame
  F0i, NED) at ``telemetry_rate``; HEARTBEAT, SYS_STATUS, BATTERY_STATUS at ``status_rate``;
- boot clock: PX4 "boots" at simulation time 0, so ``time_boot_ms`` = :func:`boot_time_ms` (simulation time,
  rounded to the millisecond) in telemetry, and setpoint stamps are compared with simulation instants on the same
  millisecond grid;
- malformed, unknown or unhandled MAVLink is ignored and counted (:attr:`Px4Emulator.counters`).
"""

from __future__ import annotations

import math
import socket
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from fpr_model.frames import enu_to_ned, flu_to_frd, quat_enu_flu_to_ned_frd, quat_ned_frd_to_enu_flu
from fpr_model.rotations import quat_multiply, quat_to_euler_zyx
from fpr_px4_bridge.px4_protocol import (
    ATTITUDE_IGNORE,
    BODY_PITCH_RATE_IGNORE,
    BODY_ROLL_RATE_IGNORE,
    BODY_YAW_RATE_IGNORE,
    FORCE_DISARM_MAGIC,
    MAV_AUTOPILOT_PX4,
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_DO_FLIGHTTERMINATION,
    MAV_CMD_DO_SET_MODE,
    MAV_MODE_FLAG_AUTO_ENABLED,
    MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    MAV_MODE_FLAG_GUIDED_ENABLED,
    MAV_MODE_FLAG_SAFETY_ARMED,
    MAV_MODE_FLAG_STABILIZE_ENABLED,
    MAV_STATE_ACTIVE,
    MAV_TYPE_QUADROTOR,
    THROTTLE_IGNORE,
    Px4AutoSubMode,
    Px4MainMode,
    encode_custom_mode,
    import_mavlink,
    mode_name,
)

from fpr_sim.scenario import Px4Config
from fpr_sim.sensors import ImuSample

__all__ = ["LOCAL_BASE_PORT", "REMOTE_BASE_PORT", "EmulatorCounters", "Px4Emulator", "Px4Setpoint",
           "SetpointLatency", "boot_time_ms"]

#: PX4 SITL instance k binds 127.0.0.1:(14580 + k) and sends to 127.0.0.1:(14540 + k) (its onboard MAVLink link).
LOCAL_BASE_PORT = 14580
REMOTE_BASE_PORT = 14540
_RECEIVE_BUFFER = 1 << 20  # [bytes] requested SO_RCVBUF

MAV_RESULT_ACCEPTED = 0
MAV_RESULT_TEMPORARILY_REJECTED = 1
MAV_RESULT_DENIED = 2
MAV_RESULT_UNSUPPORTED = 3
MAV_STATE_STANDBY = 3
#: modes that need RC sticks (PX4 mode requirement "manual control"): RC-loss failsafe when airborne in them
_RC_MODES = (Px4MainMode.MANUAL, Px4MainMode.STABILIZED, Px4MainMode.ALTCTL, Px4MainMode.POSCTL, Px4MainMode.ACRO)
_UNIT_TOLERANCE = 1e-3


def boot_time_ms(sim_time: float) -> int:
    """The emulated PX4's ``time_boot_ms`` at simulation time ``sim_time`` [s] (it boots at t = 0)."""
    return int(round(max(0.0, sim_time) * 1000.0)) & 0xFFFFFFFF


@dataclass
class EmulatorCounters:
    """Counts of what one emulator received."""

    datagrams: int = 0
    setpoints: int = 0  #: accepted SET_ATTITUDE_TARGET (new ones and repetitions)
    new_setpoints: int = 0  #: accepted with another time_boot_ms than the one before (not a repetition)
    rejected_setpoints: int = 0  #: NaN/inf, non-unit quaternion, NaN thrust
    garbage: int = 0  #: malformed frames (bad CRC, bad length, unknown message id)
    ignored: int = 0  #: valid MAVLink we do not handle, or addressed to another system
    commands: int = 0
    failsafes: int = 0  #: offboard-loss and RC-loss failsafes
    auto_disarms: int = 0  #: COM_DISARM_PRFLT / COM_DISARM_LAND disarms


@dataclass
class SetpointLatency:
    """Ages of the new, stamped setpoints on arrival: simulation time − their ``time_boot_ms`` [s]; the last
    ``history`` (arrival time [s], age [s]) pairs are kept for windowed statistics."""

    count: int = 0
    total: float = 0.0
    max: float = -math.inf
    history: deque = field(default_factory=lambda: deque(maxlen=1 << 17))

    def add(self, arrival: float, age: float) -> None:
        self.count += 1
        self.total += age
        self.max = max(self.max, age)
        self.history.append((arrival, age))

    @property
    def mean(self) -> float:
        return self.total / self.count if self.count else math.nan

    def ages_between(self, start: float, end: float) -> np.ndarray:
        """Ages [s] of the setpoints that arrived in [start, end] (simulation time)."""
        return np.array([age for arrival, age in self.history if start <= arrival <= end], dtype=float)


@dataclass
class Px4Setpoint:
    """What the emulator feeds its attitude controller, in the WORLD frame F0 (ENU/FLU)."""

    quat: np.ndarray  #: [w,x,y,z] body FLU -> world ENU
    thrust: float  #: normalized [0, 1]
    armed: bool
    rate_feedforward: np.ndarray  #: body FLU [rad/s]


class Px4Emulator:
    """PX4 of UAV ``uav_id`` (1-based = MAVLink system id); see the module doc. Call :meth:`poll` and
    :meth:`update` with the simulation time, :meth:`send_telemetry` / :meth:`send_status` when due."""

    def __init__(self, uav_id: int, config: Px4Config, yaw_offset: float, local_port: int | None = None,
                 remote_port: int | None = None, host: str = "127.0.0.1") -> None:
        if host not in ("127.0.0.1", "localhost"):
            raise ValueError(f"MAVLink is loopback-only in this project (DESIGN.md §6), got host {host!r}")
        self.uav_id = int(uav_id)
        self.config = config
        self.yaw_offset = float(yaw_offset)
        mavlink = import_mavlink()
        self._mavlink = mavlink
        self.mav = mavlink.MAVLink(None, srcSystem=self.uav_id, srcComponent=1)
        self.mav.robust_parsing = True
        local_port = LOCAL_BASE_PORT + self.uav_id - 1 if local_port is None else int(local_port)
        remote_port = REMOTE_BASE_PORT + self.uav_id - 1 if remote_port is None else int(remote_port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _RECEIVE_BUFFER)
        except OSError:
            pass  # keep the default buffer
        self.sock.setblocking(False)
        self.sock.bind(("127.0.0.1", local_port))
        self.port: int = self.sock.getsockname()[1]  #: the local (bound) UDP port
        self.receive_buffer: int = self.sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)  #: effective [bytes]
        #: where frames go: the remote port at first, then the sender of the last valid frame (None: nowhere yet)
        self.peer: tuple[str, int] | None = ("127.0.0.1", remote_port) if remote_port > 0 else None
        self.counters = EmulatorCounters()
        self.armed = False
        self.main_mode = Px4MainMode.POSCTL
        self.sub_mode = 0
        self.time = 0.0
        self._stream_start: float | None = None  # start of the current healthy setpoint stream
        self._last_setpoint_time: float | None = None
        self._failsafe_since: float | None = None
        self._landed_since: float | None = None
        self.quat_local = np.array([1.0, 0.0, 0.0, 0.0])  # latest attitude setpoint, F0i ENU/FLU
        self.thrust = 0.0
        self.rate_feedforward = np.zeros(3)
        self.rate_mode = False
        self.landed = True
        #: PX4's _have_taken_off_since_arming: the land detector said airborne while armed
        self.taken_off = False
        self.armed_time: float | None = None  #: simulation time of the last arming [s]
        #: (simulation time [s], reason) of the last auto-disarm (reason 'preflight' or 'landed'), or None
        self.auto_disarm: tuple[float, str] | None = None
        self._rc_loss_since: float | None = None
        #: boot-clock instant [ms] of the latest setpoint (its time_boot_ms; arrival time when that was 0)
        self.setpoint_time_ms: int | None = None
        self.setpoint_latency = SetpointLatency()

    # ------------------------------------------------------------------------------------------ frames
    @property
    def _q_world_from_local(self) -> np.ndarray:
        half = 0.5 * self.yaw_offset
        return np.array([math.cos(half), 0.0, 0.0, math.sin(half)])

    # ------------------------------------------------------------------------------------------ receive
    def close(self) -> None:
        self.sock.close()

    def fileno(self) -> int:
        return self.sock.fileno()

    def poll(self, sim_time: float) -> int:
        """Read and handle every pending datagram at simulation time ``sim_time`` [s]; returns how many."""
        self.time = sim_time
        count = 0
        while True:
            try:
                data, address = self.sock.recvfrom(4096)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break
            count += 1
            self.counters.datagrams += 1
            try:
                messages = self.mav.parse_buffer(data) or []
            except Exception:  # noqa: BLE001 - any parser failure is garbage, never a crash
                self.counters.garbage += 1
                self.mav.buf = bytearray()
                self.mav.buf_index = 0
                continue
            for msg in messages:
                self._handle(msg, address)
        return count

    def _handle(self, msg, address) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self.counters.garbage += 1
            return
        self.peer = address
        if kind == "SET_ATTITUDE_TARGET":
            self._handle_attitude_target(msg)
        elif kind == "COMMAND_LONG":
            self._handle_command(msg)
        elif kind == "HEARTBEAT":
            return
        else:
            self.counters.ignored += 1

    def _for_me(self, msg) -> bool:
        return int(getattr(msg, "target_system", 0)) in (0, self.uav_id)

    def _handle_attitude_target(self, msg) -> None:
        if not self._for_me(msg):
            self.counters.ignored += 1
            return
        mask = int(msg.type_mask)
        q_ned = np.asarray(msg.q, dtype=float)
        thrust = float(msg.thrust)
        rates = np.array([msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate], dtype=float)
        attitude_used = not mask & ATTITUDE_IGNORE
        unit = np.isfinite(q_ned).all() and abs(math.sqrt(float(q_ned @ q_ned)) - 1.0) <= _UNIT_TOLERANCE
        if attitude_used and not unit:
            self.counters.rejected_setpoints += 1
            return
        if not mask & THROTTLE_IGNORE and not math.isfinite(thrust):
            self.counters.rejected_setpoints += 1
            return
        if not np.isfinite(rates).all():
            rates = np.zeros(3)
        self.counters.setpoints += 1
        self._stamp_setpoint(int(msg.time_boot_ms))
        gap_limit = 1.0 / self.config.offboard_min_rate
        if self._last_setpoint_time is None or self.time - self._last_setpoint_time > gap_limit:
            self._stream_start = self.time
        self._last_setpoint_time = self.time
        if not mask & THROTTLE_IGNORE:
            self.thrust = min(1.0, max(0.0, thrust))
        ignore = np.array([mask & BODY_ROLL_RATE_IGNORE, mask & BODY_PITCH_RATE_IGNORE, mask & BODY_YAW_RATE_IGNORE])
        rates_flu = flu_to_frd(np.where(ignore != 0, 0.0, rates))  # FRD <-> FLU is its own inverse
        if attitude_used:
            self.quat_local = quat_ned_frd_to_enu_flu(q_ned / np.linalg.norm(q_ned))
            self.rate_mode = False
            self.rate_feedforward = np.array([0.0, 0.0, rates_flu[2]])
        elif not (mask & BODY_ROLL_RATE_IGNORE and mask & BODY_PITCH_RATE_IGNORE):
            self.rate_mode = True
            self.rate_feedforward = rates_flu

    def _stamp_setpoint(self, time_boot_ms: int) -> None:
        """Track the newest setpoint instant (see the module doc); 0: no time given, stamped on arrival."""
        now_ms = boot_time_ms(self.time)
        stamp = time_boot_ms or now_ms
        if stamp != self.setpoint_time_ms:
            self.setpoint_time_ms = stamp
            self.counters.new_setpoints += 1
            if time_boot_ms:
                self.setpoint_latency.add(self.time, (now_ms - stamp) * 1e-3)

    def stream_healthy(self) -> bool:
        """A setpoint stream faster than offboard_min_rate has run for at least offboard_warmup seconds."""
        if self._last_setpoint_time is None or self._stream_start is None:
            return False
        fresh = self.time - self._last_setpoint_time <= 1.0 / self.config.offboard_min_rate
        return fresh and self._last_setpoint_time - self._stream_start >= self.config.offboard_warmup

    def _ack(self, command: int, result: int) -> None:
        self._send(self.mav.command_ack_encode(command=command, result=result, progress=0, result_param2=0,
                                               target_system=0, target_component=0))

    def _handle_command(self, msg) -> None:
        if not self._for_me(msg):
            self.counters.ignored += 1
            return
        self.counters.commands += 1
        command = int(msg.command)
        if command == MAV_CMD_COMPONENT_ARM_DISARM:
            if msg.param1 >= 0.5:
                if self.armed:
                    result = MAV_RESULT_ACCEPTED
                elif self.stream_healthy():
                    result = MAV_RESULT_ACCEPTED
                    self.arm(self.time)
                else:
                    result = MAV_RESULT_TEMPORARILY_REJECTED
            else:
                if not self.armed or self.landed or abs(msg.param2 - FORCE_DISARM_MAGIC) < 0.5:
                    self.armed = False
                    result = MAV_RESULT_ACCEPTED
                else:
                    result = MAV_RESULT_DENIED
            self._ack(command, result)
        elif command == MAV_CMD_DO_SET_MODE:
            main, sub = int(round(msg.param2)), int(round(msg.param3))
            if not int(round(msg.param1)) & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                self._ack(command, MAV_RESULT_UNSUPPORTED)
            elif main == Px4MainMode.OFFBOARD:
                if self.stream_healthy():
                    self._set_mode(Px4MainMode.OFFBOARD, 0)
                    self._ack(command, MAV_RESULT_ACCEPTED)
                else:
                    self._ack(command, MAV_RESULT_TEMPORARILY_REJECTED)
            elif main == Px4MainMode.AUTO and sub in (Px4AutoSubMode.LAND, Px4AutoSubMode.LOITER):
                self._set_mode(main, sub)
                self._ack(command, MAV_RESULT_ACCEPTED)
            elif main in (Px4MainMode.POSCTL, Px4MainMode.ALTCTL, Px4MainMode.STABILIZED, Px4MainMode.MANUAL):
                self._set_mode(main, 0)
                self._ack(command, MAV_RESULT_ACCEPTED)
            else:
                self._ack(command, MAV_RESULT_UNSUPPORTED)
        elif command == MAV_CMD_DO_FLIGHTTERMINATION:
            if msg.param1 >= 0.5:
                self.armed = False
                self._set_mode(Px4MainMode.TERMINATION, 0)
            self._ack(command, MAV_RESULT_ACCEPTED)
        else:
            self._ack(command, MAV_RESULT_UNSUPPORTED)

    def _set_mode(self, main: int, sub: int) -> None:
        self.main_mode, self.sub_mode = main, sub
        self._failsafe_since = None

    def arm(self, sim_time: float) -> None:
        """Arm at ``sim_time`` [s] (an accepted ARM, or a scenario that starts armed): resets the take-off flag
        and the auto-disarm timers as PX4's commander does."""
        self.armed = True
        self.armed_time = float(sim_time)
        self.taken_off = not self.landed
        self._landed_since = None
        self._rc_loss_since = None

    # ------------------------------------------------------------------------------------------ mode logic
    @property
    def custom_mode(self) -> int:
        return encode_custom_mode(self.main_mode, self.sub_mode)

    @property
    def offboard(self) -> bool:
        return self.main_mode == Px4MainMode.OFFBOARD

    @property
    def takes_offboard_setpoints(self) -> bool:
        """Armed, and not in a mode that ignores the offboard stream (AUTO.LAND, AUTO.LOITER: the operator's LAND
        and the failsafes): the simulator's lockstep waits for a live stream only while this holds."""
        return self.armed and not (self.main_mode == Px4MainMode.AUTO and self.sub_mode in (
            Px4AutoSubMode.LAND, Px4AutoSubMode.LOITER))

    @property
    def mode_name(self) -> str:
        """The main/sub mode as PX4 names it (OFFBOARD, POSCTL, AUTO.LAND, ...), for messages."""
        return mode_name(self.main_mode, self.sub_mode) + ("" if self.armed else " (disarmed)")

    @property
    def needs_rc(self) -> bool:
        """The present mode flies on RC sticks (PX4's mode requirement "manual control")."""
        return self.main_mode in _RC_MODES

    def update(self, sim_time: float, landed: bool, attitude_world: np.ndarray) -> Px4Setpoint:
        """PX4's mode logic at ``sim_time`` (module doc): offboard- and RC-loss failsafes, hold -> land,
        auto-disarm; returns the setpoint to fly (world frame).

        ``landed``: the land detector (the vehicle's gear touches the ground); ``attitude_world``: its true
        attitude (hold/land keep yaw).
        """
        self.time = sim_time
        self.landed = landed
        cfg = self.config
        if self.armed and not landed:
            self.taken_off = True
        if self.armed and self.offboard and self._last_setpoint_time is not None and \
                sim_time - self._last_setpoint_time > cfg.offboard_loss_timeout:
            self._start_failsafe(sim_time)
        if self.armed and not landed and self.needs_rc:
            self._rc_loss_since = sim_time if self._rc_loss_since is None else self._rc_loss_since
            if sim_time - self._rc_loss_since > cfg.rc_loss_timeout:
                self._start_failsafe(sim_time)
        else:
            self._rc_loss_since = None
        if self._failsafe_since is not None and self.main_mode == Px4MainMode.AUTO and \
                self.sub_mode == Px4AutoSubMode.LOITER and sim_time - self._failsafe_since > cfg.failsafe_hold_time:
            self.sub_mode = Px4AutoSubMode.LAND
        is_land = self.main_mode == Px4MainMode.AUTO and self.sub_mode == Px4AutoSubMode.LAND
        if self.armed:
            self._check_auto_disarm(sim_time, landed, is_land)
        q_world_local = self._q_world_from_local
        if self.offboard and not self.rate_mode:
            quat = quat_multiply(q_world_local, self.quat_local)
            return Px4Setpoint(quat, self.thrust, self.armed, self.rate_feedforward.copy())
        if self.offboard and self.rate_mode:
            return Px4Setpoint(attitude_world.copy(), self.thrust, self.armed, self.rate_feedforward.copy())
        # hold / land / position modes without a position controller: level attitude with the current yaw
        w, x, y, z = attitude_world
        yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        level = np.array([math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)])
        if landed:
            thrust = 0.0  # idle: nothing takes off outside OFFBOARD without RC (module doc)
        else:
            thrust = self.thrust * (cfg.land_descent_thrust_ratio if is_land else 1.0)
        return Px4Setpoint(level, thrust, self.armed, np.zeros(3))

    def _start_failsafe(self, sim_time: float) -> None:
        """Offboard or RC loss: hold (AUTO.LOITER) now, AUTO.LAND after ``failsafe_hold_time``."""
        self.counters.failsafes += 1
        self.main_mode, self.sub_mode = Px4MainMode.AUTO, Px4AutoSubMode.LOITER
        self._failsafe_since = sim_time
        self._rc_loss_since = None

    def _check_auto_disarm(self, sim_time: float, landed: bool, is_land: bool) -> None:
        """COM_DISARM_PRFLT and COM_DISARM_LAND (module doc); called while armed."""
        cfg = self.config
        if landed and (is_land or (self.taken_off and not self.offboard)):
            self._landed_since = sim_time if self._landed_since is None else self._landed_since
            if sim_time - self._landed_since > cfg.land_disarm_delay:
                self._disarm_automatically(sim_time, "landed")
                return
        else:
            self._landed_since = None
        armed_for = sim_time - (self.armed_time if self.armed_time is not None else 0.0)
        if not self.taken_off and cfg.disarm_preflight_timeout > 0.0 and armed_for > cfg.disarm_preflight_timeout:
            self._disarm_automatically(sim_time, "preflight")

    def _disarm_automatically(self, sim_time: float, reason: str) -> None:
        self.armed = False
        self.counters.auto_disarms += 1
        self.auto_disarm = (sim_time, reason)
        self._landed_since = None

    # ------------------------------------------------------------------------------------------ send
    def _send(self, message) -> None:
        if self.peer is None:
            return
        try:
            self.sock.sendto(message.pack(self.mav), self.peer)
        except OSError:
            pass

    def send_status(self, voltage: float, remaining: float, current: float) -> None:
        """HEARTBEAT, SYS_STATUS and BATTERY_STATUS (voltage [V], remaining [0..1], current [A])."""
        base = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self.armed:
            base |= MAV_MODE_FLAG_SAFETY_ARMED
        if self.main_mode in (Px4MainMode.OFFBOARD, Px4MainMode.AUTO):
            base |= MAV_MODE_FLAG_AUTO_ENABLED | MAV_MODE_FLAG_GUIDED_ENABLED | MAV_MODE_FLAG_STABILIZE_ENABLED
        status = MAV_STATE_ACTIVE if self.armed else MAV_STATE_STANDBY
        self._send(self.mav.heartbeat_encode(type=MAV_TYPE_QUADROTOR, autopilot=MAV_AUTOPILOT_PX4, base_mode=base,
                                             custom_mode=self.custom_mode, system_status=status, mavlink_version=3))
        millivolts = int(min(max(voltage * 1000.0, 0.0), 65534))
        centiamps = int(min(max(current * 100.0, 0.0), 32767))
        percent = int(round(100.0 * min(max(remaining, 0.0), 1.0)))
        self._send(self.mav.sys_status_encode(
            onboard_control_sensors_present=0, onboard_control_sensors_enabled=0, onboard_control_sensors_health=0,
            load=0, voltage_battery=millivolts, current_battery=centiamps, battery_remaining=percent,
            drop_rate_comm=0, errors_comm=self.counters.garbage & 0xFFFF, errors_count1=0, errors_count2=0,
            errors_count3=0, errors_count4=0))
        cell = min(int(millivolts / 3), 65534)
        self._send(self.mav.battery_status_encode(
            id=0, battery_function=0, type=1, temperature=32767, voltages=[cell, cell, cell] + [65535] * 7,
            current_battery=centiamps, current_consumed=-1, energy_consumed=-1, battery_remaining=percent))

    def send_telemetry(self, sample: ImuSample, sim_time: float | None = None) -> None:
        """ATTITUDE_QUATERNION, ATTITUDE, HIGHRES_IMU, LOCAL_POSITION_NED from a sample in F0i / FLU, taken at
        simulation time ``sim_time`` [s] (default: the time of the last :meth:`poll` / :meth:`update`)."""
        t = self.time if sim_time is None else float(sim_time)
        ms = boot_time_ms(t)
        q_ned = quat_enu_flu_to_ned_frd(sample.quat_local)
        rates = flu_to_frd(sample.rate)
        accel = flu_to_frd(sample.specific_force)
        self._send(self.mav.attitude_quaternion_encode(
            time_boot_ms=ms, q1=float(q_ned[0]), q2=float(q_ned[1]), q3=float(q_ned[2]), q4=float(q_ned[3]),
            rollspeed=float(rates[0]), pitchspeed=float(rates[1]), yawspeed=float(rates[2])))
        roll, pitch, yaw = quat_to_euler_zyx(q_ned)
        self._send(self.mav.attitude_encode(time_boot_ms=ms, roll=roll, pitch=pitch, yaw=yaw,
                                            rollspeed=float(rates[0]), pitchspeed=float(rates[1]),
                                            yawspeed=float(rates[2])))
        self._send(self.mav.highres_imu_encode(
            time_usec=int(round(max(0.0, t) * 1e6)), xacc=float(accel[0]), yacc=float(accel[1]), zacc=float(accel[2]),
            xgyro=float(rates[0]), ygyro=float(rates[1]), zgyro=float(rates[2]), xmag=0.0, ymag=0.0, zmag=0.0,
            abs_pressure=0.0, diff_pressure=0.0, pressure_alt=0.0, temperature=25.0, fields_updated=0x3F, id=0))
        p = enu_to_ned(sample.position_local)
        v = enu_to_ned(sample.velocity_local)
        self._send(self.mav.local_position_ned_encode(
            time_boot_ms=ms, x=float(p[0]), y=float(p[1]), z=float(p[2]), vx=float(v[0]), vy=float(v[1]),
            vz=float(v[2])))
