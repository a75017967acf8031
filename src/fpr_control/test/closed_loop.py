"""Test helper: n controllers flying the fpr_model dynamics (no ROS).

Plant: ``fpr_model.dynamics.rk4_step`` at 1 kHz; control at 50 Hz; each UAV tracks its attitude setpoint
instantly (thesis §3.3.3 assumption), so it applies ``f_i = R^d_i e_z f^d_t,i`` in F0 for the whole period.
Each UAV has its own local frame F0i with a yaw offset (its setpoint is converted back to F0 here), its own
exact LocalState built from the true state, and the ζ_j are exchanged every period (perfect communication).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from fpr_control.controller import Controller, ControlOutput, GroundTruth
from fpr_control.information import InfoPlausibility, LocalEstimate, PeerInfo
from fpr_control.reference import TeleopReference
from fpr_model.dynamics import gravity, rk4_step, thrusts_from_wrench
from fpr_model.geometry import make_configuration
from fpr_model.kinematics import uav_velocities
from fpr_model.parameters import FprParameters
from fpr_model.rotations import (
    euler_zyx_to_quat,
    quat_multiply,
    quat_to_rotmat,
    rot_z,
    rotmat_to_euler_zyx,
    rotmat_to_quat,
)

#: ζ_j plausibility for controllers in this harness: its UAVs track their attitude setpoint instantly (the first
#: step snaps each from the identity to its setpoint, ~120° of yaw in 20 ms), a turn the default jump bound
#: (fpr_control.information.InfoPlausibility) rightly refuses; the other bounds stay the defaults.
HARNESS_PLAUSIBILITY = InfoPlausibility(max_angular_rate=1e6)


def hover_state(params: FprParameters, leg_angle: float = math.radians(45.0), yaw: float = 0.3,
                height: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    q = make_configuration([0.2, -0.1, height], euler_zyx_to_quat(0.0, 0.0, yaw), [leg_angle] * params.n)
    return q, np.zeros(params.n + 6)


def command(n: int, roll=0.0, pitch=0.0, leg=0.25 * math.pi, force=0.0, mode=2) -> TeleopReference:
    ref = TeleopReference.hold(roll, pitch, np.full(n, leg))
    ref.contact_force = force
    ref.mode = mode
    return ref


@dataclass
class Sim:
    params: FprParameters
    controllers: list[Controller]
    q: np.ndarray
    nu: np.ndarray
    yaw_offsets: np.ndarray  # yaw of F0i relative to F0 [rad]
    external: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    t: float = 0.0
    uav_quats: np.ndarray = field(default=None)
    thrusts: np.ndarray = field(default=None)  # (n, 3) applied, F0
    log: list = field(default_factory=list)
    local_noise: Callable[[LocalEstimate], LocalEstimate] | None = None

    def __post_init__(self) -> None:
        n = self.params.n
        if self.uav_quats is None:
            self.uav_quats = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        if self.thrusts is None:
            self.thrusts = thrusts_from_wrench(self.params, self.q, gravity(self.params, self.q))

    # ---------------------------------------------------------------------------------------------
    def ground_truth(self) -> GroundTruth:
        n = self.params.n
        return GroundTruth(self.q[:3].copy(), self.q[3:7].copy(), self.nu[:3].copy(), self.nu[3:6].copy(),
                           self.q[7:].copy(), self.nu[6:].copy(), self.uav_quats.copy().reshape(n, 4))

    def local_estimate(self, i: int) -> LocalEstimate:
        """Exact LocalState of UAV i (0-based) from the true state."""
        rotation = quat_to_rotmat(self.q[3:7])
        roll, pitch, yaw_p = rotmat_to_euler_zyx(rotation)
        flat_from_world = rot_z(-yaw_p)
        velocities = uav_velocities(self.params, self.q, self.nu)
        uav_rotation = quat_to_rotmat(self.uav_quats[i])
        flat_uav = flat_from_world @ uav_rotation
        uav_yaw_world = rotmat_to_euler_zyx(uav_rotation)[2]
        uav_yaw_local = math.remainder(uav_yaw_world - self.yaw_offsets[i], 2 * math.pi)
        est = LocalEstimate(
            leg_angle=float(self.q[7 + i]), platform_roll=roll, platform_pitch=pitch,
            attitude=rotmat_to_quat(flat_uav), velocity=flat_from_world @ velocities[i],
            relative_yaw=rotmat_to_euler_zyx(flat_uav)[2], uav_yaw=uav_yaw_local, valid=True)
        return self.local_noise(est) if self.local_noise is not None else est

    # ---------------------------------------------------------------------------------------------
    def control(self, cmd: TeleopReference | None, silent: set[int] | None = None) -> list[ControlOutput]:
        """Perfect, instantaneous communication: before the step every controller (itself included) receives
        ζ_j = [θ_j, Fp v_j, Fp q_j (now), f^d_t,j (last command)] of every UAV j not in ``silent``."""
        outputs = []
        gt = self.ground_truth()
        locals_ = [self.local_estimate(i) for i in range(self.params.n)]
        for j, est in enumerate(locals_):
            if silent and j + 1 in silent:
                continue
            info = PeerInfo(j + 1, est.leg_angle, est.velocity.copy(), est.attitude.copy(),
                            float(np.linalg.norm(self.thrusts[j])))
            for controller in self.controllers:
                controller.receive_info(info, self.t)
        for i, controller in enumerate(self.controllers):
            outputs.append(controller.step(self.t, locals_[i], cmd, gt))
        for i, out in enumerate(outputs):
            world_quat = quat_multiply(euler_zyx_to_quat(0.0, 0.0, self.yaw_offsets[i]), out.attitude)
            self.uav_quats[i] = world_quat / np.linalg.norm(world_quat)
            self.thrusts[i] = quat_to_rotmat(self.uav_quats[i])[:, 2] * out.thrust
        return outputs

    def run(self, duration: float, cmd: TeleopReference | None, control_period: float = 0.02,
            physics_dt: float = 0.001, on_tick: Callable[[list[ControlOutput]], None] | None = None,
            **control_kwargs) -> list[ControlOutput]:
        steps = int(round(control_period / physics_dt))
        outputs: list[ControlOutput] = []
        for _ in range(int(round(duration / control_period))):
            outputs = self.control(cmd, **control_kwargs)
            if on_tick is not None:
                on_tick(outputs)
            for _ in range(steps):
                external = self.external(self.q, self.nu) if self.external is not None else None
                tau = self.thrusts.reshape(-1) @ _jacobian(self.params, self.q)
                self.q, self.nu = rk4_step(self.params, self.q, self.nu, tau, physics_dt, external)
                self.t += physics_dt
            self.log.append((self.t, self.q.copy(), self.nu.copy(), outputs))
        return outputs


def _jacobian(params, q):
    from fpr_model.kinematics import jacobian

    return jacobian(params, q)
