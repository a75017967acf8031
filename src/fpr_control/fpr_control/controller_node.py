"""controller node (one per UAV, namespace /fpr/uav<i>): LocalState + ζ_j + teleop -> setpoint, ζ_i, wrench,
controller_status (fpr_msgs/ControllerStatus) at 50 Hz (DESIGN.md §3-§4; DESIGN.md calls that topic
``diagnostics``: renamed so that the name means the standard message), and its REP-107 health on ``/diagnostics``
(diagnostic_msgs/DiagnosticArray) once a second. The computation is :class:`fpr_control.controller.Controller`.

    ros2 run fpr_control controller --ros-args -r __ns:=/fpr/uav1 -p uav_id:=1 -p mode:=communicating \
        --params-file install/fpr_control/share/fpr_control/config/controller.yaml
"""

from __future__ import annotations

import math

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from fpr_model.diagnostics import OK, WARN, StatusReport, to_diagnostic_array
from fpr_model.parameters import default_parameters, load_parameters
from fpr_model.rotations import quat_to_euler_zyx
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Imu

from fpr_control.command_limits import CommandLimits, bound_command
from fpr_control.controller import (
    DEFAULT_GAINS,
    MODE_CODES,
    Controller,
    ControllerConfig,
    GroundTruth,
    gains_from_dict,
)
from fpr_control.information import InfoPlausibility, LocalEstimate, PeerInfo
from fpr_control.node_utils import LOG_THROTTLE_S, describe, spin_node
from fpr_control.reference import TeleopReference
from fpr_msgs.msg import (
    AttitudeThrustSetpoint,
    ControllerStatus,
    FprState,
    InformationVector,
    LocalState,
    TeleopCommand,
    WrenchEstimate,
)


def _quat_wxyz(q) -> np.ndarray:
    return np.array([q.w, q.x, q.y, q.z], dtype=float)


def _vec(v) -> np.ndarray:
    return np.array([v.x, v.y, v.z], dtype=float)


