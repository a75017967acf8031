"""controller node (one per UAV, namespace /fpr/uav<i>): LocalState + ζ_j + teleop -> setpoint, ζ_i, wrench,
controller_status (fpr_msgs/ControllerStatus) at 50 Hz (DESIGN.md §3-§4; DESIGN.md calls that topic
``diagnostics``: renamed so that the name means the standard message), and its REP-107 health on ``/diagnostics``
(diagnostic_msgs/DiagnosticArray) once a second. The computation is :class:`fpr_control.controller.Controller`.

    ros2 run fpr_control controller --ros-args -r __ns:=/fpr/uav1 -p uav_id:=1 -p mode:=communicating \
        --params-file install/fpr_control/share/fpr_control/config/controller.yaml
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from fpr_model.diagnostics import OK, WARN, StatusReport, to_diagnostic_array
from fpr_model.node_parameters import NodeParameters, Param, node_seconds, throttle
from fpr_model.parameters import default_parameters, load_parameters
from fpr_model.rotations import quat_to_euler_zyx
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Imu

from fpr_control.command_limits import CommandLimits, bound_command
from fpr_control.contact_guard import LOST, STATE_NAMES, ContactGuardConfig
from fpr_control.controller import (
    DEFAULT_GAINS,
    IMPEDANCE_FORCE_INPUTS,
    MODE_CODES,
    MODES,
    STATE_SOURCES,
    Controller,
    ControllerConfig,
    GroundTruth,
    gains_from_dict,
)
from fpr_control.information import InfoPlausibility, LocalEstimate, PeerInfo
from fpr_control.node_utils import LOG_THROTTLE_S, spin_node
from fpr_control.observers import OBSERVER_KINDS
from fpr_control.reference import TeleopReference
from fpr_control.rejoin import RejoinConfig
from fpr_msgs.msg import (
    AttitudeThrustSetpoint,
    ControllerStatus,
    FprState,
    InformationVector,
    LocalState,
    TeleopCommand,
    UavStatus,
    WrenchEstimate,
)


def _quat_wxyz(q) -> np.ndarray:
    return np.array([q.w, q.x, q.y, q.z], dtype=float)


def _vec(v) -> np.ndarray:
    return np.array([v.x, v.y, v.z], dtype=float)


class ControllerNode(Node):
    def __init__(self, **node_kwargs) -> None:
        super().__init__("controller", **node_kwargs)
        table = NodeParameters(self)
        self.parameters = table

        def d(name: str, default, text: str, **kw):
            return table.declare(name, Param(default, text, **kw))

        def dyn(name: str, default, text: str, apply, check=None, **kw):
            return table.declare(name, Param(default, text, dynamic=True, **kw), apply=apply, check=check)

        uav_id = d("uav_id", 1, "this UAV's id i (1-based)", low=1, high=64)
        n = d("n", 3, "number of UAVs / legs", low=3, high=64)
        mode = d("mode", "communicating", "control law", choices=MODES)
        observer = d("observer", "fowo", "wrench observer", choices=OBSERVER_KINDS)
        state_source = d("state_source", "local", (
            "local (LocalState + peers' zeta) or ground_truth (motion capture on motion_capture_topic, F0; implied by "
            "centralized)"), choices=STATE_SOURCES)
        motion_capture_topic = d("motion_capture_topic", "/fpr/motion_capture", (
            "fpr_msgs/FprState the ground-truth modes fly on: the simulator's (or a MOCAP bridge's) motion capture; "
            "/fpr/ground_truth is the simulator's exact truth"))
        self.motion_capture_timeout = d("motion_capture_timeout", 0.25, (
            "[s] ground-truth modes: motion capture older than this is stale -> hold, and ControllerStatus."
            "local_state_valid false (the swarm guard's emergency); the simulator's runs at 100 Hz"),
            low=0.01, high=10.0)
        rate = d("rate", 50.0, "control rate [Hz]", low=1.0, high=1000.0)
        info_timeout = dyn("info_timeout", 0.2, "[s] a peer's zeta older than this -> fallback to NC",
                           lambda v: self.controller.reconfigure(info_timeout=v), low=0.001, high=10.0)
        max_thrust = dyn("max_thrust", 25.0, "f_max [N]: thrust saturation of the setpoint",
                         lambda v: self.controller.reconfigure(max_thrust=v), low=0.1, high=100.0)
        max_tilt_deg = dyn("max_tilt_deg", 35.0, "[deg] tilt limit of the thrust direction",
                           lambda v: self.controller.reconfigure(max_tilt=math.radians(v)), low=1.0, high=89.0)
        force_input = d("impedance_force_input", "interaction", (
            "decentralized impedance: estimated platform force entering (4.34) as epsilon_tau: 'interaction' (along "
            "the desired contact force only; a load is compensated) or 'full' (the printed law: a load drifts the "
            "robot at f_e / B^d)"), choices=IMPEDANCE_FORCE_INPUTS)

        def set_attribute(attribute: str):
            return lambda v: setattr(self, attribute, float(v))

        self.local_timeout = dyn("local_state_timeout", 0.2, "[s] LocalState older -> invalid",
                                 set_attribute("local_timeout"), low=0.001, high=10.0)
        self.imu_timeout = dyn("imu_timeout", 0.5, "[s] IMU older -> yaw from LocalState.uav_yaw",
                               set_attribute("imu_timeout"), low=0.001, high=10.0)
        self.teleop_timeout = dyn("teleop_timeout", 1.0, "[s] no TeleopCommand for this long -> zero velocities, "
                                  "hold the rest", set_attribute("teleop_timeout"), low=0.01, high=60.0)
        self.bridge_status_timeout = dyn(
            "bridge_status_timeout", 0.5, "[s] the own px4_bridge's status older than this (after one arrived): the "
            "setpoints are taken as not flown (bumpless rejoin)", set_attribute("bridge_status_timeout"),
            low=0.01, high=10.0)
        rejoin_leg_rate = d("rejoin_leg_rate_deg", 8.0, (
            "[deg/s] after the setpoints were not flown (emergency Hold, a bridge restart), the leg-angle reference "
            "moves from the measured legs to the command at this rate (fpr_control.rejoin)"), low=0.1, high=360.0)
        rejoin_attitude_rate = d("rejoin_attitude_rate_deg", 5.0, (
            "[deg/s] same for the platform roll and pitch reference"), low=0.1, high=360.0)
        # contact guard (fpr_control.contact_guard): a force demand that finds no contact fades out
        guard_defaults = ContactGuardConfig()
        contact_guard = ContactGuardConfig(
            enabled=bool(d("contact_guard.enabled", guard_defaults.enabled, (
                "fade a contact-force demand (impedance) that finds no contact, instead of flying the robot along "
                "the platform normal at f^d_c / B^d"))),
            engage_force=float(d("contact_guard.engage_force", guard_defaults.engage_force, (
                "[N] demands above are guarded; releasing the trigger below this re-arms the guard"),
                low=0.0, high=100.0)),
            min_fraction=float(d("contact_guard.min_fraction", guard_defaults.min_fraction, (
                "contact met while the estimated contact force is at least this x the demand"),
                low=0.01, high=1.0)),
            max_free_travel=float(d("contact_guard.max_free_travel", guard_defaults.max_free_travel, (
                "[m] platform travel along its normal without contact before the contact is declared lost"),
                low=0.01, high=10.0)),
            max_unmet_time=float(d("contact_guard.max_unmet_time", guard_defaults.max_unmet_time, (
                "[s] time without contact before the contact is declared lost"), low=0.02, high=60.0)),
            fade_rate=float(d("contact_guard.fade_rate", guard_defaults.fade_rate, (
                "[N/s] ramp of the applied demand to 0 once the contact is lost"), low=0.1, high=1000.0)))
        model_file = d("model_file", "", "FprParameters YAML (empty: thesis Table B.1 defaults)")
        info_input_topic = d("info_input_topic", "/fpr/info", (
            "topic the peers' zeta_j are read from (the own zeta_i is always published on /fpr/info); set it to "
            "a relay's output to inject communication faults (fpr_experiments info_link)"))
        # bounded inputs (issue 12): the controller's own limits on /fpr/teleop (fpr_control.command_limits); dynamic:
        # a set is validated as a whole CommandLimits (e.g. leg_angle_min < leg_angle_max) before it applies
        lim = CommandLimits()

        def limit(name: str, field_name: str, default: float, text: str, to_si=float, **kw) -> float:
            def candidate(v) -> CommandLimits:
                return replace(self.command_limits, **{field_name: to_si(v)})

            def check(v) -> str | None:
                try:
                    candidate(v)
                except ValueError as error:
                    return f"{name} = {v}: {error}"
                return None

            def apply(v) -> None:
                self.command_limits = candidate(v)

            return to_si(dyn(name, default, text, apply, check, **kw))

        self.command_limits = CommandLimits(
            leg_angle_min=limit("command_leg_angle_min_deg", "leg_angle_min", math.degrees(lim.leg_angle_min),
                                "[deg] commanded leg angles below are clamped to it (default: the teleop's 15 deg)",
                                math.radians, high=180.0),
            leg_angle_max=limit("command_leg_angle_max_deg", "leg_angle_max", math.degrees(lim.leg_angle_max),
                                "[deg] commanded leg angles above are clamped to it (default: the teleop's 80 deg)",
                                math.radians, high=180.0),
            leg_stop_min=limit("command_leg_stop_min_deg", "leg_stop_min", math.degrees(lim.leg_stop_min),
                               "[deg] joint stop: a command with a leg angle below is refused, in [0, leg_angle_min]",
                               math.radians, high=180.0),
            leg_stop_max=limit("command_leg_stop_max_deg", "leg_stop_max", math.degrees(lim.leg_stop_max),
                               "[deg] joint stop: a command with a leg angle above is refused, in "
                               "[leg_angle_max, 180]", math.radians, high=180.0),
            max_tilt=limit("command_max_tilt_deg", "max_tilt", math.degrees(lim.max_tilt),
                           "[deg] |roll|, |pitch| limit of the command; default 30 (teleop_tilt30)", math.radians,
                           low=0.1, high=89.0),
            max_speed=limit("command_max_speed", "max_speed", lim.max_speed,
                            "[m/s] |platform velocity| limit (F_Fp)", low=0.01, high=20.0),
            max_yaw_rate=limit("command_max_yaw_rate", "max_yaw_rate", lim.max_yaw_rate, "[rad/s] |yaw rate| limit",
                               low=0.01, high=10.0),
            max_tilt_rate=limit("command_max_tilt_rate", "max_tilt_rate", lim.max_tilt_rate,
                                "[rad/s] |roll rate|, |pitch rate| limit", low=0.01, high=10.0),
            max_leg_rate=limit("command_max_leg_rate", "max_leg_rate", lim.max_leg_rate, "[rad/s] |leg rate| limit",
                               low=0.01, high=10.0),
            max_acceleration=limit("command_max_acceleration", "max_acceleration", lim.max_acceleration,
                                   "[m/s^2] |platform acceleration| limit (F_Fp)", low=0.01, high=50.0),
            max_yaw_acceleration=limit("command_max_yaw_acceleration", "max_yaw_acceleration",
                                       lim.max_yaw_acceleration, "[rad/s^2] |yaw acceleration| limit",
                                       low=0.01, high=50.0),
            max_contact_force=limit("command_max_contact_force", "max_contact_force", lim.max_contact_force,
                                    "[N] contact force limit: [0, this] passes, [-this, refuse_ratio x this] is "
                                    "clamped", low=0.01, high=200.0),
            refuse_ratio=limit("command_refuse_ratio", "refuse_ratio", lim.refuse_ratio,
                               "a value beyond this x its symmetric limit refuses the whole command (the last valid "
                               "one is kept); between the limit and this x the limit it is clamped", low=1.0,
                               high=10.0))
        self._teleop_refused = 0  #: consecutive refused TeleopCommands (announced on return)
        # zeta_j plausibility and one publisher per uav_id (issue 12; fpr_control.information)
        ip = InfoPlausibility()

        def info_bound(name: str, default: float, text: str, **kw) -> float:
            return float(d(name, float(default), text, **kw))

        plausibility = InfoPlausibility(
            leg_angle_min=math.radians(info_bound("info_leg_angle_min_deg", math.degrees(ip.leg_angle_min),
                                                  "[deg] a zeta_j with a leg angle below is refused (joint stop "
                                                  "10 deg - 3 deg)", high=180.0)),
            leg_angle_max=math.radians(info_bound("info_leg_angle_max_deg", math.degrees(ip.leg_angle_max),
                                                  "[deg] a zeta_j with a leg angle above is refused (the model's "
                                                  "domain (0, 90])", high=180.0)),
            max_speed=info_bound("info_max_speed", ip.max_speed, "[m/s] a zeta_j with |Fp v_j| above is refused"),
            max_thrust=info_bound("info_max_thrust", ip.max_thrust, "[N] a zeta_j with a thrust above is refused"),
            max_leg_rate=info_bound("info_max_leg_rate", ip.max_leg_rate, "[rad/s] refuse a zeta_j whose leg angle "
                                    "jumps more than this x dt + 5 deg from the last accepted one"),
            max_angular_rate=info_bound("info_max_angular_rate", ip.max_angular_rate, "[rad/s] refuse a zeta_j "
                                        "whose attitude turns more than this x dt + 10 deg from the last accepted"),
            max_acceleration=info_bound("info_max_acceleration", ip.max_acceleration, "[m/s^2] refuse a zeta_j "
                                        "whose velocity jumps more than this x dt + 1 m/s from the last accepted"),
            publisher_timeout=info_bound("info_publisher_timeout", ip.publisher_timeout, "[s] a uav_id's "
                                         "established zeta publisher silent this long may be replaced", low=0.001))
        own_writer_direct = info_input_topic == "/fpr/info"
        # gains: one parameter per leaf of DEFAULT_GAINS; the motion laws' gains are dynamic (validated by building
        # the whole ControllerGains first), the observer's are read-only (its state was built with them)
        self._gains_values: dict[str, dict] = {}

        def gain_parameter(group: str, name: str, default):
            leaf = f"gains.{group}.{name}"
            if group == "observer":
                return d(leaf, default, f"{group} gain {name}")

            def candidate(v):
                values = {g: dict(leaves) for g, leaves in self._gains_values.items()}
                values[group][name] = list(v) if isinstance(v, (list, tuple)) else v
                return values, gains_from_dict(values, self.n)

            def check(v) -> str | None:
                try:
                    candidate(v)
                except (ValueError, TypeError) as error:
                    return f"{leaf} = {v}: {error}"
                return None

            def apply(v) -> None:
                self._gains_values, gains = candidate(v)
                self.controller.reconfigure(gains=gains)

            if name == "integral_zone":  # .inf: no zone, the thesis's saturation-only rule (README "PID anti-windup")
                return dyn(leaf, default, f"{group} {name} [m, rad, rad]: integrate an error only while |error| <= "
                           "this; .inf: always", apply, check, high=math.inf)
            return dyn(leaf, default, f"{group} gain {name}", apply, check)

        for group, values in DEFAULT_GAINS.items():
            self._gains_values[group] = {}
            for name, default in values.items():
                value = gain_parameter(group, name, default)
                self._gains_values[group][name] = list(value) if isinstance(value, (list, tuple)) else value
        gains = self._gains_values

        params = load_parameters(model_file) if model_file else default_parameters(int(n))
        if params.n != n:
            raise ValueError(f"model_file has n = {params.n}, parameter n = {n}")
        self.config = ControllerConfig(
            uav_id=int(uav_id), mode=mode, gains=gains_from_dict(gains, int(n)), observer=observer,
            state_source=state_source, period=1.0 / rate, info_timeout=info_timeout, max_thrust=max_thrust,
            max_tilt=math.radians(max_tilt_deg), impedance_force_input=force_input, info_plausibility=plausibility,
            own_writer_direct=own_writer_direct,
            rejoin=RejoinConfig(math.radians(rejoin_leg_rate), math.radians(rejoin_attitude_rate)),
            contact_guard=contact_guard)
        self.controller = Controller(params, self.config)
        self.n = int(n)

        best_effort = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.create_subscription(LocalState, "local_state", self._on_local, best_effort)
        self.create_subscription(InformationVector, info_input_topic, self._on_info, QoSProfile(
            depth=20, reliability=ReliabilityPolicy.BEST_EFFORT))
        self.create_subscription(TeleopCommand, "/fpr/teleop", self._on_teleop, best_effort)
        self.create_subscription(Imu, "imu", self._on_imu, qos_profile_sensor_data)
        self.create_subscription(UavStatus, "status", self._on_bridge_status, best_effort)
        if self.controller.uses_ground_truth:
            self.create_subscription(FprState, motion_capture_topic, self._on_ground_truth, best_effort)
        # publishers reliable (REP-2003: any subscriber can connect); the graph's own subscribers are best effort,
        # so a lost zeta or setpoint is never retransmitted late: the next one replaces it
        self.setpoint_pub = self.create_publisher(AttitudeThrustSetpoint, "setpoint", 5)
        self.info_pub = self.create_publisher(InformationVector, "/fpr/info", 5)
        self.wrench_pub = self.create_publisher(WrenchEstimate, "wrench", 5)
        self.status_pub = self.create_publisher(ControllerStatus, "controller_status", 10)
        #: REP-107 health once a second on /diagnostics (fpr_model.diagnostics), read by rqt_runtime_monitor/Foxglove
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._next_diagnostics = -math.inf

        self._local: LocalEstimate | None = None
        self._local_time = -math.inf
        self._had_local = False  #: a valid LocalState arrived once: its absence is then a warning, not start-up
        self._teleop: TeleopReference | None = None
        self._teleop_time = -math.inf
        self._imu_yaw: float | None = None
        self._imu_time = -math.inf
        self._ground_truth: GroundTruth | None = None
        self._ground_truth_time = -math.inf
        self._bridge_state: int | None = None  #: the own px4_bridge's UavStatus.state (None: never heard)
        self._bridge_status_time = -math.inf
        self._flown_said: bool | None = None
        self._state_valid = False  #: the state this controller flies on is valid (set every tick)
        self.create_timer(self.config.period, self._on_tick)
        self.get_logger().info(
            f"controller uav {uav_id}/{n}: mode {mode}, observer {observer}, state {state_source}, "
            f"{rate:.0f} Hz, info_timeout {info_timeout} s, f_max {max_thrust} N, tilt {max_tilt_deg} deg"
            + (f", impedance force input {force_input}" if mode == "impedance" else ""))

    def _now(self) -> float:
        return node_seconds(self)

    # ---- callbacks: message -> core dataclasses -----------------------------------------------------
    def _on_local(self, msg: LocalState) -> None:
        if msg.uav_id not in (0, self.config.uav_id):
            self.get_logger().warning(f"LocalState from uav {msg.uav_id} ignored (I am {self.config.uav_id})",
                                      **throttle(self, LOG_THROTTLE_S))
            return
        local = LocalEstimate(
            leg_angle=msg.leg_angle, platform_roll=msg.platform_roll, platform_pitch=msg.platform_pitch,
            attitude=_quat_wxyz(msg.uav_attitude_flat), velocity=_vec(msg.uav_velocity_flat),
            relative_yaw=msg.relative_yaw, uav_yaw=msg.uav_yaw, valid=bool(msg.valid))
        if not local.is_finite():
            self.get_logger().warning("LocalState contains NaN/inf or a zero quaternion: ignored",
                                      **throttle(self, LOG_THROTTLE_S))
            return
        self._local, self._local_time = local, self._now()

    def _on_info(self, msg: InformationVector, msg_info: dict) -> None:
        """``msg_info``: rclpy's MessageInfo (a dict; Jazzy has no publisher GID, the publication sequence number
        tells the publishers apart, fpr_control.information). Invalid vectors (the sender's estimate is stale)
        count as missing, silently."""
        sequence = msg_info.get("publication_sequence_number") if msg_info else None
        info = PeerInfo(int(msg.uav_id), msg.leg_angle, _vec(msg.velocity), _quat_wxyz(msg.attitude), msg.thrust)
        reason = self.controller.receive_info(info, self._now(), int(sequence) if sequence else None,
                                              bool(msg.valid))
        table = self.controller.information
        for line in table.take_announcements():  # once per intruder stream / takeover
            self.get_logger().warning(f"/fpr/info: {line}")
        for line in table.take_returns():
            self.get_logger().info(f"/fpr/info: {line}", **throttle(self, LOG_THROTTLE_S))
        if reason is not None:
            self.get_logger().warning(f"/fpr/info rejected: {reason}", **throttle(self, LOG_THROTTLE_S))

    def _on_teleop(self, msg: TeleopCommand) -> None:
        if len(msg.leg_angles) != self.n or len(msg.leg_rates) != self.n:
            self.get_logger().warning(f"TeleopCommand with {len(msg.leg_angles)} leg angles (n = {self.n}): ignored",
                                      **throttle(self, LOG_THROTTLE_S))
            return
        command = TeleopReference(
            _vec(msg.platform_velocity), _vec(msg.platform_acceleration), msg.yaw_rate, msg.yaw_acceleration,
            msg.roll, msg.roll_rate, msg.pitch, msg.pitch_rate, np.array(msg.leg_angles, dtype=float),
            np.array(msg.leg_rates, dtype=float), msg.contact_force, int(msg.mode))
        if not command.is_finite():
            self.get_logger().warning("TeleopCommand contains NaN/inf: ignored (holding the last one)",
                                      **throttle(self, LOG_THROTTLE_S))
            return
        bounded = bound_command(command, self.command_limits)
        if bounded.command is None:
            self._teleop_refused += 1
            self.get_logger().warning(f"TeleopCommand refused: {bounded.refused}: holding the last valid command "
                                      f"({self._teleop_refused} refused in a row)",
                                      **throttle(self, LOG_THROTTLE_S))
            return
        if self._teleop_refused:
            self.get_logger().info(f"TeleopCommand accepted again after {self._teleop_refused} refused")
            self._teleop_refused = 0
        if bounded.clamped:
            self.get_logger().warning("TeleopCommand clamped to the controller's limits: " + ", ".join(bounded.clamped),
                                      **throttle(self, LOG_THROTTLE_S))
        self._teleop, self._teleop_time = bounded.command, self._now()

    def _on_imu(self, msg: Imu) -> None:
        quat = _quat_wxyz(msg.orientation)
        norm = float(np.linalg.norm(quat))
        if not np.all(np.isfinite(quat)) or not 0.5 < norm < 1.5:
            self.get_logger().warning("Imu orientation is not a finite unit quaternion: ignored",
                                      **throttle(self, LOG_THROTTLE_S))
            return
        self._imu_yaw, self._imu_time = quat_to_euler_zyx(quat / norm)[2], self._now()

    def _on_ground_truth(self, msg: FprState) -> None:
        n = self.n
        if len(msg.leg_angles) != n or len(msg.leg_rates) != n or len(msg.uav_poses) != n:
            self.get_logger().warning("FprState arrays do not have n entries: ignored",
                                      **throttle(self, LOG_THROTTLE_S))
            return
        gt = GroundTruth(
            _vec(msg.platform_pose.position), _quat_wxyz(msg.platform_pose.orientation),
            _vec(msg.platform_twist.linear), _vec(msg.platform_twist.angular),
            np.array(msg.leg_angles, dtype=float), np.array(msg.leg_rates, dtype=float),
            np.array([_quat_wxyz(p.orientation) for p in msg.uav_poses]))
        if not gt.is_finite():
            self.get_logger().warning("FprState contains NaN/inf: ignored", **throttle(self, LOG_THROTTLE_S))
            return
        self._ground_truth, self._ground_truth_time = gt, self._now()

    # ---- control tick ----------------------------------------------------------------------------------
    def _say_fallback(self, active: bool, ages, stamp) -> None:
        """One line when the controller falls back to NC (4.32), one when it returns (issue 12: never silent)."""
        previous = getattr(self, "_fallback_since", None)
        now = stamp.sec + 1e-9 * stamp.nanosec
        timeout = self.config.info_timeout
        if active and previous is None:
            self._fallback_since = now
            stale = [f"zeta_{j + 1} {f'{a:.2f} s old' if math.isfinite(a) else 'never received'}"
                     for j, a in enumerate(ages) if not a <= timeout]
            if stale and all(not math.isfinite(a) for a in ages if not a <= timeout):  # start-up: none yet, normal
                self.get_logger().info(f"mode {self.config.mode}: NC (4.32) until the peers' zeta arrive")
                return
            self.get_logger().warning(
                f"mode {self.config.mode}: falling back to NC (4.32): {', '.join(stale) or 'own echo missing'} "
                f"(info_timeout {timeout:g} s)", **throttle(self, 1.0))
        elif not active and previous is not None:
            self._fallback_since = None
            self.get_logger().info(f"mode {self.config.mode}: every zeta fresh, mode {self.config.mode} active (NC "
                                   f"for {now - previous:.2f} s)", **throttle(self, 1.0))

    def _on_bridge_status(self, msg: UavStatus) -> None:
        if msg.uav_id == self.config.uav_id:
            self._bridge_state, self._bridge_status_time = int(msg.state), self._now()

    def _flown(self, now: float) -> bool:
        """PX4 flies this controller's setpoints: the own bridge reports OFFBOARD (True while no bridge status
        ever came: a graph without bridges); a status older than bridge_status_timeout is a dead bridge. The
        change is said once each way (fpr_control.rejoin)."""
        if self._bridge_state is None:
            return True
        fresh = now - self._bridge_status_time <= self.bridge_status_timeout
        flown = fresh and self._bridge_state == UavStatus.STATE_OFFBOARD
        if self.controller.rejoin.was_flown and flown != self._flown_said:
            if not flown:
                why = (f"bridge state {self._bridge_state}" if fresh else
                       f"no bridge status for {now - self._bridge_status_time:.2f} s")
                self.get_logger().info(f"setpoints not flown ({why}): the reference follows the measured "
                                       "configuration, no integration (bumpless rejoin)")
            elif self._flown_said is not None:
                cfg = self.config.rejoin
                self.get_logger().info(
                    f"setpoints flown again: rejoining the command at <= {math.degrees(cfg.leg_rate):g} deg/s (legs) "
                    f"and {math.degrees(cfg.attitude_rate):g} deg/s (roll, pitch)")
            self._flown_said = flown
        elif not self.controller.rejoin.was_flown and flown:
            self._flown_said = True
        return flown

    def _fresh_ground_truth(self, now: float) -> tuple[GroundTruth | None, str]:
        """The motion capture if it is at most ``motion_capture_timeout`` old (ground-truth modes), else None and why:
        the controller then holds ("no valid ground truth"), and the tick logs that with the reason in one line;
        (None, "") in the local modes."""
        if not self.controller.uses_ground_truth:
            return None, ""
        if self._ground_truth is None:
            return None, "no FprState (motion capture) received yet"
        if now - self._ground_truth_time > self.motion_capture_timeout:
            return None, (f"motion capture stale, the last FprState is {now - self._ground_truth_time:.2f} s old "
                          f"(motion_capture_timeout {self.motion_capture_timeout} s): holding, state reported invalid")
        return self._ground_truth, ""

    def _on_tick(self) -> None:
        now = self._now()
        local = self._local if now - self._local_time <= self.local_timeout else None
        if local is not None and local.valid:
            self._had_local = True
        if local is None and not self.controller.uses_ground_truth:
            if self._had_local:
                self.get_logger().warning(
                    f"no fresh LocalState for {self.local_timeout} s: holding (check this UAV's pose_estimator and "
                    f"camera: ros2 topic hz local_state)", **throttle(self, LOG_THROTTLE_S))
            else:  # the estimator waits for its first consistent detections: the normal start-up (issue 14)
                self.get_logger().info("waiting for the first LocalState (start-up): holding",
                                       **throttle(self, LOG_THROTTLE_S))
        command = self._teleop
        if command is not None and now - self._teleop_time > self.teleop_timeout:
            command = command.stopped()
            self.get_logger().warning("no TeleopCommand: zero velocities, holding the configuration",
                                      **throttle(self, LOG_THROTTLE_S))
        imu_yaw = self._imu_yaw if now - self._imu_time <= self.imu_timeout else None
        ground_truth, ground_truth_missing = self._fresh_ground_truth(now)
        out = self.controller.step(now, local, command, ground_truth, imu_yaw, flown=self._flown(now))
        # the state this controller flies on: its LocalState, or in the ground-truth modes the motion capture (an
        # unused onboard estimator going blind must not land a centralized flight; a dead motion capture must)
        self._state_valid = (ground_truth is not None) if self.controller.uses_ground_truth else \
            bool(out.local_state_valid)
        if out.contact_guard_event and out.contact_guard_state == LOST:  # one call site per severity (rclpy)
            self.get_logger().warning(out.contact_guard_event)
        elif out.contact_guard_event:
            self.get_logger().info(out.contact_guard_event)
        if out.warning and not self._had_local and not self.controller.uses_ground_truth:
            self.get_logger().info(out.warning + " (start-up)", **throttle(self, LOG_THROTTLE_S))
        elif out.warning:
            reason = f": {ground_truth_missing}" if ground_truth_missing else ""
            self.get_logger().warning(out.warning + reason, **throttle(self, LOG_THROTTLE_S))
        stamp = self.get_clock().now().to_msg()
        uav_id = self.config.uav_id

        sp = AttitudeThrustSetpoint()
        sp.header.stamp, sp.header.frame_id, sp.uav_id = stamp, f"uav{uav_id}/local_enu", uav_id
        w, x, y, z = (float(v) for v in out.attitude)
        sp.attitude.w, sp.attitude.x, sp.attitude.y, sp.attitude.z = w, x, y, z
        sp.thrust = float(out.thrust)
        self.setpoint_pub.publish(sp)

        if out.info is not None:
            info = InformationVector()
            info.header.stamp, info.header.frame_id, info.uav_id = stamp, "flat_platform", uav_id
            info.leg_angle = float(out.info.leg_angle)
            info.velocity.x, info.velocity.y, info.velocity.z = (float(v) for v in out.info.velocity)
            aw, ax, ay, az = (float(v) for v in out.info.attitude)
            info.attitude.w, info.attitude.x, info.attitude.y, info.attitude.z = aw, ax, ay, az
            info.thrust = float(out.info.thrust)
            info.valid = self._state_valid
            self.info_pub.publish(info)
            self.controller.information.note_own_publication()  # the own writer's sequence number (own echo)

        wr = WrenchEstimate()
        wr.header.stamp, wr.header.frame_id = stamp, "world" if self.controller.uses_ground_truth else "flat_platform"
        wr.uav_id, wr.observer = uav_id, self.config.observer
        wr.platform_force.x, wr.platform_force.y, wr.platform_force.z = (float(v) for v in out.wrench[:3])
        wr.platform_moment.x, wr.platform_moment.y, wr.platform_moment.z = (float(v) for v in out.wrench[3:6])
        wr.leg_moments = [float(v) for v in out.wrench[6:]]
        wr.contact_force = float(out.contact_force)
        self.wrench_pub.publish(wr)

        st = ControllerStatus()
        st.header.stamp, st.header.frame_id, st.uav_id = stamp, wr.header.frame_id, uav_id
        st.configured_mode, st.active_mode = MODE_CODES[self.config.mode], MODE_CODES[out.active_mode]
        st.fallback_active = bool(out.fallback_active)
        st.info_ages = [float(a) for a in out.info_ages]  # inf: never received
        self._say_fallback(bool(out.fallback_active), out.info_ages, stamp)
        st.thrust_saturated, st.tilt_saturated = bool(out.thrust_saturated), bool(out.tilt_saturated)
        st.local_state_valid = self._state_valid  # ground-truth modes: the motion capture is fresh
        st.loop_time = float(out.loop_time)
        st.platform_tilt = float(out.platform_tilt)  # the bridge's swarm guard: flight envelope
        desired = out.desired
        if desired is None:  # no successful control step yet
            nan = math.nan
            st.desired_position.x = st.desired_position.y = st.desired_position.z = nan
            st.desired_roll = st.desired_pitch = st.desired_yaw = st.desired_contact_force = nan
            st.desired_leg_angles = [nan] * self.n
        else:
            st.desired_position.x, st.desired_position.y, st.desired_position.z = (
                float(v) for v in desired.position)
            st.desired_roll, st.desired_pitch, st.desired_yaw = (
                float(desired.roll), float(desired.pitch), float(desired.yaw))
            st.desired_leg_angles = [float(v) for v in desired.leg_angles]
            st.desired_contact_force = float(desired.contact_force)
        st.applied_contact_force = float(out.applied_contact_force)
        st.contact_guard = int(out.contact_guard_state)
        self.status_pub.publish(st)
        self._publish_diagnostics(out, stamp)

    def _publish_diagnostics(self, out, stamp) -> None:
        """Once a second (node clock): OK while the configured law runs on fresh inputs; WARN in the NC fallback,
        while holding without a valid local state, or with a saturated command."""
        now = self._now()
        if now < self._next_diagnostics:
            return
        self._next_diagnostics = now + 1.0
        stale = [j + 1 for j, age in enumerate(out.info_ages) if age > self.config.info_timeout]
        if not self._state_valid:
            level, message = WARN, ("motion capture stale: holding" if self.controller.uses_ground_truth
                                    else "no valid local state: holding")
        elif out.fallback_active:
            level, message = WARN, f"NC fallback (4.32): no fresh zeta from UAV {', '.join(map(str, stale))}"
        elif out.contact_guard_state == LOST:
            level, message = WARN, "contact lost: the force demand is faded to 0 until the trigger is released"
        elif out.thrust_saturated or out.tilt_saturated:
            level, message = WARN, f"{'thrust' if out.thrust_saturated else 'tilt'} saturated"
        else:
            level, message = OK, f"{out.active_mode} law running"
        report = StatusReport(self.get_fully_qualified_name(), level, message, f"uav{self.config.uav_id}", {
            "configured mode": self.config.mode, "active mode": out.active_mode,
            "zeta ages [s]": [float(a) for a in out.info_ages], "local state valid": bool(out.local_state_valid),
            "thrust saturated": bool(out.thrust_saturated), "tilt saturated": bool(out.tilt_saturated),
            "loop time [ms]": 1000.0 * float(out.loop_time),
            "platform tilt [deg]": math.degrees(float(out.platform_tilt)),  # the bridges' envelope: 45° by default
            "contact guard": STATE_NAMES.get(out.contact_guard_state, "?"),
            "applied contact force [N]": float(out.applied_contact_force)})
        self.diagnostics_pub.publish(to_diagnostic_array([report], stamp))


def main(args=None) -> None:
    spin_node(ControllerNode, args)


if __name__ == "__main__":
    main()
