"""ROS 2 node ``aruco_detector``: marker pose C_T_M from the on-board camera (thin wrapper of :mod:`.aruco`).

Run in the UAV's namespace: ``ros2 run fpr_estimation aruco_detector --ros-args -r __ns:=/fpr/uav1
--params-file share/fpr_estimation/config/aruco_detector.yaml``.
Subscribes ``camera/image_raw`` (sensor_msgs/Image) and ``camera/camera_info`` (sensor_msgs/CameraInfo);
publishes ``marker`` (fpr_msgs/MarkerDetection) for every image where the marker is found and, optionally,
``marker/debug_image`` (mono8 with the detected axes). Bad input (no camera_info yet, empty or truncated image,
unsupported encoding) is logged (rate-limited) and produces no output.
"""

from __future__ import annotations

import cv2
import numpy as np
from fpr_model.calibration import CameraModel
from fpr_model.node_parameters import NodeParameters, Param, throttle
from fpr_model.opencv_dispatch import ENVIRONMENT_VARIABLE, apply_opencv_dispatch
from fpr_model.rotations import rotmat_to_quat
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from fpr_estimation.aruco import ArucoConfig, ArucoPoseDetector, decode_image
from fpr_estimation.node_utils import spin_node
from fpr_msgs.msg import MarkerDetection

_PARAMETERS = {
    "dictionary": ("DICT_ARUCO_MIP_36H12", "OpenCV ArUco dictionary name"),
    "marker_id": Param(0, "id of the marker under the platform", high=4095),
    "marker_size": Param(0.109, "[m] side of the marker's black square", low=0.001, high=10.0),
    "corner_refinement": Param("apriltag", "corner refinement", choices=("none", "subpix", "contour", "apriltag")),
    "corner_refinement_win_size": Param(5, "[px] corner refinement window (subpix)", low=1, high=100),
    "corner_refinement_max_iterations": (30, "corner refinement iterations"),
    "corner_refinement_min_accuracy": (0.01, "[px] corner refinement stop criterion"),
    "adaptive_thresh_win_size_min": Param(3, "[px] adaptive threshold window, smallest", low=3, high=255),
    "adaptive_thresh_win_size_max": Param(23, "[px] adaptive threshold window, largest", low=3, high=255),
    "adaptive_thresh_win_size_step": Param(10, "[px] adaptive threshold window step", low=1, high=255),
    "min_marker_perimeter_rate": Param(0.03, "smallest marker perimeter / image max dimension", high=4.0),
    "april_tag_min_white_black_diff": Param(30, "[grey levels] AprilTag quad detector: min white-black difference "
                                           "(OpenCV's 5 chases pixel noise: ~50x slower on noisy frames)", high=255),
    "ambiguity_threshold": Param(2.0, "IPPE ambiguity ratio below which the solution closest to the previous is kept",
                                 low=1.0, high=1000.0),
    "roi_margin": Param(0.5, "region of interest: the last marker's bounding box grown by this fraction of its size "
                        "on every side is searched first, the whole frame only when the marker is not there (same "
                        "corners, ~5x less CPU); 0: every frame searched whole", high=10.0),
    "roi_border": Param(16, "[px] added to the region of interest's margin on every side", high=10000),
    "roi_hold": Param(10, "frames without the marker during which its last region of interest is still searched "
                      "first (then the whole frame); 0: forgotten at once", high=1000),
    "publish_debug_image": (False, "publish marker/debug_image with the pose axes drawn"),
    "log_interval": (2.0, "[s] minimum interval between repeated warnings"),
}


