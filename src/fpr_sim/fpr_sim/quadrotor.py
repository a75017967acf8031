"""The n quadrotors of the plant: PX4-like attitude control, mixer, motors, rotational dynamics, battery.

Vectorized over the n vehicles (arrays with a leading axis n). Per vehicle, with body frame FLU and world ENU:

- attitude P loop (3.39): ``ω_d = 2·P·sgn(q_err,0)·q_err,1:3`` with ``q_err = q⁻¹ ∘ q_d``; P = 1/τ [1/s], so
  that a small attitude step is tracked as a first-order lag of time constant τ when the rates are tracked;
- rate PID (3.40): ``m_d = K_P ε_ω + K_D ε̇_ω + K_I ∫ε_ω`` (derivative on the measurement, clamped integrator),
  both at ``controller_rate`` (250 Hz, PX4) with zero-order hold in between;
- mixer (3.41): rotor thrusts ``T_j = c_T Ω_j²`` from ``[f_t, m_x, m_y, m_z]`` by the inverse of the "+"
  allocation matrix (rotor 1 front +x, 2 left +y, 3 back, 4 right), with collective shifted to keep the
  moments when a rotor saturates, then clipped to ``[0, f_max(V)/4]``;
- collective command ``f_t = u_f · f_max(V)`` ((C.1) inverted, (C.2)) with the battery voltage V of
  :class:`Battery` (it drops over the flight, Table C.1 curve per vehicle);
- first-order motor lag ``Ṫ_j = (T_j,cmd − T_j)/τ_m``;
- rotational dynamics (2.92): ``q̇ = ½ q ∘ [0, ω]``, ``I ω̇ = m − ω × I ω`` with ``m`` the rotor moments plus
  the external body moment (spherical-joint offset moment (2.93), ground), integrated with RK4.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from fpr_model.battery import ThrustCoefficients
from fpr_model.rotations import quat_error, quat_to_rotmat

from fpr_sim.scenario import BatteryConfig, Px4Config, QuadrotorConfig, per_uav

__all__ = ["AttitudeCommand", "Battery", "QuadrotorFleet", "mix"]


@dataclass
class AttitudeCommand:
    """What each PX4 feeds its attitude controller: ENU/FLU attitude [w,x,y,z] (n, 4), normalized thrust
    u_f in [0, 1] (n,), armed flags (n,) bool. ``rate_feedforward`` optional body rates [rad/s] (n, 3)."""

    quat: np.ndarray
    thrust: np.ndarray
    armed: np.ndarray
    rate_feedforward: np.ndarray | None = None


class Battery:
    """Per-vehicle battery: ``V = V_oc(Q_used) − R·I`` with ``I = k_I·f_t`` and linear V_oc (see BatteryConfig)."""

    def __init__(self, config: BatteryConfig, n: int) -> None:
        self.config = config
        self.charge_used = np.array([float(per_uav(config.initial_charge_used, i)) for i in range(n)])  # [A h]
        self.current = np.zeros(n)

    def open_circuit_voltage(self) -> np.ndarray:
        """[V]: linear from full to empty over the capacity, then constant."""
        c = self.config
        fraction = np.clip(self.charge_used / c.capacity, 0.0, 1.0)
        return c.full_voltage - (c.full_voltage - c.empty_voltage) * fraction

    def voltage(self) -> np.ndarray:
        """Terminal voltage under the present load [V]."""
        return self.open_circuit_voltage() - self.config.internal_resistance * self.current

    def remaining(self) -> np.ndarray:
        """Remaining charge fraction in [0, 1]."""
        return np.clip(1.0 - self.charge_used / self.config.capacity, 0.0, 1.0)

    def update(self, thrust: np.ndarray, dt: float) -> None:
        """Draw ``current_per_newton · thrust`` [A] during ``dt`` [s]."""
        self.current = self.config.current_per_newton * np.maximum(thrust, 0.0)
        self.charge_used = self.charge_used + self.current * dt / 3600.0


def mix(collective: np.ndarray, moments: np.ndarray, arm: float, kappa: float, rotor_max: np.ndarray) -> np.ndarray:
    """Rotor thrusts (n, 4) [N] from collective (n,) [N] and body moments (n, 3) [N m] by inverting (3.41).

    ``arm`` d [m], ``kappa`` c_Q/c_T [m], ``rotor_max`` (n,) [N]. Moments are kept when possible: the
    collective part is shifted down (up) when a rotor exceeds its maximum (goes below 0), then all are clipped.
    """
    mx, my, mz = moments[:, 0], moments[:, 1], moments[:, 2]
    quarter = 0.25 * collective
    dm = np.stack([-my / (2 * arm) - mz / (4 * kappa), mx / (2 * arm) + mz / (4 * kappa),
                   my / (2 * arm) - mz / (4 * kappa), -mx / (2 * arm) + mz / (4 * kappa)], axis=1)
    rotors = quarter[:, None] + dm
    over = np.maximum(rotors.max(axis=1) - rotor_max, 0.0)
    rotors = rotors - over[:, None]
    under = np.maximum(-rotors.min(axis=1), 0.0)
    rotors = rotors + under[:, None]
    return np.clip(rotors, 0.0, rotor_max[:, None])


class QuadrotorFleet:
    """State and low-level control of the n quadrotors (see the module doc for the equations)."""

    def __init__(self, n: int, quad: QuadrotorConfig, px4: Px4Config, battery: BatteryConfig) -> None:
        self.n = n
        self.inertia = np.array(quad.inertia, dtype=float)  # diagonal (3,)
        if self.inertia.shape != (3,) or (self.inertia <= 0).any():
            raise ValueError(f"quadrotor.inertia: expected 3 positive diagonal values, got {quad.inertia}")
        self.arm = float(quad.arm_length)
        self.kappa = float(quad.torque_coefficient)
        self.motor_tau = float(quad.motor_time_constant)
        self.coefficients = [ThrustCoefficients(*map(float, per_uav(quad.thrust_coefficients, i))) for i in range(n)]
        self.attitude_p = np.array(px4.attitude_p_gain, dtype=float)
        self.rate_p = np.array(px4.rate_p_gain, dtype=float)
        self.rate_i = np.array(px4.rate_i_gain, dtype=float)
        self.rate_d = np.array(px4.rate_d_gain, dtype=float)
        self.integrator_limit = float(px4.rate_integrator_limit)
        self.max_rate = np.array(px4.max_rate, dtype=float)
        self.controller_period = 1.0 / px4.controller_rate
        self.battery = Battery(battery, n)
        self.quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        self.rate = np.zeros((n, 3))
        self.rotors = np.zeros((n, 4))
        self.rotor_commands = np.zeros((n, 4))
        self.rate_integral = np.zeros((n, 3))
        self.previous_rate = np.zeros((n, 3))
        self.rate_setpoint = np.zeros((n, 3))
        self.f_max = self.max_thrust()

    # ----------------------------------------------------------------------------------------------
    def max_thrust(self) -> np.ndarray:
        """f_max(V) [N] per vehicle, (C.2) with the present battery voltage (never negative)."""
        voltage = self.battery.voltage()
        return np.array([max(0.0, c.max_thrust(float(v))) for c, v in zip(self.coefficients, voltage, strict=True)])

    def thrust(self) -> np.ndarray:
        """Actual collective thrust along body +z [N], (n,)."""
        return self.rotors.sum(axis=1)

    def thrust_vectors(self) -> np.ndarray:
        """Thrust vectors in the world frame f_i = R_bi [0, 0, f_t,i] [N], (n, 3)."""
        return quat_to_rotmat(self.quat)[:, :, 2] * self.thrust()[:, None]

    def hover_rotor_state(self, thrust: np.ndarray) -> None:
        """Set rotors (and their commands) to produce ``thrust`` [N] (n,) with zero moment (initial hover)."""
        self.rotors = np.repeat(0.25 * np.asarray(thrust, dtype=float)[:, None], 4, axis=1)
        self.rotor_commands = self.rotors.copy()

    # ----------------------------------------------------------------------------------------------
    def control(self, command: AttitudeCommand, measured_rate: np.ndarray | None = None) -> None:
        """One PX4 attitude + rate controller update (3.39)-(3.41), held for ``controller_period``."""
        dt = self.controller_period
        rate = self.rate if measured_rate is None else measured_rate
        self.f_max = self.max_thrust()
        err = quat_error(self.quat, command.quat)
        sign = np.where(err[:, :1] >= 0.0, 1.0, -1.0)
        rate_sp = 2.0 * self.attitude_p * sign * err[:, 1:]
        if command.rate_feedforward is not None:
            rate_sp = rate_sp + command.rate_feedforward
        rate_sp = np.clip(rate_sp, -self.max_rate, self.max_rate)
        self.rate_setpoint = rate_sp
        error = rate_sp - rate
        armed = np.asarray(command.armed, dtype=bool)
        self.rate_integral = np.where(armed[:, None], self.rate_integral + error * dt, 0.0)
        bound = self.integrator_limit / np.maximum(self.rate_i, 1e-12)
        self.rate_integral = np.clip(self.rate_integral, -bound, bound)
        derivative = (rate - self.previous_rate) / dt  # on the measurement (PX4)
        moments = self.rate_p * error + self.rate_i * self.rate_integral - self.rate_d * derivative
        self.previous_rate = rate.copy()
        u = np.clip(np.nan_to_num(command.thrust, nan=0.0), 0.0, 1.0)
        collective = u * self.f_max
        commands = mix(collective, moments, self.arm, self.kappa, 0.25 * self.f_max)
        self.rotor_commands = np.where(armed[:, None], commands, 0.0)

    # ----------------------------------------------------------------------------------------------
    def _derivatives(self, quat, rate, rotors, body_moment):
        inertia = self.inertia
        t1, t2, t3, t4 = rotors[:, 0], rotors[:, 1], rotors[:, 2], rotors[:, 3]
        moment = np.stack([self.arm * (t2 - t4), self.arm * (t3 - t1), self.kappa * (-t1 + t2 - t3 + t4)], axis=1)
        moment = moment + body_moment
        h = rate * inertia
        w0, w1, w2 = rate[:, 0], rate[:, 1], rate[:, 2]
        gyroscopic = np.stack([w1 * h[:, 2] - w2 * h[:, 1], w2 * h[:, 0] - w0 * h[:, 2], w0 * h[:, 1] - w1 * h[:, 0]],
                              axis=1)
        rate_dot = (moment - gyroscopic) / inertia
        qw, qx, qy, qz = quat[:, 0], quat[:, 1], quat[:, 2], quat[:, 3]
        quat_dot = 0.5 * np.stack([-qx * w0 - qy * w1 - qz * w2, qw * w0 + qy * w2 - qz * w1,
                                   qw * w1 - qx * w2 + qz * w0, qw * w2 + qx * w1 - qy * w0], axis=1)
        rotor_dot = (self.rotor_commands - rotors) / self.motor_tau
        return quat_dot, rate_dot, rotor_dot

    def step(self, dt: float, body_moment: np.ndarray) -> None:
        """Advance (2.92) and the motor lag by ``dt`` [s] with RK4; ``body_moment`` (n, 3) [N m] in FLU."""
        q0, w0, r0 = self.quat, self.rate, self.rotors
        k1 = self._derivatives(q0, w0, r0, body_moment)
        h = 0.5 * dt
        k2 = self._derivatives(q0 + h * k1[0], w0 + h * k1[1], r0 + h * k1[2], body_moment)
        k3 = self._derivatives(q0 + h * k2[0], w0 + h * k2[1], r0 + h * k2[2], body_moment)
        k4 = self._derivatives(q0 + dt * k3[0], w0 + dt * k3[1], r0 + dt * k3[2], body_moment)
        sixth = dt / 6.0
        quat = q0 + sixth * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        self.quat = quat / np.linalg.norm(quat, axis=1, keepdims=True)
        self.rate = w0 + sixth * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        self.rotors = np.clip(r0 + sixth * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2]), 0.0, None)
        self.battery.update(self.thrust(), dt)

    def set_ideal(self, command: AttitudeCommand) -> None:
        """Ideal tracking (tests): attitude = setpoint, rates 0, thrust = u_f·f_max(V) at once."""
        self.f_max = self.max_thrust()
        self.quat = np.array(command.quat, dtype=float)
        self.rate = np.zeros((self.n, 3))
        u = np.clip(np.nan_to_num(command.thrust, nan=0.0), 0.0, 1.0)
        thrust = np.where(np.asarray(command.armed, dtype=bool), u * self.f_max, 0.0)
        self.hover_rotor_state(thrust)
