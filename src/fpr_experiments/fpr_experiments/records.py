"""One recorded flight as numpy arrays (ROS-free): what the metrics, the plots and the reports work on.

Times are simulation time [s]; SI units, angles in rad; world frame F0 ENU (z up); ``[w, x, y, z]`` quaternions.
Built from the recorded messages by :func:`fpr_experiments.recording.flight_record`; tests build them directly.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class TruthSeries:
    """Ground truth (``/fpr/ground_truth``, the simulator's "motion capture"), N samples."""

    t: np.ndarray               #: (N,) [s]
    position: np.ndarray        #: (N,3) platform centre P in F0 [m]
    quat: np.ndarray            #: (N,4) platform attitude F0 <- Fp
    rpy: np.ndarray             #: (N,3) ZYX roll, pitch, yaw [rad]
    legs: np.ndarray            #: (N,n) leg angles θ_l [rad]
    leg_rates: np.ndarray       #: (N,n) [rad/s]
    velocity: np.ndarray        #: (N,3) platform linear velocity in F0 [m/s]
    rate: np.ndarray            #: (N,3) platform angular velocity in Fp [rad/s]
    thrusts: np.ndarray         #: (N,n) actual thrust of each UAV [N]
    uav_positions: np.ndarray   #: (N,n,3) UAV CoM in F0 [m]
    uav_quats: np.ndarray       #: (N,n,4) UAV body (FLU) attitude in F0
    external_wrench: np.ndarray  #: (N,6+n) true τ_e: force in F0 [N], moment in Fp [N m], leg moments [N m]
    contact_force: np.ndarray   #: (N,) true normal force on the board [N]
    payload_mass: np.ndarray    #: (N,) [kg]
    battery: np.ndarray         #: (N,n) [V]


@dataclass
class CommandSeries:
    """Teleop command χ_d (``/fpr/teleop``), M samples; velocities in the flat frame F_Fp."""

    t: np.ndarray               #: (M,) [s]
    mode: np.ndarray            #: (M,) TeleopCommand.MODE_*
    velocity: np.ndarray        #: (M,3) [m/s] in F_Fp
    yaw_rate: np.ndarray        #: (M,) [rad/s]
    roll: np.ndarray            #: (M,) [rad]
    pitch: np.ndarray           #: (M,) [rad]
    contact_force: np.ndarray   #: (M,) desired f^d_c [N]
    legs: np.ndarray            #: (M,n) [rad]


def _empty(*shape: int) -> np.ndarray:
    return np.zeros((0, *shape)) if shape else np.zeros(0)


@dataclass
class UavSeries:
    """What one UAV's nodes published (bridge status, controller diagnostics / setpoints / wrench, estimator)."""

    uav_id: int
    status_t: np.ndarray = field(default_factory=_empty)
    bridge_state: np.ndarray = field(default_factory=_empty)     #: UavStatus.STATE_*
    diagnostics_t: np.ndarray = field(default_factory=_empty)
    active_mode: np.ndarray = field(default_factory=_empty)      #: ControllerStatus.MODE_*
    fallback: np.ndarray = field(default_factory=_empty)         #: bool: C/impedance -> NC fallback active
    desired_position: np.ndarray = field(default_factory=lambda: _empty(3))  #: p^d in F0 (ground-truth modes)
    desired_rpy: np.ndarray = field(default_factory=lambda: _empty(3))       #: desired roll, pitch, yaw [rad]
    desired_legs: np.ndarray = field(default_factory=lambda: _empty(3))      #: θ^d [rad]
    desired_contact_force: np.ndarray = field(default_factory=_empty)        #: f^d_c [N]
    setpoint_t: np.ndarray = field(default_factory=_empty)
    setpoint_thrust: np.ndarray = field(default_factory=_empty)  #: [N]
    wrench_t: np.ndarray = field(default_factory=_empty)
    wrench_force: np.ndarray = field(default_factory=lambda: _empty(3))   #: f̂_p,e (F0 or F_Fp) [N]
    wrench_moment: np.ndarray = field(default_factory=lambda: _empty(3))  #: p m̂_p,e [N m]
    wrench_contact: np.ndarray = field(default_factory=_empty)            #: −(R_pᵀ f̂_p,e)_z [N]
    wrench_legs: np.ndarray = field(default_factory=lambda: _empty(3))    #: m̂_l,e [N m]
    local_t: np.ndarray = field(default_factory=_empty)
    local_position: np.ndarray = field(default_factory=lambda: _empty(3))  #: EKF p p_i [m] (UAV in Fp)
    local_quat: np.ndarray = field(default_factory=lambda: _empty(4))      #: EKF p q_i
    local_leg_angle: np.ndarray = field(default_factory=_empty)
    local_roll: np.ndarray = field(default_factory=_empty)
    local_pitch: np.ndarray = field(default_factory=_empty)
    local_valid: np.ndarray = field(default_factory=_empty)
    marker_t: np.ndarray = field(default_factory=_empty)
    marker_position: np.ndarray = field(default_factory=lambda: _empty(3))  #: ArUco p p_i via (4.2) [m]
    marker_quat: np.ndarray = field(default_factory=lambda: _empty(4))
    checked_t: np.ndarray = field(default_factory=_empty)  #: detections the pose estimator got (detection_fallback)
    checked_emulated: np.ndarray = field(default_factory=_empty)  #: bool: emulated from the motion capture


@dataclass
class StateNames:
    """Names of the message enumerations (taken from the message constants by the recorder)."""

    teleop_mode: dict[int, str]
    bridge_state: dict[int, str]
    controller_mode: dict[int, str]
    fly_mode: int = 2          #: TeleopCommand.MODE_FLY
    land_mode: int = 3         #: TeleopCommand.MODE_LAND
    offboard_state: int = 4    #: UavStatus.STATE_OFFBOARD
    emergency_state: int = 8   #: UavStatus.STATE_EMERGENCY


@dataclass
class FlightRecord:
    """One flight: recorded series plus how it ran."""

    n: int
    truth: TruthSeries
    command: CommandSeries
    uavs: list[UavSeries]
    names: StateNames
    events: list[dict] = field(default_factory=list)  #: scripted-operator task events (fpr_experiments.pilot)
    #: each UAV's entries into the swarm's emergency response (UavStatus.STATE_EMERGENCY): {"t" [s], "uav",
    #: "own" (a cause of its own, else it follows a peer), "reason"} in time order (fpr_px4_bridge.swarm_guard)
    emergencies: list[dict] = field(default_factory=list)
    experiment: str = ""
    variant: str = ""
    scenario: str = ""
    script: str = ""
    controller_mode: str = ""
    cameras: str = ""
    sim_time: float = 0.0          #: [s] simulated at the end
    wall_time: float = 0.0         #: [s] wall time of the flight
    lockstep_timeouts: int = 0
    callback_errors: list[str] = field(default_factory=list)
    completed: bool = True         #: the requested duration was simulated
    camera_rate: float = 20.0      #: [Hz] (detection-rate denominator)
    landing_gear_height: float = 0.10  #: [m] UAV CoM above its feet (airborne test)
    target_position: list[float] | None = None  #: [m] world, the scenario's target (law (4.39)), if any
