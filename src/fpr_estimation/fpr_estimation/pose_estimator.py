"""ROS 2 node ``pose_estimator``: relative-pose filter and state reconstruction of UAV i (thin wrapper of
:mod:`.estimator`; thesis §4.2.2-4.2.3).

Run in the UAV's namespace: ``ros2 run fpr_estimation pose_estimator --ros-args -r __ns:=/fpr/uav1 -p uav_id:=1
--params-file share/fpr_estimation/config/pose_estimator.yaml``.
Subscribes ``marker`` (fpr_msgs/MarkerDetection), ``imu`` (sensor_msgs/Imu: FLU body attitude in the UAV's local
ENU frame, FLU rate) and ``velocity_body`` (geometry_msgs/TwistStamped, FLU); publishes ``local_state``
(fpr_msgs/LocalState) at ``output_rate`` (50 Hz) from the node clock (use_sim_time honoured), once the filter
is initialised (K consistent detections; nothing is published before, nor after a reset: the controller's
``local_state_timeout`` applies). The filter predicts on every accepted IMU message (dt from the IMU header stamps,
or the receive time when a stamp is zero) and corrects on every detection that passes the innovation gate.
Every input is checked by the core first (issue 12: rates, specific force, quaternions, stamps, marker distance);
each refusal, fallback and return is one log line, at most one per kind per ``log_interval``.
"""

from __future__ import annotations

import math

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from fpr_model.calibration import EULER_ORDERS, CameraModel, EulerZxzPose, VisionCalibration
from fpr_model.diagnostics import ERROR, OK, WARN, StatusReport, to_diagnostic_array
from fpr_model.node_parameters import NodeParameters, Param, node_seconds, throttle
from fpr_model.rotations import inverse_pose
from geometry_msgs.msg import TransformStamped, TwistStamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Imu
from tf2_msgs.msg import TFMessage

from fpr_estimation.ekf import FilterNoise
from fpr_estimation.estimator import EstimatorConfig, LogLimiter, PoseEstimatorCore
from fpr_estimation.gating import STANDARD_GRAVITY, GateConfig, InputBounds, ReinitConfig
from fpr_estimation.node_utils import spin_node
from fpr_msgs.msg import LocalState, MarkerDetection

