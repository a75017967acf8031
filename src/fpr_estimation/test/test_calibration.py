"""fpr_model.calibration: transforms (4.1)-(4.3), Table D.1, camera model, and the marker-visibility decision."""

import numpy as np
import pytest
from fpr_estimation.synthetic import uav_pose_in_platform
from fpr_model.calibration import (
    TABLE_D1_CAMERA,
    TABLE_D1_MARKER,
    CameraModel,
    EulerZxzPose,
    VisionCalibration,
    compose_transforms,
    invert_transform,
    load_vision_calibration,
    make_transform,
    transform_points,
)
from fpr_model.parameters import default_parameters
from fpr_model.rotations import euler_zxz_to_rotmat, quat_from_rotvec, quat_to_rotmat
from fpr_sim.camera_renderer import MarkerRenderer


def _random_transform(rng):
    return make_transform(quat_to_rotmat(quat_from_rotvec(rng.normal(size=3))), rng.normal(size=3))


def test_invert_and_compose():
    rng = np.random.default_rng(0)
    A, B = _random_transform(rng), _random_transform(rng)
    assert np.allclose(invert_transform(A) @ A, np.eye(4), atol=1e-12)
    assert np.allclose(invert_transform(A), np.linalg.inv(A), atol=1e-12)
    assert np.allclose(compose_transforms(A, B), A @ B, atol=1e-15)
    points = rng.normal(size=(5, 3))
    assert np.allclose(transform_points(A, points), (A[:3, :3] @ points.T).T + A[:3, 3])
    with pytest.raises(ValueError):
        make_transform(np.eye(3), [0.0, np.nan, 0.0])


def test_table_d1_values_and_round_trip():
    # Extrinsic reading: R = Rz(psi2) Rx(phi) Rz(psi1); intrinsic: (A.44) as printed.
    assert np.allclose(TABLE_D1_CAMERA.rotation, euler_zxz_to_rotmat(0.829, 0.708, 1.561))
    literal = EulerZxzPose(TABLE_D1_CAMERA.translation_cm, TABLE_D1_CAMERA.euler_zxz, "intrinsic")
    assert np.allclose(literal.rotation, euler_zxz_to_rotmat(1.561, 0.708, 0.829))
    assert np.allclose(TABLE_D1_CAMERA.translation, [0.0845, -0.0935, 0.0079])
    for pose in (TABLE_D1_CAMERA, TABLE_D1_MARKER, literal):
        back = EulerZxzPose.from_transform(pose.transform, pose.euler_order)
        assert np.allclose(back.euler_zxz, pose.euler_zxz, atol=1e-8)  # spec X6 (E16), even near phi = pi
        assert np.allclose(back.translation_cm, pose.translation_cm, atol=1e-12)
    # The marker faces down (its z axis), in both readings.
    assert TABLE_D1_MARKER.rotation[2, 2] < -0.99
    # The camera looks up and towards the platform side (front right, azimuth about -42.5 deg).
    axis = TABLE_D1_CAMERA.rotation[:, 2]
    assert np.degrees(np.arctan2(axis[1], axis[0])) == pytest.approx(-42.5, abs=0.5)
    assert np.degrees(np.arcsin(axis[2])) == pytest.approx(49.5, abs=0.5)


def _visible_fraction(calibration, leg_angles_deg, roll=0.0, pitch=0.0):
    params = default_parameters()
    renderer = MarkerRenderer(calibration.camera, calibration.marker_size)
    seen = total = 0
    for theta in leg_angles_deg:
        poses, _, _ = uav_pose_in_platform(params, [np.radians(theta)] * 3, roll, pitch)
        for pose in poses:
            camera_T_marker = compose_transforms(invert_transform(calibration.body_T_camera), invert_transform(pose),
                                                 calibration.platform_T_marker)
            seen += renderer.render(camera_T_marker).in_view
            total += 1
    return seen / total


def test_marker_in_view_of_all_cameras_flat_platform_45_to_75_deg():
    """The simulator acceptance needs every camera to see the marker (flat platform, legs 45-75 deg)."""
    assert _visible_fraction(VisionCalibration(), range(45, 76, 5)) == 1.0


def test_literal_intrinsic_reading_of_table_d1_loses_the_marker():
    """Why the extrinsic reading was chosen: with (A.44) as printed the marker is mostly out of the image."""
    literal = VisionCalibration(
        EulerZxzPose(TABLE_D1_CAMERA.translation_cm, TABLE_D1_CAMERA.euler_zxz, "intrinsic"),
        EulerZxzPose(TABLE_D1_MARKER.translation_cm, TABLE_D1_MARKER.euler_zxz, "intrinsic"))
    assert _visible_fraction(literal, range(45, 76, 5)) < 0.5


def test_camera_model_and_yaml(tmp_path):
    camera = CameraModel()
    assert camera.camera_matrix[0, 0] == 500.0 and not camera.has_distortion
    with pytest.raises(ValueError):
        CameraModel(fx=-1.0)
    with pytest.raises(ValueError):
        CameraModel(distortion=(0.1, 0.2, 0.3))
    info = CameraModel.from_camera_info(640, 480, [500, 0, 321, 0, 501, 239, 0, 0, 1], [0.1, -0.2, 0, 0, 0])
    assert (info.fx, info.fy, info.cx, info.cy) == (500, 501, 321, 239) and info.has_distortion
    path = tmp_path / "cal.yaml"
    path.write_text("node:\n  ros__parameters:\n    euler_order: intrinsic\n    marker_size: 0.2\n"
                    "    camera: {fx: 600.0}\n    camera_pose: {translation_cm: [1, 2, 3]}\n")
    cal = load_vision_calibration(path)
    assert cal.marker_size == 0.2 and cal.camera.fx == 600.0 and cal.camera.fy == 500.0
    assert np.allclose(cal.camera_pose.translation, [0.01, 0.02, 0.03])
    assert cal.camera_pose.euler_order == "intrinsic"
    assert np.allclose(load_vision_calibration().body_T_camera, TABLE_D1_CAMERA.transform)
