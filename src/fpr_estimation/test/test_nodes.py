"""aruco_detector and pose_estimator nodes in process (real rclpy), fabricated inputs, simulated time."""

import math
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from builtin_interfaces.msg import Time as TimeMsg  # noqa: E402
from fpr_estimation.aruco_detector import ArucoDetectorNode  # noqa: E402
from fpr_estimation.pose_estimator import PoseEstimatorNode  # noqa: E402
from fpr_estimation.synthetic import uav_pose_in_platform  # noqa: E402
from fpr_model.calibration import VisionCalibration, compose_transforms, invert_transform  # noqa: E402
from fpr_model.parameters import default_parameters  # noqa: E402
from fpr_model.rotations import quat_to_rotmat, rot_z, rotmat_to_euler_zyx, rotmat_to_quat  # noqa: E402
from fpr_sim.camera_renderer import MarkerRenderer  # noqa: E402
from geometry_msgs.msg import TwistStamped  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image, Imu  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402

from fpr_msgs.msg import LocalState, MarkerDetection  # noqa: E402

NS = "/fpr/uav1"
LEG = math.radians(55.0)
ROLL, PITCH = math.radians(4.0), math.radians(-3.0)


def wait_for(predicate, timeout=5.0, step=0.002):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(step)
    return predicate()


@pytest.fixture(scope="module")
def scene():
    calibration = VisionCalibration()
    poses, world_rotations, _ = uav_pose_in_platform(default_parameters(), [LEG] * 3, ROLL, PITCH, 0.7)
    camera_T_marker = compose_transforms(invert_transform(calibration.body_T_camera), invert_transform(poses[0]),
                                         calibration.platform_T_marker)
    return calibration, poses[0], world_rotations[0], camera_T_marker


@pytest.fixture
def graph():
    context = rclpy.Context()
    rclpy.init(context=context)
    nodes = []

    def add(node):
        nodes.append(node)
        executor.add_node(node)
        return node

    executor = SingleThreadedExecutor(context=context)
    helper = add(rclpy.create_node("estimation_test_helper", context=context))
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    yield context, helper, add
    executor.shutdown()
    spinner.join(timeout=2.0)  # no callback may run on a node being destroyed
    for node in nodes:
        node.destroy_node()
    rclpy.shutdown(context=context)


def _image_msg(image, encoding="mono8"):
    msg = Image()
    msg.height, msg.width = image.shape[:2]
    msg.encoding = encoding
    msg.step = msg.width * (1 if image.ndim == 2 else image.shape[2])
    msg.data = image.tobytes()
    return msg


def _camera_info(camera):
    msg = CameraInfo()
    msg.width, msg.height = camera.width, camera.height
    msg.k = [float(v) for v in camera.camera_matrix.ravel()]
    msg.d = [float(v) for v in camera.dist_coeffs]
    msg.distortion_model = "plumb_bob"
    return msg