class ControllerNode(Node):
    def __init__(self, **node_kwargs) -> None:
        super().__init__("controller", **node_kwargs)
        d = self.declare_parameter
        uav_id = d("uav_id", 1, describe("this UAV's id i (1-based)")).value
        n = d("n", 3, describe("number of UAVs / legs")).value
        mode = d("mode", "communicating", describe(
            "centralized | communicating | non_communicating | impedance | pd | pd_compensated")).value
        observer = d("observer", "fowo", describe("wrench observer: fowo | sowo | smwo")).value
        state_source = d("state_source", "local", describe(
            "local (LocalState + peers' zeta) or ground_truth (motion capture on motion_capture_topic, F0; implied by "
            "centralized)")).value
        motion_capture_topic = d("motion_capture_topic", "/fpr/motion_capture", describe(
            "fpr_msgs/FprState the ground-truth modes fly on: the simulator's (or a MOCAP bridge's) motion capture; "
            "/fpr/ground_truth is the simulator's exact truth")).value
        rate = d("rate", 50.0, describe("control rate [Hz]")).value
        info_timeout = d("info_timeout", 0.2, describe("[s] a peer's zeta older than this -> fallback to NC")).value
        max_thrust = d("max_thrust", 25.0, describe("f_max [N]: thrust saturation")).value
        max_tilt_deg = d("max_tilt_deg", 35.0, describe("[deg] tilt limit of the thrust direction")).value
        force_input = d("impedance_force_input", "interaction", describe(
            "decentralized impedance: estimated platform force entering (4.34) as epsilon_tau: 'interaction' (along "
            "the desired contact force only; a load is compensated) or 'full' (the printed law: a load drifts the "
            "robot at f_e / B^d)")).value
        self.local_timeout = d("local_state_timeout", 0.5, describe("[s] LocalState older -> invalid")).value
        self.imu_timeout = d("imu_timeout", 0.5, describe("[s] IMU older -> yaw from LocalState.uav_yaw")).value
        self.teleop_timeout = d("teleop_timeout", 1.0, describe(
            "[s] no TeleopCommand for this long -> zero velocities, hold the rest")).value
        model_file = d("model_file", "", describe("FprParameters YAML (empty: thesis Table B.1 defaults)")).value
        info_input_topic = d("info_input_topic", "/fpr/info", describe(
            "topic the peers' zeta_j are read from (the own zeta_i is always published on /fpr/info); set it to "
            "a relay's output to inject communication faults (fpr_experiments info_link)")).value
        # bounded inputs (issue 12): the controller's own limits on /fpr/teleop (fpr_control.command_limits)
        lim = CommandLimits()
        self.command_limits = CommandLimits(
            leg_angle_min=math.radians(d("command_leg_angle_min_deg", math.degrees(lim.leg_angle_min), describe(
                "[deg] commanded leg angles below are clamped to it (default: the teleop's 15 deg)")).value),
            leg_angle_max=math.radians(d("command_leg_angle_max_deg", math.degrees(lim.leg_angle_max), describe(
                "[deg] commanded leg angles above are clamped to it (default: the teleop's 80 deg)")).value),
            leg_stop_min=math.radians(d("command_leg_stop_min_deg", math.degrees(lim.leg_stop_min), describe(
                "[deg] joint stop: a command with a leg angle below is refused, in [0, leg_angle_min]")).value),
            leg_stop_max=math.radians(d("command_leg_stop_max_deg", math.degrees(lim.leg_stop_max), describe(
                "[deg] joint stop: a command with a leg angle above is refused, in [leg_angle_max, 180]")).value),
            max_tilt=math.radians(d("command_max_tilt_deg", math.degrees(lim.max_tilt), describe(
                "[deg] |roll|, |pitch| limit of the command, in (0, 90); default 30 (teleop_tilt30)")).value),
            max_speed=d("command_max_speed", lim.max_speed, describe(
                "[m/s] |platform velocity| limit (F_Fp), > 0")).value,
            max_yaw_rate=d("command_max_yaw_rate", lim.max_yaw_rate, describe("[rad/s] |yaw rate| limit")).value,
            max_tilt_rate=d("command_max_tilt_rate", lim.max_tilt_rate, describe(
                "[rad/s] |roll rate|, |pitch rate| limit")).value,
            max_leg_rate=d("command_max_leg_rate", lim.max_leg_rate, describe("[rad/s] |leg rate| limit")).value,
            max_acceleration=d("command_max_acceleration", lim.max_acceleration, describe(
                "[m/s^2] |platform acceleration| limit (F_Fp)")).value,
            max_yaw_acceleration=d("command_max_yaw_acceleration", lim.max_yaw_acceleration, describe(
                "[rad/s^2] |yaw acceleration| limit")).value,
            max_contact_force=d("command_max_contact_force", lim.max_contact_force, describe(
                "[N] contact force limit: [0, this] passes, [-this, refuse_ratio x this] is clamped")).value,
            refuse_ratio=d("command_refuse_ratio", lim.refuse_ratio, describe(
                "in [1, 10]: a value beyond this x its symmetric limit refuses the whole command (the last valid "
                "one is kept); between the limit and this x the limit it is clamped")).value)
        self._teleop_refused = 0  #: consecutive refused TeleopCommands (announced on return)
        # zeta_j plausibility and one publisher per uav_id (issue 12; fpr_control.information)
        ip = InfoPlausibility()

        def info_bound(name: str, default: float, text: str) -> float:
            return float(d(name, float(default), describe(text)).value)

        plausibility = InfoPlausibility(
            leg_angle_min=math.radians(info_bound("info_leg_angle_min_deg", math.degrees(ip.leg_angle_min),
                                                  "[deg] a zeta_j with a leg angle below is refused (joint stop "
                                                  "10 deg - 3 deg), >= 0")),
            leg_angle_max=math.radians(info_bound("info_leg_angle_max_deg", math.degrees(ip.leg_angle_max),
                                                  "[deg] a zeta_j with a leg angle above is refused (the model's "
                                                  "domain (0, 90])")),
            max_speed=info_bound("info_max_speed", ip.max_speed, "[m/s] a zeta_j with |Fp v_j| above is refused"),
            max_thrust=info_bound("info_max_thrust", ip.max_thrust, "[N] a zeta_j with a thrust above is refused"),
            max_leg_rate=info_bound("info_max_leg_rate", ip.max_leg_rate, "[rad/s] refuse a zeta_j whose leg angle "
                                    "jumps more than this x dt + 5 deg from the last accepted one"),
            max_angular_rate=info_bound("info_max_angular_rate", ip.max_angular_rate, "[rad/s] refuse a zeta_j "
                                        "whose attitude turns more than this x dt + 10 deg from the last accepted"),
            max_acceleration=info_bound("info_max_acceleration", ip.max_acceleration, "[m/s^2] refuse a zeta_j "
                                        "whose velocity jumps more than this x dt + 1 m/s from the last accepted"),
            publisher_timeout=info_bound("info_publisher_timeout", ip.publisher_timeout, "[s] a uav_id's "
                                         "established zeta publisher silent this long may be replaced (> 0)"))
        own_writer_direct = info_input_topic == "/fpr/info"
        gains = {}
        for group, values in DEFAULT_GAINS.items():
            gains[group] = {}
            for name, default in values.items():
                value = d(f"gains.{group}.{name}", default, describe(f"{group} gain {name}")).value
                gains[group][name] = list(value) if isinstance(value, (list, tuple)) else value

        params = load_parameters(model_file) if model_file else default_parameters(int(n))
        if params.n != n:
            raise ValueError(f"model_file has n = {params.n}, parameter n = {n}")
        self.config = ControllerConfig(
            uav_id=int(uav_id), mode=mode, gains=gains_from_dict(gains, int(n)), observer=observer,
            state_source=state_source, period=1.0 / rate, info_timeout=info_timeout, max_thrust=max_thrust,
            max_tilt=math.radians(max_tilt_deg), impedance_force_input=force_input, info_plausibility=plausibility,
            own_writer_direct=own_writer_direct)
        self.controller = Controller(params, self.config)
        self.n = int(n)

        best_effort = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.create_subscription(LocalState, "local_state", self._on_local, best_effort)
        self.create_subscription(InformationVector, info_input_topic, self._on_info, QoSProfile(
            depth=20, reliability=ReliabilityPolicy.BEST_EFFORT))
        self.create_subscription(TeleopCommand, "/fpr/teleop", self._on_teleop, best_effort)
        self.create_subscription(Imu, "imu", self._on_imu, qos_profile_sensor_data)
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
        self._teleop: TeleopReference | None = None
        self._teleop_time = -math.inf
        self._imu_yaw: float | None = None
        self._imu_time = -math.inf
        self._ground_truth: GroundTruth | None = None
        self.create_timer(self.config.period, self._on_tick)
        self.get_logger().info(
            f"controller uav {uav_id}/{n}: mode {mode}, observer {observer}, state {state_source}, "
            f"{rate:.0f} Hz, info_timeout {info_timeout} s, f_max {max_thrust} N, tilt {max_tilt_deg} deg"
            + (f", impedance force input {force_input}" if mode == "impedance" else ""))

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # ---- callbacks: message -> core dataclasses -----------------------------------------------------
    def _on_local(self, msg: LocalState) -> None:
        if msg.uav_id not in (0, self.config.uav_id):
            self.get_logger().warning(f"LocalState from uav {msg.uav_id} ignored (I am {self.config.uav_id})",
                                      throttle_duration_sec=LOG_THROTTLE_S)
            return
        local = LocalEstimate(
            leg_angle=msg.leg_angle, platform_roll=msg.platform_roll, platform_pitch=msg.platform_pitch,
            attitude=_quat_wxyz(msg.uav_attitude_flat), velocity=_vec(msg.uav_velocity_flat),
            relative_yaw=msg.relative_yaw, uav_yaw=msg.uav_yaw, valid=bool(msg.valid))
        if not local.is_finite():
            self.get_logger().warning("LocalState contains NaN/inf or a zero quaternion: ignored",
                                      throttle_duration_sec=LOG_THROTTLE_S)
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
            self.get_logger().info(f"/fpr/info: {line}", throttle_duration_sec=LOG_THROTTLE_S)
        if reason is not None:
            self.get_logger().warning(f"/fpr/info rejected: {reason}", throttle_duration_sec=LOG_THROTTLE_S)

    def _on_teleop(self, msg: TeleopCommand) -> None:
        if len(msg.leg_angles) != self.n or len(msg.leg_rates) != self.n:
            self.get_logger().warning(f"TeleopCommand with {len(msg.leg_angles)} leg angles (n = {self.n}): ignored",
                                      throttle_duration_sec=LOG_THROTTLE_S)
            return
        command = TeleopReference(
            _vec(msg.platform_velocity), _vec(msg.platform_acceleration), msg.yaw_rate, msg.yaw_acceleration,
            msg.roll, msg.roll_rate, msg.pitch, msg.pitch_rate, np.array(msg.leg_angles, dtype=float),
            np.array(msg.leg_rates, dtype=float), msg.contact_force, int(msg.mode))
        if not command.is_finite():
            self.get_logger().warning("TeleopCommand contains NaN/inf: ignored (holding the last one)",
                                      throttle_duration_sec=LOG_THROTTLE_S)
            return
        bounded = bound_command(command, self.command_limits)
        if bounded.command is None:
            self._teleop_refused += 1
            self.get_logger().warning(f"TeleopCommand refused: {bounded.refused}: holding the last valid command "
                                      f"({self._teleop_refused} refused in a row)",
                                      throttle_duration_sec=LOG_THROTTLE_S)
            return
        if self._teleop_refused:
            self.get_logger().info(f"TeleopCommand accepted again after {self._teleop_refused} refused")
            self._teleop_refused = 0
        if bounded.clamped:
            self.get_logger().warning("TeleopCommand clamped to the controller's limits: " + ", ".join(bounded.clamped),
                                      throttle_duration_sec=LOG_THROTTLE_S)
        self._teleop, self._teleop_time = bounded.command, self._now()

    def _on_imu(self, msg: Imu) -> None:
        quat = _quat_wxyz(msg.orientation)
        norm = float(np.linalg.norm(quat))
        if not np.all(np.isfinite(quat)) or not 0.5 < norm < 1.5:
            self.get_logger().warning("Imu orientation is not a finite unit quaternion: ignored",
                                      throttle_duration_sec=LOG_THROTTLE_S)
            return
        self._imu_yaw, self._imu_time = quat_to_euler_zyx(quat / norm)[2], self._now()

    def _on_ground_truth(self, msg: FprState) -> None:
        n = self.n
        if len(msg.leg_angles) != n or len(msg.leg_rates) != n or len(msg.uav_poses) != n:
            self.get_logger().warning("FprState arrays do not have n entries: ignored",
                                      throttle_duration_sec=LOG_THROTTLE_S)
            return
        gt = GroundTruth(
            _vec(msg.platform_pose.position), _quat_wxyz(msg.platform_pose.orientation),
            _vec(msg.platform_twist.linear), _vec(msg.platform_twist.angular),
            np.array(msg.leg_angles, dtype=float), np.array(msg.leg_rates, dtype=float),
            np.array([_quat_wxyz(p.orientation) for p in msg.uav_poses]))
        if not gt.is_finite():
            self.get_logger().warning("FprState contains NaN/inf: ignored", throttle_duration_sec=LOG_THROTTLE_S)
            return
        self._ground_truth = gt

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
                f"(info_timeout {timeout:g} s)", throttle_duration_sec=1.0)
        elif not active and previous is not None:
            self._fallback_since = None
            self.get_logger().info(f"mode {self.config.mode}: every zeta fresh, mode {self.config.mode} active (NC "
                                   f"for {now - previous:.2f} s)", throttle_duration_sec=1.0)

    def _on_tick(self) -> None:
        now = self._now()
        local = self._local if now - self._local_time <= self.local_timeout else None
        if local is None and not self.controller.uses_ground_truth:
            self.get_logger().warning("no fresh LocalState: holding", throttle_duration_sec=LOG_THROTTLE_S)
        command = self._teleop
        if command is not None and now - self._teleop_time > self.teleop_timeout:
            command = command.stopped()
            self.get_logger().warning("no TeleopCommand: zero velocities, holding the configuration",
                                      throttle_duration_sec=LOG_THROTTLE_S)
        imu_yaw = self._imu_yaw if now - self._imu_time <= self.imu_timeout else None
        out = self.controller.step(now, local, command, self._ground_truth, imu_yaw)
        if out.warning:
            self.get_logger().warning(out.warning, throttle_duration_sec=LOG_THROTTLE_S)
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
            info.valid = bool(out.local_state_valid or self.controller.uses_ground_truth)
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
        st.local_state_valid = bool(out.local_state_valid)
        st.loop_time = float(out.loop_time)
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
        self.status_pub.publish(st)
        self._publish_diagnostics(out, stamp)

    def _publish_diagnostics(self, out, stamp) -> None:
        """Once a second (node clock): OK while the configured law runs on fresh inputs; WARN in the NC fallback,
        while holding without a valid local state, or with a saturated command."""
        now = self.get_clock().now().nanoseconds * 1e-9
        if now < self._next_diagnostics:
            return
        self._next_diagnostics = now + 1.0
        stale = [j + 1 for j, age in enumerate(out.info_ages) if age > self.config.info_timeout]
        if not (out.local_state_valid or self.controller.uses_ground_truth):
            level, message = WARN, "no valid local state: holding"
        elif out.fallback_active:
            level, message = WARN, f"NC fallback (4.32): no fresh zeta from UAV {', '.join(map(str, stale))}"
        elif out.thrust_saturated or out.tilt_saturated:
            level, message = WARN, f"{'thrust' if out.thrust_saturated else 'tilt'} saturated"
        else:
            level, message = OK, f"{out.active_mode} law running"
        report = StatusReport(self.get_fully_qualified_name(), level, message, f"uav{self.config.uav_id}", {
            "configured mode": self.config.mode, "active mode": out.active_mode,
            "zeta ages [s]": [float(a) for a in out.info_ages], "local state valid": bool(out.local_state_valid),
            "thrust saturated": bool(out.thrust_saturated), "tilt saturated": bool(out.tilt_saturated),
            "loop time [ms]": 1000.0 * float(out.loop_time)})
        self.diagnostics_pub.publish(to_diagnostic_array([report], stamp))


def main(args=None) -> None:
    spin_node(ControllerNode, args)


if __name__ == "__main__":
    main()
