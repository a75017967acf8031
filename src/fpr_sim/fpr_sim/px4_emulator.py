"""One emulated PX4 autopilot per UAV, speaking MAVLink 2 over UDP on 127.0.0.1 as PX4 SITL does. ROS-free.

This is the spec of the emulator: a drop-in for PX4 SITL for the FPR bridge, MAVSDK, MAVROS and a
QGroundControl-style GCS, following PX4's source (file names below are PX4-Autopilot's, read and re-implemented,
not copied).

Link (mavlink_main.cpp, mavlink_receiver.cpp, UDP; the "onboard" link of SITL instance k = i − 1): it binds
``127.0.0.1:local_port`` (default 14580 + i − 1) and SENDS from the start (HEARTBEAT, telemetry) to
``127.0.0.1:remote_port`` (default 14540 + i − 1), where the offboard computer (fpr_px4_bridge, MAVROS, MAVSDK)
listens. Like PX4's UDP link without a fixed partner, the source address of the FIRST valid frame received becomes
the link's partner and stays it: all streams go there from then on, whoever else talks. A second client (another
address) is served as far as it asks: its commands are executed and their COMMAND_ACK (and MESSAGE_INTERVAL /
REQUEST_MESSAGE answers) go back to it, but it gets no streams (PX4 would send those to its one partner; open a
second emulator link for a second full client). :attr:`EmulatorCounters.other_clients` counts its frames.
``local_port`` 0 binds an ephemeral port (tests); ``remote_port`` 0 sends nothing until someone talks first. The
receive buffer is enlarged (``SO_RCVBUF`` 1 MiB, capped by net.core.rmem_max): :meth:`Px4Emulator.poll` must be
called continuously (the simulation does, at 250 Hz).

Received (messages for another system id are ignored and counted; every command is answered with COMMAND_ACK
to its sender, with the sender's system/component as target):

- HEARTBEAT: accepted (only latches the partner);
- COMMAND_LONG and COMMAND_INT alike (param1-3 are read):

  * COMPONENT_ARM_DISARM (400): arming by PX4's mode requirements (ModeUtil/mode_requirements.cpp,
    HealthAndArmingChecks/checks/modeCheck.cpp, offboardCheck.cpp): in OFFBOARD only with the offboard signal
    (an offboard setpoint younger than COM_OF_LOSS_T; no "1 s of stream" rule: that is advice to clients, PX4
    does not check it); in AUTO.LOITER (Hold) and AUTO.TAKEOFF always (the local position is valid); never in
    AUTO.LAND / RTL / TERMINATION (``mode_req_prevent_arming``): TEMPORARILY_REJECTED (Commander's answer to a
    denied arming transition). Modes needing manual control (MANUAL, STABILIZED, ACRO, ALTCTL, POSCTL): PX4
    without RC refuses (modeCheck.cpp clears their arming bits when manual control is lost, whatever
    COM_RC_IN_MODE; COM_RC_IN_MODE = 4 only makes the message an error). Px4Config ``manual_modes_without_rc``
    (default True) accepts them anyway, because fpr_px4_bridge arms in POSCTL and switches to OFFBOARD ~1.2 s
    later; False gives PX4's refusal. param2 = 21196 forces (arming without checks, disarming in flight);
    disarming in flight without it is DENIED (Commander: "not landed");
  * DO_SET_MODE (176) with MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and PX4's custom main/sub mode (px4_custom_mode.h):
    OFFBOARD needs the offboard signal (else TEMPORARILY_REJECTED); POSCTL, ALTCTL, STABILIZED, MANUAL, ACRO as
    for arming (``manual_modes_without_rc``); AUTO.LOITER, AUTO.LAND, AUTO.TAKEOFF accepted; AUTO.RTL, MISSION
    and the others need a global position / home / mission the indoor FPR does not have: TEMPORARILY_REJECTED
    (mode_req_global_position; PX4's failsafes, not the user, fall back from Return to Land); an unknown main
    mode or no custom flag: UNSUPPORTED;
  * NAV_TAKEOFF (22) -> AUTO.TAKEOFF, NAV_LAND (21) -> AUTO.LAND, NAV_RETURN_TO_LAUNCH (20) -> as AUTO.RTL
    (rejected, no global position); DO_FLIGHTTERMINATION (185): disarm, TERMINATION;
  * SET_MESSAGE_INTERVAL (511): param1 = message id, param2 = interval [us], −1 disables, 0 restores the default
    rate; the new interval starts now (DENIED for a message not streamed here); GET_MESSAGE_INTERVAL (510)
    answers MESSAGE_INTERVAL; REQUEST_MESSAGE (512, param1 = id) sends that message once, at the next physics step,
    to the requester (the streamed ones and AUTOPILOT_VERSION; REQUEST_AUTOPILOT_CAPABILITIES 520 too);
  * anything else: UNSUPPORTED;
- legacy SET_MODE (#11): as DO_SET_MODE with ``base_mode`` and ``custom_mode`` (PX4 handle_message_set_mode turns
  it into that command), acknowledged as command 176;
- SET_ATTITUDE_TARGET (NED/FRD quaternion, normalized thrust, type_mask honoured: ATTITUDE_IGNORE -> body rate
  mode, THROTTLE_IGNORE keeps the thrust, yaw rate feed-forward unless bit 4). A NaN/inf or non-unit quaternion
  or NaN thrust is rejected (previous setpoint kept, counted); thrust is clamped to [0, 1];
- SET_POSITION_TARGET_LOCAL_NED (mavlink_receiver.cpp handle_message_set_position_target_local_ned): position,
  velocity and acceleration (feed-forward) per axis as the type_mask says (a component whose ignore bit is set
  is not used; all three of a kind ignored = none of it), yaw or yaw rate (bits 10/11); frames LOCAL_NED (1),
  LOCAL_OFFSET_NED (7: position relative to the present one), BODY_NED (8) and BODY_OFFSET_NED (9: vectors in
  the heading frame, x forward, y right, z down; position relative to the present one); other frames, the
  force bit or nothing usable: rejected and counted. The vehicle's own local frame F0i is the MAVLink local frame
  (NED there, ENU/FLU inside: x_enu = y_ned, y_enu = x_ned, z_enu = −z_ned, yaw_enu = π/2 − yaw_ned);
- each accepted SET_ATTITUDE_TARGET or SET_POSITION_TARGET_LOCAL_NED is an offboard setpoint: it refreshes the
  offboard signal and selects what OFFBOARD flies (the last kind received: attitude/thrust straight to the
  attitude loop, or position/velocity through the position controller);
- setpoint time (for the simulator's lockstep only; real PX4 ignores ``time_boot_ms`` in SET_ATTITUDE_TARGET):
  ``time_boot_ms`` is read as the setpoint's own instant on this PX4's boot clock (fpr_px4_bridge puts the
  controller's stamp there, and keeps it on its repetitions). :attr:`Px4Emulator.setpoint_time_ms` is the
  instant of the latest setpoint; a message with the same ``time_boot_ms`` as the one before is a repetition
  (counted, still proof of life). (Different, not just later: the sender's boot-time mapping may shift by a few
  ms when its time-sync estimate moves.) ``time_boot_ms`` = 0 means "no time given" (scripted pymavlink
  clients): the message is stamped with its arrival time, i.e. every such message is new.
  SET_POSITION_TARGET_LOCAL_NED is stamped the same way with its ``time_boot_ms`` (MAVSDK and MAVROS put their
  own clock there, not this PX4's: telling the time bases apart is the lockstep's business, simulation.py);
  :attr:`Px4Emulator.setpoint_latency` keeps the age of each new stamped setpoint on arrival;
- malformed, unknown or unhandled MAVLink is ignored and counted (:attr:`Px4Emulator.counters`); a field the
  emulator cannot use (NaN where a number is needed) is counted as garbage, never a crash;
- MAVLink 2 signing (``signing_key``; the simulator's ``signing_key_file``, as PX4 with MAV_SIGN_CFG): every
  outgoing frame signed, timestamps following the wall clock (fpr_px4_bridge.link's one implementation), every
  unsigned or wrongly signed incoming frame refused and counted as garbage, so that the whole simulated graph can
  run signed (tests/test_signed_graph.py).

Modes (PX4 parameters emulated, :class:`~fpr_sim.scenario.Px4Config` field in brackets); PX4 boots in POSCTL:

- OFFBOARD flies the last offboard setpoint: SET_ATTITUDE_TARGET's attitude and thrust (the attitude loop of
  the plant, unchanged) or SET_POSITION_TARGET_LOCAL_NED through the position controller;
- the position controller (:mod:`fpr_sim.px4_position_control`, PX4 mc_pos_control's PositionControl, MPC_*
  parameters in ``position_control``) flies AUTO.LOITER (Hold: holds the position, altitude and yaw where it was
  entered), AUTO.LAND (holds x/y, descends at MPC_LAND_SPEED [``land_speed``]), AUTO.TAKEOFF (climbs at
  MPC_TKO_SPEED [``takeoff_speed``] to MIS_TAKEOFF_ALT [``takeoff_altitude``] above where it was entered, then
  switches to Hold as the navigator does), POSCTL without sticks (holds position), ALTCTL without sticks (level,
  holds altitude), and OFFBOARD position/velocity setpoints. It outputs an attitude and a normalized thrust into
  the same path as SET_ATTITUDE_TARGET. It takes over bumplessly: its hover thrust starts from the vertical
  component of the thrust the vehicle last flew with (MPC_THR_HOVER [``position_control.hover_thrust``] when it
  flew none) and the horizontal component goes into its velocity integrator; the integrators take up the rest.
  PX4's estimator is replaced by the vehicle's true position and velocity in F0i (a perfect local position);
- with per-vehicle position control each UAV holds its own position, which holds the FPR's geometry (the legs are
  held by the tilted thrusts the controller keeps); a level attitude would drop the legs' inward thrust
  components and let them splay (ALTCTL / MANUAL-like modes and the no-position fallback still do);
- land detector (PX4 MulticopterLandDetector): landed = the vehicle's gear touches the ground, or, in AUTO.LAND,
  a collective near MPC_THR_MIN (below 30 % of the way to the hover thrust) with |v_z| < LNDMC_Z_VEL_MAX
  [``land_detector_z_vel``] for LNDMC_TRIG_TIME [``land_detector_time``] (an FPR's platform can touch first);
- landed outside OFFBOARD (or OFFBOARD with a position target that does not climb), the motors run at IDLE
  (normalized thrust 0, the actuator minimum): PX4's POSCTL/ALTCTL keep a landed vehicle at idle until a
  take-off is asked with the throttle stick, Hold and Land do not take off; only AUTO.TAKEOFF (or an OFFBOARD
  setpoint) lifts it. Arming before OFFBOARD (fpr_px4_bridge) therefore leaves the robot on the ground; the
  offboard setpoints streamed meanwhile are ignored as PX4 does outside OFFBOARD;
- COM_DISARM_PRFLT [``disarm_preflight_timeout``, 10 s]: armed and not taken off for that long -> auto-disarm,
  in every mode (Commander::checkForAutoDisarm); COM_DISARM_LAND [``land_disarm_delay``, 2 s]: in AUTO.LAND,
  landed that long -> disarm; after a take-off, landed that long in any mode but OFFBOARD -> disarm;
- offboard loss (Commander failsafe, offboardCheck.cpp): in OFFBOARD, no offboard setpoint for COM_OF_LOSS_T
  [``offboard_loss_timeout``, 1 s] -> Hold (AUTO.LOITER, really holding now) for ``failsafe_hold_time``
  (standing in for COM_FAIL_ACT_T), then AUTO.LAND;
- RC loss (COM_RC_LOSS_T [``rc_loss_timeout``, 0.5 s]): airborne in a mode that needs RC that long -> the same
  Hold-then-Land chain (NAV_RCL_ACT's Return needs a global position and falls back to Land);
- AUTO.LAND of the whole FPR: every UAV descends at MPC_LAND_SPEED holding its x/y, so the structure comes down
  in shape (the platform rides above the UAVs on the legs); each UAV idles when its gear touches (or the
  low-thrust rule fires, e.g. if something else touches first) and disarms COM_DISARM_LAND later. From the
  ``hover`` scenario (1.5 m) all three are disarmed ~3.1 s after NAV_LAND (test_px4_gcs.py);
- the horizontal position loop of the FPR's PX4s is stiffer than PX4's defaults (Px4Config ``position_control``:
  MPC_XY_P 2.0, MPC_XY_VEL_P_ACC 4.0, MPC_XY_VEL_I_ACC 2.0, all within PX4's ranges): with the defaults the
  structure's weight, a negative stiffness on the UAVs' horizontal positions, makes the legs of the ``hover``
  scenario oscillate and collapse in Hold within 10 s; with the tuning the platform stays within ~6 cm in altitude
  for 10 s.

Telemetry (simulation time; :meth:`Px4Emulator.due_messages` / :meth:`Px4Emulator.send_messages`), each message
on its own interval, changeable by SET_MESSAGE_INTERVAL; defaults = PX4's onboard link (mavlink_main.cpp
configure_streams_to_default, MAVLINK_MODE_ONBOARD) except where the FPR graph needs more: HEARTBEAT 2 Hz (PX4:
1 Hz; the bridges report PX4's mode from it and the graph expects a mode change seen within 0.5 s), ATTITUDE
100 Hz, ATTITUDE_QUATERNION 50 Hz, HIGHRES_IMU 50 Hz, LOCAL_POSITION_NED 50 Hz (PX4: 30 Hz; the bridge needs
attitude, IMU and local position at >= 50 Hz), SYS_STATUS 5 Hz, BATTERY_STATUS 0.5 Hz, EXTENDED_SYS_STATE 5 Hz
(landed state ON_GROUND / TAKEOFF / IN_AIR / LANDING). HEARTBEAT: MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_PX4, system
id = UAV id, component 1, ``base_mode`` with CUSTOM_MODE_ENABLED (+ SAFETY_ARMED, + AUTO|GUIDED|STABILIZE in
OFFBOARD/AUTO, MANUAL_INPUT(+STABILIZE, +GUIDED) in the manual modes), ``custom_mode`` = PX4 main/sub mode.
Attitude, IMU and local position come from the sensor sample (F0i, NED/FRD on the wire). Boot clock: PX4
"boots" at simulation time 0, ``time_boot_ms`` = :func:`boot_time_ms`.
"""