def test_aruco_detector_node(graph, scene):
    context, helper, add = graph
    calibration, _, _, camera_T_marker = scene
    node = add(ArucoDetectorNode(context=context, namespace=NS))
    image_pub = helper.create_publisher(Image, f"{NS}/camera/image_raw", qos_profile_sensor_data)
    info_pub = helper.create_publisher(CameraInfo, f"{NS}/camera/camera_info", qos_profile_sensor_data)
    received = []
    helper.create_subscription(MarkerDetection, f"{NS}/marker", received.append, qos_profile_sensor_data)
    assert wait_for(lambda: image_pub.get_subscription_count() > 0 and info_pub.get_subscription_count() > 0)
    good = _image_msg(MarkerRenderer(calibration.camera).render(camera_T_marker).image)
    # No camera_info yet: the image is counted but nothing is published.
    image_pub.publish(good)
    assert wait_for(lambda: node.frames >= 1)
    info_pub.publish(_camera_info(calibration.camera))
    assert wait_for(lambda: node._camera is not None)
    # Bad images: empty, unsupported encoding, truncated, garbled -> no output, no crash.
    empty = Image()
    wrong = _image_msg(np.zeros((480, 640), np.uint16), "16UC1")
    truncated = _image_msg(np.zeros((480, 640), np.uint8))
    truncated.data = truncated.data[:1000]
    garbled = _image_msg(np.random.default_rng(0).integers(0, 256, (480, 640), dtype=np.uint8))
    for msg in (empty, wrong, truncated, garbled):
        image_pub.publish(msg)
    assert wait_for(lambda: node.frames >= 5)
    assert received == []
    # A good image: a detection close to the truth.
    assert wait_for(lambda: (image_pub.publish(good), len(received) > 0)[1], timeout=5.0, step=0.05)
    msg = received[-1]
    assert msg.marker_id == 0 and msg.marker_size == pytest.approx(0.109)
    position = np.array([msg.pose.position.x, msg.pose.position.y, msg.pose.position.z])
    assert np.linalg.norm(position - camera_T_marker[:3, 3]) < 0.01
    q = np.array([msg.pose.orientation.w, msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z])
    assert abs(abs(q @ rotmat_to_quat(camera_T_marker[:3, :3])) - 1.0) < 1e-4
    assert msg.reprojection_error < 0.5 and msg.ambiguity_ratio > 1.0 and len(msg.corners) == 8
    # the next frames are searched in the region of interest first (roi_margin 0.5 by default): same corners
    assert node._detector.roi is not None
    hits, count = node._detector.roi_hits, len(received)
    image_pub.publish(good)
    assert wait_for(lambda: len(received) > count)
    assert node._detector.roi_hits > hits
    assert list(received[-1].corners) == pytest.approx(list(msg.corners), abs=1e-3)