class ArucoDetectorNode(Node):
    def __init__(self, **kwargs) -> None:
        """kwargs go to rclpy.node.Node (context, namespace, parameter_overrides, ...)."""
        super().__init__("aruco_detector", **kwargs)
        self.parameters = NodeParameters(self)
        self.parameters.declare_all(_PARAMETERS)
        p = {name: self.get_parameter(name).value for name in _PARAMETERS}
        self._config = ArucoConfig(
            dictionary=str(p["dictionary"]), marker_id=int(p["marker_id"]), marker_size=float(p["marker_size"]),
            corner_refinement=str(p["corner_refinement"]),
            corner_refinement_win_size=int(p["corner_refinement_win_size"]),
            corner_refinement_max_iterations=int(p["corner_refinement_max_iterations"]),
            corner_refinement_min_accuracy=float(p["corner_refinement_min_accuracy"]),
            adaptive_thresh_win_size_min=int(p["adaptive_thresh_win_size_min"]),
            adaptive_thresh_win_size_max=int(p["adaptive_thresh_win_size_max"]),
            adaptive_thresh_win_size_step=int(p["adaptive_thresh_win_size_step"]),
            min_marker_perimeter_rate=float(p["min_marker_perimeter_rate"]),
            april_tag_min_white_black_diff=int(p["april_tag_min_white_black_diff"]),
            ambiguity_threshold=float(p["ambiguity_threshold"]), roi_margin=float(p["roi_margin"]),
            roi_border=int(p["roi_border"]), roi_hold=int(p["roi_hold"]))
        self._detector = ArucoPoseDetector(self._config)
        if apply_opencv_dispatch() != "native":  # simulation: detections the same on every CPU
            self.get_logger().info(f"OpenCV dispatch: baseline ({ENVIRONMENT_VARIABLE}): detections do not depend "
                                   "on the CPU's SIMD features")
        self._debug = bool(p["publish_debug_image"])
        self._log_interval = float(p["log_interval"])
        self._camera: CameraModel | None = None
        self.frames = 0
        self.detections = 0
        # REP-2003: publishers reliable (any subscriber can connect), the subscribers choose the sensor-data profile
        self._pub = self.create_publisher(MarkerDetection, "marker", 10)
        self._debug_pub = self.create_publisher(Image, "marker/debug_image", 10) \
            if self._debug else None
        self.create_subscription(CameraInfo, "camera/camera_info", self._on_camera_info, qos_profile_sensor_data)
        self.create_subscription(Image, "camera/image_raw", self._on_image, qos_profile_sensor_data)

    def _on_camera_info(self, msg: CameraInfo) -> None:
        try:
            camera = CameraModel.from_camera_info(msg.width, msg.height, list(msg.k), list(msg.d))
        except ValueError as error:
            self.get_logger().warning(f"camera_info refused: {error}", **throttle(self, self._log_interval))
            return
        if camera != self._camera:
            self.get_logger().info(f"camera: {camera.width}×{camera.height}, fx={camera.fx:.1f}, fy={camera.fy:.1f}")
        self._camera = camera

    def _on_image(self, msg: Image) -> None:
        self.frames += 1
        if self._camera is None:
            self.get_logger().warning("image received but no camera_info yet: no detection",
                                      **throttle(self, self._log_interval))
            return
        try:
            image = decode_image(msg.encoding, msg.width, msg.height, msg.step, msg.data)
            observation = self._detector.detect(image, self._camera)
        except (ValueError, cv2.error) as error:
            self.get_logger().warning(f"image refused: {error}", **throttle(self, self._log_interval))
            return
        if observation is None:
            return
        self.detections += 1
        out = MarkerDetection()
        out.header = msg.header
        out.marker_id = int(observation.marker_id)
        T = observation.camera_T_marker
        out.pose.position.x, out.pose.position.y, out.pose.position.z = (float(v) for v in T[:3, 3])
        w, x, y, z = rotmat_to_quat(T[:3, :3])
        out.pose.orientation.w, out.pose.orientation.x = float(w), float(x)
        out.pose.orientation.y, out.pose.orientation.z = float(y), float(z)
        out.reprojection_error = float(observation.reprojection_error)
        out.ambiguity_ratio = float(min(observation.ambiguity_ratio, 1e9))
        out.corners = [float(v) for v in observation.corners.ravel()]
        out.marker_size = float(self._config.marker_size)
        self._pub.publish(out)
        if self._debug_pub is not None:
            self._publish_debug(msg, image, observation)

    def _publish_debug(self, msg: Image, image: np.ndarray, observation) -> None:
        canvas = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        cv2.drawFrameAxes(canvas, self._camera.camera_matrix, self._camera.dist_coeffs, observation.rvec,
                          observation.tvec, 0.5 * self._config.marker_size)
        debug = Image()
        debug.header = msg.header
        debug.height, debug.width = canvas.shape[:2]
        debug.encoding = "bgr8"
        debug.step = debug.width * 3
        debug.data = canvas.tobytes()
        self._debug_pub.publish(debug)


def main(args=None) -> None:
    spin_node(ArucoDetectorNode, args)
