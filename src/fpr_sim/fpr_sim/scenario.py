"""Scenario description of one simulation run: initial state, true plant parameters, schedules (YAML).

A scenario file is a YAML mapping whose keys are the fields of :class:`Scenario` (nested mappings for the
nested dataclasses). Every level refuses unknown keys with a ValueError that lists the valid ones, so a
typo never silently falls back to a default. All values are SI (m, kg, s, rad, N, V) in the world frame
ENU (z up) unless a field says otherwise.

Example (see ``config/scenarios/*.yaml``)::

    initial_state: {mode: ground, leg_angles: 1.047}
    plant: {platform_mass: 0.27}          # true parameters: overrides of thesis Table B.1
    payloads: [{mass: 0.3, attach_time: 10.0, release_time: 20.0}]
    # or picked up where P passes within 15 cm of a hanging load, after t = 5 s, dropped 10 s later (thesis §4.4.2):
    # payloads: [{mass: 0.4, attach_time: 5.0, pickup_position: [0.5, 0.0, 1.6], pickup_radius: 0.15, hold_time: 10.0}]
    wind: {velocity: [1.0, 0.0, 0.0]}
    # or a wind generator: 26 km/h mean at the quadrotors' hover centroid, fan 3 m upstream (thesis Exp. III)
    # wind: {fan: {enabled: true, speed: 7.22, direction: [1.0, 0.0, 0.0]}}
    # switched on at t = 20 s, spinning up over 3 s: {fan: {enabled: true, start_time: 20.0, ramp_time: 3.0}}
    board: {enabled: true, point: [0.0, 0.0, 1.85], size: [0.3, 0.3]}   # a 30 x 30 cm board
    target: {enabled: true, position: [0.05, 0.0, 1.85], yaw: 0.3}       # /fpr/target (thesis §4.4.2)
    joint_stops: {lower: 0.1745, upper: 1.606}   # the legs' mechanical stops [rad] (default on; enabled: false)

Landing: PX4's AUTO.LAND (and the failsafes that end in it) lands each UAV level on its own; the legs then lose
the inward thrust component that holds them and splay onto their lower joint stop while the robot sinks
(fpr_sim.px4_emulator). Scenarios and operators should descend under the FPR controllers and land / disarm
near the ground.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fpr_sim.px4_position_control import PositionControlConfig

__all__ = [
    "ActuationConfig",
    "AerodynamicsConfig",
    "BatteryConfig",
    "BoardConfig",
    "CameraConfig",
    "ExternalWrenchEvent",
    "FanConfig",
    "GroundConfig",
    "Gust",
    "InitialState",
    "JointStopConfig",
    "LinkConfig",
    "ModelMismatchConfig",
    "MotionCaptureConfig",
    "PayloadEvent",
    "Px4Config",
    "QuadrotorConfig",
    "Scenario",
    "SensorConfig",
    "TargetConfig",
    "WindConfig",
    "bundled_scenarios_dir",
    "deep_merge",
    "load_scenario",
    "realism_dir",
    "realism_overlay",
    "realism_profiles",
    "scenario_from_dict",
    "scenario_path",
]


@dataclass
class InitialState:
    """Initial configuration of the robot.

    ``mode``: ``"ground"`` (quadrotors resting on the ground plane, platform level above them, motors off) or
    ``"hover"`` (in the air at ``position``, at rest; the PX4 emulators start armed in OFFBOARD with the hover
    setpoint held until the first setpoint arrives only if ``armed`` is true). A hover start is a vehicle that
    has been flying: the rotors deliver the hover thrusts J⁻ᵀg and the battery already carries their current, so
    the terminal voltage (BATTERY_STATUS, f_max(V) of (C.2)) is the loaded one from t = 0 (≈ 12.13 V with the
    default battery, not the unloaded 12.4 V): the held hover thrust and every later setpoint normalized with the
    reported voltage give the same newtons.
    """

    mode: str = "ground"
    position: list[float] = field(default_factory=lambda: [0.0, 0.0, 1.5])  #: platform P [m] (x, y used on ground)
    yaw: float = 0.0  #: platform yaw [rad]
    leg_angles: float | list[float] = math.radians(60.0)  #: θ_i [rad], one value for all legs or n values
    armed: bool = False  #: hover mode only: start armed in OFFBOARD, hover thrust held (tests, demos)


@dataclass
class QuadrotorConfig:
    """True rigid-body, motor and battery-thrust parameters of each quadrotor (all n identical but thrust)."""

    inertia: list[float] = field(default_factory=lambda: [0.011, 0.011, 0.021])  #: diag I_b [kg m²] (FLU)
    arm_length: float = 0.17  #: d of (3.41): rotor axis to centre [m] (34 cm frame)
    torque_coefficient: float = 0.016  #: c_Q / c_T of (3.41) [m]
    motor_time_constant: float = 0.008  #: first-order motor lag [s]
    thrust_coefficients: list[list[float]] = field(
        default_factory=lambda: [[8.02, -61.66], [8.22, -64.01], [8.15, -62.28]]
    )  #: per-UAV [a_f [N/V], b_f [N]] of (C.2) (Table C.1); the last row repeats for UAVs beyond the list
    landing_gear_height: float = 0.10  #: CoM height above the feet [m]
    landing_gear_radius: float = 0.15  #: feet distance from the vehicle's centre [m] (tipping and yaw-friction lever)


@dataclass
class BatteryConfig:
    """Battery voltage model: ``V = V_full − (V_full − V_empty)·Q_used/Q_cap − R·I``, ``I = k_I·thrust``."""

    full_voltage: float = 12.4  #: [V] open-circuit, charged (3S)
    empty_voltage: float = 10.8  #: [V] open-circuit at ``capacity``
    capacity: float = 4.0  #: [A h] (after which the open-circuit voltage stays at ``empty_voltage``)
    current_per_newton: float = 1.6  #: [A/N] current drawn per newton of thrust
    internal_resistance: float = 0.015  #: [Ω] sag under load
    initial_charge_used: list[float] = field(default_factory=lambda: [0.0])  #: [A h] per UAV (last repeats)


@dataclass
class Px4Config:
    """PX4-like attitude controller (3.39)-(3.40) gains, offboard rules and the PX4 parameters of the emulated
    mode logic (names in the field comments; see fpr_sim.px4_emulator), identical on every UAV."""

    attitude_p_gain: list[float] = field(default_factory=lambda: [6.5, 6.5, 2.8])  #: 2/τ·... : rate = P·2·q_err [1/s]
    rate_p_gain: list[float] = field(default_factory=lambda: [0.9, 0.9, 0.6])  #: K_P [N m s/rad]
    rate_i_gain: list[float] = field(default_factory=lambda: [1.2, 1.2, 0.6])  #: K_I [N m/rad], I/P as PX4 defaults
    rate_d_gain: list[float] = field(default_factory=lambda: [0.004, 0.004, 0.0])  #: K_D [N m s²/rad]
    rate_integrator_limit: float = 0.3  #: |K_I ∫ε| bound [N m]
    max_rate: list[float] = field(default_factory=lambda: [3.8, 3.8, 3.5])  #: rate setpoint limits [rad/s]
    controller_rate: float = 250.0  #: attitude/rate loop [Hz]
    #: [s] command uplink: an attitude / thrust setpoint takes effect this long after it reached the PX4 (the
    #: lockstep still counts it on arrival). The thesis's Ch. 3 set-up ran its controller on a ground computer and
    #: sent the commands over 5 GHz Wi-Fi and ROS 2 to each UAV's companion computer, then to the Pixhawk
    #: (l.4957-4959, l.9814-9820); 0: the command takes effect on arrival
    command_latency: float = 0.0
    #: COM_OF_LOSS_T [s]: offboard signal = a setpoint younger than this. The FPR's PX4s: 0.5 s (PX4's default
    #: 1.0 s, range 0-60; older trees 0.5): a UAV whose bridge died flies its last attitude until then, and the
    #: legs start to fold within it (docs/safety.md: bridge killed, tilt 33.5° with 1 s, 19.4° with 0.5 s)
    offboard_loss_timeout: float = 0.5
    failsafe_hold_time: float = 5.0  #: offboard/RC loss: Hold this long before Land [s] (PX4 COM_FAIL_ACT_T, 5 s)
    land_disarm_delay: float = 2.0  #: COM_DISARM_LAND: disarm after this long landed (LAND, or after flight) [s]
    disarm_preflight_timeout: float = 10.0  #: COM_DISARM_PRFLT: disarm if armed this long without take-off [s]
    rc_loss_timeout: float = 0.5  #: COM_RC_LOSS_T: airborne in a manual-like mode, no RC -> failsafe after [s]
    #: accept ARM and mode switches into modes that need manual control (POSCTL, ALTCTL, ...) without RC. PX4
    #: refuses both (modeCheck.cpp clears the arming and can-run bits of those modes without manual control,
    #: whatever COM_RC_IN_MODE); True keeps fpr_px4_bridge's flow (ARM in POSCTL, then OFFBOARD) working
    manual_modes_without_rc: bool = True
    land_speed: float = 0.7  #: MPC_LAND_SPEED [m/s] AUTO.LAND descent (below MPC_LAND_ALT2)
    takeoff_speed: float = 1.5  #: MPC_TKO_SPEED [m/s] AUTO.TAKEOFF climb
    takeoff_altitude: float = 2.5  #: MIS_TAKEOFF_ALT [m] above the take-off point
    land_detector_time: float = 1.0  #: LNDMC_TRIG_TIME [s] low thrust and no vertical motion -> landed
    land_detector_z_vel: float = 0.5  #: LNDMC_Z_VEL_MAX [m/s] "no vertical motion"
    #: the multicopter position controller (MPC_* parameters, fpr_sim.px4_position_control): PX4's defaults but a
    #: stiffer horizontal loop, MPC_XY_P 2.0 (PX4 0.95, range 0-2), MPC_XY_VEL_P_ACC 4.0 (PX4 1.8, range 1.2-5) and
    #: MPC_XY_VEL_I_ACC 2.0 (PX4 0.4, range 0-60): with PX4's defaults the hover scenario (legs 45°, platform above
    #: the UAVs) collapses in Hold within 10 s, the structure's weight acting on the UAVs' horizontal positions as a
    #: negative stiffness larger than the loop's (test_px4_gcs.py); with 1.8 / 3.0 / 0.4 (before) the swarm's
    #: emergency Hold after a dead bridge still folded the legs to 20-38° of platform tilt, with these 3.2-10.8°
    #: (docs/safety.md; 20-38°: the matrix of 2026-12-03 before this change, alternative soft_hold). The FPR's
    #: PX4s are tuned for the attached vehicles, as their attitude gains are.
    position_control: PositionControlConfig = field(
        default_factory=lambda: PositionControlConfig(xy_p=2.0, xy_vel_p=4.0, xy_vel_i=2.0))
    yaw_offsets: list[float] = field(default_factory=lambda: [0.0])  #: F0i yaw offset per UAV [rad]
    # Stream rates [Hz] of PX4's onboard MAVLink link (mavlink_main.cpp, MAVLINK_MODE_ONBOARD); each can be changed
    # at run time by MAV_CMD_SET_MESSAGE_INTERVAL. 0 disables a stream.
    #: HEARTBEAT (PX4: 1 Hz on every link; 2 Hz here: fpr_px4_bridge reports PX4's mode from it and the graph
    #: expects a mode change seen within 0.5 s, tests/test_bridge_emulator.py, test_swarm_flight.py)
    heartbeat_rate: float = 2.0
    attitude_rate: float = 100.0  #: ATTITUDE (PX4 onboard: 100 Hz)
    attitude_quaternion_rate: float = 50.0  #: ATTITUDE_QUATERNION (PX4 onboard: 50 Hz)
    highres_imu_rate: float = 50.0  #: HIGHRES_IMU (PX4 onboard: 50 Hz)
    local_position_rate: float = 50.0  #: LOCAL_POSITION_NED (PX4 onboard: 30 Hz; the FPR bridge needs 50 Hz)
    sys_status_rate: float = 5.0  #: SYS_STATUS (PX4 onboard: 5 Hz)
    battery_status_rate: float = 0.5  #: BATTERY_STATUS (PX4 onboard: 0.5 Hz)
    extended_sys_state_rate: float = 5.0  #: EXTENDED_SYS_STATE (PX4 onboard: 5 Hz)


#: [rad] upper bound of SensorConfig.imu_misalignment (1σ): its attitude error is modelled to first order
MAX_IMU_MISALIGNMENT = 0.1


@dataclass
class SensorConfig:
    """What each PX4 reports (fpr_sim.sensors): IMU white noise per sample, a per-UAV turn-on bias of the gyro and
    the accelerometer (a constant draw) that then wanders as a random walk advanced in simulation time
    (b(t_k) = b(t_{k−1}) + σ_rw √(t_k − t_{k−1}) ξ, ξ ~ N(0, I), the exact discretisation of the Wiener process of
    PX4 EKF2's bias model), and noise on the reported attitude, position, velocity and voltage. Deterministic with
    the seed; every bias effect off (0) in the ideal profile but the historical constant gyro bias."""

    gyro_noise: float = 0.003  #: [rad/s] 1σ per sample
    accel_noise: float = 0.05  #: [m/s²] 1σ per sample
    gyro_bias: float = 0.005  #: [rad/s] 1σ of the per-UAV constant bias draw
    attitude_noise: float = 0.002  #: [rad] 1σ on the reported attitude
    velocity_noise: float = 0.02  #: [m/s] 1σ on LOCAL_POSITION_NED velocity
    position_noise: float = 0.02  #: [m] 1σ on LOCAL_POSITION_NED position
    voltage_noise: float = 0.01  #: [V] 1σ
    accel_bias: float = 0.0  #: [m/s²] 1σ per axis of the per-UAV turn-on accelerometer bias draw (0: none)
    gyro_bias_random_walk: float = 0.0  #: [rad/s/√s] gyro bias random-walk density (PX4 EKF2_GYR_B_NOISE)
    accel_bias_random_walk: float = 0.0  #: [m/s²/√s] accelerometer bias random-walk density (EKF2_ACC_B_NOISE)
    #: [-] share of the horizontal accelerometer bias left in PX4's attitude estimate: its tilt estimate aligns the
    #: measured specific force with the vertical, so an unestimated bias b tilts it by δ = (b_y, −b_x, 0)/g (body,
    #: rad). PX4 then tracks and reports q̂ = q ∘ exp(δ) (fpr_sim.sensors.UavSensors.attitude_estimate_error).
    #: 0: EKF2 estimates the bias away (the former plant); 1: unobserved (no horizontal aiding of EKF2)
    tilt_from_accel_bias: float = 0.0
    #: [rad] 1σ per tilt axis (body x, y) of each UAV's constant misalignment between the IMU frame PX4 controls
    #: and reports and the rotors' thrust axis (frame, motor mounts, autopilot mounting): δ gets this draw too;
    #: at most MAX_IMU_MISALIGNMENT
    imu_misalignment: float = 0.0


@dataclass
class CameraConfig:
    """Onboard cameras (thesis §4.2.1, Appendix D) and the emulated-detection option (thesis §4.4.1).

    Realism effects (fpr_sim.cameras, fpr_sim.camera_renderer), each off with its default (0, or 1 for
    ``detection_probability``), each drawn from its own seeded stream so that switching one on changes no other:

    - ``latency``: a frame (or emulated detection) is stamped at its exposure instant t_k, rendered from the state at
      t_k, and published at the first /clock tick at or after t_k + latency (exact when latency is a multiple of the
      /clock period, 4 ms by default). Both camera modes.
    - ``exposure_time``: motion blur (rendered): the marker's image is smeared along the mean displacement of its
      projected corners between t_k − T_e/2 and t_k + T_e/2 (relative motion of camera and marker from the true
      twists of the UAV and the platform, first order).
    - ``contrast_variation``, ``brightness_variation``, ``lighting_gradient``: per-frame photometric changes
      (rendered): I' = g·I + o + a·x̂ + b·ŷ with g ~ N(1, σ_c²), o ~ N(0, σ_o²), (a, b) ~ N(0, σ_l² I), x̂, ŷ the
      pixel coordinates normalised to [−½, ½] (auto-exposure steps, lamps, the platform's shadow).
    - ``occlusion_probability``: with this probability per frame a band ``occlusion_width`` marker sides wide (a leg,
      a cable or their shadow) crosses the marker at a random angle and offset, multiplying what it covers by a
      factor uniform in [0, ``occlusion_shade``] (rendered).
    - calibration error: each UAV's TRUE camera differs from the calibration the estimator is configured with
      (Table D.1 b_T_C, the CameraModel intrinsics published on camera_info): focal lengths scaled by
      1 + U(−tol, tol) (``intrinsics_tolerance``), principal point shifted by U(−tol, tol) px
      (``principal_point_tolerance``), the three ZXZ angles of b_T_C by U(−tol, tol) rad
      (``mounting_angle_tolerance``) and its translation by U(−tol, tol) m per axis
      (``mounting_translation_tolerance``). The renderer and the emulator use the true camera; camera_info and the
      estimator keep the nominal one. Both camera modes.
    - ``detection_probability``: emulated detections only: each is delivered with this probability (misses).
    """

    enabled: bool = True
    rate: float = 20.0  #: [Hz]
    emulated: bool = False  #: publish noisy marker poses (MarkerDetection) instead of images
    position_noise: float = 0.02  #: emulated pose noise [m] per axis (thesis emulated camera)
    angle_noise: float = math.radians(2.0)  #: emulated pose noise [rad] per axis
    pixel_noise: float = 2.0  #: image noise 1σ [grey levels]
    blur_sigma: float = 0.0  #: Gaussian blur [px], 0 = none
    latency: float = 0.0  #: [s] exposure instant (the stamp) to publication
    exposure_time: float = 0.0  #: [s] motion blur over the exposure (rendered); 0 = none
    contrast_variation: float = 0.0  #: 1σ of the per-frame gain g − 1 [-] (rendered)
    brightness_variation: float = 0.0  #: 1σ of the per-frame offset [grey levels] (rendered)
    lighting_gradient: float = 0.0  #: 1σ of each gradient coefficient across the image [grey levels] (rendered)
    occlusion_probability: float = 0.0  #: per-frame probability of a band over the marker (rendered)
    occlusion_width: float = 0.25  #: band width [marker sides]
    occlusion_shade: float = 0.6  #: covered pixels × U(0, occlusion_shade) (0: opaque black)
    detection_probability: float = 1.0  #: emulated detections: probability that a frame gives a detection
    intrinsics_tolerance: float = 0.0  #: true fx, fy = nominal × (1 + U(−tol, tol)) [-], per UAV
    principal_point_tolerance: float = 0.0  #: true cx, cy = nominal + U(−tol, tol) [px], per UAV
    mounting_angle_tolerance: float = 0.0  #: true b_T_C ZXZ angles = Table D.1 + U(−tol, tol) [rad], per UAV
    mounting_translation_tolerance: float = 0.0  #: true b_T_C translation = Table D.1 + U(−tol, tol) [m] per axis


@dataclass
class GroundConfig:
    """Ground plane z = height with penalty contact (spring-damper normal, spring-damper stick/slip friction)."""

    enabled: bool = True
    height: float = 0.0  #: [m]
    stiffness: float = 20000.0  #: [N/m]
    damping: float = 300.0  #: [N s/m]
    friction: float = 0.8  #: Coulomb coefficient
    tangential_stiffness: float = 5000.0  #: stick spring [N/m]
    tangential_damping: float = 150.0  #: [N s/m]


@dataclass
class JointStopConfig:
    """Mechanical stops of the legs' revolute joints (angles θ_i): a stiff, damped penalty moment about
    the joint axis outside ``[lower, upper]``, unilateral (it pushes back, never pulls):

    ``τ_i = max(0, k (lower − θ_i) − c θ̇_i)`` for θ_i < lower, ``τ_i = min(0, k (upper − θ_i) − c θ̇_i)`` for
    θ_i > upper, 0 between (an internal moment between the leg and the platform: it enters only the θ_i row of
    the generalized forces of (2.86)).

    Range [10°, 92°]: the model and its Jacobian are valid for θ ∈ (0, 90°] (θ = 0: the leg in the platform
    plane; J is invertible on [0, π/2] [Six 2018b], thesis §2.4.1, errata §0.1) and the thesis gives no stop
    angles for the prototype's leg bearings (its only joint-stop figure is the spherical joints' tilt cone
    γ = 35°, (5.23)). Both ends of that range are numerically hostile, which sets the stops (measured with the
    Table B.1 structure, StructureDynamics.body_mass_matrix):

    - towards θ = 0 the mass matrix degenerates: a leg's effective inertia 1/(M̃⁻¹)_θθ is 0.53 kg m² at 60°,
      0.026 at 10°, 0.002 at 2° (smallest eigenvalue of M̃ 0.26, 0.012, 0.0009). With a 2° stop an AUTO.LAND
      from 2 m ended chattering on the flat legs (θ̇ ≈ 0.2 rad/s after 10 s), and diverged at touch-down with
      c = 40 (explicit RK4: c·dt/I ≈ 20 ≫ 2.8); with 10° it comes to rest;
    - at θ = arccos(−r/l) = 97° the three tips meet under the platform centre (M̃'s smallest eigenvalue 0.002):
      a 95° stop leaves no room for its penetration, 92° leaves 5°. (The prototype's quadrotors, 34 cm frames
      with 8" propellers, would touch each other near 80° already; flights stay within 45°-75°.)

    Stiffness and damping: k = 2000 N m/rad holds the largest runaway moment (f_max·l ≈ 40 N m) within ~1.2°;
    c = 10 N m s/rad keeps c·dt/I ≤ 0.5 and ω·dt ≤ 0.35 down to the light end (I ≈ 0.02 kg m²), well inside
    the 1 kHz RK4's stability region.
    """

    enabled: bool = True
    lower: float = math.radians(10.0)  #: [rad]
    upper: float = math.radians(92.0)  #: [rad]
    stiffness: float = 2000.0  #: k [N m/rad]
    damping: float = 10.0  #: c [N m s/rad]


@dataclass
class PayloadEvent:
    """A point mass attached to the platform centre P (scheduled by :class:`fpr_sim.environment.Environment`).

    Timed (``pickup_position`` null, the default): attached from ``attach_time`` until ``release_time`` [s].

    Pick-up by proximity (thesis §4.4.2 Scenario I, l.6878-6997: the operator flies the platform to a tennis ball
    hanging in the air with a load suspended below it, about 400 g in all, l.6882-6883; the ball enters the hole at
    the platform centre and the load is lifted; the tennis-ball tasks of Table 4.3, l.6699-6712, likewise): after
    ``attach_time`` the payload attaches the first time the platform centre P comes within ``pickup_radius`` of
    ``pickup_position`` (before ``release_time``), and only once; it is released at ``release_time`` or, when
    ``hold_time`` > 0, ``hold_time`` after it attached, whichever comes first. The attachment is instantaneous, as
    for a timed payload: the mass at P steps, the platform velocity is kept (the thesis gives no pick-up
    dynamics). A timed payload with ``hold_time`` > 0 is released at ``min(release_time, attach_time +
    hold_time)``. The attached mass is in the ground truth (``payload_mass``) from the step it attaches.
    """

    mass: float = 0.3  #: [kg] (thesis Sc. I ball + load ≈ 0.4, l.6882-6883)
    attach_time: float = 0.0  #: [s] timed: attach at; pick-up: the earliest time it can be picked up
    release_time: float = math.inf  #: [s] released at (at the latest)
    #: [m] world point the payload hangs at (the tennis ball's centre); null: timed payload (attach at attach_time)
    pickup_position: list[float] | None = None
    #: [m] P within this distance of ``pickup_position`` picks it up. 0.15: the thesis's success criterion of the
    #: pick-up tasks, "the distance from the target's centre to the attached load (≈ 15 cm)" (l.6993-6994)
    pickup_radius: float = 0.15
    #: [s] > 0: released this long after it attached (if before ``release_time``); 0: held until ``release_time``
    #: (not in the thesis: its tasks lasted 45 s each, some loads were released before the end, l.6975-6997)
    hold_time: float = 0.0


@dataclass
class Gust:
    """An additional air velocity [m/s] (world) during [start, start + duration], half-sine shaped."""

    start: float = 0.0
    duration: float = 1.0
    velocity: list[float] = field(default_factory=lambda: [1.0, 0.0, 0.0])


@dataclass
class FanConfig:
    """A wind generator (thesis Exp. III, l.5245-5251: "a wind generator", about 26 km/h measured at the centroid
    of the three quadrotors at their hover height, blowing along +x0; Exp. IV Task 3, l.5408-5413: about 13 km/h):
    a round free jet from an outlet of diameter ``diameter`` at ``position`` blowing along ``direction``, with
    seeded turbulence. Its air velocity adds to :class:`WindConfig`'s uniform wind and is evaluated each physics
    step where the robot's parts are (the platform centre, each leg's middle, each quadrotor), so the force
    changes as the robot moves in or out of the jet (model and constants: :class:`fpr_sim.environment.FanJet`).

    Mean velocity at a point at axial distance x > 0 from the outlet and radial distance r from the axis (none
    behind the outlet plane, x ≤ 0): along ``direction``, of magnitude

        U(x, r) = U_0 · min(1, B·D / x) · exp(−ln 2 · r² / b(x)²),    b(x) = max(D / 2, S·x)

    (centre-line decay and Gaussian profile of the self-similar round jet; the near field is a potential core of
    the outlet speed and half-width D/2). ``U_0`` follows from ``speed`` = U at ``reference_point``.
    Turbulence: ``turbulence_intensity`` · U(x, r) · ξ(t), ξ a unit-variance first-order Gauss-Markov process on
    each world axis with time constant ``turbulence_time_constant`` (a first-order / Dryden-longitudinal-like
    spectrum), the same ξ for all of the robot's points, deterministic with the scenario seed.

    Schedule: both the mean velocity and the turbulence are multiplied by s(t) = 0 before ``start_time`` and from
    ``end_time`` on, ``min(1, (t − start_time) / ramp_time)`` in between (1 with ``ramp_time`` = 0), so the
    turbulence always scales with the local mean speed and vanishes while the fan is off. ``speed`` is the
    full-speed value (s = 1). With a ground start, give ``reference_point`` (e.g. the quadrotors' hover centroid):
    the default is the quadrotors' centroid in the initial state, on the ground then.
    """

    enabled: bool = False
    #: outlet centre [m] world; None: ``distance`` m upstream of ``reference_point`` on the jet axis
    #: (``reference_point − distance·direction``: the fan aims at the reference point)
    position: list[float] | None = None
    distance: float = 3.0  #: [m] outlet → reference point when ``position`` is None (not given in the thesis)
    direction: list[float] = field(default_factory=lambda: [1.0, 0.0, 0.0])  #: jet axis, world (+x0, thesis)
    #: D, outlet diameter [m]: not in the thesis; 1.5 m (a large drum fan, about the robot's span) makes the
    #: default drag give the thesis's estimate at 13 km/h (≈ 2 N, −2 N m, Exp. IV Task 3), see WindConfig
    diameter: float = 1.5
    #: mean air speed at ``reference_point`` [m/s]; default 26 km/h (thesis Exp. III, l.5246); 13 km/h = 3.61
    speed: float = 26.0 / 3.6
    #: where ``speed`` holds [m] world; None: the quadrotors' centroid in the initial state (a hover start: where
    #: the thesis measured, "the centroid of the three quadrotors at their hovering height")
    reference_point: list[float] | None = None
    #: σ_u / U per axis [-]: 0.15 (fan jets: 10-20 % in the near field, up to 25 % far downstream; see FanJet)
    turbulence_intensity: float = 0.15
    #: τ of the Gauss-Markov turbulence [s]: integral length (~ the jet half-width, 0.3-0.5 m) / mean speed
    turbulence_time_constant: float = 0.1
    decay_constant: float = 5.8  #: B of U_c/U_0 = B·D/x [-] (round jet, Hussein et al. 1994; Pope 2000 Table 5.1)
    spreading_rate: float = 0.094  #: S = db/dx of the velocity half-width [-] (round jet, same sources)
    #: [s] the fan switches on (before: still air from the fan, no turbulence either); default 0 (on from the start).
    #: Not in the thesis; lets an experiment take off in still air and start the fan once hovering (Exp. III:
    #: the robot hovers in front of the wind generator, l.5245-5251)
    start_time: float = 0.0
    #: [s] spin-up: the mean speed (and with it the turbulence) ramps linearly from 0 at ``start_time`` to full at
    #: ``start_time + ramp_time``; default 0: a step (not in the thesis)
    ramp_time: float = 0.0
    #: [s] the fan stops (a step to still air); default inf: never (not in the thesis)
    end_time: float = math.inf


@dataclass
class WindConfig:
    """Wind as an air velocity with linear drag ``c (w − v)`` on the platform, the legs (at mid-length) and the
    quadrotors: a uniform part (``velocity`` + half-sine ``gusts``, the same everywhere) plus, when enabled, the
    jet of a wind generator (``fan``, :class:`FanConfig`, which varies in space and time).

    Linear drag: for a hovering multirotor the rotors' drag (blade flapping and induced drag, the "H-force") is
    nearly linear in the relative air speed (Mahony, Kumar & Corke, IEEE RAM 19(3), 2012, "rotor drag"), and it
    dominates the frame's quadratic drag at these speeds. The defaults are kept as they were: in a UNIFORM
    3.61 m/s (13 km/h) wind the hovering robot takes 0.86 N s/m · 3.61 m/s = 3.1 N (legs at 45°: τ_e x force
    3.1 N, pitch moment −2.1 N m); in the default fan jet, which covers the robot only partly (the lateral
    quadrotors sit off the axis), 13 km/h at the quadrotors' centroid gives 2.1 N / −1.4 N m with the legs at
    45° and 2.3 N / −2.0 N m at 60°, the thesis's estimate of Exp. IV Task 3 (about 2 N and −2 N m,
    l.5412-5413); 26 km/h (Exp. III) doubles them. The jet geometry is not in the thesis: the fan diameter
    (1.5 m, :class:`FanConfig`) rather than the drag was chosen to match, so existing scenarios are unchanged.
    """

    velocity: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  #: constant part [m/s]
    gusts: list[Gust] = field(default_factory=list)
    platform_drag: float = 0.05  #: [N s/m]
    leg_drag: float = 0.02  #: [N s/m] per leg
    uav_drag: float = 0.25  #: [N s/m] per quadrotor
    fan: FanConfig = field(default_factory=FanConfig)  #: a wind generator's jet (default off)


@dataclass
class ExternalWrenchEvent:
    """A wrench on the platform during [start, end): ``force`` [N] world at P, ``moment`` [N m] in Fp."""

    start: float = 0.0
    end: float = math.inf
    force: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    moment: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])


@dataclass
class BoardConfig:
    """A stiff board (plane through ``point`` with unit ``normal`` pointing to the free side) the platform's
    end-effector point ``end_effector`` (in Fp) can push on: penalty normal force, Coulomb friction.

    The board is a rectangle centred on ``point``: ``size[0]`` along ``edge`` (projected onto the board plane)
    and ``size[1]`` along ``normal × edge``; contact happens only while the end-effector point is over it (its
    projection onto the plane inside the rectangle; sliding past an edge ends the contact). ``inf`` (default)
    is an unbounded plane on that side, the former behaviour. The thesis's board is 30 × 30 cm (l.5339, l.7041:
    ``size: [0.3, 0.3]``). The contact region is the slab behind the rectangle, ``contact_depth`` deep: an
    end-effector pressed into the face is pushed back out through it; one that went beside the board and came
    over it from behind, deeper than ``contact_depth``, is behind the board and feels nothing. (Before
    ``contact_depth``, the whole prism behind the rectangle pushed out through the face: a table_3_7 hardware
    flight that slid past the edge, climbed 35 cm behind the plane and came back over it met a 1,600 N
    penalty force and crashed: a model artefact, not a contact.)
    """

    enabled: bool = False
    point: list[float] = field(default_factory=lambda: [0.0, 0.0, 3.0])  #: [m] world, the board's centre
    normal: list[float] = field(default_factory=lambda: [0.0, 0.0, -1.0])  #: world, towards the robot
    size: list[float] = field(default_factory=lambda: [math.inf, math.inf])  #: side lengths [m] (inf: unbounded)
    edge: list[float] = field(default_factory=lambda: [1.0, 0.0, 0.0])  #: world direction of the side size[0]
    end_effector: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.05])  #: contact point in Fp [m]
    stiffness: float = 5000.0  #: [N/m]
    damping: float = 50.0  #: [N s/m]
    friction: float = 0.3
    #: [m] deepest penetration behind the face that is still a contact with it (inf: the whole prism, as before).
    #: 0.05: a wooden board's ~2 cm plus the deepest impact the robot makes (≈ v·√(m/k) = 1 m/s·√(4 kg / 5000
    #: N/m) ≈ 2.8 cm at an unlikely 1 m/s), so no flown push tunnels through
    contact_depth: float = 0.05


@dataclass
class TargetConfig:
    """Emulated relative pose of a target for the approach law (4.39) of thesis §4.4.2 Scenario II (l.7049-7068):
    when enabled the simulator publishes ``/fpr/target`` (geometry_msgs/PoseStamped, frame ``flat_platform``) at
    ``rate``: the target position minus the platform centre in the flat platform frame F_Fp (platform yaw only,
    z up) and the rotation about z by the target's yaw minus the platform's, wrapped to (−π, π]
    (fpr_sim.target). The thesis emulated it from motion capture with the noise of its emulated MOCAP poses,
    2 cm per axis and 2° (l.6604-6608): Gaussian, per axis of the position and on the yaw, seeded.
    """

    enabled: bool = False
    #: target point [m] world, e.g. the centre of the 10 × 10 cm region on the board (l.7042-7044)
    position: list[float] = field(default_factory=lambda: [0.0, 0.0, 3.0])
    yaw: float = 0.0  #: target yaw in F0 [rad]
    position_noise: float = 0.02  #: 1σ per axis [m] (thesis l.6606-6607)
    yaw_noise: float = math.radians(2.0)  #: 1σ [rad] (thesis l.6606-6607)
    rate: float = 50.0  #: publishing rate [Hz] (simulation time)


@dataclass
class ModelMismatchConfig:
    """Realism: the plant's TRUE parameters differ from the controllers' Table B.1 model (thesis Appendix B,
    l.9808-9811), each drawn once per run, uniformly within ``±`` the half-width given here, from
    ``SeedSequence([seed, MISMATCH_SEED_STREAM])`` (fpr_sim.plant_realism.draw_model_mismatch). Off (and every
    half-width 0) in the ideal profile; a half-width 0 leaves that parameter exact. Values the scenario states in
    ``plant:`` win over the draw. The hardware values and their reasons are in src/fpr_sim/README.md ("Realism")
    and config/realism/hardware/10_model_mismatch.yaml.

    Not modelled: per-leg lengths, per-leg anchor radii / angles and per-leg masses (FprParameters has one leg
    length, one leg mass and the symmetric anchor layout α_i = 2π(i−1)/n; the structure's fitted mass-matrix basis
    and the compiled kernel assume that symmetry), so ``leg_length`` etc. are common draws for all legs.
    """

    enabled: bool = False
    platform_mass: float = 0.0  #: ± [kg] on m_p
    uav_mass: float = 0.0  #: ± [kg] on each m_b,i (independent draws)
    leg_mass: float = 0.0  #: ± [kg] on m_l (one draw, all legs)
    platform_com_xy: float = 0.0  #: ± [m] on s_p,x and s_p,y (independent)
    platform_com_z: float = 0.0  #: ± [m] on s_p,z
    leg_com: float = 0.0  #: ± [m] on s_l,x (along the leg)
    platform_inertia: float = 0.0  #: ± relative [-] on each diagonal entry of I_p
    leg_inertia: float = 0.0  #: ± relative [-] on each diagonal entry of I_l
    leg_length: float = 0.0  #: ± [m] on l (one draw, all legs)
    platform_radius: float = 0.0  #: ± [m] on r
    joint_offset: float = 0.0  #: ± [m] on d of (2.93)
    joint_offset_angle: float = 0.0  #: ± [rad] on β
    quadrotor_inertia: float = 0.0  #: ± relative [-] on each diagonal entry of ``quadrotor.inertia`` (all UAVs)


@dataclass
class ActuationConfig:
    """Realism: motors and thrust differ from what the bridge's (C.1)-(C.2) model assumes (fpr_model.battery,
    Table C.1), drawn per run from ``SeedSequence([seed, ACTUATION_SEED_STREAM])``
    (fpr_sim.plant_realism.draw_actuation); the thrust noise from its own stream. Every knob off at 0.

    - true thrust curve per UAV i: ``f_max,i = a_f,i (1 + ε_a,i) V + b_f,i + δ_b,i``, ε_a uniform in
      ±``thrust_slope_error``, δ_b uniform in ±``thrust_offset_error`` [N] (the plant's (C.2); the bridge keeps
      Table C.1);
    - per-rotor thrust gain ``k_ij = 1 + ε_ij``, ε uniform in ±``rotor_thrust_spread``: rotor j of UAV i produces
      ``k_ij T_ij`` (a moment imbalance the PX4 rate integrator must hold, (3.41) with unequal c_T);
    - thrust noise: produced thrust × ``(1 + σ ξ_ij(t))``, ξ a unit-variance first-order Gauss-Markov process per
      rotor with time constant ``thrust_noise_time_constant``, σ = ``thrust_noise``; a share ρ =
      ``thrust_noise_common`` of its variance is common to the UAV's four rotors,
      ``ξ_ij = √ρ c_i + √(1 − ρ) e_ij`` (c_i, e_ij independent processes of the same law): an inflow disturbance
      (the room's recirculating downwash, gusts) larger than the 25 cm between a UAV's rotors moves its collective
      thrust, not its torques (0: independent rotors, as before);
    - ``motor_time_constant`` [s] > 0 replaces ``quadrotor.motor_time_constant`` (0: keep it);
    - ``battery_internal_resistance`` [Ω] > 0 replaces ``battery.internal_resistance`` (0: keep it).
    """

    enabled: bool = False
    thrust_slope_error: float = 0.0  #: ± relative [-] on a_f of (C.2), per UAV
    thrust_offset_error: float = 0.0  #: ± [N] on b_f of (C.2), per UAV
    rotor_thrust_spread: float = 0.0  #: ± relative [-] on each rotor's thrust gain
    thrust_noise: float = 0.0  #: σ relative [-] of the multiplicative per-rotor thrust noise
    thrust_noise_time_constant: float = 0.05  #: [s] of its Gauss-Markov process
    thrust_noise_common: float = 0.0  #: ρ in [0, 1]: share of the thrust-noise variance common to a UAV's rotors
    motor_time_constant: float = 0.0  #: [s] first-order motor lag (0: ``quadrotor.motor_time_constant``)
    battery_internal_resistance: float = 0.0  #: [Ω] (0: ``battery.internal_resistance``)


@dataclass
class AerodynamicsConfig:
    """Realism: ground effect and rotor drag (the fan jet is :class:`FanConfig`). Off in the ideal profile.

    - ground effect (Cheeseman & Bennett 1955): each UAV's thrust × ``1 / (1 − (R / 4z)²)``, R = ``rotor_radius``
      [m] (0: off), z the rotor plane's height above the ground (CoM height + ``rotor_height``), clamped to
      ``z ≥ ground_effect_min_ratio · R`` (the law diverges at z = R/4; 0.5 caps the gain at 4/3);
    - rotor drag (Mahony, Kumar & Corke 2012; Faessler, Franchi & Scaramuzza 2018): on each UAV
      ``f = −c · f_t · (I − z_b z_bᵀ)(v − w)`` [N], c = ``rotor_drag`` [s/m] (0: off), f_t its thrust, v its
      velocity, w the air velocity there, z_b its rotor axis (world). It replaces ``wind.uav_drag`` (isotropic,
      wind only): the hardware profile sets ``wind.uav_drag: 0``.
    """

    enabled: bool = False
    rotor_radius: float = 0.0  #: R [m] of the ground-effect law (0: no ground effect)
    rotor_height: float = 0.0  #: [m] rotor plane above the quadrotor's CoM
    ground_effect_min_ratio: float = 0.5  #: clamp z/R >= this [-]
    rotor_drag: float = 0.0  #: c [s/m]: in-plane drag per newton of thrust per m/s of airspeed (0: off)


@dataclass
class MotionCaptureConfig:
    """Realism: the motion capture the centralized modes fly on (``/fpr/motion_capture``, fpr_msgs/FprState, the
    topic a MOCAP bridge publishes on the real robot). Enabled: at ``rate``, each frame is dropped with
    ``dropout_probability`` (missed frames), else stamped at its capture instant and published ``latency`` later,
    with Gaussian noise on the platform and UAV positions (``position_noise`` per axis) and attitudes
    (``attitude_noise`` per axis, right-multiplied), the leg angles (``leg_angle_noise``), the linear velocities
    (``velocity_noise``) and the platform and leg rates (``rate_noise``). Disabled (ideal): an exact copy of
    ``/fpr/ground_truth``, published with it, undelayed. ``/fpr/ground_truth`` is always the exact truth."""

    enabled: bool = False
    rate: float = 100.0  #: [Hz] frames (simulation time)
    latency: float = 0.0  #: [s] capture instant (the stamp) to publication
    dropout_probability: float = 0.0  #: probability that a frame is missed
    position_noise: float = 0.0  #: [m] 1σ per axis
    attitude_noise: float = 0.0  #: [rad] 1σ per axis
    leg_angle_noise: float = 0.0  #: [rad] 1σ
    velocity_noise: float = 0.0  #: [m/s] 1σ per axis
    rate_noise: float = 0.0  #: [rad/s] 1σ per axis (platform angular rate, leg rates)


@dataclass
class LinkConfig:
    """Realism: the inter-UAV link (information vectors ζ_i) as a Wi-Fi link, applied by fpr_experiments'
    ``info_link`` node (model: :mod:`fpr_experiments.link`; values and sources: src/fpr_experiments/README.md).
    Ideal (``enabled: false``): the DDS topic as it is.

    Every ζ_i is delivered to each receiver j ≠ i independently (one channel per directed pair, seeded from the
    scenario seed), in simulation time:

    - latency ``latency_min`` + a lognormal jitter of mean ``latency_mean`` and standard deviation
      ``latency_std`` [s] (``latency_std`` 0: the jitter is exactly ``latency_mean``); order preserved per pair
      (FIFO: a ζ is never delivered before one its sender sent earlier to the same receiver);
    - loss: a Gilbert–Elliott two-state channel per pair, its state a continuous-time Markov chain (mean time
      ``burst_interval`` in the good state, ``burst_duration`` in a burst, both [s]); a ζ is lost with
      probability ``loss`` in the good state and ``burst_loss`` in a burst.
    """

    enabled: bool = False
    latency_min: float = 0.0  #: [s] fixed part (radio, MAC, DDS and both stacks at their fastest)
    latency_mean: float = 0.0  #: [s] mean of the lognormal jitter above ``latency_min``
    latency_std: float = 0.0  #: [s] standard deviation of the jitter
    loss: float = 0.0  #: [-] i.i.d. loss probability in the good state
    burst_interval: float = math.inf  #: [s] mean time in the good state between bursts (inf: no bursts)
    burst_duration: float = 0.0  #: [s] mean duration of a burst (the bad state)
    burst_loss: float = 1.0  #: [-] loss probability during a burst

    def __post_init__(self) -> None:
        for name in ("latency_min", "latency_mean", "latency_std", "burst_duration"):
            value = getattr(self, name)
            if not (value >= 0.0 and math.isfinite(value)):
                raise ValueError(f"link.{name}: must be finite and >= 0 [s], got {value}")
        for name in ("loss", "burst_loss"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"link.{name}: a probability in [0, 1], got {value}")
        if not self.burst_interval > 0.0:
            raise ValueError(f"link.burst_interval: must be > 0 [s] (inf: no bursts), got {self.burst_interval}")
        if self.latency_std > 0.0 and self.latency_mean <= 0.0:
            raise ValueError("link.latency_std > 0 needs latency_mean > 0 (a lognormal jitter has a positive mean)")
        if math.isfinite(self.burst_interval) and self.burst_duration <= 0.0:
            raise ValueError("link.burst_duration: must be > 0 [s] when bursts occur (finite burst_interval)")


@dataclass
class Scenario:
    """Everything that defines one run, beyond the node's parameters."""

    name: str = "default"
    seed: int = 0
    n: int = 3
    #: realism profile (:func:`realism_profiles`): ``ideal`` (the defaults below: unit-level tests) or ``hardware``
    #: (config/realism/hardware/*.yaml laid under the scenario's own values, which always win)
    realism: str = "ideal"
    initial_state: InitialState = field(default_factory=InitialState)
    plant: dict[str, Any] = field(default_factory=dict)  #: FprParameters overrides (fpr_model field names)
    quadrotor: QuadrotorConfig = field(default_factory=QuadrotorConfig)
    battery: BatteryConfig = field(default_factory=BatteryConfig)
    px4: Px4Config = field(default_factory=Px4Config)
    sensors: SensorConfig = field(default_factory=SensorConfig)
    cameras: CameraConfig = field(default_factory=CameraConfig)
    ground: GroundConfig = field(default_factory=GroundConfig)
    joint_stops: JointStopConfig = field(default_factory=JointStopConfig)
    board: BoardConfig = field(default_factory=BoardConfig)
    wind: WindConfig = field(default_factory=WindConfig)
    target: TargetConfig = field(default_factory=TargetConfig)
    payloads: list[PayloadEvent] = field(default_factory=list)
    external_wrenches: list[ExternalWrenchEvent] = field(default_factory=list)
    mismatch: ModelMismatchConfig = field(default_factory=ModelMismatchConfig)
    actuation: ActuationConfig = field(default_factory=ActuationConfig)
    aerodynamics: AerodynamicsConfig = field(default_factory=AerodynamicsConfig)
    motion_capture: MotionCaptureConfig = field(default_factory=MotionCaptureConfig)
    link: LinkConfig = field(default_factory=LinkConfig)

    def leg_angles(self) -> np.ndarray:
        """Initial leg angles as an (n,) array [rad]."""
        value = np.atleast_1d(np.asarray(self.initial_state.leg_angles, dtype=float))
        if value.size == 1:
            value = np.full(self.n, float(value[0]))
        if value.shape != (self.n,):
            raise ValueError(f"initial_state.leg_angles: expected 1 or n = {self.n} values, got {value.size}")
        return value


def per_uav(values: list, index: int) -> Any:
    """Entry ``index`` (0-based) of a per-UAV list whose last entry repeats for the UAVs beyond it."""
    if not values:
        raise ValueError("per-UAV list is empty")
    return values[min(index, len(values) - 1)]


def _convert(tp: Any, value: Any, path: str) -> Any:
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        return _dataclass_from_dict(tp, value, path)
    if origin is list:
        (item_type,) = typing.get_args(tp)
        if not isinstance(value, list):
            raise ValueError(f"{path}: expected a list, got {value!r}")
        return [_convert(item_type, item, f"{path}[{k}]") for k, item in enumerate(value)]
    if tp is type(None):
        if value is not None:
            raise ValueError(f"{path}: expected null, got {value!r}")
        return None
    if origin in (typing.Union, types.UnionType):
        errors = []
        for option in typing.get_args(tp):
            try:
                return _convert(option, value, path)
            except ValueError as error:
                errors.append(str(error))
        raise ValueError(f"{path}: {value!r} matches none of {typing.get_args(tp)}")
    if origin is dict or tp is dict:
        if not isinstance(value, dict):
            raise ValueError(f"{path}: expected a mapping, got {value!r}")
        return dict(value)
    if tp is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{path}: expected true/false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{path}: expected an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, str) and value.strip().lower() in ("inf", ".inf", "infinity"):
            return math.inf
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{path}: expected a number, got {value!r}")
        if math.isnan(float(value)):
            raise ValueError(f"{path}: NaN is not allowed")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ValueError(f"{path}: expected a string, got {value!r}")
        return value
    return value


