"""ROS 2 node ``pose_estimator``: relative-pose filter and state reconstruction of UAV i (thin wrapper of
:mod:`.estimator`; thesis §4.2.2-4.2.3).

Run in the UAV's namespace: ``ros2 run fpr_estimation pose_estimator --ros-args -r __ns:=/fpr/uav1 -p uav_id:=1
--params-file share/fpr_estimation/config/pose_estimator.yaml``.
Subscribes ``marker`` (fpr_msgs/MarkerDetection), ``imu`` (sensor_msgs/Imu: FLU body attitude in the UAV's local
ENU frame, FLU rate) and ``velocity_body`` (geometry_msgs/TwistStamped, FLU); publishes ``local_state``
(fpr_msgs/LocalState) at ``output_rate`` (50 Hz) from the node clock (use_sim_time honoured), once the first
detection has been accepted. The filter predicts on every IMU message (dt from the IMU header stamps, or the
receive time when a stamp is zero) and corrects on every detection that passes the innovation gate.
"""

from __future__ import annotations

import math

import numpy as np
from fpr_model.calibration import CameraModel, EulerZxzPose, VisionCalibration
from fpr_model.rotations import quat_to_rotmat
from geometry_msgs.msg import TwistStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Imu

from fpr_estimation.ekf import FilterNoise
from fpr_estimation.estimator import EstimatorConfig, PoseEstimatorCore
from fpr_estimation.gating import GateConfig
from fpr_estimation.node_utils import spin_node
from fpr_msgs.msg import LocalState, MarkerDetection

_PARAMETERS = {
    "uav_id": (1, "UAV index i (1-based): selects the leg anchor alpha_i = 2 pi (i - 1) / n"),
    "n": (3, "number of UAVs / legs"),
    "platform_radius": (0.127, "[m] r, platform centre to revolute joint (Table B.1)"),
    "filter": ("ekf", "ekf (thesis (4.9)-(4.16)) or mekf (multiplicative error-state EKF)"),
    "estimate_gyro_bias": (True, "mekf only: estimate a gyro bias"),
    "position_random_walk": (0.05, "[m/sqrt(s)] process noise of p_p_i (Q)"),
    "attitude_random_walk": (0.03, "[rad/sqrt(s)] process noise of the relative attitude (Q)"),
    "gyro_bias_random_walk": (0.002, "[rad/s/sqrt(s)] mekf bias process noise"),
    "initial_gyro_bias_sigma": (0.02, "[rad/s] mekf initial bias uncertainty"),
    "measurement_position_sigma": (0.02, "[m] detection position noise per axis (R)"),
    "measurement_angle_sigma": (math.radians(2.0), "[rad] detection angle noise per axis (R)"),
    "gate_mode": ("threshold", "innovation gate: threshold | mahalanobis | off"),
    "gate_max_position_error": (0.10, "[m] threshold gate on the position innovation"),
    "gate_max_angle_error": (math.radians(10.0), "[rad] threshold gate on the attitude innovation"),
    "gate_mahalanobis_threshold": (22.46, "chi-square(6) threshold of the Mahalanobis gate"),
    "max_consecutive_rejections": (10, "re-initialise from the detection after this many rejections in a row"),
    "stale_timeout": (0.5, "[s] no accepted detection for this long: valid = false (prediction continues)"),
    "max_prediction_step": (0.1, "[s] IMU gaps longer than this are not integrated"),
    "output_rate": (50.0, "[Hz] local_state publication rate"),
    "euler_order": ("extrinsic", "how to read the ZXZ angles of Table D.1 (see fpr_model.calibration)"),
    "camera_translation_cm": ([8.45, -9.35, 0.79], "[cm] camera position in the body frame, b_T_C (Table D.1)"),
    "camera_euler_zxz": ([1.561, 0.708, 0.829], "[rad] camera ZXZ angles (psi1, phi, psi2), b_T_C (Table D.1)"),
    "marker_translation_cm": ([-0.83, 0.26, -2.47], "[cm] marker position in the platform frame, p_T_M"),
    "marker_euler_zxz": ([-0.716, 3.136, 0.837], "[rad] marker ZXZ angles (psi1, phi, psi2), p_T_M"),
    "frame_id": ("", "frame_id of local_state; empty: uav<i>/platform"),
    "log_interval": (2.0, "[s] minimum interval between repeated warnings"),
}


def _stamp_seconds(stamp) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


