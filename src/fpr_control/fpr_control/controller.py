"""One UAV's controller: state -> observer -> law -> thrust distribution -> own setpoint (DESIGN.md §4).

Every UAV runs the same computation for the whole robot and applies its own share (thesis §4.3.2):

- ``centralized``: ground truth (motion capture) in F0, PID motion law (4.27)-(4.28) with the Table 4.1
  "Centralized" gains, desired pose integrated from the teleoperation velocities.
- ``communicating`` (C): own LocalState + the others' ζ_j, PID (4.27)-(4.29) in F_Fp.
- ``non_communicating`` (NC): the others' states replaced by desired values (4.32).
- ``impedance``: impedance law (4.33)-(4.34) with a momentum observer (4.35)-(4.37). Decentralized (no position),
  the estimated platform force enters ε_τ (3.26) only along the desired interaction force
  (``impedance_force_input = "interaction"``, :func:`fpr_control.laws.interaction_force_selection`), so a load
  is compensated rather than turned into a steady sink f_e / B^d; ``"full"`` keeps the printed (4.34).
- ``pd``, ``pd_compensated``: the Table 3.4 comparison laws (PD, PD + feed-forward −τ̂_e).

``state_source = "ground_truth"`` runs impedance / pd / pd_compensated on the ground truth in F0 with the full
position error (thesis Ch. 3 setting, Table 3.1 gains); ``centralized`` implies it. With ``state_source =
"local"``, C, impedance, pd and pd_compensated need every peer's ζ: when one is older than ``info_timeout`` the
controller falls back to NC and reports it, and returns when all are fresh again.

The wrench estimate is expressed in the controller frame (F_Fp or F0) for the force, Fp for the moment.
No rclpy here; the node converts messages to the dataclasses below.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from fpr_model._math import norm_floats
from fpr_model._validation import all_finite
from fpr_model.dynamics import model_terms
from fpr_model.geometry import desired_uav_rotation, leg_anchor_angles
from fpr_model.kinematics import jacobian_at
from fpr_model.parameters import FprParameters
from fpr_model.rotations import quat_tilt, quat_to_euler_zyx, quat_to_rotmat, rotmat_to_euler_zyx

from fpr_control.contact_guard import ContactGuard, ContactGuardConfig
from fpr_control.information import (
    InfoPlausibility,
    InformationTable,
    LocalEstimate,
    PeerInfo,
    flat_platform_quat,
    reconstruct_state,
    thrust_vector,
)
from fpr_control.laws import (
    ImpedanceGains,
    PidGains,
    PidMotionLaw,
    configuration_error,
    control_wrench,
    impedance_acceleration,
    interaction_force_selection,
    observer_inputs,
    pd_acceleration,
    pid_gains_from_groups,
    wrench_tracking_error,
)
from fpr_control.observers import OBSERVER_KINDS, ObserverGains, make_observer
from fpr_control.reference import (
    CentralizedReference,
    DesiredTrajectory,
    TeleopReference,
    decentralized_reference,
)
from fpr_control.rejoin import RejoinConfig, RejoinRamp
from fpr_control.setpoints import (
    hover_thrust_share,
    local_frame_attitude,
    saturate_thrust_vector,
)

MODES = ("centralized", "communicating", "non_communicating", "impedance", "pd", "pd_compensated")
MODE_CODES = {name: code for code, name in enumerate(MODES)}  # = fpr_msgs/ControllerStatus MODE_*
STATE_SOURCES = ("local", "ground_truth")
#: What of the estimated platform force enters the decentralized impedance (4.34) as ε_τ (3.26):
#: "interaction" only its component along the desired interaction force (fpr_control.laws.interaction_force_selection),
#: "full" all of it (the printed law: a load then drifts the robot at f_e / B^d_p). Ground truth: always (3.26).
IMPEDANCE_FORCE_INPUTS = ("interaction", "full")
#: TeleopCommand.MODE_FLY: integrators run and the centralized reference is free only while flying.
TELEOP_MODE_FLY = 2
_NEEDS_PEERS = ("communicating", "impedance", "pd", "pd_compensated")


@dataclass(frozen=True)
class ControllerGains:
    """All gains (diagonals of length 6 + n). Defaults: see :func:`default_gains`."""

    impedance_centralized: ImpedanceGains
    impedance_decentralized: ImpedanceGains
    pid_centralized: PidGains
    pid_decentralized: PidGains
    observer: ObserverGains = field(default_factory=ObserverGains)


#: Default gains as (position, orientation, legs) triples or Table 4.1 (kp, kd, ki) rows; the node declares one
#: ROS parameter per leaf ("gains.<group>.<name>") and config/controller.yaml repeats them.
DEFAULT_GAINS: dict = {
    # Table 3.1 (centralized impedance; also the ground-truth pd / pd_compensated modes' observer)
    "impedance_centralized": {"inertia": [5.0, 8.0, 5.0], "damping": [10.0, 25.0, 20.0],
                              "stiffness": [25.0, 25.0, 15.0]},
    # Table 4.5: the position stiffness is meaningless without a position (its error is 0 in (4.29))
    "impedance_decentralized": {"inertia": [5.0, 8.0, 5.0], "damping": [10.0, 25.0, 20.0],
                                "stiffness": [0.0, 25.0, 15.0]},
    # Table 4.1, columns (Kp, Kd, Ki); "*" (not available in the decentralized controller) = 0
    "pid_centralized": {"position_xy": [9.0, 6.0, 25.0], "position_z": [16.0, 8.0, 50.0],
                        "orientation_xy": [9.0, 6.0, 1.0], "orientation_z": [9.0, 6.0, 0.5],
                        "legs": [9.0, 6.0, 10.0], "integral_limit": [2.0, 2.0, 2.0],
                        "integral_zone": [math.inf, math.inf, math.inf]},
    "pid_decentralized": {"position_xy": [0.0, 9.0, 0.0], "position_z": [0.0, 8.0, 0.0],
                          "orientation_xy": [9.0, 6.0, 1.0], "orientation_z": [0.0, 6.0, 0.0],
                          "legs": [9.0, 6.0, 0.5], "integral_limit": [2.0, 2.0, 2.0],
                          "integral_zone": [math.inf, math.inf, math.inf]},
    # Table 3.1 observer gains (position, orientation, legs); smwo_epsilon: sgn* linear zone (3.21)
    "observer": {"fowo": [2.0, 1.0, 1.0], "sowo_k1": [4.0, 2.0, 2.0], "sowo_k2": [1.0, 0.5, 0.5],
                 "smwo_ks": [4.0, 1.0, 1.0], "smwo_kt": [3.2, 1.6, 1.6], "smwo_epsilon": 0.02},
}


def gains_from_dict(d: dict, n: int) -> ControllerGains:
    """:class:`ControllerGains` from the :data:`DEFAULT_GAINS` layout (missing entries take the defaults)."""
    merged = {group: {**values, **d.get(group, {})} for group, values in DEFAULT_GAINS.items()}

    def impedance(group: str) -> ImpedanceGains:
        g = merged[group]
        return ImpedanceGains.from_groups(g["inertia"], g["damping"], g["stiffness"], n)

    o = merged["observer"]
    observer = ObserverGains(tuple(o["fowo"]), tuple(o["sowo_k1"]), tuple(o["sowo_k2"]), tuple(o["smwo_ks"]),
                             tuple(o["smwo_kt"]), float(o["smwo_epsilon"]))
    return ControllerGains(impedance("impedance_centralized"), impedance("impedance_decentralized"),
                           pid_gains_from_groups(merged["pid_centralized"], n),
                           pid_gains_from_groups(merged["pid_decentralized"], n), observer)


@dataclass(frozen=True)
class ControllerConfig:
    uav_id: int
    mode: str
    gains: ControllerGains
    observer: str = "fowo"
    state_source: str = "local"
    period: float = 0.02  # [s] control period
    info_timeout: float = 0.2  # [s]
    max_thrust: float = 25.0  # f_max [N]
    max_tilt: float = math.radians(35.0)  # [rad] from the vertical of the controller frame
    require_own_echo: bool = True  # the own ζ_i must come back on the shared topic (else fallback)
    impedance_force_input: str = "interaction"  # one of IMPEDANCE_FORCE_INPUTS (decentralized impedance only)
    info_plausibility: InfoPlausibility = field(default_factory=InfoPlausibility)  # ζ_j checks (issue 12)
    own_writer_direct: bool = False  # the own ζ_i is read back from the topic it is written on (no relay)
    rejoin: RejoinConfig = field(default_factory=RejoinConfig)  # bumpless rejoin after an emergency (issue 12)
    contact_guard: ContactGuardConfig = field(default_factory=ContactGuardConfig)  # fpr_control.contact_guard

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        if self.observer not in OBSERVER_KINDS:
            raise ValueError(f"observer must be one of {OBSERVER_KINDS}, got {self.observer!r}")
        if self.state_source not in STATE_SOURCES:
            raise ValueError(f"state_source must be one of {STATE_SOURCES}, got {self.state_source!r}")
        if self.impedance_force_input not in IMPEDANCE_FORCE_INPUTS:
            raise ValueError(f"impedance_force_input must be one of {IMPEDANCE_FORCE_INPUTS}, "
                             f"got {self.impedance_force_input!r}")
        if not (self.period > 0.0 and self.info_timeout > 0.0 and self.max_thrust > 0.0
                and 0.0 < self.max_tilt < 0.5 * math.pi):
            raise ValueError("period, info_timeout, max_thrust must be > 0 and max_tilt in (0, pi/2)")


@dataclass
class GroundTruth:
    """Ground truth (fpr_msgs/FprState) in F0: platform pose, ν parts, UAV attitudes."""

    platform_position: np.ndarray
    platform_quat: np.ndarray  # [w, x, y, z]
    platform_velocity: np.ndarray  # F0
    platform_rate: np.ndarray  # Fp
    leg_angles: np.ndarray
    leg_rates: np.ndarray
    uav_quats: np.ndarray  # (n, 4) [w, x, y, z], body FLU -> F0

    def is_finite(self) -> bool:
        return all_finite(self.platform_position, self.platform_quat, self.platform_velocity, self.platform_rate,
                          self.leg_angles, self.leg_rates, self.uav_quats) and norm_floats(self.platform_quat) > 0.5


@dataclass(frozen=True)
class DesiredState:
    """The desired configuration q^d the law tracked in one control step (fpr_msgs/ControllerStatus desired_*).

    Controller frame: F0 in the ground-truth modes (p^d and ψ^d integrated by :class:`CentralizedReference`),
    F_Fp in the decentralized ones (p^d = 0: the position is unknown; ψ^d = 0: F_Fp carries the yaw), (4.25).
    """

    position: np.ndarray  # p^d [m], controller frame
    roll: float  # ϕ^d [rad], ZYX Euler angles of q^d_p
    pitch: float  # ϑ^d [rad]
    yaw: float  # ψ^d [rad]
    leg_angles: np.ndarray  # θ^d (n,) [rad]
    contact_force: float  # f^d_c [N] (3.43)

    @staticmethod
    def from_trajectory(desired: DesiredTrajectory, contact_force: float) -> DesiredState:
        """Unpack q^d = [p^d (3), q^d_p (4, [w, x, y, z]), θ^d (n)] of a :class:`DesiredTrajectory`."""
        roll, pitch, yaw = quat_to_euler_zyx(desired.q[3:7])
        return DesiredState(desired.q[:3].copy(), float(roll), float(pitch), float(yaw), desired.q[7:].copy(),
                            float(contact_force))


@dataclass
class ControlOutput:
    """One control step's results."""

    attitude: np.ndarray  # 0i q^d_i [w, x, y, z] in the UAV's own local frame
    thrust: float  # f^d_t,i [N], in [0, f_max]
    thrust_vectors: np.ndarray | None  # (n, 3) full f of the law in the controller frame, before saturation
    info: PeerInfo | None  # own ζ_i (None without a valid own estimate)
    wrench: np.ndarray  # τ̂_e (6+n) [controller-frame force, Fp moment, leg moments]
    contact_force: float  # −(R_pᵀ f̂_p,e)_z [N]
    active_mode: str
    fallback_active: bool
    info_ages: np.ndarray
    thrust_saturated: bool
    tilt_saturated: bool
    local_state_valid: bool
    state_ok: bool  # False: no usable state, the setpoint is a hold / hover fallback
    warning: str | None = None
    loop_time: float = 0.0
    #: q^d tracked in this step; a hold (state_ok False) repeats the last step's, None before the first good step
    desired: DesiredState | None = None
    #: f^d_c the law tracked [N] after the contact guard (desired.contact_force is the operator's demand)
    applied_contact_force: float = 0.0
    contact_guard_state: int = 0  #: fpr_control.contact_guard IDLE / PUSHING / LOST
    contact_guard_event: str | None = None  #: one line when the guard declares the contact lost or re-arms
    #: [rad] the platform's tilt from the vertical in the state this step used (NaN: none yet); the bridges' swarm
    #: guard's flight envelope (ControllerStatus.platform_tilt)
    platform_tilt: float = math.nan


