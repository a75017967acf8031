"""PX4's MAVLink vocabulary used by the bridge and by the simulator's PX4 emulator (ROS-free).

- PX4 ``custom_mode`` (HEARTBEAT / DO_SET_MODE): a union ``{u16 reserved; u8 main_mode; u8 sub_mode}``
  (PX4 ``src/modules/commander/px4_custom_mode.h``), i.e. ``custom_mode = main << 16 | sub << 24``.
  OFFBOARD is main mode 6 -> ``custom_mode = 393216`` (spec px4_ros_facts.md §1.4; 5 is a known wrong value).
- ``MAV_MODE_FLAG`` bits of HEARTBEAT ``base_mode``; SET_ATTITUDE_TARGET ``type_mask`` bits (§1.2).
- SET_ATTITUDE_TARGET from/to an ENU/FLU attitude (``[w, x, y, z]``, body FLU -> local ENU) and a normalized
  thrust: the quaternion goes through :mod:`fpr_model.frames` (NED/FRD on the wire, §1.7), the thrust is
  PX4's normalized collective thrust in [0, 1] (§1.3, §1.6; see :mod:`fpr_model.battery` for newtons).
- :func:`import_mavlink` sets ``MAVLINK20=1`` before importing pymavlink (toolchain.md §7) and returns the
  MAVLink 2 ``common`` dialect module.

The messages the bridge consumes from PX4 are listed in :data:`TELEMETRY_MESSAGES` (what an emulator must send).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from fpr_model.frames import quat_enu_flu_to_ned_frd, quat_ned_frd_to_enu_flu

__all__ = [
    "ATTITUDE_IGNORE",
    "ATTITUDE_THRUST_TYPE_MASK",
    "BODY_PITCH_RATE_IGNORE",
    "BODY_ROLL_RATE_IGNORE",
    "BODY_YAW_RATE_IGNORE",
    "FORCE_DISARM_MAGIC",
    "MAV_AUTOPILOT_INVALID",
    "MAV_AUTOPILOT_PX4",
    "MAV_CMD_COMPONENT_ARM_DISARM",
    "MAV_CMD_DO_FLIGHTTERMINATION",
    "MAV_CMD_DO_SET_MODE",
    "MAV_CMD_SET_MESSAGE_INTERVAL",
    "MAV_COMP_ID_AUTOPILOT1",
    "MAV_COMP_ID_ONBOARD_COMPUTER",
    "MAV_MODE_FLAG_AUTO_ENABLED",
    "MAV_MODE_FLAG_CUSTOM_MODE_ENABLED",
    "MAV_MODE_FLAG_GUIDED_ENABLED",
    "MAV_MODE_FLAG_HIL_ENABLED",
    "MAV_MODE_FLAG_MANUAL_INPUT_ENABLED",
    "MAV_MODE_FLAG_SAFETY_ARMED",
    "MAV_MODE_FLAG_STABILIZE_ENABLED",
    "MAV_MODE_FLAG_TEST_ENABLED",
    "MAV_RESULT_ACCEPTED",
    "MAV_RESULT_NAMES",
    "MAV_STATE_ACTIVE",
    "MAV_TYPE_ONBOARD_CONTROLLER",
    "MAV_TYPE_QUADROTOR",
    "Px4MainMode",
    "Px4Mode",
    "Px4AutoSubMode",
    "AttitudeTarget",
    "CUSTOM_MODE_AUTO_LAND",
    "CUSTOM_MODE_OFFBOARD",
    "TELEMETRY_MESSAGES",
    "THROTTLE_IGNORE",
    "THRUST_BODY_SET",
    "decode_custom_mode",
    "decode_set_attitude_target",
    "encode_custom_mode",
    "encode_set_attitude_target",
    "import_mavlink",
    "is_armed",
    "mode_name",
    "set_mode_params",
    "validate_attitude_thrust",
]


def import_mavlink() -> ModuleType:
    """Return pymavlink's MAVLink 2 ``common`` dialect module, with ``MAVLINK20=1`` set before any import.

    ``MAVLINK20`` decides the wire version of ``mavutil``; the v20 dialect module always packs MAVLink 2.
    """
    os.environ["MAVLINK20"] = "1"
    from pymavlink.dialects.v20 import common

    return common


# ---- MAVLink enums (common.xml), as plain ints so that this module imports without pymavlink -------------
MAV_TYPE_QUADROTOR = 2
MAV_TYPE_GCS = 6
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_PX4 = 12
MAV_AUTOPILOT_INVALID = 8
MAV_STATE_ACTIVE = 4
MAV_COMP_ID_AUTOPILOT1 = 1
MAV_COMP_ID_ONBOARD_COMPUTER = 191

MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_TEST_ENABLED = 2
MAV_MODE_FLAG_AUTO_ENABLED = 4
MAV_MODE_FLAG_GUIDED_ENABLED = 8
MAV_MODE_FLAG_STABILIZE_ENABLED = 16
MAV_MODE_FLAG_HIL_ENABLED = 32
MAV_MODE_FLAG_MANUAL_INPUT_ENABLED = 64
MAV_MODE_FLAG_SAFETY_ARMED = 128

MAV_CMD_DO_SET_MODE = 176
MAV_CMD_DO_FLIGHTTERMINATION = 185
MAV_CMD_COMPONENT_ARM_DISARM = 400
#: param1 = message id, param2 = interval [us] (-1: stop the stream, 0: the autopilot's default rate)
MAV_CMD_SET_MESSAGE_INTERVAL = 511
#: COMPONENT_ARM_DISARM param2 that forces a disarm even in flight (PX4 and ArduPilot).
FORCE_DISARM_MAGIC = 21196.0

MAV_RESULT_ACCEPTED = 0
MAV_RESULT_NAMES = {
    0: "ACCEPTED",
    1: "TEMPORARILY_REJECTED",
    2: "DENIED",
    3: "UNSUPPORTED",
    4: "FAILED",
    5: "IN_PROGRESS",
    6: "CANCELLED",
}

# ---- SET_ATTITUDE_TARGET type_mask (ATTITUDE_TARGET_TYPEMASK) ----------------------------------------------
BODY_ROLL_RATE_IGNORE = 1
BODY_PITCH_RATE_IGNORE = 2
BODY_YAW_RATE_IGNORE = 4
THRUST_BODY_SET = 32
THROTTLE_IGNORE = 64
ATTITUDE_IGNORE = 128
#: Attitude + thrust, all body rates ignored (spec §1.2): 7.
ATTITUDE_THRUST_TYPE_MASK = BODY_ROLL_RATE_IGNORE | BODY_PITCH_RATE_IGNORE | BODY_YAW_RATE_IGNORE

#: Messages the bridge consumes from PX4 (an emulator should stream them; all others are ignored).
TELEMETRY_MESSAGES = (
    "HEARTBEAT",            # base_mode (armed), custom_mode (PX4 mode): link liveness, state machine
    "COMMAND_ACK",          # answers to COMMAND_LONG (arm, set mode, terminate)
    "ATTITUDE_QUATERNION",  # q (FRD -> NED), body rates FRD: imu orientation / angular velocity
    "HIGHRES_IMU",          # specific force FRD [m/s^2] (or SCALED_IMU [mG]): imu linear acceleration
    "ODOMETRY",             # velocity in BODY_FRD (child_frame_id 12) -> velocity_body
    "LOCAL_POSITION_NED",   # velocity NED, rotated into the body with the attitude (if no ODOMETRY)
    "SYS_STATUS",           # voltage_battery [mV], current [cA], remaining [%]
    "BATTERY_STATUS",       # cell voltages [mV], current [cA], remaining [%]
)


class Px4MainMode:
    """PX4 ``PX4_CUSTOM_MAIN_MODE`` (px4_custom_mode.h), counting from MANUAL = 1."""

    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7
    RATTITUDE_LEGACY = 8
    SIMPLE = 9
    TERMINATION = 10


class Px4AutoSubMode:
    """PX4 ``PX4_CUSTOM_SUB_MODE_AUTO`` (sub modes of main mode AUTO)."""

    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6
    FOLLOW_TARGET = 8
    PRECLAND = 9
    VTOL_TAKEOFF = 10


_MAIN_NAMES = {
    Px4MainMode.MANUAL: "MANUAL",
    Px4MainMode.ALTCTL: "ALTCTL",
    Px4MainMode.POSCTL: "POSCTL",
    Px4MainMode.AUTO: "AUTO",
    Px4MainMode.ACRO: "ACRO",
    Px4MainMode.OFFBOARD: "OFFBOARD",
    Px4MainMode.STABILIZED: "STABILIZED",
    Px4MainMode.RATTITUDE_LEGACY: "RATTITUDE",
    Px4MainMode.SIMPLE: "SIMPLE",
    Px4MainMode.TERMINATION: "TERMINATION",
}
_AUTO_SUB_NAMES = {
    Px4AutoSubMode.READY: "READY",
    Px4AutoSubMode.TAKEOFF: "TAKEOFF",
    Px4AutoSubMode.LOITER: "LOITER",
    Px4AutoSubMode.MISSION: "MISSION",
    Px4AutoSubMode.RTL: "RTL",
    Px4AutoSubMode.LAND: "LAND",
    Px4AutoSubMode.FOLLOW_TARGET: "FOLLOW_TARGET",
    Px4AutoSubMode.PRECLAND: "PRECLAND",
    Px4AutoSubMode.VTOL_TAKEOFF: "VTOL_TAKEOFF",
}
_POSCTL_SUB_NAMES = {0: "POSCTL", 1: "ORBIT", 2: "SLOW"}


@dataclass(frozen=True)
class Px4Mode:
    """A decoded PX4 custom mode: main mode, sub mode and its name ("OFFBOARD", "AUTO.LAND", ...)."""

    main_mode: int
    sub_mode: int
    name: str

    @property
    def is_offboard(self) -> bool:
        return self.main_mode == Px4MainMode.OFFBOARD

    @property
    def is_land(self) -> bool:
        return self.main_mode == Px4MainMode.AUTO and self.sub_mode == Px4AutoSubMode.LAND

    @property
    def is_hold(self) -> bool:
        """AUTO.LOITER (PX4's Hold)."""
        return self.main_mode == Px4MainMode.AUTO and self.sub_mode == Px4AutoSubMode.LOITER


def encode_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """HEARTBEAT ``custom_mode`` of a PX4 (main, sub) mode: ``main << 16 | sub << 24``."""
    if not (0 <= main_mode <= 255 and 0 <= sub_mode <= 255):
        raise ValueError(f"PX4 main/sub modes are bytes, got {main_mode}/{sub_mode}")
    return (int(main_mode) << 16) | (int(sub_mode) << 24)


def mode_name(main_mode: int, sub_mode: int = 0) -> str:
    """PX4 mode name: "OFFBOARD", "POSCTL", "AUTO.LAND", ...; "UNKNOWN(main.sub)" for other values."""
    main = _MAIN_NAMES.get(main_mode)
    if main is None:
        return f"UNKNOWN({main_mode}.{sub_mode})"
    if main_mode == Px4MainMode.AUTO:
        return "AUTO." + _AUTO_SUB_NAMES.get(sub_mode, str(sub_mode))
    if main_mode == Px4MainMode.POSCTL and sub_mode:
        return "POSCTL." + _POSCTL_SUB_NAMES.get(sub_mode, str(sub_mode))
    return main


def decode_custom_mode(custom_mode: int) -> Px4Mode:
    """Split a HEARTBEAT ``custom_mode`` into PX4 main and sub modes (the low 16 bits are reserved)."""
    custom_mode = int(custom_mode) & 0xFFFFFFFF
    main_mode = (custom_mode >> 16) & 0xFF
    sub_mode = (custom_mode >> 24) & 0xFF
    return Px4Mode(main_mode=main_mode, sub_mode=sub_mode, name=mode_name(main_mode, sub_mode))


#: ``custom_mode`` of OFFBOARD: 6 << 16 = 393216.
CUSTOM_MODE_OFFBOARD = encode_custom_mode(Px4MainMode.OFFBOARD)
#: ``custom_mode`` of AUTO.LAND: 4 << 16 | 6 << 24 = 100925440.
CUSTOM_MODE_AUTO_LAND = encode_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LAND)


