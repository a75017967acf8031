"""The simulated FPR: passive structure + n quadrotors + environment, stepped at a fixed 1 kHz.

Block diagram of one step ``dt`` (default 1 ms):

1. the PX4 attitude/rate controllers of :class:`~fpr_sim.quadrotor.QuadrotorFleet` run when due (250 Hz);
2. the quadrotor thrust vectors ``f_i = R_bi [0, 0, f_t,i]`` are held over the step (zero-order hold) and the
   structure (:class:`~fpr_sim.structure.StructureDynamics`, thesis (2.86) with the plant's TRUE parameters) is
   advanced by classical RK4 with the environment forces (ground, board, wind, scheduled wrench) evaluated at
   every stage; the platform quaternion is re-normalised. The air velocities are evaluated once per step at the
   step's start (:meth:`Plant._air_velocities`: the uniform wind, plus the fan's jet at the platform centre, each
   quadrotor and each leg's middle) and held over the stages;
3. the leg force on each quadrotor ``f_l,i = m_b,i a_i − f_i − m_b,i g − f_env,i`` (a_i from the tip velocity
   change over the step) gives the spherical-joint offset moment (2.93) ``m_l,i = (S_i − B_i) × f_l,i`` with
   ``S_i − B_i = R_bi d [cos β, sin β, 0]`` (the physical lever from the CoM to the joint), plus, for the
   quadrotors standing on the ground, the landing gear's levelling and yaw-friction moments (bounded by the
   gear's normal force, :meth:`Plant._add_landing_gear_moments`); the quadrotors' attitude dynamics (2.92) are
   then advanced by RK4 with it.

The legs' revolute joints have mechanical stops (scenario ``joint_stops``, default [10°, 92°]): outside them a
stiff, damped, unilateral penalty moment (:func:`joint_stop_moment`) enters the θ_i rows of the generalized
forces at every RK4 stage, so runaway runs (e.g. PX4's per-UAV AUTO.LAND folding the legs) end against a stop
instead of diverging. Inside the stops nothing changes (the frozen oracle trajectories never reach them).

The PX4 rate controllers get the land-detector flag of each quadrotor (:meth:`Plant.uav_landed`: its gear
touches the ground), which freezes their integrators as PX4 does.

The structure state is integrated in platform-body velocities ξ = [R_pᵀ v_p, ω_p, θ̇]; ν (2.2) is derived.
The 1 kHz loop runs on plain Python floats (numpy costs ~1 µs per call on 3-vectors); its results are checked
against frozen trajectories of the former numpy implementation in test/test_plant_oracle.py (to 1e-10).

Realism (scenario ``mismatch``, ``actuation``, ``aerodynamics``; :mod:`fpr_sim.plant_realism`): the TRUE
parameters may be drawn off Table B.1 (:func:`true_parameters`), the fleet gets the true (C.2) curve, motor lag,
quadrotor inertia and battery resistance, and at the start of each step the per-rotor produced-thrust factors
(gain spread × noise × ground effect) and the rotor drag on each quadrotor are computed here (held over the
step, inputs of both kernels). With every effect off nothing of this runs.

Two implementations of steps 1-3 (``Plant.kernel``): this module (the reference, :meth:`Plant._advance`) and
the optional compiled kernel of :mod:`fpr_sim._kernels` (a C port of the same code, ~7× faster), selected by
``Plant(..., kernel=)`` or ``$FPR_SIM_KERNEL`` (auto | compiled | python; auto uses the compiled kernel when it
was built). Both replay the same frozen trajectories.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from fpr_model._math import cross
from fpr_model.geometry import desired_uav_rotation
from fpr_model.parameters import FprParameters, default_parameters, parameters_from_dict
from fpr_model.rotations import _quat_to_rotmat, rotmat_to_quat

from fpr_sim._kernels import PlantKernel, resolve_kernel
from fpr_sim.environment import Environment
from fpr_sim.plant_realism import PlantRealism, draw_model_mismatch
from fpr_sim.quadrotor import AttitudeCommand, QuadrotorFleet
from fpr_sim.scalar_math import rotation_entries
from fpr_sim.scenario import Scenario
from fpr_sim.structure import PointForces, StructureDynamics, StructureState

__all__ = ["GroundTruth", "Plant", "joint_stop_moment", "true_parameters"]


def true_parameters(scenario: Scenario) -> FprParameters:
    """The plant's own parameters: Table B.1 defaults, overridden by the model-mismatch draws
    (:func:`fpr_sim.plant_realism.draw_model_mismatch`, when ``scenario.mismatch`` is enabled), overridden by
    ``scenario.plant`` (fpr_model names: a value the scenario states wins over the draw)."""
    overrides = {**draw_model_mismatch(scenario), **scenario.plant}
    return parameters_from_dict(overrides, base=default_parameters(scenario.n))


def joint_stop_moment(theta: float, rate: float, lower: float, upper: float, stiffness: float,
                      damping: float) -> float:
    """Moment of a leg's mechanical joint stop [N m] about its joint axis, positive towards larger θ (the θ_i
    row of the generalized forces of (2.86)); ``theta`` [rad], ``rate`` θ̇ [rad/s], stops [rad], ``stiffness``
    [N m/rad], ``damping`` [N m s/rad]. Unilateral penalty (see :class:`~fpr_sim.scenario.JointStopConfig`):
    ``max(0, k (lower − θ) − c θ̇)`` below ``lower``, ``min(0, k (upper − θ) − c θ̇)`` above ``upper``, else 0.
    The compiled kernel (plant_kernel.c, joint_stop_moment) computes the same expression."""
    if theta < lower:
        return max(0.0, stiffness * (lower - theta) - damping * rate)
    if theta > upper:
        return min(0.0, stiffness * (upper - theta) - damping * rate)
    return 0.0


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

    def __init__(self, scenario: Scenario, dt: float = 1e-3, params: FprParameters | None = None,
                 kernel: str | None = None) -> None:
        self.scenario = scenario
        #: 'compiled' (the C kernel of fpr_sim._kernels runs the step) or 'python' (this module, the reference);
        #: requested by ``kernel`` = 'auto' | 'compiled' | 'python' (None: $FPR_SIM_KERNEL, default 'auto')
        self.kernel = resolve_kernel(kernel, scenario.n)
        #: the realism effects of the plant (draws, thrust factors, rotor drag; fpr_sim.plant_realism)
        self.realism = PlantRealism(scenario, float(dt))
        self.params = params if params is not None else true_parameters(scenario)
        if self.params.n != scenario.n:
            raise ValueError(f"plant parameters have n = {self.params.n}, scenario n = {scenario.n}")
        self.n = scenario.n
        self.dt = float(dt)
        self.structure = StructureDynamics(self.params, kernel=self.kernel)
        self.fleet = QuadrotorFleet(self.n, self.realism.quadrotor, scenario.px4, self.realism.battery,
                                    kernel=self.kernel)
        self.environment = Environment(scenario)
        self.gear = float(scenario.quadrotor.landing_gear_height)
        self.uav_masses = np.array(self.params.uav_masses)
        # B_iS_i in Fbi (thesis §2.3.3, Fig. 2.3): x_bi lies at +β about z_bi from B_iS_i, so B_iS_i = d·Rz(−β)·e_x.
        # With the yaw rule (3.37) (x_bi at +β from the horizontal −l_i) the joint then faces the leg, i.e. points
        # back toward the platform, as on the prototype (Rz(+β) would put it 90° sideways, off the leg).
        self.joint_offset = self.params.joint_offset * np.array(
            [np.cos(self.params.joint_offset_angle), -np.sin(self.params.joint_offset_angle), 0.0])
        self.ideal_attitude = False  #: tests: attitudes and thrusts follow the commands instantly
        self.time = 0.0
        self.steps = 0
        self._next_control = 0.0
        self.command = AttitudeCommand(quat=np.tile([1.0, 0, 0, 0], (self.n, 1)), thrust=np.zeros(self.n),
                                       armed=np.zeros(self.n, dtype=bool))
        self._contact_force = 0.0
        # constants of the 1 kHz loop as plain floats
        sd = self.structure
        self._leg_length = float(sd.leg_length)
        self._anchors = [tuple(a) for a in sd.anchors.tolist()]
        self._cos_alpha = sd.cos_alpha.tolist()
        self._sin_alpha = sd.sin_alpha.tolist()
        self._joint_axes = [tuple(k) for k in sd.joint_axes.tolist()]
        self._gravity = tuple(np.asarray(self.params.gravity_vector, dtype=float).tolist())
        self._joint_offset = tuple(self.joint_offset.tolist())
        self._uav_masses = self.uav_masses.tolist()
        wind = scenario.wind
        self._uav_drag, self._leg_drag, self._platform_drag = wind.uav_drag, wind.leg_drag, wind.platform_drag
        self._board_enabled = bool(self.environment.board.enabled)
        stops = scenario.joint_stops
        #: (lower, upper, stiffness, damping) of the legs' joint stops, None when disabled
        self._joint_stops = ((float(stops.lower), float(stops.upper), float(stops.stiffness), float(stops.damping))
                             if stops.enabled else None)
        self._end_effector = tuple(self.environment.board_end_effector.tolist())
        self._x_list = [0.0] * (13 + 2 * self.n)
        self._tips = None  # cached tip kinematics of _x_list
        self._tip_velocity_list = [(0.0, 0.0, 0.0)] * self.n
        self._tip_acceleration_list = [(0.0, 0.0, 0.0)] * self.n
        self._yaw_anchors = [math.nan] * self.n  # landing-gear yaw friction anchors [rad] (NaN: not touching)
        self._air_list: list[float] | None = None  # air velocities of the step (see _air_velocities), None: still air
        self._uav_force_list: list[tuple] | None = None  # realism: rotor drag (n, 3) world [N] of the step, or None
        self.reset_to_initial_state()
        # the wind generator's default reference point: the quadrotors' centroid in the initial state (thesis
        # Exp. III measured the wind speed there, at hover height)
        uav_centroid = np.mean(self._tip_kinematics_list(self._x_list)[0], axis=0)
        self.environment.attach_fan(uav_centroid, self.dt)
        self._compiled = PlantKernel(self) if self.kernel == "compiled" else None

    # ---------------------------------------------------------------------------------------------- state
    def _set_x(self, x: list[float]) -> None:
        """The structure state x = [P, q_p, θ, u, ω, θ̇] (plain floats; ``_x`` keeps a numpy copy)."""
        self._x_list = x
        self._tips = None

    @property
    def _x(self) -> np.ndarray:
        """x as a numpy array (a copy)."""
        return np.array(self._x_list)

    @property
    def _tip_velocity(self) -> np.ndarray:
        return np.array(self._tip_velocity_list)

    @property
    def _tip_acceleration(self) -> np.ndarray:
        return np.array(self._tip_acceleration_list)

    def set_state(self, state: StructureState) -> None:
        """Place the structure at ``state`` (ν converted to body velocities)."""
        n = self.n
        quat = np.asarray(state.quat, dtype=float)
        quat = quat / np.linalg.norm(quat)
        R = _quat_to_rotmat(quat)
        x = np.zeros(13 + 2 * n)
        x[0:3] = state.position
        x[3:7] = quat
        x[7:7 + n] = state.leg_angles
        x[7 + n:10 + n] = R.T @ np.asarray(state.velocity, dtype=float)
        x[10 + n:13 + n] = state.rate
        x[13 + n:] = state.leg_rates
        self._set_x(x.tolist())
        self._tip_velocity_list = self._tip_kinematics_list(self._x_list)[1]
        self._tip_acceleration_list = [(0.0, 0.0, 0.0)] * n
        self.environment.ground.anchors[:] = np.nan
        self._yaw_anchors = [math.nan] * n

    @property
    def state(self) -> StructureState:
        """Current structure state (q, ν) (copies)."""
        n = self.n
        x = self._x
        R = _quat_to_rotmat(x[3:7])
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
            self.fleet.hover_rotor_state(thrust, self.realism.rotor_gains)
            # hovering already: the battery delivers the hover current, so the terminal voltage (and f_max(V),
            # BATTERY_STATUS) is the loaded one from t = 0, as it will be after the first step
            self.fleet.battery.update(thrust, 0.0)

    def default_uav_attitudes(self, thrust_vectors: np.ndarray | None = None) -> np.ndarray:
        """Attitudes (n, 4) with z_b along the thrust vectors (default: up) and the yaw rule (3.37) (β)."""

        n = self.n
        if thrust_vectors is None:
            thrust_vectors = np.tile([0.0, 0.0, 1.0], (n, 1))
        _, tips_body, e = self._tip_geometry(self._x)
        R = _quat_to_rotmat(self._x[3:7])
        beta = self.params.joint_offset_angle
        return np.array([rotmat_to_quat(desired_uav_rotation(thrust_vectors[i], R @ e[i], beta)) for i in range(n)])

    # ---------------------------------------------------------------------------------------------- kinematics
    def _tip_geometry(self, x):
        n = self.n
        c = np.cos(x[7:7 + n])
        s = np.sin(x[7:7 + n])
        tips, e = self.structure.tip_positions_body(c, s)
        return (c, s), tips, e

    def _tip_kinematics(self, x):
        """Tip positions and velocities (n, 3), world."""
        positions, velocities = self._tip_kinematics_list(x.tolist() if isinstance(x, np.ndarray) else x)
        return np.array(positions), np.array(velocities)

    def _tip_kinematics_list(self, x: list[float]) -> tuple[list[tuple], list[tuple]]:
        """Tip positions B_i and velocities (world) on plain floats: ``p_i = P + R ρ_i``,
        ``v_i = R (u + ω × ρ_i + l θ̇_i ∂e_i/∂θ_i)`` with ρ_i = a_i + l e_i (thesis (2.5), Fp quantities)."""
        n = self.n
        length = self._leg_length
        px, py, pz = x[0:3]
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_entries(*x[3:7])
        u0, u1, u2, w0, w1, w2 = x[7 + n:13 + n]
        positions, velocities = [], []
        for i in range(n):
            theta = x[7 + i]
            c = math.cos(theta)
            s = math.sin(theta)
            (a0, a1, a2), ca, sa = self._anchors[i], self._cos_alpha[i], self._sin_alpha[i]
            t0, t1, t2 = a0 + length * ca * c, a1 + length * sa * c, a2 - length * s
            lr = length * x[13 + n + i]
            v0 = u0 + w1 * t2 - w2 * t1 - lr * ca * s
            v1 = u1 + w2 * t0 - w0 * t2 - lr * sa * s
            v2 = u2 + w0 * t1 - w1 * t0 - lr * c
            positions.append((px + r00 * t0 + r01 * t1 + r02 * t2, py + r10 * t0 + r11 * t1 + r12 * t2,
                              pz + r20 * t0 + r21 * t1 + r22 * t2))
            velocities.append((r00 * v0 + r01 * v1 + r02 * v2, r10 * v0 + r11 * v1 + r12 * v2,
                               r20 * v0 + r21 * v1 + r22 * v2))
        return positions, velocities

    # ---------------------------------------------------------------------------------------------- dynamics
    def _derivative(self, x: list[float], thrust: list[tuple]) -> list[float]:
        """ẋ of the structure state x = [P, q_p, θ, u, ω, θ̇] with the held thrust vectors (world) and the
        environment forces of this stage, on plain floats. Point forces f (world) at body points ρ (Fp) enter
        the generalized force in ξ coordinates as ``[Rᵀf, ρ × Rᵀf, k_i · ((ρ − a_i) × Rᵀf)]`` ((2.28)
        generalised, see StructureDynamics.generalized_forces); thesis (2.86) is solved by
        StructureDynamics.accelerate."""
        n = self.n
        length = self._leg_length
        env = self.environment
        px, py, pz, qw, qx, qy, qz = x[0:7]
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_entries(qw, qx, qy, qz)
        xi = x[7 + n:]
        u0, u1, u2, w0, w1, w2 = xi[:6]
        ground = self._ground_active
        wind = self._air_list  # [platform, quadrotors 1..n, leg middles 1..n] x 3 (world), held over the step
        need_velocity = ground or wind is not None
        # platform force (world, at P) and Q̃ accumulators (Fp)
        fp0, fp1, fp2 = self._platform_force_list
        q0 = q1 = q2 = m0 = m1 = m2 = 0.0
        joint = []
        c_list, s_list = [], []
        anchors_ground = self._anchor_list
        stops = self._joint_stops
        for i in range(n):
            theta = x[7 + i]
            c = math.cos(theta)
            s = math.sin(theta)
            c_list.append(c)
            s_list.append(s)
            (a0, a1, a2), ca, sa = self._anchors[i], self._cos_alpha[i], self._sin_alpha[i]
            e0, e1, e2 = ca * c, sa * c, -s
            t0, t1, t2 = a0 + length * e0, a1 + length * e1, a2 + length * e2
            f0, f1, f2 = thrust[i]
            mid0 = mid1 = mid2 = 0.0  # leg-middle force, Fp
            if need_velocity:
                lr = length * xi[6 + i]
                n0, n1, n2 = -ca * s, -sa * s, -c
                b0 = u0 + w1 * t2 - w2 * t1 + lr * n0
                b1 = u1 + w2 * t0 - w0 * t2 + lr * n1
                b2 = u2 + w0 * t1 - w1 * t0 + lr * n2
                v0 = r00 * b0 + r01 * b1 + r02 * b2
                v1 = r10 * b0 + r11 * b1 + r12 * b2
                v2 = r20 * b0 + r21 * b1 + r22 * b2
                if ground:
                    g0, g1, g2 = env.ground.point_force(
                        anchors_ground[i], px + r00 * t0 + r01 * t1 + r02 * t2, py + r10 * t0 + r11 * t1 + r12 * t2,
                        pz + r20 * t0 + r21 * t1 + r22 * t2 - self.gear, v0, v1, v2)
                    f0 += g0
                    f1 += g1
                    f2 += g2
                if wind is not None:
                    k = 3 + 3 * i
                    air0, air1, air2 = wind[k], wind[k + 1], wind[k + 2]  # at the quadrotor
                    drag = self._uav_drag
                    f0 += drag * (air0 - v0)
                    f1 += drag * (air1 - v1)
                    f2 += drag * (air2 - v2)
                    k += 3 * n
                    air0, air1, air2 = wind[k], wind[k + 1], wind[k + 2]  # at the leg's middle
                    h0, h1, h2 = 0.5 * (t0 + a0), 0.5 * (t1 + a1), 0.5 * (t2 + a2)
                    hl = 0.5 * lr
                    b0 = u0 + w1 * h2 - w2 * h1 + hl * n0
                    b1 = u1 + w2 * h0 - w0 * h2 + hl * n1
                    b2 = u2 + w0 * h1 - w1 * h0 + hl * n2
                    d0 = self._leg_drag * (air0 - (r00 * b0 + r01 * b1 + r02 * b2))
                    d1 = self._leg_drag * (air1 - (r10 * b0 + r11 * b1 + r12 * b2))
                    d2 = self._leg_drag * (air2 - (r20 * b0 + r21 * b1 + r22 * b2))
                    mid0 = r00 * d0 + r10 * d1 + r20 * d2
                    mid1 = r01 * d0 + r11 * d1 + r21 * d2
                    mid2 = r02 * d0 + r12 * d1 + r22 * d2
            # tip force in Fp
            g0 = r00 * f0 + r10 * f1 + r20 * f2
            g1 = r01 * f0 + r11 * f1 + r21 * f2
            g2 = r02 * f0 + r12 * f1 + r22 * f2
            q0 += g0 + mid0
            q1 += g1 + mid1
            q2 += g2 + mid2
            m0 += t1 * g2 - t2 * g1
            m1 += t2 * g0 - t0 * g2
            m2 += t0 * g1 - t1 * g0
            # lever of the joint moment: l e_i × (f_tip + f_mid / 2), and the mid force's moment about P
            l0, l1, l2 = g0 + 0.5 * mid0, g1 + 0.5 * mid1, g2 + 0.5 * mid2
            if mid0 or mid1 or mid2:
                h0, h1, h2 = a0 + 0.5 * length * e0, a1 + 0.5 * length * e1, a2 + 0.5 * length * e2
                m0 += h1 * mid2 - h2 * mid1
                m1 += h2 * mid0 - h0 * mid2
                m2 += h0 * mid1 - h1 * mid0
            k0, k1, k2 = self._joint_axes[i]
            moment = length * (k0 * (e1 * l2 - e2 * l1) + k1 * (e2 * l0 - e0 * l2) + k2 * (e0 * l1 - e1 * l0))
            if stops is not None and not stops[0] <= theta <= stops[1]:  # the leg is in a mechanical stop
                moment += joint_stop_moment(theta, xi[6 + i], *stops)
            joint.append(moment)
        if ground:
            vc0 = r00 * u0 + r01 * u1 + r02 * u2
            vc1 = r10 * u0 + r11 * u1 + r12 * u2
            vc2 = r20 * u0 + r21 * u1 + r22 * u2
            g0, g1, g2 = env.ground.point_force(anchors_ground[n], px, py, pz, vc0, vc1, vc2)
            fp0 += g0
            fp1 += g1
            fp2 += g2
        if wind is not None:
            drag = self._platform_drag
            fp0 += drag * (wind[0] - (r00 * u0 + r01 * u1 + r02 * u2))
            fp1 += drag * (wind[1] - (r10 * u0 + r11 * u1 + r12 * u2))
            fp2 += drag * (wind[2] - (r20 * u0 + r21 * u1 + r22 * u2))
        if self._board_enabled:
            e0, e1, e2 = self._end_effector
            b0 = u0 + w1 * e2 - w2 * e1
            b1 = u1 + w2 * e0 - w0 * e2
            b2 = u2 + w0 * e1 - w1 * e0
            (f0, f1, f2), normal = env.board_force_scalar(
                (px + r00 * e0 + r01 * e1 + r02 * e2, py + r10 * e0 + r11 * e1 + r12 * e2,
                 pz + r20 * e0 + r21 * e1 + r22 * e2),
                (r00 * b0 + r01 * b1 + r02 * b2, r10 * b0 + r11 * b1 + r12 * b2, r20 * b0 + r21 * b1 + r22 * b2))
            self._stage_contact = normal
            if normal > 0.0:
                g0 = r00 * f0 + r10 * f1 + r20 * f2
                g1 = r01 * f0 + r11 * f1 + r21 * f2
                g2 = r02 * f0 + r12 * f1 + r22 * f2
                q0 += g0
                q1 += g1
                q2 += g2
                m0 += e1 * g2 - e2 * g1
                m1 += e2 * g0 - e0 * g2
                m2 += e0 * g1 - e1 * g0
        mo0, mo1, mo2 = self._platform_moment_list
        q_force = [q0 + r00 * fp0 + r10 * fp1 + r20 * fp2, q1 + r01 * fp0 + r11 * fp1 + r21 * fp2,
                   q2 + r02 * fp0 + r12 * fp1 + r22 * fp2, m0 + mo0, m1 + mo1, m2 + mo2] + joint
        gx, gy, gz = self._gravity
        g_body = [r00 * gx + r10 * gy + r20 * gz, r01 * gx + r11 * gy + r21 * gz, r02 * gx + r12 * gy + r22 * gz]
        xi_dot = self.structure.accelerate(c_list, s_list, xi, g_body, q_force)
        return [r00 * u0 + r01 * u1 + r02 * u2, r10 * u0 + r11 * u1 + r12 * u2, r20 * u0 + r21 * u1 + r22 * u2,
                0.5 * (-qx * w0 - qy * w1 - qz * w2), 0.5 * (qw * w0 + qy * w2 - qz * w1),
                0.5 * (qw * w1 - qx * w2 + qz * w0), 0.5 * (qw * w2 + qx * w1 - qy * w0)] + xi[6:] + xi_dot

    def set_command(self, command: AttitudeCommand) -> None:
        """Setpoints of the n PX4 attitude controllers (ENU/FLU attitudes, normalized thrusts, armed flags)."""
        self.command = command

    def step(self) -> None:
        """Advance the plant by one fixed step ``dt`` (see the module doc): the scheduling here, the physics in
        :meth:`_advance` (Python reference) or in the compiled kernel (same equations, fpr_sim._kernels)."""
        env = self.environment
        fleet = self.fleet
        if self.time >= self._next_control - 1e-12:
            if self.ideal_attitude:
                fleet.set_ideal(self.command)
            else:
                fleet.control(self.command, landed=self.uav_landed())
            self._next_control += fleet.controller_period
        # payloads (timed, or picked up when P is near: the state at the step's start), then the mass matrix basis
        # both kernels use
        payload = env.payload_mass(self.time, self._x_list[0:3]) if self.scenario.payloads else 0.0
        if payload != self.structure.payload_mass:
            self.structure.set_payload_mass(payload)
        self._air_list = self._air_velocities() if env.has_wind else None
        if self.realism.active:
            self._realism_inputs()
        if self.scenario.external_wrenches:
            force, moment = env.platform_wrench(self.time)
            self._platform_force_list = force.tolist()
            self._platform_moment_list = moment.tolist()
        else:
            self._platform_force_list = self._platform_moment_list = (0.0, 0.0, 0.0)
        # the compiled kernel declines only a singular mass matrix: the reference then raises as it always did
        if self._compiled is None or not self._compiled.advance(self):
            self._advance()
        self.time = (self.steps + 1) * self.dt
        self.steps += 1

    def _realism_inputs(self) -> None:
        """The realism inputs of this step, from the state at its start (held over the step, both kernels): the
        per-rotor produced-thrust factors (``fleet.rotor_factors``) and the rotor drag on each quadrotor
        (``_uav_force_list``, world [N])."""
        realism = self.realism
        if self._tips is None:
            self._tips = self._tip_kinematics_list(self._x_list)
        fleet = self.fleet
        if realism.has_factors:
            fleet.rotor_factors = realism.thrust_factors(self._tips[0])
        if realism.rotor_drag > 0.0:
            self._uav_force_list = realism.drag_forces(fleet._quat, fleet._rotors, fleet.rotor_factors,
                                                       self._tips[1], self._air_list)

    def mismatch_report(self) -> dict:
        """The plant's true values where they differ from the controllers' model, for experiment reports: the
        realism draws (:meth:`fpr_sim.plant_realism.PlantRealism.report`) and the true FprParameters in use
        (``true_parameters``, fpr_model.parameters.parameters_to_dict)."""
        from fpr_model.parameters import parameters_to_dict

        return {**self.realism.report(), "true_parameters": parameters_to_dict(self.params)}

    def _air_velocities(self) -> list[float]:
        """Air velocity [m/s] (world) now at the platform centre P, at each quadrotor B_i and at each leg's middle
        (A_i + B_i)/2, flattened: 3 (1 + 2n) floats [P, B_1..B_n, mid_1..mid_n]. The uniform wind is the same
        everywhere; the fan's jet is evaluated at these points of the current state (held over the step)."""
        env = self.environment
        n = self.n
        if env.fan is None:
            return env.wind_velocity(self.time).tolist() * (1 + 2 * n)
        x = self._x_list
        if self._tips is None:
            self._tips = self._tip_kinematics_list(x)
        tips = self._tips[0]
        px, py, pz = x[0:3]
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_entries(*x[3:7])
        points = [(px, py, pz)]
        points += tips
        for (a0, a1, a2), (b0, b1, b2) in zip(self._anchors, tips, strict=True):
            points.append((0.5 * (px + r00 * a0 + r01 * a1 + r02 * a2 + b0),
                           0.5 * (py + r10 * a0 + r11 * a1 + r12 * a2 + b1),
                           0.5 * (pz + r20 * a0 + r21 * a1 + r22 * a2 + b2)))
        return env.air_velocities(self.time, points)

    def _advance(self) -> None:
        """The physics of one step after the scheduling of :meth:`step` (pure-Python reference)."""
        n = self.n
        dt = self.dt
        env = self.environment
        fleet = self.fleet
        x = self._x_list
        if self._tips is None:
            self._tips = self._tip_kinematics_list(x)
        tip_pos, tip_vel = self._tips
        ground_cfg = self.scenario.ground
        self._ground_active = False
        if ground_cfg.enabled:
            margin = 0.05 + 2.0 * max(abs(v[2]) for v in tip_vel) * dt
            self._ground_active = (min(p[2] for p in tip_pos) - self.gear < ground_cfg.height + margin
                                   or x[2] < ground_cfg.height + margin)
        self._anchor_list = env.ground.anchors.tolist()
        self._stage_contact = 0.0
        thrust = fleet.thrust_vectors_list()
        if self._uav_force_list is not None:  # realism: the rotor drag, held over the step like the thrust
            thrust = [(t0 + f0, t1 + f1, t2 + f2) for (t0, t1, t2), (f0, f1, f2) in
                      zip(thrust, self._uav_force_list, strict=True)]
        # classical RK4 on the structure state (thrusts held over the step)
        h = 0.5 * dt
        k1 = self._derivative(x, thrust)
        contact = self._stage_contact
        k2 = self._derivative([a + h * b for a, b in zip(x, k1, strict=True)], thrust)
        k3 = self._derivative([a + h * b for a, b in zip(x, k2, strict=True)], thrust)
        k4 = self._derivative([a + dt * b for a, b in zip(x, k3, strict=True)], thrust)
        sixth = dt / 6.0
        x = [a + sixth * (b1 + 2.0 * b2 + 2.0 * b3 + b4) for a, b1, b2, b3, b4 in zip(x, k1, k2, k3, k4, strict=True)]
        norm = math.sqrt(x[3] * x[3] + x[4] * x[4] + x[5] * x[5] + x[6] * x[6])
        x[3:7] = [x[3] / norm, x[4] / norm, x[5] / norm, x[6] / norm]
        self._set_x(x)
        self._contact_force = contact
        # environment forces on the quadrotors at the new state (for the leg force and the reported wrench)
        tip_pos, tip_vel = self._tips = self._tip_kinematics_list(x)
        env_uav = [[0.0, 0.0, 0.0] for _ in range(n)]
        if self._ground_active:
            feet = [(p[0], p[1], p[2] - self.gear) for p in tip_pos]
            env.ground.update_anchors(feet + [tuple(x[0:3])])
            anchors = env.ground.anchors.tolist()
            for i in range(n):
                env_uav[i] = list(env.ground.point_force(anchors[i], *feet[i], *tip_vel[i]))
        foot_normals = [f[2] for f in env_uav]  # ground normal force on each quadrotor's gear [N] (before wind)
        if self._air_list is not None:
            drag = self._uav_drag
            air = self._air_list
            for i in range(n):
                for k in range(3):
                    env_uav[i][k] += drag * (air[3 + 3 * i + k] - tip_vel[i][k])
        # spherical-joint offset moment (2.93) on each quadrotor, body frame: m = d_b × (R_biᵀ f_l,i),
        # f_l,i = m_b,i a_i − f_i − m_b,i g − f_env,i with a_i the tip acceleration over the step
        gx, gy, gz = self._gravity
        d0, d1, d2 = self._joint_offset
        body_moments = []
        accelerations = []
        landed = self._ground_active and any(a[0] == a[0] for a in env.ground.anchors[:n].tolist())
        uav_quats = fleet.quat_list()
        for i in range(n):
            acc = [(tip_vel[i][k] - self._tip_velocity_list[i][k]) / dt for k in range(3)]
            accelerations.append(acc)
            mass = self._uav_masses[i]
            f0 = mass * (acc[0] - gx) - thrust[i][0] - env_uav[i][0]
            f1 = mass * (acc[1] - gy) - thrust[i][1] - env_uav[i][1]
            f2 = mass * (acc[2] - gz) - thrust[i][2] - env_uav[i][2]
            r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_entries(*uav_quats[i])
            b0 = r00 * f0 + r10 * f1 + r20 * f2
            b1 = r01 * f0 + r11 * f1 + r21 * f2
            b2 = r02 * f0 + r12 * f1 + r22 * f2
            body_moments.append([d1 * b2 - d2 * b1, d2 * b0 - d0 * b2, d0 * b1 - d1 * b0])
        if landed:
            self._add_landing_gear_moments(body_moments, uav_quats, foot_normals)
        else:
            self._yaw_anchors = [math.nan] * n
        self._tip_velocity_list = tip_vel
        self._tip_acceleration_list = accelerations
        if self.ideal_attitude:
            fleet.battery.update(fleet.thrust(), dt)
        else:
            fleet.step(dt, body_moments)

    def uav_landed(self) -> list[bool]:
        """Per quadrotor: its landing gear touches the ground (a ground anchor is set). This is what PX4's land
        detector reports (landed / maybe_landed) for the rate controller's integrator freeze."""
        return [a == a for a in self.environment.ground.anchors[:self.n, 0].tolist()]

    def _add_landing_gear_moments(self, body_moments: list[list[float]], uav_quats: list[list[float]],
                                  normals: list[float]) -> None:
        """Moments of the landing gear on the quadrotors whose feet touch the ground (body FLU, N m), in place.

        The gear is a unilateral contact of feet at ``landing_gear_radius`` r from the vehicle's centre, carrying
        the normal force N_i of the quadrotor's ground contact (``normals``):

        - levelling (roll/pitch): a torsional spring-damper towards level, ``k_l·(up_b × e_z) − c_l ω_xy`` with
          ``k_l = 2 m_b g d_arm``, bounded by the tipping moment ``N_i r`` (no moment once the thrust carries
          the vehicle, none that could pull it down);
        - yaw: stick/slip friction of the feet, a torsional spring ``k_ψ = k_t r²`` (ground tangential stiffness)
          to a yaw anchor with damping ``c_ψ = c_t r²``, bounded by ``μ N_i r``; the anchor slides when the bound
          is reached (as the translational friction anchors of the environment) and is dropped on lift-off.

        Without the yaw friction a disarmed quadrotor standing on the ground would spin freely under the
        joint-offset moment (2.93) of the leg's horizontal force.
        """
        anchors = self.environment.ground.anchors[:self.n, 0].tolist()
        rates = self.fleet.rate.tolist()
        ground = self.scenario.ground
        radius = float(self.scenario.quadrotor.landing_gear_radius)
        arm = self.scenario.quadrotor.arm_length
        yaw_stiffness = ground.tangential_stiffness * radius * radius
        yaw_damping = ground.tangential_damping * radius * radius
        for i, anchor in enumerate(anchors):
            if anchor != anchor:  # NaN: not touching
                self._yaw_anchors[i] = math.nan
                continue
            qw, qx, qy, qz = uav_quats[i]
            _, _, _, _, _, _, up0, up1, up2 = rotation_entries(qw, qx, qy, qz)  # world z in body coordinates
            w0, w1, w2 = rates[i]
            tipping = max(normals[i], 0.0) * radius
            stiffness = self._uav_masses[i] * self.params.gravity * 0.5 * arm * 4.0
            # tilt = up_body × e_z (body-frame axis·sin(angle) from body z to world up)
            m0 = -stiffness * up1 - 0.2 * w0
            m1 = stiffness * up0 - 0.2 * w1
            size = math.hypot(m0, m1)
            if size > tipping:
                scale = tipping / size
                m0 *= scale
                m1 *= scale
            # yaw friction about the world vertical
            yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
            yaw_anchor = self._yaw_anchors[i]
            if yaw_anchor != yaw_anchor:
                yaw_anchor = yaw
            stretch = math.remainder(yaw - yaw_anchor, 2.0 * math.pi)
            limit = ground.friction * max(normals[i], 0.0) * radius
            if yaw_stiffness * abs(stretch) > limit:  # slipping: the anchor follows
                stretch = math.copysign(limit / yaw_stiffness, stretch)
                yaw_anchor = yaw - stretch
            self._yaw_anchors[i] = yaw_anchor
            mz = -yaw_stiffness * stretch - yaw_damping * (up0 * w0 + up1 * w1 + up2 * w2)
            mz = min(max(mz, -limit), limit)
            body_moments[i][0] += m0 + mz * up0
            body_moments[i][1] += m1 + mz * up1
            body_moments[i][2] += mz * up2

    # ---------------------------------------------------------------------------------------------- outputs
    def ground_truth(self) -> GroundTruth:
        """The true state now (see :class:`GroundTruth`)."""
        state = self.state
        tip_pos, tip_vel = self._tip_kinematics(self._x)
        Rb = _quat_to_rotmat(self.fleet.quat)
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
        """True τ_e (6+n) of the disturbances now: board, scheduled wrench, wind (uniform and fan, on the platform,
        the legs' middles and the quadrotors, with the air velocities of :meth:`_air_velocities` at this time and
        state), ground, payload weight, and the legs' joint-stop moments (the controllers' model has no stops: an
        observer sees them as disturbances).

        Layout [f_p (F0), m_p (Fp), joint moments] as (2.26); evaluated by the generalized-force map of the
        environment forces alone (thrust and the structure's own gravity excluded).
        """
        n = self.n
        x = self._x
        R = _quat_to_rotmat(x[3:7])
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
        if self._uav_force_list is not None:  # realism: the rotor drag of the last step
            tip = tip + np.array(self._uav_force_list)
        if self.environment.has_wind:
            wind = self.scenario.wind
            air = np.reshape(self._air_velocities(), (1 + 2 * n, 3))
            tip = tip + wind.uav_drag * (air[1:1 + n] - tip_vel)
            forces.append(wind.platform_drag * (air[0] - R @ x[7 + n:10 + n]))
            points.append(np.zeros(3))
            # the legs' drag at their middles (Fp): v = R (u + ω × (a_i + l e_i / 2) + (l/2) θ̇_i ∂e_i/∂θ_i)
            sd = self.structure
            e = np.column_stack([sd.cos_alpha * c, sd.sin_alpha * c, -s])
            de = np.column_stack([-sd.cos_alpha * s, -sd.sin_alpha * s, -c])
            half = 0.5 * sd.leg_length
            mid_velocity = (x[7 + n:10 + n] + cross(x[10 + n:13 + n], sd.anchors + half * e)
                            + half * x[13 + n:, None] * de)
            mids = wind.leg_drag * (air[1 + n:] @ R - mid_velocity)
        if self.environment.board.enabled:
            pb = self.environment.board_end_effector
            f_board, _ = self.environment.board_force(
                x[0:3] + R @ pb, R @ (x[7 + n:10 + n] + cross(x[10 + n:13 + n], pb)))
            points.append(pb)
            forces.append(f_board)
        pf = PointForces(np.array(points), np.array(forces) @ R, tip @ R, mids, moment, np.zeros(n))
        q_body = self.structure.generalized_forces(c, s, pf)
        q_body[:3] = R @ q_body[:3]
        if self._joint_stops is not None:
            q_body[6:] += self.joint_stop_moments()
        return q_body

    def joint_stop_moments(self) -> np.ndarray:
        """Moments of the legs' mechanical stops now [N m] (n,), :func:`joint_stop_moment` (0 when disabled)."""
        n = self.n
        x = self._x_list
        if self._joint_stops is None:
            return np.zeros(n)
        return np.array([joint_stop_moment(x[7 + i], x[13 + n + i], *self._joint_stops) for i in range(n)])