class PoseEstimatorNode(Node):
    def __init__(self, **kwargs) -> None:
        """kwargs go to rclpy.node.Node (context, namespace, parameter_overrides, ...)."""
        super().__init__("pose_estimator", **kwargs)
        for name, (default, description) in _PARAMETERS.items():
            self.declare_parameter(name, default, ParameterDescriptor(description=description))
        p = {name: self.get_parameter(name).value for name in _PARAMETERS}
        order = str(p["euler_order"])
        calibration = VisionCalibration(
            EulerZxzPose(tuple(p["camera_translation_cm"]), tuple(p["camera_euler_zxz"]), order),
            EulerZxzPose(tuple(p["marker_translation_cm"]), tuple(p["marker_euler_zxz"]), order),
            CameraModel())
        config = EstimatorConfig(
            uav_id=int(p["uav_id"]), n=int(p["n"]), platform_radius=float(p["platform_radius"]),
            filter=str(p["filter"]), estimate_gyro_bias=bool(p["estimate_gyro_bias"]),
            noise=FilterNoise(float(p["position_random_walk"]), float(p["attitude_random_walk"]),
                              float(p["gyro_bias_random_walk"]), float(p["initial_gyro_bias_sigma"]),
                              float(p["measurement_position_sigma"]), float(p["measurement_angle_sigma"])),
            gate=GateConfig(str(p["gate_mode"]), float(p["gate_max_position_error"]),
                            float(p["gate_max_angle_error"]), float(p["gate_mahalanobis_threshold"])),
            stale_timeout=float(p["stale_timeout"]),
            max_consecutive_rejections=int(p["max_consecutive_rejections"]),
            max_prediction_step=float(p["max_prediction_step"]))
        self.core = PoseEstimatorCore(config, calibration)
        self._frame_id = str(p["frame_id"]) or f"uav{config.uav_id}/platform"
        self._uav_id = config.uav_id
        self._log_interval = float(p["log_interval"])
        self._was_valid = False
        self.published = 0
        self._pub = self.create_publisher(LocalState, "local_state", 10)
        self.create_subscription(MarkerDetection, "marker", self._on_marker, qos_profile_sensor_data)
        self.create_subscription(Imu, "imu", self._on_imu, qos_profile_sensor_data)
        self.create_subscription(TwistStamped, "velocity_body", self._on_velocity, qos_profile_sensor_data)
        rate = float(p["output_rate"])
        if not rate > 0.0:
            raise ValueError(f"output_rate must be positive, got {rate}")
        self.create_timer(1.0 / rate, self._on_timer)

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_imu(self, msg: Imu) -> None:
        stamp = _stamp_seconds(msg.header.stamp) or self._now()
        o, w = msg.orientation, msg.angular_velocity
        problem = self.core.on_imu(stamp, np.array([o.w, o.x, o.y, o.z]), np.array([w.x, w.y, w.z]))
        if problem:
            self.get_logger().warning(problem, throttle_duration_sec=self._log_interval)

    def _on_velocity(self, msg: TwistStamped) -> None:
        v = msg.twist.linear
        problem = self.core.on_velocity(np.array([v.x, v.y, v.z]))
        if problem:
            self.get_logger().warning(problem, throttle_duration_sec=self._log_interval)

    def _on_marker(self, msg: MarkerDetection) -> None:
        q, t = msg.pose.orientation, msg.pose.position
        quat = np.array([q.w, q.x, q.y, q.z])
        norm = float(np.linalg.norm(quat)) if np.isfinite(quat).all() else float("nan")
        if not 0.5 < norm < 1.5:
            self.get_logger().warning(f"detection with an invalid quaternion (norm {norm}) ignored",
                                      throttle_duration_sec=self._log_interval)
            return
        T = np.eye(4)
        T[:3, :3] = quat_to_rotmat(quat / norm)
        T[:3, 3] = [t.x, t.y, t.z]
        result = self.core.on_detection(self._now(), T)
        if isinstance(result, str):
            self.get_logger().warning(result, throttle_duration_sec=self._log_interval)
        elif not result.accepted:
            self.get_logger().warning(f"detection rejected by the gate: {100 * result.position_error:.1f} cm, "
                                      f"{math.degrees(result.angle_error):.1f} deg "
                                      f"(total rejected {self.core.rejected_detections})",
                                      throttle_duration_sec=self._log_interval)

    def _on_timer(self) -> None:
        now_msg = self.get_clock().now()
        out = self.core.output(now_msg.nanoseconds * 1e-9)
        if out is None:
            self.get_logger().warning("no marker detection accepted yet: local_state not published",
                                      throttle_duration_sec=self._log_interval)
            return
        if self._was_valid and not out.valid:
            self.get_logger().warning(f"estimate stale: no accepted detection for {out.detection_age:.2f} s")
        self._was_valid = out.valid
        msg = LocalState()
        msg.header.stamp = now_msg.to_msg()
        msg.header.frame_id = self._frame_id
        msg.uav_id = self._uav_id
        pose = msg.relative_pose
        pose.position.x, pose.position.y, pose.position.z = (float(v) for v in out.position)
        pose.orientation.w, pose.orientation.x, pose.orientation.y, pose.orientation.z = (
            float(v) for v in out.quaternion)
        rec = out.reconstruction
        valid = out.valid
        if rec is None:
            self.get_logger().warning("no valid IMU attitude yet: reconstruction unavailable, valid = false",
                                      throttle_duration_sec=self._log_interval)
            valid = False
            msg.uav_attitude_flat.w = 1.0
        else:
            msg.leg_angle = rec.leg_angle
            msg.platform_roll = rec.platform_roll
            msg.platform_pitch = rec.platform_pitch
            a = msg.uav_attitude_flat
            a.w, a.x, a.y, a.z = (float(v) for v in rec.uav_attitude_flat)
            v = msg.uav_velocity_flat
            v.x, v.y, v.z = (float(c) for c in rec.uav_velocity_flat)
            msg.relative_yaw = rec.relative_yaw
            msg.uav_yaw = rec.uav_yaw
        w = msg.uav_angular_velocity
        w.x, w.y, w.z = (float(c) for c in out.body_rate)
        msg.pose_stddev = [float(s) for s in out.pose_stddev]
        msg.detection_age = float(out.detection_age)
        msg.rejected_detections = int(out.rejected_detections)
        msg.valid = bool(valid)
        self._pub.publish(msg)
        self.published += 1


def main(args=None) -> None:
    spin_node(PoseEstimatorNode, args)
