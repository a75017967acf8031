"""The true TF tree: the chain world -> platform -> leg<i> -> uav<i>/base_link reproduces the ground truth."""

import numpy as np
from fpr_model.rotations import quat_to_rotmat
from fpr_sim.plant import Plant
from fpr_sim.scenario import scenario_from_dict
from fpr_sim.tf_tree import camera_transforms, robot_transforms


def _matrix(transform):
    T = np.eye(4)
    T[:3, :3] = quat_to_rotmat(transform.quat)
    T[:3, 3] = transform.translation
    return T


def _chain(transforms, child):
    by_child = {t.child: t for t in transforms}
    T = np.eye(4)
    while child in by_child:
        transform = by_child[child]
        T = _matrix(transform) @ T
        child = transform.parent
    assert child == "world"
    return T


def test_chain_reproduces_the_true_uav_poses_with_model_mismatch():
    plant = Plant(scenario_from_dict({"initial_state": {"mode": "hover", "leg_angles": [0.8, 1.0, 0.9]}},
                                     realism="hardware"))
    for _ in range(300):
        plant.step()
    truth = plant.ground_truth()
    s = truth.state
    transforms = robot_transforms(plant.params, s.position, s.quat, s.leg_angles, truth.uav_positions, truth.uav_quats)
    assert len(transforms) == 1 + 2 * plant.n
    for i in range(plant.n):
        T = _chain(transforms, f"uav{i + 1}/base_link")
        np.testing.assert_allclose(T[:3, 3], truth.uav_positions[i], atol=1e-9)
        np.testing.assert_allclose(T[:3, :3], quat_to_rotmat(truth.uav_quats[i]), atol=1e-9)
        leg_to_uav = next(t for t in transforms if t.child == f"uav{i + 1}/base_link")
        # the tip is the TRUE leg length along x of F_li (the drawn one, not Table B.1's)
        np.testing.assert_allclose(leg_to_uav.translation, [plant.params.leg_length, 0.0, 0.0], atol=1e-6)


def test_camera_transforms_are_the_mountings():
    mount = np.eye(4)
    mount[:3, 3] = [0.05, 0.0, -0.04]
    (static,) = camera_transforms([mount])
    assert (static.parent, static.child) == ("uav1/base_link", "uav1/camera_optical")
    np.testing.assert_allclose(_matrix(static), mount)