def test_pose_estimator_node_with_sim_time(graph, scene):
    context, helper, add = graph
    _, platform_T_body, world_R_body, camera_T_marker = scene
    node = add(PoseEstimatorNode(context=context, namespace=NS, parameter_overrides=[
        Parameter("use_sim_time", value=True), Parameter("uav_id", value=1)]))
    clock_pub = helper.create_publisher(Clock, "/clock", 10)
    imu_pub = helper.create_publisher(Imu, f"{NS}/imu", qos_profile_sensor_data)
    velocity_pub = helper.create_publisher(TwistStamped, f"{NS}/velocity_body", qos_profile_sensor_data)
    marker_pub = helper.create_publisher(MarkerDetection, f"{NS}/marker", qos_profile_sensor_data)
    states, tfs = [], []
    helper.create_subscription(LocalState, f"{NS}/local_state", states.append, 100)
    helper.create_subscription(TFMessage, "/tf", tfs.append, 100)
    assert wait_for(lambda: all(p.get_subscription_count() > 0 for p in (clock_pub, imu_pub, velocity_pub,
                                                                         marker_pub)))
    assert wait_for(lambda: node._pub.get_subscription_count() > 0)
    yaw_offset = 2.0  # the UAV's local frame F0i is rotated by an unknown yaw
    imu_quat = rotmat_to_quat(rot_z(yaw_offset) @ world_R_body)
    marker = MarkerDetection()
    marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = camera_T_marker[:3, 3]
    qm = rotmat_to_quat(camera_T_marker[:3, :3])
    marker.pose.orientation.w, marker.pose.orientation.x = qm[0], qm[1]
    marker.pose.orientation.y, marker.pose.orientation.z = qm[2], qm[3]
    velocity = TwistStamped()
    velocity.twist.linear.x = 0.3

    def stamp(t):
        return TimeMsg(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))

    def step_to(t, detect=True, nan_imu=False, rate=0.0):
        clock_pub.publish(Clock(clock=stamp(t)))
        assert wait_for(lambda: node.get_clock().now().nanoseconds >= int(round(t * 1e9)), timeout=2.0)
        imu = Imu()
        imu.header.stamp = stamp(t)
        imu.orientation.w, imu.orientation.x, imu.orientation.y, imu.orientation.z = (
            (math.nan,) * 4 if nan_imu else imu_quat)
        imu.angular_velocity.z = rate
        imu_pub.publish(imu)
        velocity_pub.publish(velocity)
        if detect and round(t / 0.005) % 10 == 0:  # 20 Hz
            marker_pub.publish(marker)

    t = 1.0
    for _ in range(400):  # 2 s of simulated time at 200 Hz
        t += 0.005
        step_to(t)
    assert wait_for(lambda: len(states) >= 90)
    stamps = np.array([s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec for s in states])
    window = stamps[(stamps > 1.5) & (stamps <= 2.5)]
    assert len(window) == 50  # 50 Hz in simulated time
    assert np.allclose(np.diff(stamps), 0.02, atol=1e-6)
    last = states[-1]
    assert last.valid and last.uav_id == 1 and last.header.frame_id == "uav1/platform"
    assert last.leg_angle == pytest.approx(LEG, abs=1e-3)
    assert last.platform_roll == pytest.approx(ROLL, abs=1e-3)
    assert last.platform_pitch == pytest.approx(PITCH, abs=1e-3)
    assert last.relative_pose.position.x == pytest.approx(platform_T_body[0, 3], abs=1e-3)
    assert last.relative_yaw == pytest.approx(rotmat_to_euler_zyx(platform_T_body[:3, :3])[2], abs=1e-3)
    assert last.detection_age < 0.06 and last.rejected_detections == 0
    # Issue 14: the estimate on /tf, uav1/base_link -> uav1/platform_estimate, is the platform's pose in the body:
    # the inverse of p T_bi, here the scene's true body_T_platform (stamped like the local_state)
    assert wait_for(lambda: any(m.transforms[0].header.stamp == last.header.stamp for m in tfs))
    (transform,) = next(m.transforms for m in tfs if m.transforms[0].header.stamp == last.header.stamp)
    assert (transform.header.frame_id, transform.child_frame_id) == ("uav1/base_link", "uav1/platform_estimate")
    body_T_platform = np.linalg.inv(platform_T_body)
    tr, rot = transform.transform.translation, transform.transform.rotation
    assert [tr.x, tr.y, tr.z] == pytest.approx(body_T_platform[:3, 3].tolist(), abs=2e-3)
    assert np.allclose(quat_to_rotmat([rot.w, rot.x, rot.y, rot.z]), body_T_platform[:3, :3], atol=2e-3)
    # Issue 12's fault: IMU rates of 1e9 rad/s are refused; the estimate stays valid, finite and unmoved.
    for _ in range(40):
        t += 0.005
        step_to(t, rate=1e9)
    assert wait_for(lambda: states[-1].header.stamp.sec + 1e-9 * states[-1].header.stamp.nanosec >= t - 0.021)
    assert wait_for(lambda: node.core.refused.get("imu_rate", 0) >= 40) and node.core.refused["imu_rate"] == 40
    assert states[-1].valid and np.isfinite(states[-1].pose_stddev).all()
    assert states[-1].relative_yaw == pytest.approx(rotmat_to_euler_zyx(platform_T_body[:3, :3])[2], abs=1e-3)
    # Detections stop and the IMU sends NaN: no crash, finite output, stale after 0.5 s.
    for _ in range(120):
        t += 0.005
        step_to(t, detect=False, nan_imu=True)
    assert wait_for(lambda: states[-1].header.stamp.sec + 1e-9 * states[-1].header.stamp.nanosec >= t - 0.021)
    assert not states[-1].valid and states[-1].detection_age > 0.5
    assert all(np.isfinite([s.leg_angle, s.platform_roll, s.relative_pose.orientation.w]).all() for s in states)
