"""The simulated FPR: passive structure + n quadrotors + environment, stepped at a fixed 1 kHz.

Block diagram of one step ``dt`` (default 1 ms):

1. the PX4 attitude/rate controllers of :class:`~fpr_sim.quadrotor.QuadrotorFleet` run when due (250 Hz);
2. the quadrotor thrust vectors ``f_i = R_bi [0, 0, f_t,i]`` are held over the step (zero-order hold) and the
   structure (:class:`~fpr_sim.structure.StructureDynamics`, thesis (2.86) with the plant's TRUE parameters) is
   advanced by classical RK4 with the environment forces (ground, board, wind, scheduled wrench) evaluated at
   every stage; the platform quaternion is re-normalised;
3. the leg force on each quadrotor ``f_l,i = m_b,i a_i − f_i − m_b,i g − f_env,i`` (a_i from the tip velocity
   change over the step) gives the spherical-joint offset moment (2.93) ``m_l,i = (S_i − B_i) × f_l,i`` with
   ``S_i − B_i = R_bi d [cos β, sin β, 0]`` (the physical lever from the CoM to the joint); the quadrotors'
   attitude dynamics (2.92) are then advanced by RK4 with it.

The structure state is integrated in platform-body velocities ξ = [R_pᵀ v_p, ω_p, θ̇]; ν (2.2) is derived.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from fpr_model.parameters import FprParameters, default_parameters, parameters_from_dict

from fpr_sim.environment import Environment
from fpr_sim.quadrotor import AttitudeCommand, QuadrotorFleet
from fpr_sim.scenario import Scenario
from fpr_sim.structure import PointForces, StructureDynamics, StructureState

__all__ = ["GroundTruth", "Plant", "true_parameters"]


def true_parameters(scenario: Scenario) -> FprParameters:
    """The plant's own parameters: Table B.1 defaults overridden by ``scenario.plant`` (fpr_model names)."""
    return parameters_from_dict(dict(scenario.plant), base=default_parameters(scenario.n))


def _rotmat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z],
    ])


@dataclass
class GroundTruth:
    """True state at one instant (what /fpr/ground_truth carries; see fpr_msgs/FprState)."""

    time: float
    state: StructureState
    uav_positions: np.ndarray  # (n, 3) world [m]
    uav_quats: np.ndarray  # (n, 4) FLU -> ENU
    uav_velocities: np.ndarray  # (n, 3) world [m/s]
    uav_rates: np.ndarray  # (n, 3) body FLU [rad/s]
    uav_specific_forces: np.ndarray  # (n, 3) body FLU [m/s²] (accelerometer truth)
    uav_thrusts: np.ndarray  # (n,) [N]
    external_wrench: np.ndarray  # (6+n,) true τ_e: [f_p (F0), m_p (Fp), joint moments] (gravity/thrust excluded)
    contact_force: float  # board normal force [N]
    payload_mass: float  # [kg]
    battery_voltages: np.ndarray  # (n,) [V]
    battery_remaining: np.ndarray  # (n,) [0..1]