class Controller:
    """Decentralized (or centralized) FPR controller of UAV ``config.uav_id``; call :meth:`step` every period."""

    def __init__(self, params: FprParameters, config: ControllerConfig) -> None:
        self.params = params
        self.config = config
        n = params.n
        self.n = n
        self.information = InformationTable(n, config.uav_id, config.info_timeout, config.require_own_echo,
                                            config.info_plausibility, config.own_writer_direct)
        self.observer = make_observer(config.observer, config.gains.observer, n)
        use_truth = config.mode == "centralized" or config.state_source == "ground_truth"
        self.uses_ground_truth = use_truth
        self.pid = PidMotionLaw(config.gains.pid_centralized if use_truth else config.gains.pid_decentralized)
        self.impedance_gains = (config.gains.impedance_centralized if use_truth
                                else config.gains.impedance_decentralized)
        self.reference = CentralizedReference()
        alphas = leg_anchor_angles(n)
        self._radial = np.array([math.cos(alphas[config.uav_id - 1]), math.sin(alphas[config.uav_id - 1]), 0.0])
        self._last_local: LocalEstimate | None = None
        self._last_thrusts: np.ndarray | None = None  # (n, 3) applied thrust vectors, controller frame
        self._last_own_thrust = hover_thrust_share(params.total_mass, params.gravity, n)
        self._last_output: ControlOutput | None = None
        self._hold_command: TeleopReference | None = None
        self._previous_active = config.mode
        self._observer_paused = False
        self.rejoin = RejoinRamp(config.rejoin)
        self._flown = True
        self.contact_guard = ContactGuard(config.contact_guard)

    #: ControllerConfig fields :meth:`reconfigure` may change in flight (ROS parameters set at run time)
    DYNAMIC_FIELDS = ("gains", "max_thrust", "max_tilt", "info_timeout")

    def reconfigure(self, **changes) -> None:
        """Apply run-time changes of :data:`DYNAMIC_FIELDS` (the node's dynamic parameters): the new config is
        validated as a whole first (ControllerConfig raises ValueError, nothing changes), then the next
        :meth:`step` uses it. New gains replace the motion laws' gains (the PID keeps its integral state, clamped to
        the new bound on the next step); the observer's gains are not dynamic (its state was built with them)."""
        unknown = sorted(set(changes) - set(self.DYNAMIC_FIELDS))
        if unknown:
            raise ValueError(f"not changeable in flight: {unknown} (dynamic: {self.DYNAMIC_FIELDS})")
        config = replace(self.config, **changes)
        if config.gains.observer != self.config.gains.observer:
            raise ValueError("the observer gains are not changeable in flight")
        self.config = config
        self.information.timeout = config.info_timeout
        gains = config.gains
        self.pid.gains = gains.pid_centralized if self.uses_ground_truth else gains.pid_decentralized
        self.impedance_gains = gains.impedance_centralized if self.uses_ground_truth else gains.impedance_decentralized

    # ------------------------------------------------------------------------------------------------
    def receive_info(self, info: PeerInfo, now: float, sequence: int | None = None, valid: bool = True) -> str | None:
        """Store a peer's ζ_j with its publisher's sequence number (returns a rejection reason or None; see
        :meth:`fpr_control.information.InformationTable.update`)."""
        return self.information.update(info, now, sequence, valid)

    def _active_mode(self, now: float) -> tuple[str, bool]:
        mode = self.config.mode
        if self.uses_ground_truth or mode not in _NEEDS_PEERS:
            return mode, False
        if self.information.all_fresh(now):
            return mode, False
        return "non_communicating", True

    # ------------------------------------------------------------------------------------------------
    def step(self, now: float, local: LocalEstimate | None, command: TeleopReference | None,
             ground_truth: GroundTruth | None = None, uav_yaw_local: float | None = None,
             flown: bool = True) -> ControlOutput:
        """One control period at time ``now`` [s]. ``uav_yaw_local`` = own IMU yaw in F0i [rad] (defaults to
        ``local.uav_yaw``; in ground-truth mode without either, F0i is taken as F0). ``flown``: this UAV's PX4 flies
        the setpoints (False in the swarm's emergency Hold or a bridge's warm-up: the reference then follows the
        measured configuration and rejoins bumplessly, :mod:`fpr_control.rejoin`)."""
        start = time.perf_counter()
        self._flown = bool(flown)
        warning = None
        local_valid = local is not None and local.is_finite()
        if local is not None and not local_valid:
            warning = "own local state is not finite: using the last valid one"
        if local_valid:
            self._last_local = local
        local = self._last_local
        local_ok = local is not None and local_valid and local.valid
        if command is not None and not command.is_finite():
            warning = "teleoperation command is not finite: holding"
            command = None
        active, fallback = self._active_mode(now)
        ages = self.information.ages(now)
        try:
            out = self._compute(now, local, command, ground_truth, uav_yaw_local, active, fallback, ages, local_ok)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as error:  # includes SingularConfiguration
            out = self._safe_output(local, active, fallback, ages, local_ok, uav_yaw_local)
            warning = f"control step failed ({error}): holding the last setpoint"
        if out.warning is None:
            out.warning = warning
        out.platform_tilt = self._platform_tilt(local, ground_truth)
        out.loop_time = time.perf_counter() - start
        if out.state_ok:
            self._last_output = out
        return out

    def _platform_tilt(self, local: LocalEstimate | None, ground_truth: GroundTruth | None) -> float:
        """[rad] angle between the platform's z axis z_p and the vertical in the state of this step: the motion
        capture's platform_quat (F0) in the ground-truth modes, else the last valid LocalState's roll and pitch (the
        flat-platform frame F_Fp of §4.3.1 shares F0's vertical); NaN without one. Reported, not used by the law: the
        bridges' swarm guard lands the swarm when it stays above its envelope (fpr_px4_bridge.swarm_guard)."""
        if self.uses_ground_truth:
            if ground_truth is None or not ground_truth.is_finite():
                return math.nan
            quat = ground_truth.platform_quat
            return float(quat_tilt(quat / np.linalg.norm(quat)))
        if local is None:
            return math.nan
        return float(quat_tilt(flat_platform_quat(local.platform_roll, local.platform_pitch)))

    # ------------------------------------------------------------------------------------------------
    def _command(self, command: TeleopReference | None, roll: float, pitch: float,
                 leg_angles: np.ndarray) -> TeleopReference:
        if command is not None:
            self._hold_command = None
            return command
        if self._hold_command is None:
            self._hold_command = TeleopReference.hold(roll, pitch, leg_angles)
        return self._hold_command

    def _measured_leg_angles(self, now: float, local: LocalEstimate) -> np.ndarray:
        """θ of every leg [rad] as far as this UAV knows: its own estimate, the peers' fresh ζ_j (else its own: a
        common start keeps the rejoin references of the UAVs alike)."""
        legs = np.full(self.n, local.leg_angle)
        ages = self.information.ages(now)
        for j in range(1, self.n + 1):
            info = self.information.get(j)
            if j != self.config.uav_id and info is not None and ages[j - 1] <= self.config.info_timeout:
                legs[j - 1] = info.leg_angle
        return legs

    def _rejoin_command(self, command: TeleopReference, roll: float, pitch: float,
                        leg_angles: np.ndarray | None) -> TeleopReference:
        """The bumpless-rejoin reference (:mod:`fpr_control.rejoin`) from the measured roll, pitch and leg angles
        [rad]; the observer forgets its momentum history when the setpoints are flown again (the thrusts it assumed
        were not applied meanwhile)."""
        suspended = self.rejoin.suspended
        out = self.rejoin.apply(self._flown, self.config.period, command, roll, pitch, leg_angles)
        if suspended and not self.rejoin.suspended:
            self.observer.reset()
        return out

    def _compute(self, now, local, command, ground_truth, uav_yaw_local, active, fallback, ages, local_ok):
        cfg, n, own = self.config, self.n, self.config.uav_id - 1
        flying = command is not None and command.mode == TELEOP_MODE_FLY
        # J(q) and J^† once per step: FKM (2.21), Jᵀ f of the observer (2.28), thrust distribution (3.32)
        if self.uses_ground_truth:
            if ground_truth is None or not ground_truth.is_finite():
                return self._safe_output(local, active, fallback, ages, local_ok, uav_yaw_local,
                                         "no valid ground truth")
            gt = ground_truth
            quat = gt.platform_quat / np.linalg.norm(gt.platform_quat)
            q = np.concatenate([gt.platform_position, quat, gt.leg_angles])
            nu = np.concatenate([gt.platform_velocity, gt.platform_rate, gt.leg_rates])
            jacobian = jacobian_at(self.params, q, check_leg_range=False)
            rotation = jacobian.configuration.rotation  # R_p (A.60)
            roll, pitch, yaw = rotmat_to_euler_zyx(rotation)
            cmd = self._rejoin_command(self._command(command, roll, pitch, gt.leg_angles.copy()), roll, pitch,
                                       gt.leg_angles)
            if not flying or not self.reference.initialized or self.rejoin.suspended:
                self.reference.reset(gt.platform_position, yaw)
            desired = self.reference.step(cmd, cfg.period, roll, pitch, rotation)
            uav_yaw_frame = rotmat_to_euler_zyx(quat_to_rotmat(gt.uav_quats[own]))[2]
            if uav_yaw_local is None:
                uav_yaw_local = local.uav_yaw if local is not None else uav_yaw_frame
            applied = self._last_thrusts
            use_position = True
        else:
            if local is None:
                return self._safe_output(local, active, fallback, ages, local_ok, uav_yaw_local,
                                         "no valid local state yet")
            roll, pitch = local.platform_roll, local.platform_pitch
            cmd = self._command(command, roll, pitch, np.full(n, local.leg_angle))
            measured = self._measured_leg_angles(now, local) if self.rejoin.needs_measurement(self._flown) else None
            cmd = self._rejoin_command(cmd, roll, pitch, measured)
            rotation = quat_to_rotmat(flat_platform_quat(roll, pitch))
            desired = decentralized_reference(cmd, roll, pitch, rotation)
            peers = None
            if active != "non_communicating":
                peers = {j: self.information.get(j) for j in range(1, n + 1) if j != cfg.uav_id}
            state = reconstruct_state(self.params, cfg.uav_id, local, peers, desired.q[7:], desired.nu)
            q, nu, jacobian = state.q, state.nu, state.jacobian
            uav_yaw_frame = local.relative_yaw
            if uav_yaw_local is None:
                uav_yaw_local = local.uav_yaw
            applied = None
            if peers is not None:
                applied = np.empty((n, 3))
                for j in range(1, n + 1):
                    if j == cfg.uav_id:
                        applied[j - 1] = thrust_vector(local.attitude, self._last_own_thrust)
                    else:
                        applied[j - 1] = thrust_vector(peers[j].attitude, peers[j].thrust)
            use_position = False

        terms = model_terms(self.params, jacobian, nu)
        # ---- observer (3.8)-(3.24) / (4.35)-(4.37): paused while the others' thrusts are unknown (NC)
        if applied is None and not self.uses_ground_truth:
            self._observer_paused = True
        else:
            if self._observer_paused:
                self.observer.reset()
                self._observer_paused = False
            # before the first command (centralized): the thrusts that hold gravity, [Jᵀ]† g
            thrusts = applied if applied is not None else jacobian.thrusts(terms.gravity)
            momentum, beta = observer_inputs(terms, nu, thrusts.reshape(-1))
            self.observer.update(momentum, beta, cfg.period)
        tau_hat = self.observer.estimate
        # ---- contact guard (fpr_control.contact_guard): a force demand that finds no contact fades out
        normal = rotation[:, 2]  # z_p in the controller frame
        estimated_contact = float(-(normal @ tau_hat[:3]))  # −(R_pᵀ f̂_p,e)_z (3.45)
        guard = self.contact_guard.step(
            cmd.contact_force, estimated_contact, float(normal @ nu[:3]), cfg.period,
            tracking=flying and active == "impedance" and not self.rejoin.suspended)
        if guard.applied_force != cmd.contact_force:  # τ^d_e (3.43) is linear in f^d_c
            scale = guard.applied_force / cmd.contact_force if cmd.contact_force != 0.0 else 0.0
            desired = replace(desired, wrench=desired.wrench * scale)

        # ---- law
        if active != self._previous_active and active == "non_communicating":
            self.pid.reset()
        self._previous_active = active
        if not flying:
            self.pid.reset()
        error = configuration_error(q, desired.q, use_position)
        tau = self._law(active, terms, error, nu, desired, tau_hat, flying)
        thrusts_full = jacobian.thrusts(tau)  # (3.32) / (4.33)
        if not np.isfinite(thrusts_full).all():
            raise ArithmeticError("non-finite thrusts")

        # ---- saturation and own setpoint (3.36)-(3.38), (4.38)
        if self.uses_ground_truth:  # the saturated thrusts of every UAV are the observer's next f
            saturated = [saturate_thrust_vector(f, cfg.max_thrust, cfg.max_tilt) for f in thrusts_full]
            self._last_thrusts = np.array([s.vector for s in saturated])
            mine = saturated[own]
        else:
            mine = saturate_thrust_vector(thrusts_full[own], cfg.max_thrust, cfg.max_tilt)
        leg_direction = rotation @ jacobian.configuration.leg_rotations[own, :, 0]  # pR_li e_x (2.8), in F
        attitude_frame = desired_uav_rotation(mine.vector, leg_direction, self.params.joint_offset_angle,
                                              rotation @ self._radial)
        attitude = local_frame_attitude(attitude_frame, uav_yaw_frame, uav_yaw_local)
        thrust = float(np.linalg.norm(mine.vector))
        self._last_own_thrust = thrust

        info = None
        if local is not None:
            info = PeerInfo(cfg.uav_id, local.leg_angle, local.velocity.copy(), local.attitude.copy(), thrust)
        return ControlOutput(
            attitude=attitude, thrust=thrust, thrust_vectors=thrusts_full, info=info, wrench=tau_hat.copy(),
            contact_force=estimated_contact, active_mode=active, fallback_active=fallback,
            info_ages=ages, thrust_saturated=mine.thrust_saturated, tilt_saturated=mine.tilt_saturated,
            local_state_valid=local_ok, state_ok=True,
            desired=DesiredState.from_trajectory(desired, cmd.contact_force),
            applied_contact_force=guard.applied_force, contact_guard_state=guard.state,
            contact_guard_event=guard.event,
        )

    def _law(self, active: str, terms, error, nu, desired: DesiredTrajectory, tau_hat, flying) -> np.ndarray:
        if active == "impedance":
            selection = None  # (3.26) in every row: Ch. 3 setting (with the position stiffness) or "full"
            if not self.uses_ground_truth and self.config.impedance_force_input == "interaction":
                selection = interaction_force_selection(desired.wrench[:3])  # no position: see its doc
            u = impedance_acceleration(self.impedance_gains, error, nu, desired.nu, desired.nu_dot,
                                       wrench_tracking_error(tau_hat, desired.wrench, selection))
            return control_wrench(terms, u, nu, tau_hat)  # (3.31) / (4.33)
        if active in ("pd", "pd_compensated"):
            u = pd_acceleration(self.pid.gains, error, nu, desired.nu, desired.nu_dot)
            return control_wrench(terms, u, nu, tau_hat if active == "pd_compensated" else None)
        u = self.pid.acceleration(error, nu, desired.nu, desired.nu_dot, self.config.period,
                                  integrate=flying and not self.rejoin.suspended)
        return control_wrench(terms, u, nu)  # (4.27)

    def _safe_output(self, local, active, fallback, ages, local_ok, uav_yaw_local, warning=None) -> ControlOutput:
        """Hold the last good setpoint, or level attitude with the hover share of the weight."""
        last = self._last_output
        if last is not None:
            attitude, thrust = last.attitude.copy(), last.thrust
        else:
            yaw = uav_yaw_local if uav_yaw_local is not None else (local.uav_yaw if local is not None else 0.0)
            attitude = np.array([math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)])
            thrust = min(hover_thrust_share(self.params.total_mass, self.params.gravity, self.n),
                         self.config.max_thrust)
        info = None
        if local is not None:
            info = PeerInfo(self.config.uav_id, local.leg_angle, local.velocity.copy(), local.attitude.copy(), thrust)
        return ControlOutput(
            attitude=attitude, thrust=float(thrust), thrust_vectors=None, info=info,
            wrench=self.observer.estimate.copy(), contact_force=0.0, active_mode=active, fallback_active=fallback,
            info_ages=ages, thrust_saturated=False, tilt_saturated=False, local_state_valid=local_ok,
            state_ok=False, warning=warning, desired=last.desired if last is not None else None,
        )
