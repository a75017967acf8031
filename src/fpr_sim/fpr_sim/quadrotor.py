"""The n quadrotors of the plant: PX4-like attitude control, mixer, motors, rotational dynamics, battery.

Vectorized over the n vehicles (arrays with a leading axis n). Per vehicle, with body frame FLU and world ENU:

- attitude P loop (3.39): ``ω_d = 2·P·sgn(q_err,0)·q_err,1:3`` with ``q_err = q⁻¹ ∘ q_d``; P = 1/τ [1/s], so
  that a small attitude step is tracked as a first-order lag of time constant τ when the rates are tracked;
- rate PID (3.40): ``m_d = K_P ε_ω + K_D ε̇_ω + K_I ∫ε_ω`` (derivative on the measurement, clamped integrator;
  as in PX4's mc_rate_control the integrator is reset while disarmed and FROZEN while the land detector says
  landed, here: the vehicle's landing gear touches the ground), both at ``controller_rate`` (250 Hz, PX4)
  with zero-order hold in between;
- mixer (3.41): rotor thrusts ``T_j = c_T Ω_j²`` from ``[f_t, m_x, m_y, m_z]`` by the inverse of the "+"
  allocation matrix (rotor 1 front +x, 2 left +y, 3 back, 4 right), desaturated as PX4 does with airmode off
  (the collective is only ever reduced; roll/pitch, then yaw authority is given up instead), then clipped to
  ``[0, f_max(V)/4]``;
- collective command ``f_t = u_f · f_max(V)`` ((C.1) inverted, (C.2)) with the battery voltage V of
  :class:`Battery` (it drops over the flight, Table C.1 curve per vehicle);
- first-order motor lag ``Ṫ_j = (T_j,cmd − T_j)/τ_m``;
- produced rotor thrust ``k_ij T_j`` with the per-rotor factors ``rotor_factors`` (realism: thrust gain spread,
  thrust noise and ground effect, :mod:`fpr_sim.plant_realism`; None: k = 1, the ideal plant) held over a step:
  they scale the rotors' force and moments (3.41), not the battery current (the motors' state);
- rotational dynamics (2.92): ``q̇ = ½ q ∘ [0, ω]``, ``I ω̇ = m − ω × I ω`` with ``m`` the rotor moments plus
  the external body moment (spherical-joint offset moment (2.93), ground), integrated with RK4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from fpr_model.battery import ThrustCoefficients
from fpr_model.rotations import quat_error

from fpr_sim._kernels import QuadKernel, resolve_kernel
from fpr_sim.scenario import BatteryConfig, Px4Config, QuadrotorConfig, per_uav

__all__ = ["AttitudeCommand", "Battery", "QuadrotorFleet", "mix", "plain_floats"]


@dataclass
class AttitudeCommand:
    """What each PX4 feeds its attitude controller: ENU/FLU attitude [w,x,y,z] (n, 4), normalized thrust
    u_f in [0, 1] (n,), armed flags (n,) bool. ``rate_feedforward`` optional body rates [rad/s] (n, 3)."""

    quat: np.ndarray
    thrust: np.ndarray
    armed: np.ndarray
    rate_feedforward: np.ndarray | None = None


class Battery:
    """Per-vehicle battery: ``V = V_oc(Q_used) − R·I`` with ``I = k_I·f_t`` and linear V_oc (see BatteryConfig).

    ``charge_used`` [A h] and ``current`` [A] are (n,) arrays (stored as floats for the 1 kHz loop)."""

    def __init__(self, config: BatteryConfig, n: int) -> None:
        self.config = config
        self._charge_used = [float(per_uav(config.initial_charge_used, i)) for i in range(n)]
        self._current = [0.0] * n

    charge_used = property(lambda self: np.array(self._charge_used),
                           lambda self, value: setattr(self, "_charge_used", plain_floats(value)))
    current = property(lambda self: np.array(self._current),
                       lambda self, value: setattr(self, "_current", plain_floats(value)))

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

    def update(self, thrust, dt: float) -> None:
        """Draw ``current_per_newton · thrust`` [A] during ``dt`` [s]; ``thrust`` (n,) [N]."""
        k = self.config.current_per_newton
        self._current = current = [k * max(t, 0.0) for t in plain_floats(thrust)]
        self._charge_used = [q + i * dt / 3600.0 for q, i in zip(self._charge_used, current, strict=True)]


def mix(collective: np.ndarray, moments: np.ndarray, arm: float, kappa: float, rotor_max: np.ndarray) -> np.ndarray:
    """Rotor thrusts (n, 4) [N] from collective (n,) [N] and body moments (n, 3) [N m] by inverting (3.41).

    ``arm`` d [m], ``kappa`` c_Q/c_T [m], ``rotor_max`` (n,) [N]. Saturation is handled as PX4's mixer with
    airmode off (the default): the collective is never raised above the command; see :func:`mix_one`.
    """
    return np.array([mix_one(f, m, arm, kappa, top) for f, m, top in
                     zip(plain_floats(collective), np.asarray(moments, dtype=float).tolist(), plain_floats(rotor_max),
                         strict=True)]).reshape(-1, 4)


#: PX4 lets the yaw desaturation use 15 % of the actuator range above the maximum (mixYaw) [-]
_YAW_HEADROOM = 0.15


def mix_one(collective: float, moments: list[float], arm: float, kappa: float, rotor_max: float) -> list[float]:
    """:func:`mix` for one vehicle, plain floats: inverse of the "+" allocation (3.41) (rotor 1 front +x, 2 left
    +y, 3 back, 4 right; ``T_1..4`` [N]) with PX4's sequential desaturation, airmode disabled (PX4 default
    MC_AIRMODE = 0; control_allocator ControlAllocationSequentialDesaturation::mixAirmodeDisabled):

    1. collective + roll + pitch; desaturate along the collective direction, REDUCE ONLY (the thrust is never
       increased to unsaturate a rotor: a low collective command stays low);
    2. desaturate along the roll, then the pitch direction (the moments are reduced, not the thrust raised);
    3. add yaw; desaturate along the yaw direction with 15 % headroom above ``rotor_max``; then along the
       collective direction, reduce only;
    4. clip to ``[0, rotor_max]``.

    Each desaturation (PX4 desaturateActuators) moves the rotors along the axis by the gain that removes the
    largest over- and under-shoot (``k_min + k_max``), then by half of the remaining gain. Unsaturated
    commands are the exact inverse of (3.41).
    """
    mx, my, mz = moments
    half_arm = 0.5 / arm
    quarter_kappa = 0.25 / kappa
    quarter = 0.25 * collective
    roll_axis = (0.0, half_arm, 0.0, -half_arm)  # ∂T_j/∂m_x
    pitch_axis = (-half_arm, 0.0, half_arm, 0.0)  # ∂T_j/∂m_y
    yaw_axis = (-quarter_kappa, quarter_kappa, -quarter_kappa, quarter_kappa)  # ∂T_j/∂m_z
    thrust_axis = (0.25, 0.25, 0.25, 0.25)  # ∂T_j/∂f_t
    rotors = [quarter + mx * r + my * p for r, p in zip(roll_axis, pitch_axis, strict=True)]
    if min(rotors) < 0.0 or max(rotors) > rotor_max:  # (inside the bounds every desaturation gain is 0)
        _desaturate(rotors, thrust_axis, rotor_max, reduce_only=True)
        _desaturate(rotors, roll_axis, rotor_max)
        _desaturate(rotors, pitch_axis, rotor_max)
    rotors = [t + mz * y for t, y in zip(rotors, yaw_axis, strict=True)]
    if min(rotors) < 0.0 or max(rotors) > rotor_max:
        _desaturate(rotors, yaw_axis, rotor_max * (1.0 + _YAW_HEADROOM))
        _desaturate(rotors, thrust_axis, rotor_max, reduce_only=True)
    return [min(max(t, 0.0), rotor_max) for t in rotors]


def _desaturation_gain(rotors: list[float], axis: tuple, top: float) -> float:
    """PX4 computeDesaturationGain: ``k_min + k_max`` over the rotors outside [0, top] of the gains that bring
    each back to its bound along ``axis`` (rotors the axis does not move are skipped)."""
    k_min = k_max = 0.0
    for t, a in zip(rotors, axis, strict=True):
        if a == 0.0:
            continue
        if t < 0.0:
            k = -t / a
        elif t > top:
            k = (top - t) / a
        else:
            continue
        k_min = min(k_min, k)
        k_max = max(k_max, k)
    return k_min + k_max


def _desaturate(rotors: list[float], axis: tuple, top: float, reduce_only: bool = False) -> None:
    """PX4 desaturateActuators, in place: move along ``axis`` by the desaturation gain, then by half the gain
    that remains; ``reduce_only`` (for the collective axis) skips the move if the first gain is positive."""
    gain = _desaturation_gain(rotors, axis, top)
    if reduce_only and gain > 0.0:
        return
    for j in range(4):
        rotors[j] += gain * axis[j]
    gain = 0.5 * _desaturation_gain(rotors, axis, top)
    for j in range(4):
        rotors[j] += gain * axis[j]


class QuadrotorFleet:
    """State and low-level control of the n quadrotors (see the module doc for the equations).

    The state arrays ``quat`` (n, 4), ``rate`` (n, 3), ``rotors`` (n, 4) [N], ``rotor_commands``,
    ``rate_integral``, ``previous_rate`` and ``rate_setpoint`` (n, 3) are stored as plain floats for the
    1 kHz loop; reading one returns a numpy copy, assigning one replaces it.
    """

    def __init__(self, n: int, quad: QuadrotorConfig, px4: Px4Config, battery: BatteryConfig,
                 kernel: str | None = None) -> None:
        self.n = n
        #: 'compiled' (control and step run in fpr_sim._kernels' C kernel, which reads the constants below once,
        #: here) or 'python' (this module, the reference); ``kernel`` = 'auto' | 'compiled' | 'python'
        #: (None: $FPR_SIM_KERNEL, default 'auto')
        self.kernel = resolve_kernel(kernel, n)
        self.inertia = np.array(quad.inertia, dtype=float)  # diagonal (3,)
        if self.inertia.shape != (3,) or (self.inertia <= 0).any():
            raise ValueError(f"quadrotor.inertia: expected 3 positive diagonal values, got {quad.inertia}")
        self._inertia = tuple(self.inertia.tolist())
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
        #: per-rotor produced-thrust factors (n, 4) held over the next step (set by the plant each step), or None
        self.rotor_factors: list[list[float]] | None = None
        self._compiled = QuadKernel(self) if self.kernel == "compiled" else None

    quat = property(lambda self: np.array(self._quat), lambda self, value: setattr(self, "_quat", _rows(value)))
    rate = property(lambda self: np.array(self._rate), lambda self, value: setattr(self, "_rate", _rows(value)))
    rotors = property(lambda self: np.array(self._rotors),
                      lambda self, value: setattr(self, "_rotors", _rows(value)))
    rotor_commands = property(lambda self: np.array(self._rotor_commands),
                              lambda self, value: setattr(self, "_rotor_commands", _rows(value)))
    rate_integral = property(lambda self: np.array(self._rate_integral),
                             lambda self, value: setattr(self, "_rate_integral", _rows(value)))
    previous_rate = property(lambda self: np.array(self._previous_rate),
                             lambda self, value: setattr(self, "_previous_rate", _rows(value)))
    rate_setpoint = property(lambda self: np.array(self._rate_setpoint),
                             lambda self, value: setattr(self, "_rate_setpoint", _rows(value)))

    # ----------------------------------------------------------------------------------------------
    def max_thrust(self) -> np.ndarray:
        """f_max(V) [N] per vehicle, (C.2) with the present battery voltage (never negative)."""
        voltage = self.battery.voltage()
        return np.array([max(0.0, c.max_thrust(float(v))) for c, v in zip(self.coefficients, voltage, strict=True)])

    def quat_list(self) -> list[list[float]]:
        """The attitudes [w,x,y,z] (FLU -> ENU) as plain floats (not a copy: do not modify)."""
        return self._quat

    def thrust(self) -> np.ndarray:
        """Actual (produced) collective thrust along body +z [N], (n,): Σ_j k_ij T_j."""
        if self.rotor_factors is None:
            return np.array([sum(r) for r in self._rotors])
        return np.array([k[0] * r[0] + k[1] * r[1] + k[2] * r[2] + k[3] * r[3]
                         for k, r in zip(self.rotor_factors, self._rotors, strict=True)])

    def thrust_vectors(self) -> np.ndarray:
        """Thrust vectors in the world frame f_i = R_bi [0, 0, f_t,i] [N], (n, 3)."""
        return np.array(self.thrust_vectors_list())

    def thrust_vectors_list(self) -> list[tuple[float, float, float]]:
        """:meth:`thrust_vectors` as plain floats (the 1 kHz loop): third column of (A.60) times f_t."""
        out = []
        factors = self.rotor_factors
        for i, ((w, x, y, z), (t1, t2, t3, t4)) in enumerate(zip(self._quat, self._rotors, strict=True)):
            if factors is None:
                f = t1 + t2 + t3 + t4
            else:
                k = factors[i]
                f = k[0] * t1 + k[1] * t2 + k[2] * t3 + k[3] * t4
            out.append((2.0 * (x * z + w * y) * f, 2.0 * (y * z - w * x) * f, (w * w - x * x - y * y + z * z) * f))
        return out

    def hover_rotor_state(self, thrust: np.ndarray, gains: list[list[float]] | None = None) -> None:
        """Set rotors (and their commands) to produce ``thrust`` [N] (n,) with zero moment (initial hover); with
        per-rotor thrust ``gains`` (n, 4) each rotor state is ``T/4 / k_ij`` (the produced thrusts are equal)."""
        if gains is None:
            self._rotors = [[0.25 * t] * 4 for t in plain_floats(thrust)]
        else:
            self._rotors = [[0.25 * t / k for k in row] for t, row in zip(plain_floats(thrust), gains, strict=True)]
        self._rotor_commands = [list(r) for r in self._rotors]

    # ----------------------------------------------------------------------------------------------
    def control(self, command: AttitudeCommand, measured_rate: np.ndarray | None = None,
                landed: list[bool] | None = None) -> None:
        """One PX4 attitude + rate controller update (3.39)-(3.41), held for ``controller_period``.

        Per vehicle and axis: ``ω_d = clip(2 P sgn(q_err,0) q_err,1:3 + ω_ff, ±ω_max)`` (3.39) with
        ``q_err = q⁻¹ ∘ q_d`` (fpr_model.rotations.quat_error), ``m = K_P ε + K_I ∫ε − K_D ω̇`` (3.40; integral
        reset while disarmed, frozen while ``landed[i]`` (PX4 RateControl::update(..., landed): no integration
        against the ground) and clamped to ``|K_I ∫ε| ≤ limit``), rotor commands by :func:`mix_one` (3.41)
        from ``f_t = clip(u_f, 0, 1)·f_max(V)``; zero while disarmed. ``landed`` (n,) defaults to all False.
        Runs in the compiled kernel when selected (plain (n, ·) commands of finite attitudes; anything else,
        and the errors it raises, go through the Python reference :meth:`control_python`)."""
        if self._compiled is not None:
            self.f_max = self.max_thrust()
            rates = self._rate if measured_rate is None else _rows(measured_rate)
            on_ground = [False] * self.n if landed is None else [bool(v) for v in landed]
            if len(on_ground) == self.n and self._compiled.control(self, command, rates, on_ground):
                return
        self.control_python(command, measured_rate, landed)

    def control_python(self, command: AttitudeCommand, measured_rate: np.ndarray | None = None,
                       landed: list[bool] | None = None) -> None:
        """:meth:`control` in Python (the reference)."""
        dt = self.controller_period
        on_ground = [False] * self.n if landed is None else [bool(v) for v in landed]
        rates = self._rate if measured_rate is None else _rows(measured_rate)
        self.f_max = self.max_thrust()
        errors = quat_error(np.array(self._quat), command.quat).tolist()
        feedforward = None if command.rate_feedforward is None else _rows(command.rate_feedforward)
        armed = np.asarray(command.armed, dtype=bool).tolist()
        thrusts = plain_floats(command.thrust)
        gains = (self.attitude_p.tolist(), self.rate_p.tolist(), self.rate_i.tolist(), self.rate_d.tolist(),
                 self.max_rate.tolist())
        attitude_p, rate_p, rate_i, rate_d, max_rate = gains
        bounds = [self.integrator_limit / max(k, 1e-12) for k in rate_i]
        setpoints, integrals, commands = [], [], []
        for i, (err, rate, previous, integral) in enumerate(
                zip(errors, rates, self._previous_rate, self._rate_integral, strict=True)):
            sign = 1.0 if err[0] >= 0.0 else -1.0
            setpoint, new_integral, moments = [], [], []
            for k in range(3):
                sp = 2.0 * attitude_p[k] * sign * err[1 + k]
                if feedforward is not None:
                    sp += feedforward[i][k]
                sp = min(max(sp, -max_rate[k]), max_rate[k])
                error = sp - rate[k]
                if not armed[i]:
                    acc = 0.0
                elif on_ground[i]:
                    acc = integral[k]
                else:
                    acc = integral[k] + error * dt
                acc = min(max(acc, -bounds[k]), bounds[k])
                derivative = (rate[k] - previous[k]) / dt  # on the measurement (PX4)
                setpoint.append(sp)
                new_integral.append(acc)
                moments.append(rate_p[k] * error + rate_i[k] * acc - rate_d[k] * derivative)
            setpoints.append(setpoint)
            integrals.append(new_integral)
            u = thrusts[i]
            u = 0.0 if u != u else min(max(u, 0.0), 1.0)
            f_max = float(self.f_max[i])
            rotors = mix_one(u * f_max, moments, self.arm, self.kappa, 0.25 * f_max)
            commands.append(rotors if armed[i] else [0.0, 0.0, 0.0, 0.0])
        self._rate_setpoint = setpoints
        self._rate_integral = integrals
        self._previous_rate = [list(r) for r in rates]
        self._rotor_commands = commands

    # ----------------------------------------------------------------------------------------------
    def step(self, dt: float, body_moment) -> None:
        """Advance (2.92) and the motor lag by ``dt`` [s] with classical RK4; ``body_moment`` (n, 3) [N m] FLU.

        Plain floats per vehicle. The motor lag ``Ṫ = (T_cmd − T)/τ_m`` is linear with a held command, so its
        RK4 stage values are evaluated in closed form: with ``e = T_cmd − T_0`` and ``a = dt/τ_m`` the stage
        slopes are ``k_s = β_s e/τ_m``, ``β = [1, 1 − a/2, 1 − a/2 + a²/4, 1 − a + a²/2 − a³/4]``, identical to
        stepping the 4 rotor states through the 4 stages; the rotor moments of each stage follow linearly.
        Runs in the compiled kernel when selected, else :meth:`step_python`."""
        if self._compiled is not None:
            moments = body_moment if isinstance(body_moment, list) else _rows(body_moment)
            self._compiled.step(self, dt, moments)
            return
        self.step_python(dt, body_moment)

    def step_python(self, dt: float, body_moment) -> None:
        """:meth:`step` in Python (the reference)."""
        moments = body_moment if isinstance(body_moment, list) else _rows(body_moment)
        i0, i1, i2 = self._inertia
        arm = self.arm
        kappa = self.kappa
        tau = self.motor_tau
        a = dt / tau
        beta2 = 1.0 - 0.5 * a
        beta3 = 1.0 - 0.5 * a * beta2
        beta4 = 1.0 - a * beta3
        h = 0.5 * dt
        sixth = dt / 6.0
        quats, rates, rotors = [], [], []
        factors = self.rotor_factors
        for i, (q, w, r, cmd, m) in enumerate(zip(self._quat, self._rate, self._rotors, self._rotor_commands, moments,
                                                  strict=True)):
            t1, t2, t3, t4 = r
            e1, e2, e3, e4 = cmd[0] - t1, cmd[1] - t2, cmd[2] - t3, cmd[3] - t4
            # produced thrusts k_j T_j and their stage changes k_j e_j (factors: realism, None = 1)
            p1, p2, p3, p4, d1, d2, d3, d4 = t1, t2, t3, t4, e1, e2, e3, e4
            if factors is not None:
                c1, c2, c3, c4 = factors[i]
                p1, p2, p3, p4 = c1 * t1, c2 * t2, c3 * t3, c4 * t4
                d1, d2, d3, d4 = c1 * e1, c2 * e2, c3 * e3, c4 * e4
            # moment of the rotors at T_0 (plus the external moment) and its change per unit stage offset of T
            base = (arm * (p2 - p4) + m[0], arm * (p3 - p1) + m[1], kappa * (-p1 + p2 - p3 + p4) + m[2])
            slope = (arm * (d2 - d4) / tau, arm * (d3 - d1) / tau, kappa * (-d1 + d2 - d3 + d4) / tau)
            # stage s evaluates the rotors at T_0 + offset_s·e/τ_m (offsets 0, h, h·β2, dt·β3)
            y = q + w
            k1 = _attitude_derivative(y, base, slope, 0.0, i0, i1, i2)
            k2 = _attitude_derivative([u + h * v for u, v in zip(y, k1, strict=True)], base, slope, h, i0, i1, i2)
            k3 = _attitude_derivative([u + h * v for u, v in zip(y, k2, strict=True)], base, slope, h * beta2,
                                      i0, i1, i2)
            k4 = _attitude_derivative([u + dt * v for u, v in zip(y, k3, strict=True)], base, slope, dt * beta3,
                                      i0, i1, i2)
            y = [u + sixth * (v1 + 2 * v2 + 2 * v3 + v4) for u, v1, v2, v3, v4 in zip(y, k1, k2, k3, k4, strict=True)]
            norm = math.sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2] + y[3] * y[3])
            quats.append([y[0] / norm, y[1] / norm, y[2] / norm, y[3] / norm])
            rates.append(y[4:7])
            gain = sixth * (1.0 + 2.0 * beta2 + 2.0 * beta3 + beta4) / tau
            rotors.append([max(t1 + gain * e1, 0.0), max(t2 + gain * e2, 0.0), max(t3 + gain * e3, 0.0),
                           max(t4 + gain * e4, 0.0)])
        self._quat = quats
        self._rate = rates
        self._rotors = rotors
        self.battery.update([r[0] + r[1] + r[2] + r[3] for r in rotors], dt)

    def set_ideal(self, command: AttitudeCommand) -> None:
        """Ideal tracking (tests): attitude = setpoint, rates 0, thrust = u_f·f_max(V) at once."""
        self.f_max = self.max_thrust()
        self.quat = np.array(command.quat, dtype=float)
        self.rate = np.zeros((self.n, 3))
        u = np.clip(np.nan_to_num(command.thrust, nan=0.0), 0.0, 1.0)
        thrust = np.where(np.asarray(command.armed, dtype=bool), u * self.f_max, 0.0)
        self.hover_rotor_state(thrust)


def _rows(value) -> list[list[float]]:
    """A 2-D array-like as a list of lists of floats (a copy)."""
    if isinstance(value, list):
        return [list(map(float, row)) for row in value]
    return np.asarray(value, dtype=float).tolist()


def plain_floats(value) -> list:
    """An array-like (or scalar) as plain Python floats: a list for 1-D (a scalar gives one), a list of lists for
    2-D; the same numbers as ``float()`` of each element, without a numpy scalar per element."""
    return np.atleast_1d(np.asarray(value, dtype=float)).tolist()



def _attitude_derivative(y: list[float], base: tuple, slope: tuple, offset: float, i0: float, i1: float,
                         i2: float) -> tuple[float, ...]:
    """d/dt of one vehicle's [q (4), ω (3)] by (2.92): ``q̇ = ½ q ∘ [0, ω]``, ``I ω̇ = m − ω × I ω`` with the
    body moment ``m = base + offset·slope`` (rotor moments of (3.41) at this RK4 stage plus the external one)."""
    qw, qx, qy, qz, w0, w1, w2 = y
    h0, h1, h2 = w0 * i0, w1 * i1, w2 * i2
    return (0.5 * (-qx * w0 - qy * w1 - qz * w2), 0.5 * (qw * w0 + qy * w2 - qz * w1),
            0.5 * (qw * w1 - qx * w2 + qz * w0), 0.5 * (qw * w2 + qx * w1 - qy * w0),
            (base[0] + offset * slope[0] - (w1 * h2 - w2 * h1)) / i0,
            (base[1] + offset * slope[1] - (w2 * h0 - w0 * h2)) / i1,
            (base[2] + offset * slope[2] - (w0 * h1 - w1 * h0)) / i2)
