"""PX4 telemetry (NED/FRD, MAVLink units) -> ROS conventions (ENU/FLU, SI), without rclpy.

All frame changes go through :mod:`fpr_model.frames` (spec px4_ros_facts.md §1.7):
- attitude ``q_NED_FRD`` (ATTITUDE_QUATERNION, ODOMETRY) -> ``q_ENU_FLU`` (body FLU -> the UAV's local ENU);
- body rates / specific force / body velocity FRD -> FLU: ``(x, −y, −z)``;
- world velocity NED (LOCAL_POSITION_NED) -> ENU, then into the body: ``v_FLU = R(q_ENU_FLU)^T v_ENU``.

Stamps: ``time_boot_ms`` / boot ``time_usec`` mapped onto the local clock by a :class:`BootTimeMapper`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from fpr_model.frames import frd_to_flu, ned_to_enu, quat_ned_frd_to_enu_flu
from fpr_model.rotations import quat_conjugate, quat_rotate

from fpr_px4_bridge.time_sync import BootTimeMapper

__all__ = ["BatterySample", "BodyVelocitySample", "ImuSample", "LocalPositionSample", "TelemetryDecoder"]

_MAV_FRAME_LOCAL_NED = 1
_MAV_FRAME_BODY_FRD = 12
_UINT16_MAX = 65535
#: ``time_usec`` values above this are UNIX epoch times, not time since boot (~11.6 days).
_BOOT_USEC_LIMIT = 1_000_000_000_000
#: An acceleration older than this is not attached to an attitude sample [s].
_ACCEL_MAX_AGE = 0.1


@dataclass(frozen=True)
class ImuSample:
    """``sensor_msgs/Imu`` content: orientation in the local ENU frame, FLU rates and specific force."""

    stamp: float                      #: [s] local (ROS) time of the measurement
    orientation: np.ndarray           #: [w, x, y, z], body FLU -> local ENU
    angular_velocity: np.ndarray      #: [rad/s] FLU
    linear_acceleration: np.ndarray | None  #: [m/s^2] FLU specific force (+9.81 z at rest), None if unknown


@dataclass(frozen=True)
class BodyVelocitySample:
    stamp: float                      #: [s] local time
    linear: np.ndarray                #: [m/s] FLU body-frame velocity
    angular: np.ndarray               #: [rad/s] FLU body rates (latest known; zeros if none yet)


@dataclass(frozen=True)
class LocalPositionSample:
    """PX4's local position, as far as the swarm guard's flight envelope needs it."""

    stamp: float                      #: [s] local time
    height: float                     #: [m] up (−z of LOCAL_POSITION_NED), from PX4's local origin
    climb_rate: float                 #: [m/s] up (−vz)
    north: float = math.nan           #: [m] x of LOCAL_POSITION_NED (NaN: not finite)
    east: float = math.nan            #: [m] y of LOCAL_POSITION_NED


@dataclass(frozen=True)
class BatterySample:
    stamp: float                      #: [s] local receive time
    voltage: float                    #: [V], NaN unknown
    current: float                    #: [A], positive discharging as MAVLink reports it; NaN unknown
    remaining: float                  #: [0..1], NaN unknown


def _finite_array(values) -> np.ndarray | None:
    array = np.asarray(values, dtype=float)
    return array if np.isfinite(array).all() else None


class TelemetryDecoder:
    """Turns accepted PX4 telemetry messages into ENU/FLU samples; keeps the latest attitude and battery."""

    def __init__(self, mapper: BootTimeMapper | None = None) -> None:
        self.mapper = mapper or BootTimeMapper()
        self.attitude: np.ndarray | None = None  # latest q_ENU_FLU
        self.rates: np.ndarray = np.zeros(3)
        self._accel: np.ndarray | None = None
        self._accel_stamp = -math.inf
        self.battery: BatterySample | None = None
        self.local_position: LocalPositionSample | None = None  #: latest LOCAL_POSITION_NED (height, climb)
        self.invalid_values = 0  # telemetry dropped because of NaN/inf/zero quaternion

    def _boot_ms_stamp(self, time_boot_ms: int, received: float) -> float:
        boot = float(time_boot_ms) * 1e-3
        self.mapper.update(boot, received)
        return self.mapper.to_local(boot, received)

    def _boot_us_stamp(self, time_usec: int, received: float) -> float:
        if time_usec <= 0 or time_usec > _BOOT_USEC_LIMIT:
            return received
        return self.mapper.to_local(float(time_usec) * 1e-6, received)

    def decode(self, msg, received: float):
        """Return a sample (ImuSample, BodyVelocitySample, BatterySample) for ``msg``, or None."""
        kind = msg.get_type()
        handler = getattr(self, "_on_" + kind.lower(), None)
        if handler is None:
            return None
        return handler(msg, received)

    def _on_attitude_quaternion(self, msg, received: float):
        q = _finite_array([msg.q1, msg.q2, msg.q3, msg.q4])
        rates = _finite_array([msg.rollspeed, msg.pitchspeed, msg.yawspeed])
        if q is None or rates is None or float(q @ q) < 0.25:
            self.invalid_values += 1
            return None
        stamp = self._boot_ms_stamp(msg.time_boot_ms, received)
        q_enu = quat_ned_frd_to_enu_flu(q / math.sqrt(float(q @ q)))
        self.attitude = q_enu
        self.rates = frd_to_flu(rates)
        accel = self._accel if stamp - self._accel_stamp <= _ACCEL_MAX_AGE else None
        return ImuSample(stamp=stamp, orientation=q_enu, angular_velocity=self.rates, linear_acceleration=accel)

    def _store_accel(self, acc_frd, stamp: float) -> None:
        acc = _finite_array(acc_frd)
        if acc is None:
            self.invalid_values += 1
            return
        self._accel = frd_to_flu(acc)
        self._accel_stamp = stamp

    def _on_highres_imu(self, msg, received: float):
        self._store_accel([msg.xacc, msg.yacc, msg.zacc], self._boot_us_stamp(msg.time_usec, received))
        return None

    def _on_scaled_imu(self, msg, received: float):
        milli_g = 9.80665e-3
        self._store_accel([msg.xacc * milli_g, msg.yacc * milli_g, msg.zacc * milli_g],
                          self._boot_ms_stamp(msg.time_boot_ms, received))
        return None

    def _on_odometry(self, msg, received: float):
        v = _finite_array([msg.vx, msg.vy, msg.vz])
        q = _finite_array(msg.q)
        if v is None:
            self.invalid_values += 1
            return None
        stamp = self._boot_us_stamp(msg.time_usec, received)
        if msg.child_frame_id == _MAV_FRAME_BODY_FRD:
            v_flu = frd_to_flu(v)
        elif q is not None and float(q @ q) > 0.25:
            # velocity in the local NED frame: rotate into the body with the message's own attitude
            q_enu = quat_ned_frd_to_enu_flu(q / math.sqrt(float(q @ q)))
            v_flu = quat_rotate(quat_conjugate(q_enu), ned_to_enu(v))
        else:
            self.invalid_values += 1
            return None
        rates = _finite_array([msg.rollspeed, msg.pitchspeed, msg.yawspeed])
        angular = frd_to_flu(rates) if rates is not None else self.rates
        return BodyVelocitySample(stamp=stamp, linear=v_flu, angular=angular)

    def _on_local_position_ned(self, msg, received: float):
        v = _finite_array([msg.vx, msg.vy, msg.vz])
        if v is None or self.attitude is None:
            if v is None:
                self.invalid_values += 1
            return None
        stamp = self._boot_ms_stamp(msg.time_boot_ms, received)
        if math.isfinite(msg.z):
            north, east = (float(c) if math.isfinite(c) else math.nan for c in (msg.x, msg.y))
            self.local_position = LocalPositionSample(stamp=received, height=-float(msg.z), climb_rate=-float(v[2]),
                                                      north=north, east=east)
        v_flu = quat_rotate(quat_conjugate(self.attitude), ned_to_enu(v))
        return BodyVelocitySample(stamp=stamp, linear=v_flu, angular=self.rates)

    def _on_sys_status(self, msg, received: float):
        voltage = msg.voltage_battery * 1e-3 if 0 < msg.voltage_battery < _UINT16_MAX else math.nan
        current = msg.current_battery * 1e-2 if msg.current_battery >= 0 else math.nan
        remaining = msg.battery_remaining * 1e-2 if 0 <= msg.battery_remaining <= 100 else math.nan
        self.battery = BatterySample(stamp=received, voltage=voltage, current=current, remaining=remaining)
        return self.battery

    def _on_battery_status(self, msg, received: float):
        cells = [v for v in msg.voltages if 0 < v < _UINT16_MAX]
        voltage = sum(cells) * 1e-3 if cells else math.nan
        current = msg.current_battery * 1e-2 if msg.current_battery >= 0 else math.nan
        remaining = msg.battery_remaining * 1e-2 if 0 <= msg.battery_remaining <= 100 else math.nan
        self.battery = BatterySample(stamp=received, voltage=voltage, current=current, remaining=remaining)
        return self.battery