def is_armed(base_mode: int) -> bool:
    """``MAV_MODE_FLAG_SAFETY_ARMED`` set in a HEARTBEAT ``base_mode``."""
    return bool(int(base_mode) & MAV_MODE_FLAG_SAFETY_ARMED)


def set_mode_params(main_mode: int, sub_mode: int = 0) -> tuple[float, float, float]:
    """``MAV_CMD_DO_SET_MODE`` params 1-3 for a PX4 custom mode: (CUSTOM_MODE_ENABLED, main, sub) (spec §1.4)."""
    return float(MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(main_mode), float(sub_mode)


# ---- SET_ATTITUDE_TARGET -----------------------------------------------------------------------------------
_UNIT_TOLERANCE = 1e-3


def validate_attitude_thrust(q_enu_flu, thrust_normalized: float, unit_tolerance: float = _UNIT_TOLERANCE
                             ) -> tuple[np.ndarray, float]:
    """Check an attitude/thrust pair before it goes on the wire; return ``(unit q, thrust)``.

    Raises ValueError on NaN/inf, ``| ‖q‖ − 1 | > unit_tolerance`` or a thrust outside [0, 1]: a bad setpoint
    is refused, never repaired beyond renormalizing an almost-unit quaternion.
    """
    q = np.asarray(q_enu_flu, dtype=float)
    if q.shape != (4,):
        raise ValueError(f"attitude quaternion must have 4 components, got shape {q.shape}")
    if not np.isfinite(q).all():
        raise ValueError(f"attitude quaternion contains NaN/inf: {q.tolist()}")
    norm = math.sqrt(float(q @ q))
    if abs(norm - 1.0) > unit_tolerance:
        raise ValueError(f"attitude quaternion is not unit: norm {norm:.6g}")
    thrust = float(thrust_normalized)
    if not (math.isfinite(thrust) and 0.0 <= thrust <= 1.0):
        raise ValueError(f"normalized thrust must be finite and in [0, 1], got {thrust}")
    return q / norm, thrust


def encode_set_attitude_target(mav, time_boot_ms: int, target_system: int, target_component: int,
                               q_enu_flu, thrust_normalized: float):
    """SET_ATTITUDE_TARGET (id 82) for an ENU/FLU attitude ``[w, x, y, z]`` and a normalized thrust in [0, 1].

    ``q`` on the wire is FRD -> NED: ``q_NED_FRD = q_NE ∘ q_ENU_FLU ∘ q_x(π)`` (:mod:`fpr_model.frames`);
    ``type_mask`` = 7 (body rates ignored); ``mav`` is a pymavlink ``MAVLink`` object (any ``file``).
    Raises ValueError (see :func:`validate_attitude_thrust`) instead of encoding a bad setpoint.
    """
    q, thrust = validate_attitude_thrust(q_enu_flu, thrust_normalized)
    q_ned_frd = quat_enu_flu_to_ned_frd(q)
    return mav.set_attitude_target_encode(
        time_boot_ms=int(time_boot_ms) & 0xFFFFFFFF,
        target_system=int(target_system),
        target_component=int(target_component),
        type_mask=ATTITUDE_THRUST_TYPE_MASK,
        q=[float(c) for c in q_ned_frd],
        body_roll_rate=0.0,
        body_pitch_rate=0.0,
        body_yaw_rate=0.0,
        thrust=thrust,
    )


@dataclass(frozen=True)
class AttitudeTarget:
    """A received SET_ATTITUDE_TARGET, in both frames."""

    time_boot_ms: int
    target_system: int
    target_component: int
    type_mask: int
    q_ned_frd: np.ndarray  #: [w, x, y, z], body FRD -> local NED, as on the wire
    q_enu_flu: np.ndarray  #: [w, x, y, z], body FLU -> local ENU
    body_rates_frd: np.ndarray  #: [rad/s] roll, pitch, yaw rates (ignored when type_mask bits 1/2/4 set)
    thrust: float  #: normalized collective thrust

    @property
    def attitude_ignored(self) -> bool:
        return bool(self.type_mask & ATTITUDE_IGNORE)

    @property
    def thrust_ignored(self) -> bool:
        return bool(self.type_mask & THROTTLE_IGNORE)


def decode_set_attitude_target(msg) -> AttitudeTarget:
    """Read a pymavlink SET_ATTITUDE_TARGET message into an :class:`AttitudeTarget` (q converted to ENU/FLU).

    Raises ValueError if the quaternion is not finite or is zero (an emulator must not apply it).
    """
    q_ned = np.asarray(msg.q, dtype=float)
    if q_ned.shape != (4,) or not np.isfinite(q_ned).all() or float(q_ned @ q_ned) == 0.0:
        raise ValueError(f"SET_ATTITUDE_TARGET with an invalid quaternion {list(msg.q)}")
    q_ned = q_ned / math.sqrt(float(q_ned @ q_ned))
    return AttitudeTarget(
        time_boot_ms=int(msg.time_boot_ms),
        target_system=int(msg.target_system),
        target_component=int(msg.target_component),
        type_mask=int(msg.type_mask),
        q_ned_frd=q_ned,
        q_enu_flu=quat_ned_frd_to_enu_flu(q_ned),
        body_rates_frd=np.array([msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate], dtype=float),
        thrust=float(msg.thrust),
    )
