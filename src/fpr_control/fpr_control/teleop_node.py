"""teleop node (ground station): sensor_msgs/Joy on ``joy`` -> fpr_msgs/TeleopCommand on /fpr/teleop at 50 Hz.

The mapping (Fig. 4.5 layout, dead zones, low-pass, limits) is config/teleop.yaml, read through the
``mapping_file`` parameter; the core is :class:`fpr_control.teleop_filter.TeleopFilter`. With
``initial_legs_from_info`` (default), before FLY the command starts from the robot's configuration: the mean
of the leg angles the UAVs report on /fpr/info (:mod:`fpr_control.teleop_start`), roll and pitch 0.

With ``target_approach`` (default off), the hybrid scheme of thesis §4.4.2 Scenario II: in FLY, while a fresh,
valid relative target pose arrives on /fpr/target (geometry_msgs/PoseStamped, frame ``flat_platform``: position =
target minus platform centre in F_Fp [m], orientation = rotation about z by the relative yaw), the x/y velocity
and yaw-rate targets come from the law (4.39) (:mod:`fpr_control.target_approach`) instead of the sticks, through
the same low-pass filter; z velocity, contact force, roll, pitch and legs stay with the operator. Stale or refused
target -> the sticks again (logged once per change).

    ros2 run fpr_control teleop --ros-args -p n:=3
    ros2 run fpr_control teleop --ros-args -p target_approach:=true
"""

from __future__ import annotations

import math
import os

import yaml
from fpr_model.node_parameters import NodeParameters, node_seconds, throttle
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Joy

from fpr_control.node_utils import LOG_THROTTLE_S, spin_node
from fpr_control.target_approach import TargetApproach, approach_config_from_teleop
from fpr_control.teleop_filter import MODE_NAMES, TeleopFilter, config_from_dict
from fpr_control.teleop_start import ReportedLegAngles, ReportedLegAnglesConfig
from fpr_msgs.msg import InformationVector, TeleopCommand


def default_mapping_file() -> str:
    try:
        from ament_index_python.packages import get_package_share_directory

        return os.path.join(get_package_share_directory("fpr_control"), "config", "teleop.yaml")
    except Exception:  # noqa: BLE001 - ament index missing (source tree): use the file next to the package
        return os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config", "teleop.yaml")