_PARAMETERS = {
    "uav_id": Param(1, "UAV index i (1-based): selects the leg anchor alpha_i = 2 pi (i - 1) / n", low=1, high=64),
    "n": Param(3, "number of UAVs / legs", low=3, high=64),
    "platform_radius": (0.127, "[m] r, platform centre to revolute joint (Table B.1)"),
    "filter": Param("ekf", "ekf (thesis (4.9)-(4.16)) or mekf (multiplicative error-state EKF)",
                    choices=("ekf", "mekf")),
    "estimate_gyro_bias": (True, "mekf only: estimate a gyro bias"),
    "platform_rate": (False, "mekf only: the platform's angular velocity as a state (a Gauss-Markov process), "
                             "used by the prediction and the latency compensation (not in the thesis)"),
    "platform_rate_random_walk": (1.0, "[rad/s/sqrt(s)] mekf platform_rate: density of the rate's process"),
    "platform_rate_time_constant": (1.0, "[s] mekf platform_rate: the rate decays to 0 with it without detections"),
    "position_random_walk": (0.05, "[m/sqrt(s)] process noise of p_p_i (Q)"),
    "attitude_random_walk": (0.1, "[rad/sqrt(s)] process noise of the relative attitude (Q): gyro noise and the "
                                  "platform's own rotation, which the model (4.10) leaves out"),
    "gyro_bias_random_walk": (0.002, "[rad/s/sqrt(s)] mekf bias process noise"),
    "initial_gyro_bias_sigma": (0.02, "[rad/s] mekf initial bias uncertainty"),
    "measurement_position_sigma": (0.02, "[m] detection position noise per axis (R)"),
    "measurement_angle_sigma": (math.radians(2.0), "[rad] detection angle noise per axis (R)"),
    "gate_mode": Param("threshold", "innovation gate", choices=("threshold", "mahalanobis", "off")),
    "gate_max_position_error": (0.10, "[m] threshold gate on the position innovation"),
    "gate_max_angle_error": (math.radians(10.0), "[rad] threshold gate on the attitude innovation"),
    "gate_mahalanobis_threshold": (22.46, "chi-square(6) threshold of the Mahalanobis gate"),
    "gate_position_error_rate": (0.08, "[m/s] threshold gate: growth of the position bound per second without an "
                                       "accepted detection (0: a fixed bound)"),
    "gate_angle_error_rate": (math.radians(6.0), "[rad/s] threshold gate: growth of the attitude bound"),
    "gate_position_error_limit": (0.18, "[m] threshold gate: cap of the growing position bound"),
    "gate_angle_error_limit": (math.radians(16.0), "[rad] threshold gate: cap of the growing attitude bound"),
    "stale_timeout": (0.5, "[s] no accepted detection for this long: valid = false (prediction continues)"),
    "max_prediction_step": (0.1, "[s] IMU gaps longer than this are not integrated (reported)"),
    "imu_gap_reset": (0.5, "[s] an IMU gap this long resets an initialised filter: it re-initialises from K "
                      "consistent detections (a restarted bridge or PX4); 0: never"),
    "latency_compensation": (True, "carry each detection from its capture stamp (header) to the filter's time by the "
                                   "UAV's rotation in between (IMU attitudes); false: applied at arrival (thesis)"),
    "latency_horizon": (0.5, "[s] IMU attitudes kept for the latency compensation; an older detection is applied "
                             "uncompensated (warned)"),
    # Input guards (issue 12): refused inputs never reach the filter.
    "max_body_rate": (35.0, "[rad/s] IMU samples with a larger |rate| are refused (PX4 gyro range, 2000 deg/s)"),
    "max_specific_force": (16.0 * STANDARD_GRAVITY,
                           "[m/s^2] IMU samples with a larger |specific force| are refused (16 g accelerometer range)"),
    "max_quaternion_norm_error": (0.01, "IMU / detection quaternions with | |q| - 1 | above this are refused"),
    "max_stamp_future": (0.2, "[s] IMU samples / detections stamped later than now + this are refused"),
    "max_marker_distance": (2.0, "[m] detections farther from the camera are refused (also caps the position sigma)"),
    # (Re-)initialisation only on consistent detections (issue 12).
    "reinit_consistent_detections": Param(4, "K: (re-)initialise only from K consecutive mutually consistent "
                                          "detections", low=1, high=100),
    "reinit_window": (0.3, "[s] the K consistent detections span at most this"),
    "reinit_position_tolerance": (0.10, "[m] pairwise position agreement of the K detections"),
    "reinit_angle_tolerance": (math.radians(10.0), "[rad] pairwise attitude agreement (after the IMU rotation)"),
    "reinit_min_lost_time": (1.5, "[s] an initialised filter is re-initialised only after this long without an "
                                  "accepted detection (shorter bursts are gated)"),
    "output_rate": Param(50.0, "[Hz] local_state publication rate", low=1.0, high=1000.0),
    "euler_order": Param("extrinsic", "how to read the ZXZ angles of Table D.1 (see fpr_model.calibration)",
                         choices=EULER_ORDERS),
    "camera_translation_cm": ([8.45, -9.35, 0.79], "[cm] camera position in the body frame, b_T_C (Table D.1)"),
    "camera_euler_zxz": ([1.561, 0.708, 0.829], "[rad] camera ZXZ angles (psi1, phi, psi2), b_T_C (Table D.1)"),
    "marker_translation_cm": ([-0.83, 0.26, -2.47], "[cm] marker position in the platform frame, p_T_M"),
    "marker_euler_zxz": ([-0.716, 3.136, 0.837], "[rad] marker ZXZ angles (psi1, phi, psi2), p_T_M"),
    "frame_id": ("", "frame_id of local_state; empty: uav<i>/platform"),
    "publish_tf": (True, "publish the estimate on /tf as body_frame_id -> tf_frame_id (the platform as this UAV "
                         "estimates it, beside the simulator's true 'platform' in RViz / Foxglove); built only "
                         "while /tf has a subscriber"),
    "body_frame_id": ("", "parent frame of the estimate's TF: this UAV's body; empty: uav<i>/base_link"),
    "tf_frame_id": ("", "child frame of the estimate's TF; empty: uav<i>/platform_estimate"),
    "log_interval": (2.0, "[s] minimum interval between repeated warnings"),
}


def _stamp_seconds(stamp) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