class Plant:
    """The whole simulated robot (see the module doc). Time ``t`` in s starts at 0."""

    def __init__(self, scenario: Scenario, dt: float = 1e-3, params: FprParameters | None = None) -> None:
        self.scenario = scenario
        self.params = params if params is not None else true_parameters(scenario)
        if self.params.n != scenario.n:
            raise ValueError(f"plant parameters have n = {self.params.n}, scenario n = {scenario.n}")
        self.n = scenario.n
        self.dt = float(dt)
        self.structure = StructureDynamics(self.params)
        self.fleet = QuadrotorFleet(self.n, scenario.quadrotor, scenario.px4, scenario.battery)
        self.environment = Environment(scenario)
        self.gear = float(scenario.quadrotor.landing_gear_height)
        self.uav_masses = np.array(self.params.uav_masses)
        self.joint_offset = self.params.joint_offset * np.array(
            [np.cos(self.params.joint_offset_angle), np.sin(self.params.joint_offset_angle), 0.0])
        self.ideal_attitude = False  #: tests: attitudes and thrusts follow the commands instantly
        self.time = 0.0
        self.steps = 0
        self._next_control = 0.0
        self.command = AttitudeCommand(quat=np.tile([1.0, 0, 0, 0], (self.n, 1)), thrust=np.zeros(self.n),
                                       armed=np.zeros(self.n, dtype=bool))
        self._x = np.zeros(13 + 2 * self.n)
        self._contact_force = 0.0
        self._external = np.zeros(6 + self.n)
        self._env_uav_forces = np.zeros((self.n, 3))
        self._tip_velocity = np.zeros((self.n, 3))
        self._tip_acceleration = np.zeros((self.n, 3))
        self.reset_to_initial_state()

    # ---------------------------------------------------------------------------------------------- state
    def set_state(self, state: StructureState) -> None:
        """Place the structure at ``state`` (ν converted to body velocities)."""
        n = self.n
        quat = np.asarray(state.quat, dtype=float)
        quat = quat / np.linalg.norm(quat)
        R = _rotmat(quat)
        x = self._x
        x[0:3] = state.position
        x[3:7] = quat
        x[7:7 + n] = state.leg_angles
        x[7 + n:10 + n] = R.T @ np.asarray(state.velocity, dtype=float)
        x[10 + n:13 + n] = state.rate
        x[13 + n:] = state.leg_rates
        self._tip_velocity = self._tip_kinematics(x)[1]
        self._tip_acceleration = np.zeros((n, 3))
        self.environment.ground.anchors[:] = np.nan

    @property
    def state(self) -> StructureState:
        """Current structure state (q, ν) (copies)."""
        n = self.n
        x = self._x
        R = _rotmat(x[3:7])
        return StructureState(x[0:3].copy(), x[3:7].copy(), x[7:7 + n].copy(), R @ x[7 + n:10 + n],
                              x[10 + n:13 + n].copy(), x[13 + n:].copy())

    def reset_to_initial_state(self) -> None:
        """Initial state of the scenario: resting on the ground (platform level) or hovering at rest."""
        init = self.scenario.initial_state
        n = self.n
        theta = self.scenario.leg_angles()
        yaw = float(init.yaw)
        quat = np.array([np.cos(0.5 * yaw), 0.0, 0.0, np.sin(0.5 * yaw)])
        position = np.array(init.position, dtype=float)
        if init.mode == "ground":
            drop = self.params.leg_length * np.sin(theta).max()
            # feet slightly in the ground: the static penetration under the robot's weight
            sink = self.params.total_mass * self.params.gravity / (n * self.scenario.ground.stiffness)
            position[2] = self.scenario.ground.height + self.gear + drop - sink
        zero = np.zeros(3)
        self.set_state(StructureState(position, quat, theta, zero, zero.copy(), np.zeros(n)))
        self.fleet.quat = self.default_uav_attitudes()
        self.fleet.rate = np.zeros((n, 3))
        if init.mode == "hover":
            from fpr_model.dynamics import gravity, thrusts_from_wrench

            q = self.state.configuration()
            forces = thrusts_from_wrench(self.params, q, gravity(self.params, q))
            thrust = np.linalg.norm(forces, axis=1)
            self.fleet.quat = self.default_uav_attitudes(forces)
            self.fleet.hover_rotor_state(thrust)

    def default_uav_attitudes(self, thrust_vectors: np.ndarray | None = None) -> np.ndarray:
        """Attitudes (n, 4) with z_b along the thrust vectors (default: up) and the yaw rule (3.37) (β)."""
        from fpr_model.rotations import rotmat_to_quat

        n = self.n
        if thrust_vectors is None:
            thrust_vectors = np.tile([0.0, 0.0, 1.0], (n, 1))
        _, tips_body, e = self._tip_geometry(self._x)
        R = _rotmat(self._x[3:7])
        out = np.zeros((n, 4))
        for i in range(n):
            z = thrust_vectors[i] / np.linalg.norm(thrust_vectors[i])
            leg = R @ e[i]
            x_aux = _cross3(leg, z)
            x_aux /= np.linalg.norm(x_aux)
            angle = self.params.joint_offset_angle - 0.5 * np.pi  # (3.37): rotate l × z by β − π/2 about z
            x = np.cos(angle) * x_aux + np.sin(angle) * _cross3(z, x_aux)
            out[i] = rotmat_to_quat(np.column_stack([x, _cross3(z, x), z]))
        return out

    # ---------------------------------------------------------------------------------------------- kinematics
    def _tip_geometry(self, x):
        n = self.n
        c = np.cos(x[7:7 + n])
        s = np.sin(x[7:7 + n])
        tips, e = self.structure.tip_positions_body(c, s)
        return (c, s), tips, e

    def _tip_kinematics(self, x):
        """Tip positions and velocities (n, 3), world."""
        n = self.n
        (c, s), tips, e = self._tip_geometry(x)
        R = _rotmat(x[3:7])
        u, w, rates = x[7 + n:10 + n], x[10 + n:13 + n], x[13 + n:]
        velocity_body = u + _cross3(w, tips) + (self.structure.leg_length * rates)[:, None] * \
            self.structure.leg_normals_body(c, s)
        return x[0:3] + tips @ R.T, velocity_body @ R.T

    # ---------------------------------------------------------------------------------------------- dynamics
    def _derivative(self, x: np.ndarray, thrust_world: np.ndarray, payload: bool) -> np.ndarray:
        n = self.n
        sd = self.structure
        quat = x[3:7]
        R = _rotmat(quat)
        theta = x[7:7 + n]
        c = np.cos(theta)
        s = np.sin(theta)
        c2 = c * c - s * s
        s2 = 2.0 * s * c
        xi = x[7 + n:]
        u, w, rates = xi[:3], xi[3:6], xi[6:]
        tips, e = sd.tip_positions_body(c, s)
        tip_forces_world = thrust_world.copy()
        platform_points = []
        platform_forces_world = []
        env = self.environment
        mids = None
        mid_forces = np.zeros((n, 3))
        need_tip_velocity = self._ground_active or env.has_wind
        if need_tip_velocity:
            normals = sd.leg_normals_body(c, s)
            tip_vel = (u + _cross3(w, tips) + (sd.leg_length * rates)[:, None] * normals) @ R.T
            tip_pos = x[0:3] + tips @ R.T
        if self._ground_active:
            feet = tip_pos.copy()
            feet[:, 2] -= self.gear
            centre = x[0:3]
            points = np.vstack([feet, centre[None, :]])
            velocities = np.vstack([tip_vel, (R @ u)[None, :]])
            ground = env.ground.forces(points, velocities)
            tip_forces_world += ground[:n]
            platform_points.append(np.zeros(3))
            platform_forces_world.append(ground[n])
        if env.has_wind:
            air = self._wind
            cfg = self.scenario.wind
            tip_forces_world += cfg.uav_drag * (air - tip_vel)
            mids = 0.5 * (tips + sd.anchors)
            mid_vel = (u + _cross3(w, mids) + (0.5 * sd.leg_length * rates)[:, None] * normals) @ R.T
            mid_forces = (cfg.leg_drag * (air - mid_vel)) @ R
            platform_points.append(np.zeros(3))
            platform_forces_world.append(cfg.platform_drag * (air - R @ u))
        platform_moment = self._platform_moment
        if self._platform_force is not None:
            platform_points.append(np.zeros(3))
            platform_forces_world.append(self._platform_force)
        if env.board.enabled:
            point_body = env.board_end_effector
            point = x[0:3] + R @ point_body
            velocity = R @ (u + _cross3(w, point_body))
            force, normal = env.board_force(point, velocity)
            self._stage_contact = normal
            if normal > 0.0:
                platform_points.append(point_body)
                platform_forces_world.append(force)
        if platform_points:
            pp = np.array(platform_points)
            pf = np.array(platform_forces_world) @ R
        else:
            pp = self._no_points
            pf = self._no_points
        forces = PointForces(pp, pf, tip_forces_world @ R, mid_forces, platform_moment, self._zero_joint)
        q_force = sd.generalized_forces(c, s, forces)
        xi_dot = sd._body_acceleration(c, s, c2, s2, xi, R.T @ sd.gravity_vector, q_force)
        dx = np.empty_like(x)
        dx[0:3] = R @ u
        qw, qx, qy, qz = quat
        wx, wy, wz = w
        dx[3] = 0.5 * (-qx * wx - qy * wy - qz * wz)
        dx[4] = 0.5 * (qw * wx + qy * wz - qz * wy)
        dx[5] = 0.5 * (qw * wy - qx * wz + qz * wx)
        dx[6] = 0.5 * (qw * wz + qx * wy - qy * wx)
        dx[7:7 + n] = rates
        dx[7 + n:] = xi_dot
        return dx

    def set_command(self, command: AttitudeCommand) -> None:
        """Setpoints of the n PX4 attitude controllers (ENU/FLU attitudes, normalized thrusts, armed flags)."""
        self.command = command

    def step(self) -> None:
        """Advance the plant by one fixed step ``dt`` (see the module doc)."""
        n = self.n
        dt = self.dt
        env = self.environment
        fleet = self.fleet
        if self.time >= self._next_control - 1e-12:
            if self.ideal_attitude:
                fleet.set_ideal(self.command)
            else:
                fleet.control(self.command)
            self._next_control += fleet.controller_period
        payload = env.payload_mass(self.time)
        if payload != self.structure.payload_mass:
            self.structure.set_payload_mass(payload)
        tip_pos, tip_vel = self._tip_kinematics(self._x)
        margin = 0.05 + 2.0 * np.abs(tip_vel[:, 2]).max() * dt
        self._ground_active = bool(self.scenario.ground.enabled and (
            (tip_pos[:, 2] - self.gear).min() < self.scenario.ground.height + margin
            or self._x[2] < self.scenario.ground.height + margin))
        self._wind = env.wind_velocity(self.time) if env.has_wind else None
        force, moment = env.platform_wrench(self.time)
        self._platform_force = force if force.any() else None
        self._platform_moment = moment
        self._no_points = np.zeros((0, 3))
        self._zero_joint = np.zeros(n)
        self._stage_contact = 0.0
        thrust = fleet.thrust_vectors()
        x = self._x
        k1 = self._derivative(x, thrust, payload)
        contact = self._stage_contact
        k2 = self._derivative(x + 0.5 * dt * k1, thrust, payload)
        k3 = self._derivative(x + 0.5 * dt * k2, thrust, payload)
        k4 = self._derivative(x + dt * k3, thrust, payload)
        x = x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        x[3:7] /= np.sqrt(x[3:7] @ x[3:7])
        self._x = x
        self._contact_force = contact
        # environment forces on the quadrotors at the new state (for the leg force and the reported wrench)
        tip_pos, tip_vel = self._tip_kinematics(x)
        env_uav = np.zeros((n, 3))
        if self._ground_active:
            feet = tip_pos.copy()
            feet[:, 2] -= self.gear
            env.ground.update_anchors(np.vstack([feet, x[None, 0:3]]))
            env_uav += env.ground.forces(np.vstack([feet, x[None, 0:3]]),
                                         np.vstack([tip_vel, _rotmat(x[3:7]) @ x[7 + n:10 + n]]))[:n]
        if self._wind is not None:
            env_uav += self.scenario.wind.uav_drag * (self._wind - tip_vel)
        self._tip_acceleration = (tip_vel - self._tip_velocity) / dt
        self._tip_velocity = tip_vel
        self._env_uav_forces = env_uav
        # spherical-joint offset moment (2.93) on each quadrotor, body frame
        leg_force = self.uav_masses[:, None] * (self._tip_acceleration - self.params.gravity_vector) - thrust - env_uav
        Rb = _batch_rotmat(fleet.quat)
        lever = Rb @ self.joint_offset  # (n, 3) world: B_i -> S_i
        moment_world = _cross3(lever, leg_force)
        body_moment = np.einsum("nji,nj->ni", Rb, moment_world)
        on_ground = self._ground_active and bool(np.any(env.ground.anchors[:n, 0] == env.ground.anchors[:n, 0]))
        if on_ground:
            body_moment = body_moment + self._ground_leveling_moment(Rb)
        if self.ideal_attitude:
            fleet.battery.update(fleet.thrust(), dt)
        else:
            fleet.step(dt, body_moment)
        self.time = (self.steps + 1) * dt
        self.steps += 1

    def _ground_leveling_moment(self, Rb: np.ndarray) -> np.ndarray:
        """Moment of the landing gear on quadrotors standing on the ground: a stiff torsional spring-damper
        towards level (roll/pitch only), for the quadrotors whose feet touch (anchor set)."""
        touching = ~np.isnan(self.environment.ground.anchors[:self.n, 0])
        up_body = Rb[:, 2, :]  # world z in body coordinates (rows of Rbᵀ)
        tilt = _cross3(up_body, [0.0, 0.0, 1.0])  # body-frame axis·sin(angle) from body z to world up
        weight = self.uav_masses * self.params.gravity
        stiffness = (weight * 0.5 * self.scenario.quadrotor.arm_length * 4.0)[:, None]
        moment = -stiffness * tilt - 0.2 * self.fleet.rate * np.array([1.0, 1.0, 0.0])
        return moment * touching[:, None]

    # ---------------------------------------------------------------------------------------------- outputs
    def ground_truth(self) -> GroundTruth:
        """The true state now (see :class:`GroundTruth`)."""
        state = self.state
        tip_pos, tip_vel = self._tip_kinematics(self._x)
        Rb = _batch_rotmat(self.fleet.quat)
        specific = np.einsum("nji,nj->ni", Rb, self._tip_acceleration - self.params.gravity_vector)
        external = self.external_wrench()
        return GroundTruth(
            time=self.time, state=state, uav_positions=tip_pos, uav_quats=self.fleet.quat.copy(),
            uav_velocities=tip_vel, uav_rates=self.fleet.rate.copy(), uav_specific_forces=specific,
            uav_thrusts=self.fleet.thrust(), external_wrench=external, contact_force=self._contact_force,
            payload_mass=self.structure.payload_mass, battery_voltages=self.fleet.battery.voltage(),
            battery_remaining=self.fleet.battery.remaining(),
        )

    def external_wrench(self) -> np.ndarray:
        """True τ_e (6+n) of the disturbances now: board, scheduled wrench, wind, ground, payload weight.

        Layout [f_p (F0), m_p (Fp), joint moments] as (2.26); evaluated by the generalized-force map of the
        environment forces alone (thrust and the structure's own gravity excluded).
        """
        n = self.n
        x = self._x
        R = _rotmat(x[3:7])
        c = np.cos(x[7:7 + n])
        s = np.sin(x[7:7 + n])
        tip_pos, tip_vel = self._tip_kinematics(x)
        points, forces = [], []
        force, moment = self.environment.platform_wrench(self.time)
        points.append(np.zeros(3))
        forces.append(force + np.array([0.0, 0.0, -self.structure.payload_mass * self.params.gravity]))
        if self.scenario.ground.enabled:
            ground = self.environment.ground.forces(
                np.vstack([tip_pos - [0.0, 0.0, self.gear], x[None, 0:3]]),
                np.vstack([tip_vel, (R @ x[7 + n:10 + n])[None, :]]))
            tip = ground[:n]
            points.append(np.zeros(3))
            forces.append(ground[n])
        else:
            tip = np.zeros((n, 3))
        mids = np.zeros((n, 3))
        if self.environment.has_wind:
            air = self.environment.wind_velocity(self.time)
            tip = tip + self.scenario.wind.uav_drag * (air - tip_vel)
            forces.append(self.scenario.wind.platform_drag * (air - R @ x[7 + n:10 + n]))
            points.append(np.zeros(3))
        if self.environment.board.enabled:
            pb = self.environment.board_end_effector
            f_board, _ = self.environment.board_force(
                x[0:3] + R @ pb, R @ (x[7 + n:10 + n] + _cross3(x[10 + n:13 + n], pb)))
            points.append(pb)
            forces.append(f_board)
        pf = PointForces(np.array(points), np.array(forces) @ R, tip @ R, mids, moment, np.zeros(n))
        q_body = self.structure.generalized_forces(c, s, pf)
        q_body[:3] = R @ q_body[:3]
        return q_body


def _cross3(a, b) -> np.ndarray:
    """a × b for (3,) or (k, 3) arrays (broadcasting), cheaper than np.cross for small arrays."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _batch_rotmat(quats: np.ndarray) -> np.ndarray:
    from fpr_model.rotations import quat_to_rotmat

    return quat_to_rotmat(quats)