class TeleopNode(Node):
    def __init__(self, **node_kwargs) -> None:
        super().__init__("teleop", **node_kwargs)
        d = NodeParameters(self)
        n = int(d("n", 3, "number of legs (TeleopCommand.leg_angles length)", low=3, high=64))
        self.rate = float(d("rate", 50.0, "publishing rate [Hz]", low=1.0, high=1000.0))
        mapping_file = d("mapping_file", "",
                         "gamepad mapping YAML (empty: installed config/teleop.yaml)")
        use_feasibility = bool(d("feasible_leg_range", False,
            "also clamp the leg angle into fpr_model.feasibility.feasible_leg_angle_range at the commanded roll/pitch"
        ))
        self.min_force_margin = float(d("min_force_margin", 2.0, "[N] feasibility threshold"))
        self.min_moment_margin = float(d("min_moment_margin", 1.0, "[N m] feasibility threshold"))
        legs_from_info = bool(d("initial_legs_from_info", True,
            "before FLY, follow the mean of the UAVs' leg angles on /fpr/info (roll/pitch at 0), so arming "
            "commands no configuration change; false: start from the mapping's initial values"))
        info_timeout = float(d("info_timeout", 0.5,
            "[s] an /fpr/info leg angle older than this is not used", low=0.001, high=60.0))
        info_smoothing = float(d("info_smoothing", 1.0,
            "[s] time constant of the average of the reported leg angles (0: none)"))
        target_approach = bool(d("target_approach", False,
            "hybrid scheme of thesis 4.4.2 Scenario II: in FLY, x/y velocity and yaw rate from the target-approach "
            "law (4.39) on the relative target pose /fpr/target (z velocity, contact force, roll, pitch, legs "
            "stay with the operator); false: sticks only, /fpr/target not subscribed"))
        target_lambda_p = float(d("target_lambda_p", 0.4,
            "[1/s] lambda_p of (4.39): F_Fp x/y velocity = lambda_p * relative target x/y"))
        target_lambda_psi = float(d("target_lambda_psi", 0.25,
            "[1/s] lambda_psi of (4.39): F_Fp yaw rate = lambda_psi * relative target yaw"))
        target_timeout = float(d("target_timeout", 0.5,
            "[s] a /fpr/target pose older than this is not used (back to the sticks)", low=0.001,
            high=60.0))
        path = mapping_file or default_mapping_file()
        with open(path, encoding="utf-8") as stream:
            config = config_from_dict(yaml.safe_load(stream), n=n)
        leg_range = None
        if use_feasibility:
            from fpr_model.feasibility import feasible_leg_angle_range
            from fpr_model.parameters import default_parameters

            params = default_parameters(n)

            def leg_range(roll: float, pitch: float) -> tuple[float, float]:
                result = feasible_leg_angle_range(params, roll, pitch, self.min_force_margin,
                                                  self.min_moment_margin)
                if result is None:
                    raise ValueError("no feasible leg angle at this orientation")
                return result

        self.filter = TeleopFilter(config, leg_range, start_from_robot=legs_from_info)
        self.reported_legs: ReportedLegAngles | None = None
        joy_qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.create_subscription(Joy, "joy", self._on_joy, joy_qos)
        if legs_from_info:
            self.reported_legs = ReportedLegAngles(ReportedLegAnglesConfig(n, info_timeout, info_smoothing))
            self.create_subscription(InformationVector, "/fpr/info", self._on_info, QoSProfile(
                depth=20, reliability=ReliabilityPolicy.BEST_EFFORT))  # as the controllers
        self.target: TargetApproach | None = None
        if target_approach:
            self.target = TargetApproach(approach_config_from_teleop(
                config, target_lambda_p, target_lambda_psi, target_timeout))
            self.create_subscription(PoseStamped, "/fpr/target", self._on_target, qos_profile_sensor_data)
        self.pub = self.create_publisher(TeleopCommand, "/fpr/teleop", 10)
        self._last_tick: float | None = None
        self._last_mode = self.filter.mode
        self._was_stale = True
        self.create_timer(1.0 / self.rate, self._on_tick)
        self.get_logger().info(f"teleop: mapping {path}, {self.rate:.0f} Hz, n = {n}, "
                               f"feasible leg range {'on' if use_feasibility else 'off'}, initial legs "
                               f"{'from /fpr/info' if legs_from_info else 'from the mapping'}, target approach "
                               + (f"on (lambda_p {target_lambda_p:g} 1/s, lambda_psi {target_lambda_psi:g} 1/s, "
                                  f"timeout {target_timeout:g} s)" if target_approach else "off"))

    def _now(self) -> float:
        return node_seconds(self)

    def _on_joy(self, msg: Joy) -> None:
        reason = self.filter.joy(self._now(), list(msg.axes), list(msg.buttons))
        if reason is not None:
            self.get_logger().warning(f"Joy ignored: {reason}", **throttle(self, LOG_THROTTLE_S))

    def _on_info(self, msg: InformationVector) -> None:
        reason = self.reported_legs.receive(int(msg.uav_id), msg.leg_angle, bool(msg.valid), self._now())
        if reason is not None:
            self.get_logger().warning(f"/fpr/info ignored: {reason}", **throttle(self, LOG_THROTTLE_S))

    def _on_target(self, msg: PoseStamped) -> None:
        p, q = msg.pose.position, msg.pose.orientation
        reason = self.target.receive(self._now(), (p.x, p.y, p.z), (q.w, q.x, q.y, q.z), msg.header.frame_id)
        if reason is not None:
            self.get_logger().warning(f"/fpr/target refused: {reason}", **throttle(self, LOG_THROTTLE_S))

    def _on_tick(self) -> None:
        now = self._now()
        dt = 1.0 / self.rate if self._last_tick is None else min(max(now - self._last_tick, 0.0), 0.5)
        self._last_tick = now
        measured = self.reported_legs.update(now, dt) if self.reported_legs is not None else None
        approach = self.target.command(now) if self.target is not None else None
        out = self.filter.step(now, dt, measured.leg_angle if measured is not None else None,
                               approach.as_targets() if approach is not None else None)
        for report in self.filter.take_reports():
            self.get_logger().info(report)
        if self.target is not None:
            for level, report in self.target.take_reports():
                if level == "warning":  # one call site per severity (rclpy rule)
                    self.get_logger().warning(report)
                else:
                    self.get_logger().info(report)
        if out.joy_stale and not self._was_stale:
            self.get_logger().warning("joystick silent: zero velocities, holding roll/pitch/legs/force")
        self._was_stale = out.joy_stale
        if out.mode != self._last_mode:
            self.get_logger().info(f"teleop mode -> {MODE_NAMES[out.mode]}")
            self._last_mode = out.mode
        msg = TeleopCommand()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "flat_platform"
        msg.mode = out.mode
        msg.platform_velocity.x, msg.platform_velocity.y, msg.platform_velocity.z = (
            float(v) for v in out.platform_velocity)
        msg.platform_acceleration.x, msg.platform_acceleration.y, msg.platform_acceleration.z = (
            float(v) for v in out.platform_acceleration)
        msg.yaw_rate, msg.yaw_acceleration = float(out.yaw_rate), float(out.yaw_acceleration)
        msg.roll, msg.roll_rate = float(out.roll), float(out.roll_rate)
        msg.pitch, msg.pitch_rate = float(out.pitch), float(out.pitch_rate)
        msg.leg_angles = [float(v) for v in out.leg_angles]
        msg.leg_rates = [float(v) for v in out.leg_rates]
        msg.contact_force = float(out.contact_force)
        if not all(math.isfinite(v) for v in [msg.roll, msg.pitch, msg.contact_force, *msg.leg_angles]):
            self.get_logger().warning("teleop output not finite: not published", **throttle(self, LOG_THROTTLE_S))
            return
        self.pub.publish(msg)


def main(args=None) -> None:
    spin_node(TeleopNode, args)


if __name__ == "__main__":
    main()