class PoseEstimatorNode(Node):
    def __init__(self, **kwargs) -> None:
        """kwargs go to rclpy.node.Node (context, namespace, parameter_overrides, ...)."""
        super().__init__("pose_estimator", **kwargs)
        self.parameters = NodeParameters(self)
        self.parameters.declare_all(_PARAMETERS)
        p = {name: self.get_parameter(name).value for name in _PARAMETERS}
        order = str(p["euler_order"])
        calibration = VisionCalibration(
            EulerZxzPose(tuple(p["camera_translation_cm"]), tuple(p["camera_euler_zxz"]), order),
            EulerZxzPose(tuple(p["marker_translation_cm"]), tuple(p["marker_euler_zxz"]), order),
            CameraModel())
        config = EstimatorConfig(
            uav_id=int(p["uav_id"]), n=int(p["n"]), platform_radius=float(p["platform_radius"]),
            filter=str(p["filter"]), estimate_gyro_bias=bool(p["estimate_gyro_bias"]),
            platform_rate=bool(p["platform_rate"]),
            noise=FilterNoise(float(p["position_random_walk"]), float(p["attitude_random_walk"]),
                              float(p["gyro_bias_random_walk"]), float(p["initial_gyro_bias_sigma"]),
                              float(p["measurement_position_sigma"]), float(p["measurement_angle_sigma"]),
                              float(p["platform_rate_random_walk"]), float(p["platform_rate_time_constant"])),
            gate=GateConfig(str(p["gate_mode"]), float(p["gate_max_position_error"]),
                            float(p["gate_max_angle_error"]), float(p["gate_mahalanobis_threshold"]),
                            float(p["gate_position_error_rate"]), float(p["gate_angle_error_rate"]),
                            float(p["gate_position_error_limit"]), float(p["gate_angle_error_limit"])),
            bounds=InputBounds(float(p["max_body_rate"]), float(p["max_specific_force"]),
                               float(p["max_quaternion_norm_error"]), float(p["max_stamp_future"]),
                               float(p["max_marker_distance"])),
            reinit=ReinitConfig(int(p["reinit_consistent_detections"]), float(p["reinit_window"]),
                                float(p["reinit_position_tolerance"]), float(p["reinit_angle_tolerance"]),
                                float(p["reinit_min_lost_time"])),
            stale_timeout=float(p["stale_timeout"]),
            max_prediction_step=float(p["max_prediction_step"]),
            imu_gap_reset=float(p["imu_gap_reset"]),
            latency_compensation=bool(p["latency_compensation"]),
            latency_horizon=float(p["latency_horizon"]))
        self.core = PoseEstimatorCore(config, calibration)
        self._frame_id = str(p["frame_id"]) or f"uav{config.uav_id}/platform"
        self._tf_parent = str(p["body_frame_id"]) or f"uav{config.uav_id}/base_link"
        self._tf_child = str(p["tf_frame_id"]) or f"uav{config.uav_id}/platform_estimate"
        #: the estimated platform frame under this UAV's body (REP-105 tree: each frame has one parent, so the
        #: estimate hangs below the true uav<i>/base_link rather than re-parenting it): p T_bi inverted
        self._tf_pub = self.create_publisher(TFMessage, "/tf", 100) if bool(p["publish_tf"]) else None
        self._uav_id = config.uav_id
        self._log_interval = float(p["log_interval"])
        self._limiter = LogLimiter(self._log_interval)
        self.published = 0
        self._pub = self.create_publisher(LocalState, "local_state", 10)
        #: REP-107 health once a second on /diagnostics (fpr_model.diagnostics)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._next_diagnostics = -math.inf
        self._resets_reported = 0
        self.create_subscription(MarkerDetection, "marker", self._on_marker, qos_profile_sensor_data)
        self.create_subscription(Imu, "imu", self._on_imu, qos_profile_sensor_data)
        self.create_subscription(TwistStamped, "velocity_body", self._on_velocity, qos_profile_sensor_data)
        rate = float(p["output_rate"])
        if not rate > 0.0:
            raise ValueError(f"output_rate must be positive, got {rate}")
        self._pre_clock_said = False
        self.create_timer(1.0 / rate, self._on_timer)

    def _now(self) -> float:
        return node_seconds(self)

    def _log_events(self) -> None:
        """One line per core event (refusal, fallback, return), at most one per kind per log_interval."""
        now = self._now()
        logger = self.get_logger()
        for event in self.core.take_events():
            line = self._limiter(event, now)
            if line is None:
                continue
            if event.level == "error":  # one call site per severity (rclpy requires it)
                logger.error(line)
            elif event.level == "warning":
                logger.warning(line)
            else:
                logger.info(line)

    def _before_clock(self, now: float) -> bool:
        """No /clock yet (use_sim_time: the node's time is 0): an input cannot be checked against the node's
        time, and would be refused as 'in the future'; dropped, said once (a multi-process start, nominal)."""
        if now > 0.0:
            return False
        if not self._pre_clock_said:
            self._pre_clock_said = True
            self.get_logger().info("inputs before the first /clock (use_sim_time): dropped until the clock runs")
        return True

    def _on_imu(self, msg: Imu) -> None:
        now = self._now()
        if self._before_clock(now):
            return
        stamp = _stamp_seconds(msg.header.stamp) or now
        o, w, a = msg.orientation, msg.angular_velocity, msg.linear_acceleration
        force = None if msg.linear_acceleration_covariance[0] == -1.0 else np.array([a.x, a.y, a.z])  # REP-145
        self.core.on_imu(stamp, np.array([o.w, o.x, o.y, o.z]), np.array([w.x, w.y, w.z]), force, now)
        self._log_events()

    def _on_velocity(self, msg: TwistStamped) -> None:
        v = msg.twist.linear
        self.core.on_velocity(np.array([v.x, v.y, v.z]))
        self._log_events()

    def _on_marker(self, msg: MarkerDetection) -> None:
        now = self._now()
        if self._before_clock(now):
            return
        q, t = msg.pose.orientation, msg.pose.position
        capture = _stamp_seconds(msg.header.stamp) or None
        self.core.on_marker(now, np.array([t.x, t.y, t.z]), np.array([q.w, q.x, q.y, q.z]), capture)
        self._log_events()

    def _on_timer(self) -> None:
        now_msg = self.get_clock().now()
        out = self.core.output(now_msg.nanoseconds * 1e-9)
        self._log_events()
        if out is None:
            self._publish_diagnostics(None, now_msg.to_msg())
            return
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
                                      **throttle(self, self._log_interval))
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
        if self._tf_pub is not None and self._tf_pub.get_subscription_count() > 0:  # lazy (issue 15)
            self._publish_tf(out.position, out.quaternion, msg.header.stamp)
        self._publish_diagnostics(msg, msg.header.stamp)

    def _publish_tf(self, position: np.ndarray, quaternion: np.ndarray, stamp) -> None:
        """/tf ``uav<i>/base_link -> uav<i>/platform_estimate``: the inverse of the estimate p T_bi (the UAV body's
        pose in Fp, (4.9)-(4.16)), i.e. the platform's pose in the body frame [m]."""
        translation, quat = inverse_pose(position, quaternion)
        transform = TransformStamped()
        transform.header.stamp, transform.header.frame_id = stamp, self._tf_parent
        transform.child_frame_id = self._tf_child
        t, r = transform.transform.translation, transform.transform.rotation
        t.x, t.y, t.z = (float(v) for v in translation)
        r.w, r.x, r.y, r.z = (float(v) for v in quat)
        self._tf_pub.publish(TFMessage(transforms=[transform]))

    def _publish_diagnostics(self, state: LocalState | None, stamp) -> None:
        """REP-107 health on /diagnostics once a second: OK while detections keep the estimate valid; WARN while it
        coasts on the IMU (no accepted detection for a while) or before the first valid output; ERROR after a
        filter reset."""
        now = self._now()
        if now < self._next_diagnostics:
            return
        self._next_diagnostics = now + 1.0
        core = self.core
        if core.resets > self._resets_reported:
            level, message = ERROR, f"filter reset after a non-finite state ({core.resets} so far)"
        elif state is None:
            level, message = WARN, (f"not initialised: {core.config.reinit.consistent_detections} consistent "
                                    f"detections needed ({core.pending_detections} seen)")
        elif not state.valid:
            level, message = WARN, "no valid estimate (stale, or no IMU attitude yet)"
        elif state.detection_age > 0.5:
            level, message = WARN, f"coasting on the IMU: last accepted detection {state.detection_age:.1f} s ago"
        else:
            level, message = OK, "tracking the marker"
        self._resets_reported = core.resets
        values = {"accepted detections": core.accepted_detections, "rejected detections": core.rejected_detections,
                  "initialisations": core.initialisations, "refused inputs": sum(core.refused.values()),
                  "latency-compensated detections": core.compensated_detections,
                  "uncompensated detections (too old)": core.uncompensated_detections}
        if math.isfinite(core.last_latency):
            values["detection latency [s]"] = core.last_latency
        if state is not None:
            values |= {"detection age [s]": float(state.detection_age),
                       "leg angle [deg]": math.degrees(state.leg_angle)}
        report = StatusReport(self.get_fully_qualified_name(), level, message, f"uav{self._uav_id}", values)
        self._diagnostics_pub.publish(to_diagnostic_array([report], stamp))


def main(args=None) -> None:
    spin_node(PoseEstimatorNode, args)
