"""Information vectors ζ_j, their ages, and the decentralized state reconstruction (thesis §4.2.3, §4.3.2-4.3.3).

- ζ_i = [θ_i, Fp v_i, Fp q_i, f^d_t,i] (4.31), (4.36): leg angle [rad], UAV velocity in F_Fp [m/s], UAV attitude
  in F_Fp ([w,x,y,z]) and last commanded thrust [N]. :class:`InformationTable` keeps the newest per UAV with
  its receive time; a peer is fresh when its age ≤ info_timeout (DESIGN.md §4).
- State reconstruction on UAV i: ``q = [0_3, Fp q_p, θ_l]`` (4.24) with Fp q_p = quat(Ry(ϑ_p) Rx(ϕ_p)) from the
  own estimate, ν = J(q)† [Fp v_1; ...; Fp v_n] (FKM (2.21)) in F_Fp.
- C: the others' θ_j, Fp v_j come from their ζ_j. NC: they are replaced by the desired values (4.32):
  θ_j = θ^d_j and Fp v^d = J(q) ν^d.
- Thrust vectors for the observer (4.37): Fp f_j = Fp R_j [0, 0, f^d_t,j].
No rclpy here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from fpr_model._math import norm_floats
from fpr_model._validation import all_finite
from fpr_model.kinematics import JacobianAt, jacobian_at
from fpr_model.parameters import FprParameters
from fpr_model.rotations import euler_zyx_to_quat, rotation_entries


@dataclass
class PeerInfo:
    """ζ_j of UAV j (1-based id)."""

    uav_id: int
    leg_angle: float
    velocity: np.ndarray  # Fp v_j [m/s]
    attitude: np.ndarray  # Fp q_j [w, x, y, z]
    thrust: float  # f^d_t,j [N]

    def problem(self) -> str | None:
        """Why this vector is unusable (non-finite, zero quaternion, negative thrust), or None."""
        if not all_finite(self.leg_angle, self.thrust, self.velocity, self.attitude):
            return "contains NaN or inf"
        if not 0.5 < norm_floats(self.attitude) < 1.5:
            return "attitude is not a unit quaternion"
        if self.thrust < 0.0:
            return "negative thrust"
        return None


@dataclass
class LocalEstimate:
    """What the own pose estimator gives (fpr_msgs/LocalState), rad, m/s."""

    leg_angle: float
    platform_roll: float  # Fp ϕ_p
    platform_pitch: float  # Fp ϑ_p
    attitude: np.ndarray  # Fp q_i [w, x, y, z]
    velocity: np.ndarray  # Fp v_i [m/s]
    relative_yaw: float  # pψ_i
    uav_yaw: float  # 0iψ_i (own IMU)
    valid: bool = True

    def is_finite(self) -> bool:
        return all_finite(self.leg_angle, self.platform_roll, self.platform_pitch, self.relative_yaw, self.uav_yaw,
                          self.attitude, self.velocity) and norm_floats(self.attitude) > 0.5


class InformationTable:
    """Newest ζ_j per UAV j ≠ own, with receive times (controller clock, s).

    With ``require_own_echo`` the own ζ_i must also come back on the shared topic within the timeout: a UAV
    whose vectors do not reach the topic (silenced) then falls back to NC together with the others, who see
    its ζ_i age."""

    def __init__(self, n: int, own_id: int, timeout: float, require_own_echo: bool = True) -> None:
        if not 1 <= own_id <= n:
            raise ValueError(f"uav_id {own_id} outside 1..{n}")
        self.n = n
        self.own_id = own_id
        self.timeout = timeout
        self.require_own_echo = require_own_echo
        self._infos: dict[int, PeerInfo] = {}
        self._times: dict[int, float] = {}
        self._own_echo_time = -math.inf

    def update(self, info: PeerInfo, receive_time: float) -> str | None:
        """Store ζ_j; returns the rejection reason (then the entry is not refreshed) or None."""
        if not 1 <= info.uav_id <= self.n:
            return f"uav_id {info.uav_id} outside 1..{self.n}"
        problem = info.problem()
        if problem is not None:
            return f"zeta_{info.uav_id} {problem}"
        if info.uav_id == self.own_id:
            self._own_echo_time = receive_time  # our own vector, echoed by the shared topic
            return None
        self._infos[info.uav_id] = info
        self._times[info.uav_id] = receive_time
        return None

    def ages(self, now: float) -> np.ndarray:
        """Age [s] of the newest ζ_j per UAV (index j − 1), own entry 0, never received = inf."""
        ages = np.full(self.n, math.inf)
        ages[self.own_id - 1] = 0.0
        for j, t in self._times.items():
            ages[j - 1] = max(now - t, 0.0)
        return ages

    def own_echo_age(self, now: float) -> float:
        """Age [s] of the last own ζ_i received back from the shared topic (inf: never)."""
        return max(now - self._own_echo_time, 0.0)

    def all_fresh(self, now: float) -> bool:
        """Every peer's ζ_j (and, with ``require_own_echo``, the own echo) is at most ``timeout`` s old (the
        :meth:`ages` of all peers ≤ timeout; a peer never received has age inf)."""
        if self.require_own_echo and self.own_echo_age(now) > self.timeout:
            return False
        return len(self._times) == self.n - 1 and all(max(now - t, 0.0) <= self.timeout
                                                      for t in self._times.values())

    def get(self, uav_id: int) -> PeerInfo | None:
        return self._infos.get(uav_id)


def flat_platform_quat(roll: float, pitch: float) -> np.ndarray:
    """Fp q_p of R = Ry(ϑ) Rx(ϕ) (thesis §4.3.1), [w, x, y, z]."""
    return euler_zyx_to_quat(roll, pitch, 0.0)


def thrust_vector(attitude: np.ndarray, thrust: float) -> np.ndarray:
    """Fp f_j = Fp R_j [0, 0, f_t,j] (4.37) [N], R_j of the normalised attitude quaternion (A.60)."""
    w, x, y, z = np.asarray(attitude, dtype=float).tolist()
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    r = rotation_entries(w / norm, x / norm, y / norm, z / norm)
    return np.array([r[2] * thrust, r[5] * thrust, r[8] * thrust])


@dataclass
class ReconstructedState:
    """q (7+n), ν (6+n) in F_Fp, the UAV velocities used (n, 3) and J(q) with J^† (the FKM's, for the rest of
    the control step)."""

    q: np.ndarray
    nu: np.ndarray
    uav_velocities: np.ndarray
    jacobian: JacobianAt


def reconstruct_state(params: FprParameters, own_id: int, local: LocalEstimate,
                      peers: dict[int, PeerInfo] | None, desired_leg_angles: np.ndarray | None = None,
                      desired_nu: np.ndarray | None = None) -> ReconstructedState:
    """(4.24) + FKM (2.21). ``peers`` None -> NC substitution (4.32) using ``desired_leg_angles`` and
    ``desired_nu`` (both required then). Raises ValueError / SingularConfigurationError on bad geometry."""
    n = params.n
    own = own_id - 1
    leg_angles = np.empty(n)
    if peers is None:
        if desired_leg_angles is None or desired_nu is None:
            raise ValueError("NC reconstruction needs the desired leg angles and velocity")
        leg_angles[:] = desired_leg_angles
    else:
        for j in range(1, n + 1):
            if j != own_id:
                leg_angles[j - 1] = peers[j].leg_angle
    leg_angles[own] = local.leg_angle
    q = np.concatenate([np.zeros(3), flat_platform_quat(local.platform_roll, local.platform_pitch), leg_angles])
    jacobian = jacobian_at(params, q)  # leg angles checked in (0, π/2]; cond(J) at the FKM
    velocities = np.empty((n, 3))
    if peers is None:
        velocities[:] = (jacobian.matrix @ desired_nu).reshape(n, 3)  # (4.32)
    else:
        for j in range(1, n + 1):
            if j != own_id:
                velocities[j - 1] = peers[j].velocity
    velocities[own] = local.velocity
    nu = jacobian.velocity(velocities.reshape(-1))  # FKM (2.21); every velocity was checked finite on receipt
    return ReconstructedState(q, nu, velocities, jacobian)
