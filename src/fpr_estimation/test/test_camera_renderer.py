"""fpr_sim.camera_renderer: geometry, visibility, determinism, noise, emulated relative poses."""

import numpy as np
from fpr_model.calibration import CameraModel, make_transform
from fpr_model.rotations import quat_from_rotvec, quat_to_rotmat, quat_to_rotvec, rotmat_to_quat
from fpr_sim.camera_renderer import MarkerRenderer, emulate_relative_pose


def _facing(distance, tilt=(0.0, 0.0, 0.0), offset=(0.0, 0.0)):
    """Marker in front of the camera, its face towards it (marker z = −camera z), slightly tilted."""
    R = np.diag([1.0, -1.0, -1.0]) @ quat_to_rotmat(quat_from_rotvec(np.asarray(tilt, dtype=float)))
    return make_transform(R, [offset[0], offset[1], distance])


def test_corners_are_the_projection_and_image_is_drawn():
    renderer = MarkerRenderer()
    frame = renderer.render(_facing(1.0, (0.2, -0.1, 0.3)))
    assert frame.image.shape == (480, 640) and frame.image.dtype == np.uint8
    assert frame.drawn and frame.in_view
    expected = CameraModel().project(renderer.marker_corners @ _facing(1.0, (0.2, -0.1, 0.3))[:3, :3].T
                                     + [0.0, 0.0, 1.0])
    assert np.allclose(frame.corners, expected, atol=1e-9)
    # Inside the marker's black border (just inside the TL corner, along the diagonal) the image is black;
    # the quiet zone just outside is white; far away is the background.
    centre = frame.corners.mean(axis=0)
    inside = frame.corners[0] + 0.05 * (centre - frame.corners[0])
    outside = frame.corners[0] - 0.05 * (centre - frame.corners[0])
    assert frame.image[int(round(inside[1])), int(round(inside[0]))] < 40
    assert frame.image[int(round(outside[1])), int(round(outside[0]))] > 215
    assert frame.image[5, 5] == renderer.background


def test_not_drawn_behind_or_outside():
    renderer = MarkerRenderer()
    behind = renderer.render(_facing(-1.0))
    assert not behind.drawn and not behind.in_view and np.all(behind.image == renderer.background)
    aside = renderer.render(_facing(1.0, offset=(5.0, 0.0)))
    assert not aside.drawn and not aside.in_view and np.all(aside.image == renderer.background)
    partly = renderer.render(_facing(1.0, offset=(0.64, 0.0)))  # straddles the right border
    assert partly.drawn and not partly.in_view
    assert np.isnan(renderer.render(np.full((4, 4), np.nan)).corners).all()


def test_deterministic_noise_and_blur():
    renderer = MarkerRenderer()
    pose = _facing(0.8, (0.1, 0.2, 0.0))
    a = renderer.render(pose, blur_sigma=1.0, noise_sigma=5.0, rng=np.random.default_rng(7)).image
    b = renderer.render(pose, blur_sigma=1.0, noise_sigma=5.0, rng=np.random.default_rng(7)).image
    c = renderer.render(pose, blur_sigma=1.0, noise_sigma=5.0, rng=np.random.default_rng(8)).image
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    background = a[:40, :40].astype(float)
    assert 3.0 < background.std() < 7.0


def test_emulated_relative_pose_statistics():
    rng = np.random.default_rng(1)
    truth = make_transform(quat_to_rotmat(quat_from_rotvec([0.3, -0.2, 1.0])), [0.5, -0.2, -0.9])
    samples = [emulate_relative_pose(truth, rng) for _ in range(2000)]
    position_std = np.std([s[:3, 3] - truth[:3, 3] for s in samples], axis=0)
    angle_errors = np.array([quat_to_rotvec(rotmat_to_quat(truth[:3, :3].T @ s[:3, :3])) for s in samples])
    assert np.allclose(position_std, 0.02, rtol=0.1)
    assert np.allclose(np.degrees(angle_errors.std(axis=0)), 2.0, rtol=0.1)
