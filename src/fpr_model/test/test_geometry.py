"""Tests of fpr_model.geometry: anchors (E1, M5), leg rotation (2.8), IGM (2.5)-(2.9), leg angles (2.11)."""

import numpy as np
import pytest
from fpr_model.geometry import (
    difference_configuration,
    integrate_configuration,
    inverse_geometric_model,
    leg_anchor_angles,
    leg_angles_from_positions,
    make_configuration,
    platform_to_leg_rotation,
    split_configuration,
    split_velocity,
)
from fpr_model.parameters import default_parameters

from fpr_model import rotations as rt


def test_m5_anchor_layout():
    assert np.allclose(np.degrees(leg_anchor_angles(3)), [0, 120, 240])
    assert np.allclose(np.degrees(leg_anchor_angles(4)), [0, 90, 180, 270])
    with pytest.raises(ValueError, match="n"):
        leg_anchor_angles(2)


def test_leg_rotation_is_zxz_product():
    rng = np.random.default_rng(0)
    for alpha, theta in rng.uniform(-3, 3, (20, 2)):
        R = platform_to_leg_rotation(alpha, theta)
        assert np.allclose(R, rt.rot_z(alpha) @ rt.rot_x(-np.pi / 2) @ rt.rot_z(theta), atol=1e-15)
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-15) and abs(np.linalg.det(R) - 1) < 1e-15
    batch = platform_to_leg_rotation(leg_anchor_angles(3), [0.1, 0.2, 0.3])
    assert batch.shape == (3, 3, 3)


def test_igm_flat_platform_legs_down():
    p = default_parameters()
    q = make_configuration([1.0, 2.0, 3.0], [1, 0, 0, 0], np.full(3, np.pi / 2))
    positions = inverse_geometric_model(p, q)
    alpha = leg_anchor_angles(3)
    expected = np.array([1.0, 2.0, 3.0]) + np.column_stack([0.127 * np.cos(alpha), 0.127 * np.sin(alpha),
                                                            np.full(3, -1.043)])
    assert np.allclose(positions, expected, atol=1e-15)
    # 45°: quadrotors below and outside the platform.
    q = make_configuration([0, 0, 0], [1, 0, 0, 0], np.full(3, np.pi / 4))
    positions = inverse_geometric_model(p, q)
    assert np.all(positions[:, 2] < 0)
    assert np.allclose(np.linalg.norm(positions[:, :2], axis=1), 0.127 + 1.043 / np.sqrt(2))


def test_igm_leg_lengths_and_leg_angles_round_trip():
    p = default_parameters(5)
    rng = np.random.default_rng(1)
    for _ in range(50):
        q = make_configuration(rng.normal(size=3), rng.normal(size=4), rng.uniform(0.01, np.pi - 0.01, 5))
        position, quat, angles = split_configuration(q)
        uav = inverse_geometric_model(p, q)
        anchors = position[:, None] + rt.quat_to_rotmat(quat) @ (0.127 * np.stack(
            [np.cos(leg_anchor_angles(5)), np.sin(leg_anchor_angles(5)), np.zeros(5)]))
        assert np.allclose(np.linalg.norm(uav - anchors.T, axis=1), p.leg_length, atol=1e-12)
        assert np.allclose(leg_angles_from_positions(p, position, quat, uav), angles, atol=1e-10)
        signed = leg_angles_from_positions(p, position, quat, uav, signed=True)
        assert np.allclose(signed, angles, atol=1e-10)
    # A quadrotor above the platform plane: the thesis acos loses the sign, the signed variant keeps it.
    q = make_configuration([0, 0, 0], [1, 0, 0, 0], [-0.3, 0.4, 0.5, 0.6, 0.7])
    uav = inverse_geometric_model(p, q)
    assert leg_angles_from_positions(p, [0, 0, 0], [1, 0, 0, 0], uav)[0] == pytest.approx(0.3)
    assert leg_angles_from_positions(p, [0, 0, 0], [1, 0, 0, 0], uav, signed=True)[0] == pytest.approx(-0.3)


def test_configuration_helpers():
    q = make_configuration([1, 2, 3], [2, 0, 0, 0], [0.1, 0.2, 0.3])
    assert np.allclose(q, [1, 2, 3, 1, 0, 0, 0, 0.1, 0.2, 0.3])
    parts = split_configuration(q)
    assert np.allclose(parts.platform_quat, [1, 0, 0, 0]) and np.allclose(parts.leg_angles, [0.1, 0.2, 0.3])
    velocity = split_velocity(np.arange(9.0))
    assert np.allclose(velocity.platform_rate, [3, 4, 5]) and np.allclose(velocity.leg_rates, [6, 7, 8])
    rng = np.random.default_rng(2)
    nu = rng.normal(size=9)
    q1 = integrate_configuration(q, nu, 0.7)
    assert np.allclose(difference_configuration(q, q1), 0.7 * nu, atol=1e-12)
    assert np.allclose(integrate_configuration(q1, nu, -0.7), q, atol=1e-12)
    # The quaternion moves with the body-frame rate.
    expected = rt.quat_integrate(q[3:7], nu[3:6], 0.7)
    assert np.allclose(q1[3:7], expected, atol=1e-15)


def test_bad_input_names_argument():
    p = default_parameters()
    q = make_configuration([0, 0, 0], [1, 0, 0, 0], [0.5] * 3)
    with pytest.raises(ValueError, match="q"):
        inverse_geometric_model(p, np.r_[q[:-1], np.nan])
    with pytest.raises(ValueError, match="q"):
        inverse_geometric_model(p, q[:-1])
    with pytest.raises(ValueError, match="q"):
        inverse_geometric_model(p, np.r_[q[:3], 0, 0, 0, 0, q[7:]])
    with pytest.raises(ValueError, match="uav_positions"):
        leg_angles_from_positions(p, [0, 0, 0], [1, 0, 0, 0], np.full((3, 3), np.inf))
    with pytest.raises(ValueError, match="platform_quat"):
        make_configuration([0, 0, 0], [0, 0, 0, 0], [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="leg_angles"):
        make_configuration([0, 0, 0], [1, 0, 0, 0], [0.1, 0.2])
    with pytest.raises(ValueError, match="nu"):
        integrate_configuration(q, np.zeros(8), 0.1)
