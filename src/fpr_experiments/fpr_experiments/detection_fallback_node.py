"""detection_fallback node: the thesis's motion-capture supervision of the onboard marker detections (§4.4.2,
l.6823-6830; :mod:`fpr_experiments.detection_fallback`). For every UAV i it reads the detections on
``/fpr/uav<i>/<input_topic>`` (the camera pipeline's) and ``/fpr/motion_capture`` (fpr_msgs/FprState), and publishes
on ``/fpr/uav<i>/<output_topic>`` (what the pose estimator reads, remapped) each detection that agrees with the
motion capture, an emulated one (motion capture + the §4.4.1 noise) in place of a false one, and emulated ones at
``rate`` while no detection passed for ``lost_timeout``. An emulated detection has no image: ``corners`` all 0 and
``reprojection_error`` NaN (how the reports count them). One log line when a UAV's detections are lost and when they
are back; false ones at most one line per ``log_interval``.

An experiment-set-up node (ground truth), like the thesis's: it needs a motion-capture system.

    ros2 run fpr_experiments detection_fallback --ros-args -p n:=3 -p use_sim_time:=true
"""

from __future__ import annotations

import math

import numpy as np
from fpr_control.node_utils import LOG_THROTTLE_S
from fpr_model.node_parameters import NodeParameters, node_seconds, throttle
from fpr_model.rotations import quat_to_rotmat, rotmat_to_quat
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.time import Time

from fpr_experiments.detection_fallback import DetectionFallback, FallbackConfig
from fpr_msgs.msg import FprState, MarkerDetection

DEFAULT_INPUT = "marker"
DEFAULT_OUTPUT = "marker_checked"


def _seconds(stamp) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def _pose_matrix(pose) -> np.ndarray:
    q = pose.orientation
    T = np.eye(4)
    T[:3, :3] = quat_to_rotmat(np.array([q.w, q.x, q.y, q.z]))
    T[:3, 3] = (pose.position.x, pose.position.y, pose.position.z)
    return T


class DetectionFallbackNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("detection_fallback", **kwargs)
        d = NodeParameters(self)
        n = int(d("n", 3, "number of UAVs", low=3, high=64))
        input_topic = str(d("input_topic", DEFAULT_INPUT, "each UAV's detections, relative to /fpr/uav<i>"))
        output_topic = str(d("output_topic", DEFAULT_OUTPUT, "each UAV's supervised detections (the pose "
                             "estimator's 'marker', remapped), relative to /fpr/uav<i>"))
        mocap_topic = str(d("motion_capture_topic", "/fpr/motion_capture", "fpr_msgs/FprState of the motion capture"))
        config = FallbackConfig(
            lost_timeout=float(d("lost_timeout", 0.5, "[s] no passed detection for longer: emulated ones (thesis "
                                 "l.6825)", low=1e-3, high=60.0)),
            max_position_error=float(d("max_position_error", 0.10, "[m] farther from the motion capture: a false "
                                       "detection (l.6827)", low=1e-3, high=10.0)),
            max_angle_error=float(d("max_angle_error", math.radians(10.0), "[rad] (l.6828)", low=1e-3, high=math.pi)),
            position_noise=float(d("position_noise", 0.02, "[m] 1-sigma per axis of an emulated relative position "
                                   "(§4.4.1)", low=0.0, high=1.0)),
            angle_noise=float(d("angle_noise", math.radians(2.0), "[rad] 1-sigma per axis of an emulated relative "
                                "attitude (§4.4.1)", low=0.0, high=1.0)),
            rate=float(d("rate", 20.0, "[Hz] emulated detections while lost (the cameras' rate)", low=1.0, high=200.0)))
        seed = int(d("seed", 0, "noise seed (the scenario's)", low=0, high=2**31 - 1))
        self._log_interval = float(d("log_interval", 2.0, "[s] minimum interval between false-detection lines",
                                     low=0.0, high=3600.0))
        self.core = DetectionFallback(n, config, seed=seed)
        self._pubs = {i: self.create_publisher(MarkerDetection, f"/fpr/uav{i}/{output_topic}", 10)
                      for i in range(1, n + 1)}
        for i in range(1, n + 1):
            self.create_subscription(MarkerDetection, f"/fpr/uav{i}/{input_topic}",
                                     lambda msg, uav=i: self._on_detection(uav, msg), qos_profile_sensor_data)
        self.create_subscription(FprState, mocap_topic, self._on_mocap, 10)
        self.create_timer(1.0 / config.rate, self._on_timer)
        self._frame_ids = {i: f"uav{i}/camera_optical" for i in range(1, n + 1)}
        self._was_lost = [False] * n
        self._last_false_line = -math.inf
        self.get_logger().info(
            f"detection_fallback: /fpr/uav<i>/{input_topic} -> /fpr/uav<i>/{output_topic}, checked against "
            f"{mocap_topic}: false beyond {100 * config.max_position_error:g} cm / "
            f"{math.degrees(config.max_angle_error):g} deg, emulated after {config.lost_timeout:g} s without one "
            f"(noise {100 * config.position_noise:g} cm / {math.degrees(config.angle_noise):g} deg; thesis §4.4.2)")

    def _now(self) -> float:
        return node_seconds(self)

    def _on_mocap(self, msg: FprState) -> None:
        def position(p):
            return (p.position.x, p.position.y, p.position.z)

        def quat(p):
            return (p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z)

        reason = self.core.on_mocap(_seconds(msg.header.stamp), position(msg.platform_pose), quat(msg.platform_pose),
                                    [position(p) for p in msg.uav_poses], [quat(p) for p in msg.uav_poses])
        if reason is not None:
            self.get_logger().warning(f"{reason}: sample refused", **throttle(self, LOG_THROTTLE_S))

    def _on_detection(self, uav: int, msg: MarkerDetection) -> None:
        self._frame_ids[uav] = msg.header.frame_id or self._frame_ids[uav]
        decision = self.core.on_detection(uav, _seconds(msg.header.stamp), _pose_matrix(msg.pose))
        if not decision.emulated:
            self._pubs[uav].publish(msg)
            self._say_back(uav)
            return
        now = self._now()
        if now - self._last_false_line >= self._log_interval:
            self._last_false_line = now
            self.get_logger().warning(f"uav{uav}: {decision.reason}: replaced by a motion-capture one "
                                      f"({self.core.false_detections[uav - 1]} so far)")
        self._pubs[uav].publish(self._emulated(uav, msg.header.stamp, decision.camera_T_marker, msg.marker_id,
                                               msg.marker_size))

    def _say_back(self, uav: int) -> None:
        if self._was_lost[uav - 1]:
            self._was_lost[uav - 1] = False
            self.get_logger().info(f"uav{uav}: detections back: motion-capture emulation off "
                                   f"({self.core.emulated[uav - 1]} emulated so far)")

    def _on_timer(self) -> None:
        now = self._now()
        if now <= 0.0:
            return
        for uav, pub in self._pubs.items():
            due = self.core.due(uav, now)
            if self.core.lost[uav - 1] and not self._was_lost[uav - 1]:
                self._was_lost[uav - 1] = True
                self.get_logger().warning(
                    f"uav{uav}: no detection passed for {self.core.lost_for(uav, now):.2f} s: motion-capture "
                    f"emulated detections at {self.core.config.rate:g} Hz until the camera's are back (thesis §4.4.2)")
            if due is None:
                continue
            stamp, camera_T_marker = due
            msg_stamp = Time(nanoseconds=int(round(stamp * 1e9))).to_msg()
            pub.publish(self._emulated(uav, msg_stamp, camera_T_marker, 0, self.core.calibration.marker_size))

    def _emulated(self, uav: int, stamp, camera_T_marker: np.ndarray, marker_id: int,
                  marker_size: float) -> MarkerDetection:
        msg = MarkerDetection()
        msg.header.stamp = stamp
        msg.header.frame_id = self._frame_ids[uav]
        msg.marker_id = int(marker_id)
        q = rotmat_to_quat(camera_T_marker[:3, :3])
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in camera_T_marker[:3, 3])
        msg.pose.orientation.w, msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z = (
            float(v) for v in q)
        msg.reprojection_error = math.nan  # no image: how the reports tell an emulated detection
        msg.ambiguity_ratio = math.nan
        msg.marker_size = float(marker_size)
        return msg


def main(args=None) -> None:
    from fpr_control.node_utils import spin_node

    spin_node(DetectionFallbackNode, args)


if __name__ == "__main__":
    main()