def _dataclass_from_dict(cls: type, data: Any, path: str) -> Any:
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ValueError(f"{path or 'scenario'}: expected a mapping, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(data) - set(names))
    if unknown:
        raise ValueError(f"{path or 'scenario'}: unknown key(s) {unknown}; valid keys are {names}")
    kwargs = {name: _convert(hints[name], value, f"{path}.{name}" if path else name) for name, value in data.items()}
    return cls(**kwargs)


def realism_dir() -> str:
    """fpr_sim's realism profiles (``share/fpr_sim/config/realism`` once installed, else the source tree's)."""
    import os

    return os.path.join(os.path.dirname(bundled_scenarios_dir()), "realism")


def realism_profiles() -> list[str]:
    """The names of the realism profiles: ``ideal`` and one per directory of :func:`realism_dir`."""
    import os

    directory = realism_dir()
    found = sorted(d for d in os.listdir(directory) if os.path.isdir(os.path.join(directory, d))) \
        if os.path.isdir(directory) else []
    return ["ideal", *[d for d in found if d != "ideal"]]


def realism_overlay(profile: str) -> dict:
    """The scenario overlay of realism profile ``profile``: every ``*.yaml`` of ``config/realism/<profile>/``
    (one file per effect group), merged in file-name order (a later file wins). ``ideal`` is the empty overlay.
    An unknown name raises ValueError listing the profiles."""
    import os

    import yaml

    if profile == "ideal":
        return {}
    directory = os.path.join(realism_dir(), profile)
    if not os.path.isdir(directory):
        raise ValueError(f"realism: unknown profile {profile!r}; profiles: {', '.join(realism_profiles())}")
    overlay: dict = {}
    for name in sorted(os.listdir(directory)):
        if name.endswith((".yaml", ".yml")):
            with open(os.path.join(directory, name), encoding="utf-8") as stream:
                part = yaml.safe_load(stream) or {}
            if not isinstance(part, dict):
                raise ValueError(f"realism profile {profile!r}: {name} is not a mapping")
            overlay = deep_merge(overlay, part)
    return overlay


def deep_merge(base: dict, override: dict) -> dict:
    """``override`` laid over ``base``: mappings merge key by key, anything else (lists too) is replaced."""
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = value
    return out


def scenario_from_dict(data: dict | None, realism: str | None = None) -> Scenario:
    """Build and validate a :class:`Scenario` from a mapping (unknown keys refused, listing valid keys).

    Realism: the profile is ``realism`` if given (e.g. the simulator's ``realism`` parameter), else the mapping's
    own ``realism`` key, else ``ideal``; its overlay (:func:`realism_overlay`) is laid under the mapping, so a
    value the scenario states always wins over the profile's."""
    data = dict(data or {})
    profile = realism or data.get("realism") or "ideal"
    if not isinstance(profile, str):
        raise ValueError(f"realism: expected a profile name ({', '.join(realism_profiles())}), got {profile!r}")
    data = deep_merge(realism_overlay(profile), data)
    data["realism"] = profile
    scenario = _dataclass_from_dict(Scenario, data, "")
    if scenario.n < 3:
        raise ValueError(f"n: at least 3 legs are needed, got {scenario.n}")
    if scenario.initial_state.mode not in ("ground", "hover"):
        raise ValueError(f"initial_state.mode: expected 'ground' or 'hover', got {scenario.initial_state.mode!r}")
    angles = scenario.leg_angles()
    if not np.all((angles > 0.0) & (angles < math.pi / 2)):
        raise ValueError(f"initial_state.leg_angles: each must be inside (0, π/2) rad, got {angles.tolist()}")
    normal = np.asarray(scenario.board.normal, dtype=float)
    if normal.shape != (3,) or not np.isfinite(normal).all() or np.linalg.norm(normal) < 1e-9:
        raise ValueError(f"board.normal: expected a non-zero 3-vector, got {scenario.board.normal}")
    _validate_board(scenario.board, normal)
    _validate_fan(scenario.wind.fan)
    _validate_realism_physics(scenario)
    for k, payload in enumerate(scenario.payloads):
        _validate_payload(payload, f"payloads[{k}]")
    target = scenario.target
    if not (len(target.position) == 3 and np.isfinite(target.position).all() and math.isfinite(target.yaw)):
        raise ValueError(f"target: position needs 3 finite values and yaw a finite angle, got {target}")
    if not (target.rate > 0.0 and math.isfinite(target.rate)) or target.position_noise < 0.0 \
            or target.yaw_noise < 0.0:
        raise ValueError("target.rate must be finite and > 0, target.position_noise and yaw_noise >= 0")
    for name in ("full_voltage", "empty_voltage", "capacity"):
        if getattr(scenario.battery, name) <= 0.0:
            raise ValueError(f"battery.{name}: must be > 0")
    if scenario.quadrotor.landing_gear_radius <= 0.0 or scenario.quadrotor.landing_gear_height < 0.0:
        raise ValueError("quadrotor.landing_gear_radius must be > 0 and quadrotor.landing_gear_height >= 0")
    stops = scenario.joint_stops
    if not 0.0 <= stops.lower < stops.upper <= math.pi or stops.stiffness < 0.0 or stops.damping < 0.0:
        raise ValueError(f"joint_stops: need 0 <= lower < upper <= π [rad] and stiffness, damping >= 0, got {stops}")
    if scenario.px4.controller_rate <= 0.0 or scenario.cameras.rate <= 0.0:
        raise ValueError("px4.controller_rate and cameras.rate must be > 0")
    latency = scenario.px4.command_latency
    if not (math.isfinite(latency) and 0.0 <= latency < scenario.px4.offboard_loss_timeout):
        raise ValueError(f"px4.command_latency: must be finite, >= 0 and below px4.offboard_loss_timeout "
                         f"({scenario.px4.offboard_loss_timeout} s) [s], got {latency}")
    _validate_sensors(scenario.sensors, scenario.cameras, scenario.motion_capture)
    return scenario


def _validate_sensors(sensors: SensorConfig, cameras: CameraConfig, mocap: MotionCaptureConfig) -> None:
    """Noise levels, times and tolerances >= 0 and finite; probabilities in [0, 1]; mocap.rate > 0."""
    groups = (("sensors", sensors, [f.name for f in dataclasses.fields(SensorConfig)]),
              ("cameras", cameras, ["position_noise", "angle_noise", "pixel_noise", "blur_sigma", "latency",
                                    "exposure_time", "contrast_variation", "brightness_variation",
                                    "lighting_gradient", "occlusion_width", "occlusion_shade",
                                    "intrinsics_tolerance", "principal_point_tolerance", "mounting_angle_tolerance",
                                    "mounting_translation_tolerance"]),
              ("motion_capture", mocap, ["latency", "position_noise", "attitude_noise", "leg_angle_noise",
                                         "velocity_noise", "rate_noise"]))
    for group, config, names in groups:
        for name in names:
            value = getattr(config, name)
            if not (value >= 0.0 and math.isfinite(value)):
                raise ValueError(f"{group}.{name}: must be finite and >= 0, got {value}")
    for group, config, name in (("sensors", sensors, "tilt_from_accel_bias"),
                                ("cameras", cameras, "occlusion_probability"),
                                ("cameras", cameras, "detection_probability"),
                                ("motion_capture", mocap, "dropout_probability")):
        if not 0.0 <= getattr(config, name) <= 1.0:
            raise ValueError(f"{group}.{name}: must be within [0, 1], got {getattr(config, name)}")
    if sensors.imu_misalignment > MAX_IMU_MISALIGNMENT:
        raise ValueError(f"sensors.imu_misalignment: must be <= {MAX_IMU_MISALIGNMENT} rad (sigma; the attitude error "
                         f"model is first order in it), got {sensors.imu_misalignment}")
    if cameras.intrinsics_tolerance >= 0.5:
        raise ValueError(f"cameras.intrinsics_tolerance: must be < 0.5, got {cameras.intrinsics_tolerance}")
    if not (mocap.rate > 0.0 and math.isfinite(mocap.rate)):
        raise ValueError(f"motion_capture.rate: must be finite and > 0 [Hz], got {mocap.rate}")


def _vector3(value: list[float] | None, name: str, nonzero: bool = False) -> np.ndarray:
    vector = np.asarray(value, dtype=float)
    if vector.shape != (3,) or not np.isfinite(vector).all() or (nonzero and np.linalg.norm(vector) < 1e-9):
        raise ValueError(f"{name}: expected a {'non-zero ' if nonzero else ''}finite 3-vector, got {value}")
    return vector


def _validate_board(board: BoardConfig, normal: np.ndarray) -> None:
    if len(board.size) != 2 or not all(s > 0.0 for s in board.size):
        raise ValueError(f"board.size: expected two side lengths > 0 [m] (inf: unbounded), got {board.size}")
    edge = _vector3(board.edge, "board.edge", nonzero=True)
    unit = normal / np.linalg.norm(normal)
    if np.linalg.norm(edge - (edge @ unit) * unit) < 1e-6 * np.linalg.norm(edge):
        raise ValueError(f"board.edge {board.edge} is along board.normal: it must have a component in the plane")
    if not board.contact_depth > 0.0:  # inf allowed (the whole prism behind the rectangle)
        raise ValueError(f"board.contact_depth: must be > 0 [m] (inf: the whole prism), got {board.contact_depth}")


def _validate_fan(fan: FanConfig) -> None:
    _vector3(fan.direction, "wind.fan.direction", nonzero=True)
    if fan.position is not None:
        _vector3(fan.position, "wind.fan.position")
    if fan.reference_point is not None:
        _vector3(fan.reference_point, "wind.fan.reference_point")
    for name in ("diameter", "distance", "turbulence_time_constant", "decay_constant", "spreading_rate"):
        value = getattr(fan, name)
        if not (value > 0.0 and math.isfinite(value)):
            raise ValueError(f"wind.fan.{name}: must be finite and > 0, got {value}")
    for name in ("speed", "turbulence_intensity", "start_time", "ramp_time"):
        value = getattr(fan, name)
        if not (value >= 0.0 and math.isfinite(value)):
            raise ValueError(f"wind.fan.{name}: must be finite and >= 0, got {value}")
    if not fan.end_time > fan.start_time:
        raise ValueError(f"wind.fan.end_time ({fan.end_time} s) must be after start_time ({fan.start_time} s)")


def _validate_realism_physics(scenario: Scenario) -> None:
    """Every knob of ``mismatch``, ``actuation`` and ``aerodynamics`` is a finite value >= 0 (half-widths, σ,
    time constants, lengths); relative half-widths stay below 1 (a parameter cannot be drawn to 0 or below)."""
    for section in ("mismatch", "actuation", "aerodynamics"):
        config = getattr(scenario, section)
        for item in dataclasses.fields(config):
            value = getattr(config, item.name)
            if isinstance(value, bool):
                continue
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{section}.{item.name}: must be finite and >= 0, got {value}")
    relative = [("mismatch", name) for name in ("platform_inertia", "leg_inertia", "quadrotor_inertia")]
    relative += [("actuation", "thrust_slope_error"), ("actuation", "rotor_thrust_spread")]
    for section, name in relative:
        if getattr(getattr(scenario, section), name) >= 1.0:
            raise ValueError(f"{section}.{name}: a relative half-width must be < 1")
    if not 0.0 <= scenario.actuation.thrust_noise_common <= 1.0:
        raise ValueError("actuation.thrust_noise_common: must be in [0, 1]")
    if scenario.actuation.thrust_noise > 0.0 and scenario.actuation.thrust_noise_time_constant <= 0.0:
        raise ValueError("actuation.thrust_noise_time_constant: must be > 0 with thrust_noise > 0")


def _validate_payload(payload: PayloadEvent, name: str) -> None:
    if not (payload.mass >= 0.0 and math.isfinite(payload.mass)):
        raise ValueError(f"{name}.mass: must be finite and >= 0 [kg], got {payload.mass}")
    if not payload.hold_time >= 0.0:
        raise ValueError(f"{name}.hold_time: must be >= 0 [s] (0: held until release_time), got {payload.hold_time}")
    if payload.pickup_position is not None:
        _vector3(payload.pickup_position, f"{name}.pickup_position")
    if not (payload.pickup_radius > 0.0 and math.isfinite(payload.pickup_radius)):
        raise ValueError(f"{name}.pickup_radius: must be finite and > 0 [m], got {payload.pickup_radius}")


def bundled_scenarios_dir() -> str:
    """fpr_sim's own scenarios (``share/fpr_sim/config/scenarios`` once installed, else the source tree's)."""
    import os

    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

        installed = os.path.join(get_package_share_directory("fpr_sim"), "config", "scenarios")
        if os.path.isdir(installed):
            return installed
    except (ImportError, PackageNotFoundError, ValueError):
        pass
    return os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config", "scenarios")


def scenario_path(name: str) -> str:
    """The file of scenario ``name``: a path to a YAML file, or the name of a bundled scenario with or without
    ``.yaml`` (``hover``, ``ground_start.yaml``). An unknown name raises FileNotFoundError listing the bundled ones."""
    import os

    if os.path.isfile(name):
        return name
    directory = bundled_scenarios_dir()
    base = os.path.basename(name)
    candidate = os.path.join(directory, base if base.endswith((".yaml", ".yml")) else base + ".yaml")
    if os.sep not in name and os.path.isfile(candidate):
        return candidate
    names = sorted(f[:-5] for f in os.listdir(directory) if f.endswith(".yaml")) if os.path.isdir(directory) else []
    raise FileNotFoundError(f"scenario {name!r}: no such file, nor a bundled scenario; bundled: {', '.join(names)}")


def load_scenario(path: str | None, realism: str | None = None) -> Scenario:
    """Load a scenario YAML file (a path or a bundled scenario's name, :func:`scenario_path`); ``None`` or an empty
    path gives the default scenario. ``realism`` (a profile name) overrides the file's ``realism`` key."""
    if not path:
        return scenario_from_dict({}, realism=realism)
    import yaml

    with open(scenario_path(path), encoding="utf-8") as stream:
        data = yaml.safe_load(stream)
    return scenario_from_dict(data or {}, realism=realism)
