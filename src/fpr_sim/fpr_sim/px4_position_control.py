"""A PX4-like multicopter position controller (mc_pos_control's PositionControl), ROS-free, for the PX4 emulator.

Frame: everything here is in the vehicle's own local frame F0i, ENU (x east, y north, z up) [m, m/s, m/s²];
attitudes are body FLU -> F0i ENU quaternions [w, x, y, z]; thrust is normalized [0, 1] as in PX4's
``vehicle_attitude_setpoint`` (PX4 itself works in NED/FRD: the signs of z are flipped here, nothing else).

Cascade (PX4 ``PositionControl::update``, the structure re-implemented, not copied):

1. position P: ``v_sp = MPC_XY_P · e_xy``, ``MPC_Z_P · e_z`` plus the velocity feed-forward; a NaN position
   component means "no position setpoint" on that axis (velocity control only), as in PX4;
2. velocity limits: horizontal norm ≤ ``MPC_XY_VEL_MAX``, vertical in [−``MPC_Z_VEL_MAX_DN``,
   ``MPC_Z_VEL_MAX_UP``];
3. velocity PID to an acceleration: ``a_sp = K_P (v_sp − v) + ∫ K_I (v_sp − v) dt − K_D v̇ + a_ff`` with
   ``MPC_XY_VEL_P_ACC / _I_ACC / _D_ACC`` and ``MPC_Z_VEL_P_ACC / _I_ACC / _D_ACC`` (acceleration units, as since
   PX4 v1.12); the vertical integrator is limited to ±g, and frozen while the vertical thrust saturates in the
   direction of the error (anti-windup); the horizontal one is frozen while the tilt limit is active in the
   direction of the error;
4. acceleration to thrust (PX4 ``_accelerationControl``): the body z axis is along ``(a_xy, g + a_z)``, tilted
   at most ``MPC_TILTMAX_AIR`` from the vertical; the vertical thrust is ``MPC_THR_HOVER · (g + a_z) / g``
   and the collective is that divided by cos(tilt), clamped to [``MPC_THR_MIN``, ``MPC_THR_MAX``];
5. attitude from the thrust direction and the yaw setpoint (PX4 ``bodyzToAttitude``): body x is the yaw
   heading projected onto the plane normal to the thrust.

Hover thrust: PX4 estimates it on line (``MPC_USE_HTE``, mc_hover_thrust_estimator). Here :meth:`reset`
starts it from the thrust vector the vehicle last flew with (its vertical component; a scenario guess when it
has none) and puts the horizontal component into the horizontal integrator, so that taking over from an
offboard attitude setpoint is bumpless; the integrators then take up the rest. This matters for the FPR:
its UAVs carry the structure through tilted thrusts (the legs' inward components), which a level hover would
drop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from fpr_model.rotations import quat_to_rotmat, rotmat_to_quat

__all__ = ["PositionControlConfig", "PositionController", "PositionControlOutput", "attitude_from_thrust"]

GRAVITY = 9.80665  #: [m/s²] PX4 CONSTANTS_ONE_G


@dataclass
class PositionControlConfig:
    """PX4 mc_pos_control parameters (defaults of PX4 v1.14/v1.15 mc_pos_control_params.c)."""

    xy_p: float = 0.95  #: MPC_XY_P [1/s]
    z_p: float = 1.0  #: MPC_Z_P [1/s]
    xy_vel_p: float = 1.8  #: MPC_XY_VEL_P_ACC [1/s]
    xy_vel_i: float = 0.4  #: MPC_XY_VEL_I_ACC [1/s²]
    xy_vel_d: float = 0.2  #: MPC_XY_VEL_D_ACC [-]
    z_vel_p: float = 4.0  #: MPC_Z_VEL_P_ACC [1/s]
    z_vel_i: float = 2.0  #: MPC_Z_VEL_I_ACC [1/s²]
    z_vel_d: float = 0.0  #: MPC_Z_VEL_D_ACC [-]
    xy_vel_max: float = 12.0  #: MPC_XY_VEL_MAX [m/s]
    z_vel_max_up: float = 3.0  #: MPC_Z_VEL_MAX_UP [m/s]
    z_vel_max_dn: float = 1.5  #: MPC_Z_VEL_MAX_DN [m/s]
    tilt_max: float = math.radians(45.0)  #: MPC_TILTMAX_AIR [rad]
    thr_min: float = 0.12  #: MPC_THR_MIN [-]
    thr_max: float = 1.0  #: MPC_THR_MAX [-]
    hover_thrust: float = 0.5  #: MPC_THR_HOVER [-]: the guess used when no flown thrust is known
    vel_deriv_cutoff: float = 5.0  #: [Hz] low-pass of the velocity derivative (PX4 MPC_VELD_LP)


@dataclass
class PositionControlOutput:
    """Attitude and thrust setpoint (F0i ENU/FLU), the same path as SET_ATTITUDE_TARGET."""

    quat: np.ndarray  #: [w,x,y,z] body FLU -> F0i ENU
    thrust: float  #: normalized collective [0, 1]
    thrust_vector: np.ndarray  #: normalized thrust vector in F0i ENU
    saturated: bool  #: the collective or the tilt limit was active


def attitude_from_thrust(thrust_dir: np.ndarray, yaw: float) -> np.ndarray:
    """Quaternion (body FLU -> ENU) whose body z is ``thrust_dir`` and whose heading is ``yaw`` [rad, ENU]."""
    z_b = np.asarray(thrust_dir, dtype=float)
    norm = float(np.linalg.norm(z_b))
    z_b = np.array([0.0, 0.0, 1.0]) if norm < 1e-9 else z_b / norm
    heading = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    y_b = np.cross(z_b, heading)
    if np.linalg.norm(y_b) < 1e-6:  # thrust horizontal along the heading: any orthogonal y
        y_b = np.cross(z_b, np.array([-math.sin(yaw), math.cos(yaw), 0.0]))
    y_b /= np.linalg.norm(y_b)
    x_b = np.cross(y_b, z_b)
    return rotmat_to_quat(np.column_stack([x_b, y_b, z_b]))


class PositionController:
    """One vehicle's position/velocity controller (module doc). Call :meth:`reset` when it takes over, then
    :meth:`update` at the controller rate."""

    def __init__(self, config: PositionControlConfig | None = None) -> None:
        self.config = config or PositionControlConfig()
        self.hover_thrust = self.config.hover_thrust
        self.vel_int = np.zeros(3)  #: velocity integrator [m/s²] (acceleration units, F0i ENU)
        self._previous_velocity: np.ndarray | None = None
        self._vel_dot = np.zeros(3)
        self.active = False

    def reset(self, last_quat: np.ndarray | None, last_thrust: float) -> None:
        """Take over from the attitude ``last_quat`` (F0i ENU/FLU) and normalized ``last_thrust`` the vehicle
        flew with (None or no vertical thrust: the configured MPC_THR_HOVER guess, zero integrators)."""
        cfg = self.config
        self.vel_int = np.zeros(3)
        self.hover_thrust = cfg.hover_thrust
        if last_quat is not None and last_thrust > 0.0:
            vector = last_thrust * quat_to_rotmat(np.asarray(last_quat, dtype=float))[:, 2]
            if vector[2] > cfg.thr_min:
                self.hover_thrust = float(min(vector[2], cfg.thr_max))
                self.vel_int[:2] = GRAVITY * vector[:2] / self.hover_thrust
        self._previous_velocity = None
        self._vel_dot = np.zeros(3)
        self.active = True

    def update(self, dt: float, position: np.ndarray, velocity: np.ndarray, position_sp: np.ndarray,
               velocity_sp: np.ndarray, yaw_sp: float, acceleration_sp: np.ndarray | None = None,
               integrate: bool = True) -> PositionControlOutput:
        """One step of ``dt`` [s]. ``position_sp`` / ``velocity_sp``: F0i ENU, NaN components unused (a position
        component replaces nothing: its P output adds to the velocity feed-forward, NaN feed-forward = 0);
        ``yaw_sp`` [rad, ENU]; ``integrate`` False freezes the integrators (landed)."""
        cfg = self.config
        position = np.asarray(position, dtype=float)
        velocity = np.asarray(velocity, dtype=float)
        gains_p = np.array([cfg.xy_p, cfg.xy_p, cfg.z_p])
        pos_error = np.where(np.isnan(position_sp), 0.0, np.asarray(position_sp, dtype=float) - position)
        vel_sp = gains_p * pos_error + np.nan_to_num(np.asarray(velocity_sp, dtype=float), nan=0.0)
        # velocity limits
        horizontal = float(np.linalg.norm(vel_sp[:2]))
        if horizontal > cfg.xy_vel_max:
            vel_sp[:2] *= cfg.xy_vel_max / horizontal
        vel_sp[2] = min(max(vel_sp[2], -cfg.z_vel_max_dn), cfg.z_vel_max_up)
        # velocity derivative (low-passed), for the D term
        if self._previous_velocity is not None and dt > 0.0:
            alpha = dt / (dt + 1.0 / (2.0 * math.pi * cfg.vel_deriv_cutoff))
            self._vel_dot += alpha * ((velocity - self._previous_velocity) / dt - self._vel_dot)
        self._previous_velocity = velocity.copy()
        vel_error = vel_sp - velocity
        kp = np.array([cfg.xy_vel_p, cfg.xy_vel_p, cfg.z_vel_p])
        ki = np.array([cfg.xy_vel_i, cfg.xy_vel_i, cfg.z_vel_i])
        kd = np.array([cfg.xy_vel_d, cfg.xy_vel_d, cfg.z_vel_d])
        acc_sp = kp * vel_error + self.vel_int - kd * self._vel_dot
        if acceleration_sp is not None:
            acc_sp = acc_sp + np.nan_to_num(np.asarray(acceleration_sp, dtype=float), nan=0.0)
        # acceleration -> thrust vector (tilt limit, hover-thrust scaling, collective limits)
        lift = GRAVITY + acc_sp[2]
        direction = np.array([acc_sp[0], acc_sp[1], max(lift, 1e-3)])
        direction /= np.linalg.norm(direction)
        tilt = math.acos(min(1.0, max(-1.0, float(direction[2]))))
        tilt_limited = tilt > cfg.tilt_max
        if tilt_limited:
            horizontal_dir = direction[:2] / max(1e-9, float(np.linalg.norm(direction[:2])))
            direction = np.array([*(math.sin(cfg.tilt_max) * horizontal_dir), math.cos(cfg.tilt_max)])
        vertical = self.hover_thrust * lift / GRAVITY
        collective = vertical / float(direction[2])
        clamped = min(max(collective, cfg.thr_min), cfg.thr_max)
        saturated = tilt_limited or clamped != collective
        if integrate and dt > 0.0:
            # anti-windup: no vertical integration pushing further into a saturated collective
            z_increment = ki[2] * vel_error[2] * dt
            if not ((collective >= cfg.thr_max and z_increment > 0.0) or (collective <= cfg.thr_min and
                                                                          z_increment < 0.0)):
                self.vel_int[2] = min(max(self.vel_int[2] + z_increment, -GRAVITY), GRAVITY)
            xy_increment = ki[:2] * vel_error[:2] * dt
            if not (tilt_limited and float(xy_increment @ acc_sp[:2]) > 0.0):
                self.vel_int[:2] += xy_increment
        vector = clamped * direction
        return PositionControlOutput(attitude_from_thrust(direction, yaw_sp), float(clamped), vector, saturated)