from __future__ import annotations

import math
import select
import socket
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from fpr_model.frames import enu_to_ned, flu_to_frd, quat_enu_flu_to_ned_frd, quat_ned_frd_to_enu_flu
from fpr_model.rotations import quat_multiply, quat_to_euler_zyx
from fpr_px4_bridge.link import advance_signing_timestamp, enable_signing
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
    MAV_MODE_FLAG_MANUAL_INPUT_ENABLED,
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

from fpr_sim.px4_position_control import PositionController
from fpr_sim.scenario import Px4Config
from fpr_sim.sensors import ImuSample

__all__ = ["LOCAL_BASE_PORT", "REMOTE_BASE_PORT", "STREAM_IDS", "EmulatorCounters", "Px4Emulator", "Px4Setpoint",
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
# MAV_CMD ids (common.xml)
MAV_CMD_NAV_RETURN_TO_LAUNCH = 20
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_GET_MESSAGE_INTERVAL = 510
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES = 520
# message ids (common.xml)
MSG_HEARTBEAT = 0
MSG_SYS_STATUS = 1
MSG_ATTITUDE = 30
MSG_ATTITUDE_QUATERNION = 31
MSG_LOCAL_POSITION_NED = 32
MSG_HIGHRES_IMU = 105
MSG_BATTERY_STATUS = 147
MSG_AUTOPILOT_VERSION = 148
MSG_EXTENDED_SYS_STATE = 245
#: the streamed messages and their Px4Config rate field
STREAM_IDS: dict[int, str] = {
    MSG_HEARTBEAT: "heartbeat_rate", MSG_SYS_STATUS: "sys_status_rate", MSG_ATTITUDE: "attitude_rate",
    MSG_ATTITUDE_QUATERNION: "attitude_quaternion_rate", MSG_LOCAL_POSITION_NED: "local_position_rate",
    MSG_HIGHRES_IMU: "highres_imu_rate", MSG_BATTERY_STATUS: "battery_status_rate",
    MSG_EXTENDED_SYS_STATE: "extended_sys_state_rate",
}
#: messages built from an IMU / estimator sample
SAMPLE_IDS = frozenset((MSG_ATTITUDE, MSG_ATTITUDE_QUATERNION, MSG_LOCAL_POSITION_NED, MSG_HIGHRES_IMU))
#: what REQUEST_MESSAGE can send once
_REQUESTABLE = frozenset(STREAM_IDS) | {MSG_AUTOPILOT_VERSION}
# MAV_LANDED_STATE
LANDED_STATE_ON_GROUND = 1
LANDED_STATE_IN_AIR = 2
LANDED_STATE_TAKEOFF = 3
LANDED_STATE_LANDING = 4
# SET_POSITION_TARGET_LOCAL_NED type_mask bits and frames
POSITION_TARGET_IGNORE_POSITION = 0b111
POSITION_TARGET_IGNORE_VELOCITY = 0b111 << 3
POSITION_TARGET_IGNORE_ACCELERATION = 0b111 << 6
POSITION_TARGET_FORCE_SET = 1 << 9
POSITION_TARGET_IGNORE_YAW = 1 << 10
POSITION_TARGET_IGNORE_YAW_RATE = 1 << 11
MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_LOCAL_OFFSET_NED = 7
MAV_FRAME_BODY_NED = 8
MAV_FRAME_BODY_OFFSET_NED = 9
# MAV_PROTOCOL_CAPABILITY bits announced in AUTOPILOT_VERSION
_CAPABILITIES = (1 << 2) | (1 << 3) | (1 << 6) | (1 << 7) | (1 << 8) | (1 << 13)  # MISSION_INT.. MAVLINK2
#: modes that need RC sticks (PX4 mode requirement "manual control", mode_requirements.cpp)
_RC_MODES = (Px4MainMode.MANUAL, Px4MainMode.STABILIZED, Px4MainMode.ALTCTL, Px4MainMode.POSCTL, Px4MainMode.ACRO)
_MAIN_MODES = frozenset(range(Px4MainMode.MANUAL, Px4MainMode.TERMINATION + 1))
_UNIT_TOLERANCE = 1e-3


def boot_time_ms(sim_time: float) -> int:
    """The emulated PX4's ``time_boot_ms`` at simulation time ``sim_time`` [s] (it boots at t = 0)."""
    return int(round(max(0.0, sim_time) * 1000.0)) & 0xFFFFFFFF


def _us(t: float) -> int:
    return int(round(t * 1e6))


@dataclass
class EmulatorCounters:
    """Counts of what one emulator received."""

    datagrams: int = 0
    setpoints: int = 0  #: accepted offboard setpoints, attitude and position (new ones and repetitions)
    new_setpoints: int = 0  #: accepted with another time_boot_ms than the one before (not a repetition)
    rejected_setpoints: int = 0  #: NaN/inf, non-unit quaternion, NaN thrust, unsupported frame / type_mask
    garbage: int = 0  #: malformed frames (bad CRC, bad length, unknown message id; unsigned ones when signing)
    ignored: int = 0  #: valid MAVLink we do not handle, or addressed to another system
    commands: int = 0
    failsafes: int = 0  #: offboard-loss and RC-loss failsafes
    auto_disarms: int = 0  #: COM_DISARM_PRFLT / COM_DISARM_LAND disarms
    other_clients: int = 0  #: valid frames from another address than the link's partner


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


@dataclass
class PositionTarget:
    """An offboard SET_POSITION_TARGET_LOCAL_NED converted to F0i ENU (NaN = not given)."""

    position: np.ndarray  #: [m]
    velocity: np.ndarray  #: [m/s]
    acceleration: np.ndarray  #: [m/s²]
    yaw: float  #: [rad] ENU, NaN: keep
    yaw_rate: float  #: [rad/s] ENU (about up), NaN: none


def _yaw_of(quat: np.ndarray) -> float:
    w, x, y, z = quat
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class Px4Emulator:
    """PX4 of UAV ``uav_id`` (1-based = MAVLink system id); see the module doc. Call :meth:`poll` and
    :meth:`update` with the simulation time, and :meth:`due_messages` / :meth:`send_messages` every step."""

    def __init__(self, uav_id: int, config: Px4Config, yaw_offset: float, local_port: int | None = None,
                 remote_port: int | None = None, host: str = "127.0.0.1", signing_key: bytes | None = None,
                 wall_clock: Callable[[], float] = time.time) -> None:
        """``signing_key`` (32 bytes): MAVLink 2 signing as PX4 with MAV_SIGN_CFG set — every outgoing frame signed
        (timestamps on ``wall_clock``, UTC Unix seconds), every unsigned or wrongly signed frame refused and counted
        as garbage; None: no signing (PX4's default)."""
        if host not in ("127.0.0.1", "localhost"):
            raise ValueError(f"MAVLink is loopback-only in this project (DESIGN.md §6), got host {host!r}")
        self.uav_id = int(uav_id)
        self.config = config
        self.yaw_offset = float(yaw_offset)
        mavlink = import_mavlink()
        self._mavlink = mavlink
        self.mav = mavlink.MAVLink(None, srcSystem=self.uav_id, srcComponent=1)
        self.mav.robust_parsing = True
        self.signing = signing_key is not None
        self._wall_clock = wall_clock
        if signing_key is not None:
            enable_signing(self.mav, signing_key, link_id=0, unix_time=wall_clock())
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
        #: where the link sends: the remote port at first, then the sender of the first valid frame, kept (None:
        #: nowhere yet)
        self.peer: tuple[str, int] | None = ("127.0.0.1", remote_port) if remote_port > 0 else None
        self.peer_latched = False  #: the partner was taken from a received frame (PX4: client source initialized)
        self.counters = EmulatorCounters()
        #: datagrams handed to the socket (sendto accepted): the overlapped layout tells the graph how many to read
        self.sent_datagrams = 0
        #: gated reception (:meth:`admit`): the admitted datagrams not handled yet, or None (poll reads the socket)
        self._admitted: deque[tuple[bytes, tuple[str, int]]] | None = None
        self.admitted_datagrams = 0  #: datagrams admitted so far (:meth:`admit`)
        #: called with (sim time, uav id, raw thrust, raw q) for every SET_ATTITUDE_TARGET addressed to this PX4,
        #: before validation (fpr_sim.px4_log); None: off
        self.input_log: Callable[[float, int, float, object], None] | None = None
        self.armed = False
        self.main_mode = Px4MainMode.POSCTL
        self.sub_mode = 0
        self.time = 0.0
        self._last_setpoint_time: float | None = None
        self._failsafe_since: float | None = None
        self._landed_since: float | None = None
        self.quat_local = np.array([1.0, 0.0, 0.0, 0.0])  # latest offboard attitude setpoint, F0i ENU/FLU
        self.thrust = 0.0
        self.rate_feedforward = np.zeros(3)
        self.rate_mode = False
        #: attitude setpoints in flight on the command uplink (Px4Config.command_latency): (due time [s], setpoint)
        self._uplink: deque[tuple[float, tuple]] = deque()
        #: the offboard setpoint kind last received: "attitude" (SET_ATTITUDE_TARGET) or "position"
        self.offboard_kind = "attitude"
        self.position_target: PositionTarget | None = None
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
        # position control (Hold, Land, Takeoff, POSCTL/ALTCTL without sticks, offboard position/velocity)
        self.position_controller = PositionController(config.position_control)
        self._pc_mode: tuple[int, int, str] | None = None  # the mode the position controller was set up for
        self._hold_position = np.zeros(3)  # F0i ENU [m]
        self._hold_yaw = 0.0  # [rad] ENU
        self._takeoff_altitude = 0.0  # [m] F0i z target of AUTO.TAKEOFF
        self._last_pc_time: float | None = None
        self._low_thrust_since: float | None = None
        self._pc_landed = False  # the land detector's low-thrust rule (AUTO.LAND)
        self._flown_quat = np.array([1.0, 0.0, 0.0, 0.0])  # last commanded attitude, F0i ENU/FLU
        self._flown_thrust = 0.0
        self._last_pc_thrust = 1.0
        self.position_local: np.ndarray | None = None  # latest F0i ENU position [m] given to update()
        self.velocity_local: np.ndarray | None = None
        self._attitude_local = np.array([1.0, 0.0, 0.0, 0.0])  # true attitude in F0i (body FLU -> F0i ENU)
        # telemetry streams: interval [us] per message id (None: disabled), next due time [us]
        self._default_intervals: dict[int, int | None] = {}
        for msg_id, name in STREAM_IDS.items():
            rate = float(getattr(config, name))
            self._default_intervals[msg_id] = _us(1.0 / rate) if rate > 0.0 else None
        self.intervals: dict[int, int | None] = dict(self._default_intervals)
        self._next_due: dict[int, int] = {msg_id: 0 for msg_id in STREAM_IDS}
        self._next_any = 0
        self._requested: list[tuple[int, tuple[str, int] | None]] = []
        self.last_sample: ImuSample | None = None
        self._battery = (0.0, 0.0, 0.0)  # voltage [V], remaining [0..1], current [A]

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

    def admit(self, total: int, timeout: float) -> None:
        """Gated reception, for a simulator that runs beside its graph in another process
        (fpr_experiments.overlapped): move datagrams from the socket into the admitted queue until ``total`` were
        admitted since the first call, waiting up to ``timeout`` s of wall time for those still in flight (a
        loopback datagram can be delivered after its sender's next message, when the kernel defers the delivery).
        From the first call on, :meth:`poll` handles admitted datagrams only: what arrives early waits in the
        socket for a later ``admit``, so the datagrams handled in a step never depend on the two processes' timing.
        ``TimeoutError`` names the UAV and the counts (the sender is dead, or its datagrams were lost)."""
        if self._admitted is None:
            self._admitted = deque()
        deadline = None
        while self.admitted_datagrams < total:
            try:
                data, address = self.sock.recvfrom(4096)
            except (BlockingIOError, InterruptedError):
                now = time.monotonic()
                deadline = now + timeout if deadline is None else deadline
                if now >= deadline:
                    raise TimeoutError(f"uav{self.uav_id}'s PX4 emulator: {self.admitted_datagrams} of the {total} "
                                       f"datagrams its client sent arrived within {timeout:g} s") from None
                select.select([self.sock], [], [], deadline - now)
                continue
            self._admitted.append((data, address))
            self.admitted_datagrams += 1

    def poll(self, sim_time: float) -> int:
        """Read and handle every pending datagram (only admitted ones after :meth:`admit`) at simulation time
        ``sim_time`` [s]; returns how many."""
        self.time = sim_time
        count = 0
        admitted = self._admitted
        while True:
            if admitted is not None:
                if not admitted:
                    break
                data, address = admitted.popleft()
            else:
                try:
                    data, address = self.sock.recvfrom(4096)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:
                    break
            count += 1
            self.counters.datagrams += 1
            self._reset_parser()  # UDP datagrams carry whole frames: a broken one must not eat the next
            try:
                messages = self.mav.parse_buffer(data) or []
            except Exception:  # noqa: BLE001 - any parser failure is garbage, never a crash
                self.counters.garbage += 1
                continue
            if self.mav.buf_len() > 0:
                self.counters.garbage += 1  # trailing bytes of no complete frame
            for msg in messages:
                try:
                    self._handle(msg, address)
                except (AttributeError, TypeError, ValueError, OverflowError):
                    self.counters.garbage += 1  # a field we cannot use: never a crash
        return count

    def _reset_parser(self) -> None:
        mav = self.mav
        mav.buf = bytearray()
        mav.buf_index = 0
        mav.expected_length = 8  # pymavlink's initial HEADER_LEN_V1 + 2
        mav.have_prefix_error = False

    def _handle(self, msg, address) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self.counters.garbage += 1
            return
        if not self.peer_latched:
            # PX4's UDP link: the first received packet sets the partner, kept from then on (module doc)
            self.peer = address
            self.peer_latched = True
        elif address != self.peer:
            self.counters.other_clients += 1
        if kind == "SET_ATTITUDE_TARGET":
            self._handle_attitude_target(msg)
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            self._handle_position_target(msg)
        elif kind in ("COMMAND_LONG", "COMMAND_INT"):
            self._handle_command(msg, address)
        elif kind == "SET_MODE":
            self._handle_set_mode(msg, address)
        elif kind == "HEARTBEAT":
            return
        else:
            self.counters.ignored += 1

    def _for_me(self, msg) -> bool:
        return int(getattr(msg, "target_system", 0)) in (0, self.uav_id)

    def _offboard_setpoint_received(self, time_boot_ms: int) -> None:
        self.counters.setpoints += 1
        self._stamp_setpoint(time_boot_ms)
        self._last_setpoint_time = self.time

    def _handle_attitude_target(self, msg) -> None:
        if not self._for_me(msg):
            self.counters.ignored += 1
            return
        if self.input_log is not None:
            self.input_log(self.time, self.uav_id, msg.thrust, msg.q)
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
        self._offboard_setpoint_received(int(msg.time_boot_ms))
        self.offboard_kind = "attitude"
        ignore = np.array([mask & BODY_ROLL_RATE_IGNORE, mask & BODY_PITCH_RATE_IGNORE, mask & BODY_YAW_RATE_IGNORE])
        rates_flu = flu_to_frd(np.where(ignore != 0, 0.0, rates))  # FRD <-> FLU is its own inverse
        setpoint = (None if mask & THROTTLE_IGNORE else min(1.0, max(0.0, thrust)),
                    quat_ned_frd_to_enu_flu(q_ned / np.linalg.norm(q_ned)) if attitude_used else None,
                    not (mask & BODY_ROLL_RATE_IGNORE and mask & BODY_PITCH_RATE_IGNORE), rates_flu)
        latency = self.config.command_latency
        if latency > 0.0:
            self._uplink.append((self.time + latency, setpoint))
        else:
            self._apply_attitude_setpoint(setpoint)

    def _apply_attitude_setpoint(self, setpoint: tuple) -> None:
        thrust, quat_local, rates_used, rates_flu = setpoint
        if thrust is not None:
            self.thrust = thrust
        if quat_local is not None:
            self.quat_local = quat_local
            self.rate_mode = False
            self.rate_feedforward = np.array([0.0, 0.0, rates_flu[2]])
        elif rates_used:
            self.rate_mode = True
            self.rate_feedforward = rates_flu

    def _release_uplink(self, sim_time: float) -> None:
        """Apply the attitude setpoints whose command-uplink latency has passed (in arrival order)."""
        uplink = self._uplink
        while uplink and uplink[0][0] <= sim_time + 1e-9:
            self._apply_attitude_setpoint(uplink.popleft()[1])

    def _handle_position_target(self, msg) -> None:
        """SET_POSITION_TARGET_LOCAL_NED (module doc): position / velocity / acceleration / yaw, NED -> F0i ENU."""
        if not self._for_me(msg):
            self.counters.ignored += 1
            return
        mask = int(msg.type_mask)
        frame = int(msg.coordinate_frame)
        if frame not in (MAV_FRAME_LOCAL_NED, MAV_FRAME_LOCAL_OFFSET_NED, MAV_FRAME_BODY_NED,
                         MAV_FRAME_BODY_OFFSET_NED) or mask & POSITION_TARGET_FORCE_SET:
            self.counters.rejected_setpoints += 1
            return
        nan3 = np.full(3, np.nan)

        def vector(values, ignore_bits: int, shift: int) -> np.ndarray:
            v = np.array(values, dtype=float)
            used = np.array([not mask & (1 << (shift + k)) for k in range(3)])
            return np.where(used, v, np.nan) if mask & ignore_bits != ignore_bits else nan3.copy()

        pos = vector((msg.x, msg.y, msg.z), POSITION_TARGET_IGNORE_POSITION, 0)
        vel = vector((msg.vx, msg.vy, msg.vz), POSITION_TARGET_IGNORE_VELOCITY, 3)
        acc = vector((msg.afx, msg.afy, msg.afz), POSITION_TARGET_IGNORE_ACCELERATION, 6)
        yaw_ned = float(msg.yaw) if not mask & POSITION_TARGET_IGNORE_YAW else math.nan
        yaw_rate_ned = float(msg.yaw_rate) if not mask & POSITION_TARGET_IGNORE_YAW_RATE else math.nan
        given = [v for v in (pos, vel, acc) if not np.isnan(v).all()]
        if not given and math.isnan(yaw_ned) and math.isnan(yaw_rate_ned):
            self.counters.rejected_setpoints += 1
            return
        for v in (pos, vel, acc):
            if np.isinf(v).any():
                self.counters.rejected_setpoints += 1
                return
        # NED -> ENU (x_enu = y_ned, y_enu = x_ned, z_enu = -z_ned); yaw_enu = π/2 − yaw_ned
        pos, vel, acc = (np.array([v[1], v[0], -v[2]]) for v in (pos, vel, acc))
        yaw = math.pi / 2.0 - yaw_ned if math.isfinite(yaw_ned) else math.nan
        yaw_rate = -yaw_rate_ned if math.isfinite(yaw_rate_ned) else math.nan
        if frame in (MAV_FRAME_BODY_NED, MAV_FRAME_BODY_OFFSET_NED):
            # body NED: x forward / y right of the vehicle's heading, z down (PX4 rotates by the current yaw)
            heading = self._current_yaw()
            c, s = math.cos(heading), math.sin(heading)

            def rotate(v: np.ndarray) -> np.ndarray:
                # in ENU after the swap: v = (right, forward, up) of the body -> world by the heading
                forward, right = v[1], v[0]
                return np.array([c * forward + s * right, s * forward - c * right, v[2]])

            pos, vel, acc = rotate(pos), rotate(vel), rotate(acc)
            if math.isfinite(yaw):
                yaw = heading + (yaw - math.pi / 2.0)
        if frame in (MAV_FRAME_LOCAL_OFFSET_NED, MAV_FRAME_BODY_NED, MAV_FRAME_BODY_OFFSET_NED):
            origin = self.position_local if self.position_local is not None else np.zeros(3)
            pos = pos + origin  # NaN stays NaN
        self._offboard_setpoint_received(int(msg.time_boot_ms))
        self.offboard_kind = "position"
        self.position_target = PositionTarget(pos, vel, acc, yaw, yaw_rate)

    def _stamp_setpoint(self, time_boot_ms: int) -> None:
        """Track the newest setpoint instant (see the module doc); 0: no time given, stamped on arrival."""
        now_ms = boot_time_ms(self.time)
        stamp = time_boot_ms or now_ms
        if stamp != self.setpoint_time_ms:
            self.setpoint_time_ms = stamp
            self.counters.new_setpoints += 1
            if time_boot_ms:
                self.setpoint_latency.add(self.time, (now_ms - stamp) * 1e-3)

    @property
    def offboard_signal(self) -> bool:
        """PX4's offboard signal (offboardCheck.cpp): an offboard setpoint younger than COM_OF_LOSS_T."""
        return self._last_setpoint_time is not None and \
            self.time - self._last_setpoint_time <= self.config.offboard_loss_timeout

    def _ack(self, command: int, result: int, address: tuple[str, int] | None = None, msg=None) -> None:
        """COMMAND_ACK to the command's sender (``address``; default: the link's partner)."""
        target_system = int(msg.get_srcSystem()) if msg is not None else 0
        target_component = int(msg.get_srcComponent()) if msg is not None else 0
        self._send(self.mav.command_ack_encode(command=command, result=result, progress=0, result_param2=0,
                                               target_system=target_system, target_component=target_component),
                   address)

    def _handle_set_mode(self, msg, address) -> None:
        """Legacy SET_MODE (#11): PX4 turns it into DO_SET_MODE (base_mode, custom main, custom sub)."""
        if int(msg.target_system) not in (0, self.uav_id):
            self.counters.ignored += 1
            return
        self.counters.commands += 1
        custom = int(msg.custom_mode)
        result = self._set_mode_command(int(msg.base_mode), (custom >> 16) & 0xFF, (custom >> 24) & 0xFF)
        self._ack(MAV_CMD_DO_SET_MODE, result, address, msg)

    def _handle_command(self, msg, address) -> None:
        if not self._for_me(msg):
            self.counters.ignored += 1
            return
        self.counters.commands += 1
        command = int(msg.command)
        p1, p2, p3 = float(msg.param1), float(msg.param2), float(msg.param3)
        if command == MAV_CMD_COMPONENT_ARM_DISARM:
            result = self._arm_command(p1 >= 0.5, abs(p2 - FORCE_DISARM_MAGIC) < 0.5)
        elif command == MAV_CMD_DO_SET_MODE:
            if not math.isfinite(p1 + p2 + p3):
                result = MAV_RESULT_DENIED
            else:
                result = self._set_mode_command(int(round(p1)), int(round(p2)), int(round(p3)))
        elif command == MAV_CMD_NAV_TAKEOFF:
            result = self._switch_to(Px4MainMode.AUTO, Px4AutoSubMode.TAKEOFF)
        elif command == MAV_CMD_NAV_LAND:
            result = self._switch_to(Px4MainMode.AUTO, Px4AutoSubMode.LAND)
        elif command == MAV_CMD_NAV_RETURN_TO_LAUNCH:
            result = self._switch_to(Px4MainMode.AUTO, Px4AutoSubMode.RTL)
        elif command == MAV_CMD_DO_FLIGHTTERMINATION:
            if p1 >= 0.5:
                self.armed = False
                self._set_mode(Px4MainMode.TERMINATION, 0)
            result = MAV_RESULT_ACCEPTED
        elif command == MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._set_message_interval(p1, p2)
        elif command == MAV_CMD_GET_MESSAGE_INTERVAL:
            result = self._get_message_interval(p1, address)
        elif command == MAV_CMD_REQUEST_MESSAGE:
            result = self._request_message(p1, address)
        elif command == MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            result = self._request_message(float(MSG_AUTOPILOT_VERSION), address)
        else:
            result = MAV_RESULT_UNSUPPORTED
        self._ack(command, result, address, msg)

    def _arm_command(self, arm: bool, forced: bool) -> int:
        """COMPONENT_ARM_DISARM by PX4's rules (module doc; Commander.cpp, modeCheck.cpp, offboardCheck.cpp)."""
        if arm:
            if self.armed:
                return MAV_RESULT_ACCEPTED
            if not forced and not self._can_arm_in_mode():
                return MAV_RESULT_TEMPORARILY_REJECTED
            self.arm(self.time)
            return MAV_RESULT_ACCEPTED
        if not self.armed:
            return MAV_RESULT_ACCEPTED
        if not (self.landed or forced):
            return MAV_RESULT_DENIED  # Commander: "Disarming denied: not landed"
        self.armed = False
        return MAV_RESULT_ACCEPTED

    def _can_arm_in_mode(self) -> bool:
        main, sub = self.main_mode, self.sub_mode
        if main == Px4MainMode.OFFBOARD:
            return self.offboard_signal
        if main in _RC_MODES:
            return self.config.manual_modes_without_rc
        if main == Px4MainMode.AUTO:
            return sub in (Px4AutoSubMode.LOITER, Px4AutoSubMode.TAKEOFF)  # LAND, RTL, ...: prevent arming
        return False  # TERMINATION and the rest

    def _set_mode_command(self, base_mode: int, main: int, sub: int) -> int:
        if not base_mode & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return MAV_RESULT_UNSUPPORTED
        if main not in _MAIN_MODES:
            return MAV_RESULT_UNSUPPORTED
        return self._switch_to(main, sub if main == Px4MainMode.AUTO else 0)

    def _switch_to(self, main: int, sub: int) -> int:
        """A commanded mode change by PX4's mode requirements (mode_requirements.cpp) without RC nor global
        position: OFFBOARD needs the offboard signal; manual modes need RC (module doc); AUTO.LOITER, LAND and
        TAKEOFF need only the local position; RTL, MISSION, ... need a global position: rejected."""
        if main == Px4MainMode.OFFBOARD:
            if not self.offboard_signal:
                return MAV_RESULT_TEMPORARILY_REJECTED
        elif main in _RC_MODES:
            if not self.config.manual_modes_without_rc:
                return MAV_RESULT_TEMPORARILY_REJECTED
        elif main == Px4MainMode.AUTO:
            if sub not in (Px4AutoSubMode.LOITER, Px4AutoSubMode.LAND, Px4AutoSubMode.TAKEOFF):
                return MAV_RESULT_TEMPORARILY_REJECTED
        else:
            return MAV_RESULT_UNSUPPORTED
        self._set_mode(main, sub)
        return MAV_RESULT_ACCEPTED

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
        self._pc_mode = None  # a take-off from here starts the position controller afresh

    # ------------------------------------------------------------------------------------------ streams
    def _set_message_interval(self, msg_id: float, interval_us: float) -> int:
        if not (math.isfinite(msg_id) and math.isfinite(interval_us)):
            return MAV_RESULT_DENIED
        key = int(round(msg_id))
        if key not in STREAM_IDS:
            return MAV_RESULT_DENIED
        interval = int(round(interval_us))
        if interval < 0:
            self.intervals[key] = None  # -1: disable
        elif interval == 0:
            self.intervals[key] = self._default_intervals[key]  # 0: the default rate
        else:
            self.intervals[key] = interval
        self._next_due[key] = _us(self.time)
        self._next_any = min(self._next_any, self._next_due[key])
        return MAV_RESULT_ACCEPTED

    def _get_message_interval(self, msg_id: float, address) -> int:
        if not math.isfinite(msg_id) or int(round(msg_id)) not in STREAM_IDS:
            return MAV_RESULT_DENIED
        key = int(round(msg_id))
        interval = self.intervals[key]
        self._send(self.mav.message_interval_encode(message_id=key, interval_us=-1 if interval is None else interval),
                   address)
        return MAV_RESULT_ACCEPTED

    def _request_message(self, msg_id: float, address) -> int:
        if not math.isfinite(msg_id) or int(round(msg_id)) not in _REQUESTABLE:
            return MAV_RESULT_DENIED
        self._requested.append((int(round(msg_id)), address))
        return MAV_RESULT_ACCEPTED

    def due_messages(self, sim_time: float) -> list[int]:
        """The streamed message ids due at ``sim_time`` [s] (each on its own interval, simulation time) plus the
        ones asked for by REQUEST_MESSAGE; advances the schedules."""
        now = _us(sim_time)
        if now < self._next_any and not self._requested:
            return []
        due = []
        for key, interval in self.intervals.items():
            if interval is None:
                continue
            if now >= self._next_due[key]:
                due.append(key)
                nxt = self._next_due[key] + interval
                self._next_due[key] = nxt if nxt > now else now + interval
        active = [self._next_due[k] for k, v in self.intervals.items() if v is not None]
        self._next_any = min(active) if active else 1 << 62
        return due

    @property
    def has_requests(self) -> bool:
        """REQUEST_MESSAGE answers are waiting for :meth:`send_messages`."""
        return bool(self._requested)

    def needs_sample(self, due: list[int]) -> bool:
        """A message of ``due`` (or a pending request) needs an IMU/estimator sample."""
        return any(k in SAMPLE_IDS for k in due) or any(k in SAMPLE_IDS for k, _ in self._requested)

    def send_messages(self, due: list[int], sim_time: float, sample: ImuSample | None, voltage: float,
                      remaining: float, current: float) -> None:
        """Send the ``due`` streamed messages to the link's partner and the requested ones to their requester.
        ``sample``: the IMU/estimator sample (F0i, FLU) at ``sim_time`` [s] (None: the last one); battery
        voltage [V], remaining [0..1], current [A]."""
        if sample is not None:
            self.last_sample = sample
        self._battery = (voltage, remaining, current)
        for key in due:
            self._send_one(key, sim_time, None)
        requested, self._requested = self._requested, []
        for key, address in requested:
            self._send_one(key, sim_time, address)

    def _send_one(self, key: int, t: float, address) -> None:
        for message in self._encode(key, t):
            self._send(message, address)

    def _encode(self, key: int, t: float) -> list:
        mav = self.mav
        ms = boot_time_ms(t)
        voltage, remaining, current = self._battery
        if key == MSG_HEARTBEAT:
            base = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            if self.armed:
                base |= MAV_MODE_FLAG_SAFETY_ARMED
            if self.main_mode in (Px4MainMode.OFFBOARD, Px4MainMode.AUTO):
                base |= MAV_MODE_FLAG_AUTO_ENABLED | MAV_MODE_FLAG_GUIDED_ENABLED | MAV_MODE_FLAG_STABILIZE_ENABLED
            elif self.main_mode in _RC_MODES:
                base |= MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
                if self.main_mode != Px4MainMode.MANUAL:
                    base |= MAV_MODE_FLAG_STABILIZE_ENABLED
                if self.main_mode == Px4MainMode.POSCTL:
                    base |= MAV_MODE_FLAG_GUIDED_ENABLED
            status = MAV_STATE_ACTIVE if self.armed else MAV_STATE_STANDBY
            return [mav.heartbeat_encode(type=MAV_TYPE_QUADROTOR, autopilot=MAV_AUTOPILOT_PX4, base_mode=base,
                                         custom_mode=self.custom_mode, system_status=status, mavlink_version=3)]
        millivolts = int(min(max(voltage * 1000.0, 0.0), 65534))
        centiamps = int(min(max(current * 100.0, 0.0), 32767))
        percent = int(round(100.0 * min(max(remaining, 0.0), 1.0)))
        if key == MSG_SYS_STATUS:
            return [mav.sys_status_encode(
                onboard_control_sensors_present=0, onboard_control_sensors_enabled=0,
                onboard_control_sensors_health=0, load=0, voltage_battery=millivolts, current_battery=centiamps,
                battery_remaining=percent, drop_rate_comm=0, errors_comm=self.counters.garbage & 0xFFFF,
                errors_count1=0, errors_count2=0, errors_count3=0, errors_count4=0)]
        if key == MSG_BATTERY_STATUS:
            cell = min(int(millivolts / 3), 65534)
            return [mav.battery_status_encode(
                id=0, battery_function=0, type=1, temperature=32767, voltages=[cell, cell, cell] + [65535] * 7,
                current_battery=centiamps, current_consumed=-1, energy_consumed=-1, battery_remaining=percent)]
        if key == MSG_EXTENDED_SYS_STATE:
            return [mav.extended_sys_state_encode(vtol_state=0, landed_state=self.landed_state)]
        if key == MSG_AUTOPILOT_VERSION:
            return [mav.autopilot_version_encode(
                capabilities=_CAPABILITIES, flight_sw_version=(1 << 24) | (15 << 16) | 0xFF, middleware_sw_version=0,
                os_sw_version=0, board_version=0, flight_custom_version=[0] * 8, middleware_custom_version=[0] * 8,
                os_custom_version=[0] * 8, vendor_id=0, product_id=0, uid=self.uav_id)]
        sample = self.last_sample
        if sample is None:
            return []
        q_ned = quat_enu_flu_to_ned_frd(sample.quat_local)
        rates = flu_to_frd(sample.rate)
        if key == MSG_ATTITUDE_QUATERNION:
            return [mav.attitude_quaternion_encode(
                time_boot_ms=ms, q1=float(q_ned[0]), q2=float(q_ned[1]), q3=float(q_ned[2]), q4=float(q_ned[3]),
                rollspeed=float(rates[0]), pitchspeed=float(rates[1]), yawspeed=float(rates[2]))]
        if key == MSG_ATTITUDE:
            roll, pitch, yaw = quat_to_euler_zyx(q_ned)
            return [mav.attitude_encode(time_boot_ms=ms, roll=roll, pitch=pitch, yaw=yaw, rollspeed=float(rates[0]),
                                        pitchspeed=float(rates[1]), yawspeed=float(rates[2]))]
        if key == MSG_HIGHRES_IMU:
            accel = flu_to_frd(sample.specific_force)
            return [mav.highres_imu_encode(
                time_usec=int(round(max(0.0, t) * 1e6)), xacc=float(accel[0]), yacc=float(accel[1]),
                zacc=float(accel[2]), xgyro=float(rates[0]), ygyro=float(rates[1]), zgyro=float(rates[2]), xmag=0.0,
                ymag=0.0, zmag=0.0, abs_pressure=0.0, diff_pressure=0.0, pressure_alt=0.0, temperature=25.0,
                fields_updated=0x3F, id=0)]
        if key == MSG_LOCAL_POSITION_NED:
            p = enu_to_ned(sample.position_local)
            v = enu_to_ned(sample.velocity_local)
            return [mav.local_position_ned_encode(time_boot_ms=ms, x=float(p[0]), y=float(p[1]), z=float(p[2]),
                                                  vx=float(v[0]), vy=float(v[1]), vz=float(v[2]))]
        return []

    # ------------------------------------------------------------------------------------------ mode logic
    @property
    def custom_mode(self) -> int:
        return encode_custom_mode(self.main_mode, self.sub_mode)

    @property
    def offboard(self) -> bool:
        return self.main_mode == Px4MainMode.OFFBOARD

    def _is_auto(self, *subs: int) -> bool:
        return self.main_mode == Px4MainMode.AUTO and self.sub_mode in subs

    @property
    def takes_offboard_setpoints(self) -> bool:
        """Armed, and not in a mode that ignores the offboard stream (AUTO.LAND, AUTO.LOITER, AUTO.TAKEOFF: the
        operator's LAND / Hold and the failsafes): the simulator's lockstep waits for a live stream only while
        this holds."""
        return self.armed and not self._is_auto(Px4AutoSubMode.LAND, Px4AutoSubMode.LOITER, Px4AutoSubMode.TAKEOFF)

    @property
    def mode_name(self) -> str:
        """The main/sub mode as PX4 names it (OFFBOARD, POSCTL, AUTO.LAND, ...), for messages."""
        return mode_name(self.main_mode, self.sub_mode) + ("" if self.armed else " (disarmed)")

    @property
    def needs_rc(self) -> bool:
        """The present mode flies on RC sticks (PX4's mode requirement "manual control")."""
        return self.main_mode in _RC_MODES

    @property
    def landed_state(self) -> int:
        """MAV_LANDED_STATE for EXTENDED_SYS_STATE (PX4's from the land detector and the mode)."""
        if not self.armed or self.landed:
            return LANDED_STATE_ON_GROUND
        if self._is_auto(Px4AutoSubMode.TAKEOFF):
            return LANDED_STATE_TAKEOFF
        if self._is_auto(Px4AutoSubMode.LAND):
            return LANDED_STATE_LANDING
        return LANDED_STATE_IN_AIR

    @property
    def flies_body_rates(self) -> bool:
        """Offboard body-rate setpoints: the attitude loop is bypassed (its setpoint is the current attitude)."""
        return self.offboard and self.offboard_kind == "attitude" and self.rate_mode

    @property
    def uses_position_control(self) -> bool:
        """The present mode flies on the position controller (it needs the local position in :meth:`update`)."""
        if self.offboard:
            return self.offboard_kind == "position"
        return self._is_auto(Px4AutoSubMode.LOITER, Px4AutoSubMode.LAND, Px4AutoSubMode.TAKEOFF) or \
            self.main_mode in (Px4MainMode.POSCTL, Px4MainMode.ALTCTL)

    def _current_yaw(self) -> float:
        return _yaw_of(self._attitude_local)

    def update(self, sim_time: float, landed: bool, attitude_world: np.ndarray,
               position_local: np.ndarray | None = None, velocity_local: np.ndarray | None = None) -> Px4Setpoint:
        """PX4's mode logic at ``sim_time`` (module doc): offboard- and RC-loss failsafes, hold -> land,
        auto-disarm, the position-controlled modes; returns the setpoint to fly (world frame).

        ``landed``: the vehicle's gear touches the ground; ``attitude_world``: its true attitude (body FLU ->
        world ENU); ``position_local`` / ``velocity_local``: its position [m] / velocity [m/s] in its own frame
        F0i ENU (PX4's local position estimate; without them the position-controlled modes fly level with the
        last thrust).
        """
        self.time = sim_time
        cfg = self.config
        if self._uplink:
            self._release_uplink(sim_time)
        self.position_local = None if position_local is None else np.asarray(position_local, dtype=float)
        self.velocity_local = None if velocity_local is None else np.asarray(velocity_local, dtype=float)
        q_local_world = self._q_world_from_local * np.array([1.0, -1.0, -1.0, -1.0])
        self._attitude_local = quat_multiply(q_local_world, attitude_world)
        landed = bool(landed) or (self._pc_landed and self._is_auto(Px4AutoSubMode.LAND))
        self.landed = landed
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
        if self._failsafe_since is not None and self._is_auto(Px4AutoSubMode.LOITER) and \
                sim_time - self._failsafe_since > cfg.failsafe_hold_time:
            self.sub_mode = Px4AutoSubMode.LAND
        is_land = self._is_auto(Px4AutoSubMode.LAND)
        if self.armed:
            self._check_auto_disarm(sim_time, landed, is_land)
        q_world_local = self._q_world_from_local
        if self.offboard and self.offboard_kind == "attitude":
            self._pc_mode = None
            if self.rate_mode:
                self._flown_quat, self._flown_thrust = self._attitude_local.copy(), self.thrust
                return Px4Setpoint(attitude_world.copy(), self.thrust, self.armed, self.rate_feedforward.copy())
            self._flown_quat, self._flown_thrust = self.quat_local.copy(), self.thrust
            quat = quat_multiply(q_world_local, self.quat_local)
            return Px4Setpoint(quat, self.thrust, self.armed, self.rate_feedforward.copy())
        if self.uses_position_control and self.position_local is not None and self.velocity_local is not None:
            quat_local, thrust, yaw_rate = self._position_control(sim_time, landed)
            self._flown_quat, self._flown_thrust = quat_local, thrust
            return Px4Setpoint(quat_multiply(q_world_local, quat_local), thrust, self.armed,
                               np.array([0.0, 0.0, yaw_rate]))
        # manual-like modes without sticks (or no local position): level attitude with the current yaw
        self._pc_mode = None
        yaw = _yaw_of(attitude_world)
        level = np.array([math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)])
        thrust = 0.0 if landed or not self.armed else self._flown_thrust  # idle on the ground (module doc)
        self._flown_quat, self._flown_thrust = quat_multiply(q_local_world, level), thrust
        return Px4Setpoint(level, thrust, self.armed, np.zeros(3))

    def _position_control(self, sim_time: float, landed: bool) -> tuple[np.ndarray, float, float]:
        """The position-controlled modes (module doc): F0i attitude, normalized thrust, yaw-rate feed-forward."""
        cfg = self.config
        pc = self.position_controller
        position, velocity = self.position_local, self.velocity_local
        mode = (self.main_mode, self.sub_mode, self.offboard_kind if self.offboard else "")
        if self._pc_mode is None:
            # taking over (module doc): bumpless from the thrust flown last (idle on the ground: the guess)
            pc.reset(self._flown_quat if self._flown_thrust > 0.0 else None, self._flown_thrust)
            self._last_pc_time = None
            self._low_thrust_since = None
            self._pc_landed = False
        if mode != self._pc_mode:
            self._hold_position = position.copy()
            self._hold_yaw = self._current_yaw()
            if self._is_auto(Px4AutoSubMode.TAKEOFF):
                self._takeoff_altitude = position[2] + cfg.takeoff_altitude
            if not self._is_auto(Px4AutoSubMode.LAND):
                self._pc_landed = False
            self._pc_mode = mode
        dt = 0.0 if self._last_pc_time is None else sim_time - self._last_pc_time
        self._last_pc_time = sim_time
        nan3 = np.full(3, np.nan)
        position_sp, velocity_sp, acceleration_sp = self._hold_position.copy(), np.zeros(3), None
        yaw_sp, yaw_rate = self._hold_yaw, 0.0
        horizontal = True
        on_ground_idle = landed
        if self.offboard:
            target = self.position_target
            position_sp, velocity_sp, acceleration_sp = target.position, target.velocity, target.acceleration
            if np.isnan(position_sp).all() and np.isnan(velocity_sp).all():
                # acceleration only: PX4 damps nothing (velocity feed-forward 0, no position)
                velocity_sp = nan3
            if math.isfinite(target.yaw):
                yaw_sp = target.yaw
            elif math.isfinite(target.yaw_rate):
                self._hold_yaw = self._current_yaw() + target.yaw_rate * dt
                yaw_sp, yaw_rate = self._hold_yaw, target.yaw_rate
            on_ground_idle = landed and not (np.nan_to_num(velocity_sp)[2] > 0.0 or
                                             position_sp[2] > position[2] + 0.1)
        elif self._is_auto(Px4AutoSubMode.TAKEOFF):
            position_sp = np.array([self._hold_position[0], self._hold_position[1], np.nan])
            velocity_sp = np.array([0.0, 0.0, min(cfg.takeoff_speed,
                                                  cfg.position_control.z_p * (self._takeoff_altitude - position[2]))])
            on_ground_idle = False
            if abs(self._takeoff_altitude - position[2]) < 0.1:
                self._set_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER)  # take-off done: Hold (navigator)
                self._pc_mode = (self.main_mode, self.sub_mode, "")
                self._hold_position = np.array([position[0], position[1], self._takeoff_altitude])
        elif self._is_auto(Px4AutoSubMode.LAND):
            position_sp = np.array([self._hold_position[0], self._hold_position[1], np.nan])
            velocity_sp = np.array([0.0, 0.0, -cfg.land_speed])
        elif self.main_mode == Px4MainMode.ALTCTL:
            horizontal = False  # sticks centred: level, altitude held
        if on_ground_idle or not self.armed:
            # PX4 keeps a landed vehicle at idle (no take-off without a climb request), integrators frozen
            self._low_thrust_since = None
            return self._level_local(), 0.0, 0.0
        if not horizontal:
            position_sp[:2] = np.nan
        out = pc.update(dt, position, velocity, position_sp, velocity_sp, yaw_sp, acceleration_sp,
                        integrate=not landed)
        quat, thrust = out.quat, out.thrust
        if not horizontal:
            quat = self._level_local()
            pc.vel_int[:2] = 0.0
        self._land_detector(sim_time, thrust, velocity)
        return quat, thrust, yaw_rate

    def _level_local(self) -> np.ndarray:
        yaw = self._current_yaw()
        return np.array([math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)])

    def _land_detector(self, sim_time: float, thrust: float, velocity: np.ndarray) -> None:
        """PX4 MulticopterLandDetector, its low-thrust rule (AUTO.LAND): a collective near MPC_THR_MIN and no
        vertical motion (|v_z| < LNDMC_Z_VEL_MAX) for LNDMC_TRIG_TIME -> landed (besides the gear contact)."""
        cfg = self.config
        if not self._is_auto(Px4AutoSubMode.LAND):
            self._low_thrust_since = None
            return
        pc = self.position_controller
        low = thrust <= cfg.position_control.thr_min + 0.3 * (pc.hover_thrust - cfg.position_control.thr_min)
        if low and abs(float(velocity[2])) < cfg.land_detector_z_vel:
            self._low_thrust_since = sim_time if self._low_thrust_since is None else self._low_thrust_since
            if sim_time - self._low_thrust_since >= cfg.land_detector_time:
                self._pc_landed = True
        else:
            self._low_thrust_since = None

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
        self._pc_landed = False

    # ------------------------------------------------------------------------------------------ send
    def _send(self, message, address: tuple[str, int] | None = None) -> None:
        target = address or self.peer
        if target is None:
            return
        if self.signing:
            advance_signing_timestamp(self.mav, self._wall_clock())
        try:
            self.sock.sendto(message.pack(self.mav), target)
        except OSError:
            return
        self.sent_datagrams += 1

    def keep_alive(self) -> None:
        """A HEARTBEAT now, outside the streams (simulation only): the simulator sends one every few tenths of a
        second of WALL time while its lockstep waits for a setpoint, so that the bridges' wall-clock watchdog
        (which tells a dead simulator from a live one although /clock stopped) never takes a live but waiting
        simulator for a dead one. A HEARTBEAT carries no time, so it changes nothing else."""
        self._send_one(MSG_HEARTBEAT, self.time, None)

    def send_status(self, voltage: float, remaining: float, current: float) -> None:
        """HEARTBEAT, SYS_STATUS and BATTERY_STATUS now (voltage [V], remaining [0..1], current [A])."""
        self._battery = (voltage, remaining, current)
        for key in (MSG_HEARTBEAT, MSG_SYS_STATUS, MSG_BATTERY_STATUS):
            self._send_one(key, self.time, None)

    def send_telemetry(self, sample: ImuSample, sim_time: float | None = None) -> None:
        """ATTITUDE_QUATERNION, ATTITUDE, HIGHRES_IMU, LOCAL_POSITION_NED now from a sample in F0i / FLU, taken at
        simulation time ``sim_time`` [s] (default: the time of the last :meth:`poll` / :meth:`update`)."""
        t = self.time if sim_time is None else float(sim_time)
        self.last_sample = sample
        for key in (MSG_ATTITUDE_QUATERNION, MSG_ATTITUDE, MSG_HIGHRES_IMU, MSG_LOCAL_POSITION_NED):
            self._send_one(key, t, None)
