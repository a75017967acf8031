"""Reconstruction (4.17)-(4.23) from exact inputs vs the IGM ground truth; independence of the UAV yaw offset."""

import numpy as np
import pytest
from fpr_estimation.reconstruction import leg_anchor, leg_angle, reconstruct_local_state
from fpr_model.geometry import inverse_geometric_model, make_configuration
from fpr_model.parameters import default_parameters
from fpr_model.rotations import (
    euler_zyx_to_quat,
    quat_from_rotvec,
    quat_to_rotmat,
    rot_z,
    rotmat_to_euler_zyx,
    rotmat_to_quat,
)


def _random_case(rng, params):
    roll, pitch = rng.uniform(-0.35, 0.35, 2)
    yaw = rng.uniform(-np.pi, np.pi)
    legs = rng.uniform(np.radians(20.0), np.radians(89.0), params.n)
    quat_p = euler_zyx_to_quat(roll, pitch, yaw)
    position = rng.normal(size=3)
    positions = inverse_geometric_model(params, make_configuration(position, quat_p, legs))
    R_p = quat_to_rotmat(quat_p)
    uav_rotations = [quat_to_rotmat(quat_from_rotvec(rng.normal(scale=0.4, size=3))) @ rot_z(rng.uniform(-3, 3))
                     for _ in range(params.n)]
    uav_velocities = rng.normal(size=(params.n, 3))
    return roll, pitch, yaw, legs, position, R_p, positions, uav_rotations, uav_velocities


@pytest.mark.parametrize("seed", range(5))
def test_reconstruction_matches_ground_truth(seed):
    rng = np.random.default_rng(seed)
    params = default_parameters()
    roll, pitch, yaw, legs, p_p, R_p, positions, uav_R, uav_v = _random_case(rng, params)
    flat_R_world = rot_z(-yaw)  # F_Fp: the world rotated by the platform yaw
    for i in range(params.n):
        relative_position = R_p.T @ (positions[i] - p_p)  # p_p_i
        platform_R_uav = R_p.T @ uav_R[i]  # p_R_i
        for yaw_offset in (0.0, 1.3, -2.9):  # the UAV's unknown local frame F0i
            rec = reconstruct_local_state(relative_position, platform_R_uav,
                                          leg_anchor(params.platform_radius, params.n, i + 1),
                                          rot_z(yaw_offset) @ uav_R[i], uav_R[i].T @ uav_v[i])
            assert rec.leg_angle == pytest.approx(legs[i], abs=1e-9)
            assert rec.platform_roll == pytest.approx(roll, abs=1e-9)
            assert rec.platform_pitch == pytest.approx(pitch, abs=1e-9)
            expected_attitude = rotmat_to_quat(flat_R_world @ uav_R[i])
            assert np.allclose(rec.uav_attitude_flat, expected_attitude, atol=1e-9)
            assert np.allclose(rec.uav_velocity_flat, flat_R_world @ uav_v[i], atol=1e-9)
            assert rec.relative_yaw == pytest.approx(rotmat_to_euler_zyx(platform_R_uav)[2], abs=1e-12)
            assert rec.uav_yaw == pytest.approx(
                np.angle(np.exp(1j * (rotmat_to_euler_zyx(uav_R[i])[2] + yaw_offset))), abs=1e-9)


def test_yaw_offset_does_not_change_the_reconstruction():
    rng = np.random.default_rng(11)
    params = default_parameters()
    _, _, _, _, p_p, R_p, positions, uav_R, uav_v = _random_case(rng, params)
    anchor = leg_anchor(params.platform_radius, params.n, 2)
    args = (R_p.T @ (positions[1] - p_p), R_p.T @ uav_R[1], anchor)
    a = reconstruct_local_state(*args, uav_R[1], uav_v[1])
    b = reconstruct_local_state(*args, rot_z(2.0) @ uav_R[1], uav_v[1])
    for field in ("leg_angle", "platform_roll", "platform_pitch", "relative_yaw"):
        assert getattr(a, field) == pytest.approx(getattr(b, field), abs=1e-12)
    assert np.allclose(a.uav_attitude_flat, b.uav_attitude_flat, atol=1e-12)
    assert np.allclose(a.uav_velocity_flat, b.uav_velocity_flat, atol=1e-12)


def test_anchor_and_leg_angle():
    assert np.allclose(leg_anchor(0.127, 3, 2), 0.127 * np.array([np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3), 0]))
    with pytest.raises(ValueError):
        leg_anchor(0.127, 3, 0)
    with pytest.raises(ValueError):
        leg_anchor(0.127, 3, 4)
    anchor = np.array([0.127, 0.0, 0.0])
    assert leg_angle(anchor + [np.cos(0.7), 0.0, -np.sin(0.7)], anchor) == pytest.approx(0.7, abs=1e-12)
