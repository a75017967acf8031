"""Tests of fpr_model.frames (ENU/FLU <-> NED/FRD), spec px4_ros_facts.md §1.7."""

import numpy as np
import pytest

from fpr_model import frames as fr
from fpr_model import rotations as rt


def test_vector_conversions_and_round_trips():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(100, 3))
    assert np.allclose(fr.enu_to_ned([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0], atol=0)
    assert np.allclose(fr.flu_to_frd([1.0, 2.0, 3.0]), [1.0, -2.0, -3.0], atol=0)
    assert np.abs(fr.ned_to_enu(fr.enu_to_ned(v)) - v).max() <= 1e-12
    assert np.abs(fr.frd_to_flu(fr.flu_to_frd(v)) - v).max() <= 1e-12


def test_quaternion_round_trip_and_matrix_consistency():
    rng = np.random.default_rng(1)
    q = rng.normal(size=(200, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(q[:, :1] < 0, -q, q)
    q_ned = fr.quat_enu_flu_to_ned_frd(q)
    assert np.all(q_ned[:, 0] >= 0)
    assert np.abs(fr.quat_ned_frd_to_enu_flu(q_ned) - q).max() <= 1e-12
    R = rt.quat_to_rotmat(q)
    assert np.abs(rt.quat_to_rotmat(q_ned) - fr.rotmat_enu_flu_to_ned_frd(R)).max() <= 1e-12
    assert np.abs(fr.rotmat_ned_frd_to_enu_flu(fr.rotmat_enu_flu_to_ned_frd(R)) - R).max() <= 1e-12


def test_attitude_maps_vectors_consistently():
    """R_ned_frd @ (FRD body vector) == ENU->NED of (R_enu_flu @ FLU body vector)."""
    q = rt.euler_zyx_to_quat(0.3, -0.2, 1.0)
    v_flu = np.array([0.5, -1.0, 2.0])
    world_enu = rt.quat_rotate(q, v_flu)
    world_ned = rt.quat_rotate(fr.quat_enu_flu_to_ned_frd(q), fr.flu_to_frd(v_flu))
    assert np.allclose(fr.enu_to_ned(world_enu), world_ned, atol=1e-14)


def test_level_north_facing_is_px4_identity():
    q_enu_north = rt.euler_zyx_to_quat(0.0, 0.0, np.pi / 2)  # ENU yaw +90° = facing north
    assert np.allclose(fr.quat_enu_flu_to_ned_frd(q_enu_north), [1, 0, 0, 0], atol=1e-15)
    assert np.allclose(fr.quat_ned_frd_to_enu_flu([1, 0, 0, 0]), q_enu_north, atol=1e-15)
    # ENU identity (facing east) is NED yaw +90°.
    q_ned = fr.quat_enu_flu_to_ned_frd([1, 0, 0, 0])
    assert np.allclose(rt.quat_to_euler_zyx(q_ned), (0, 0, np.pi / 2), atol=1e-15)


def test_euler_angles_across_frames():
    roll, pitch, yaw = 0.1, 0.2, 0.3
    q_ned = fr.quat_enu_flu_to_ned_frd(rt.euler_zyx_to_quat(roll, pitch, yaw))
    r2, p2, y2 = rt.quat_to_euler_zyx(q_ned)
    assert np.allclose([r2, p2, y2], [roll, -pitch, fr.yaw_enu_to_ned(yaw)], atol=1e-14)


def test_yaw_conversion():
    assert abs(fr.yaw_enu_to_ned(np.pi / 2)) < 1e-15
    assert abs(fr.yaw_enu_to_ned(0.0) - np.pi / 2) < 1e-15
    assert abs(fr.yaw_enu_to_ned(-np.pi / 2) - np.pi) < 1e-15
    yaw = np.linspace(-3.1, 3.1, 50)
    assert np.abs(fr.yaw_ned_to_enu(fr.yaw_enu_to_ned(yaw)) - yaw).max() <= 1e-12
    assert isinstance(fr.yaw_enu_to_ned(0.2), float)


def test_bad_input():
    with pytest.raises(ValueError, match="v"):
        fr.enu_to_ned([1.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="q"):
        fr.quat_enu_flu_to_ned_frd([1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="yaw"):
        fr.yaw_enu_to_ned(np.inf)


def test_one_vector_gives_the_bits_of_the_batch_path():
    """The single-vector float paths (issue 15) equal the batched array path bit for bit, signed zeros included."""
    rng = np.random.default_rng(5)
    vectors = rng.normal(size=(500, 3)) * 10.0
    quats = rng.normal(size=(500, 4))
    quats[::7] *= -1.0
    quats[3] = [0.0, -0.0, 1.0, -0.0]
    for convert, batch in ((fr.enu_to_ned, vectors), (fr.ned_to_enu, vectors), (fr.quat_enu_flu_to_ned_frd, quats),
                           (fr.quat_ned_frd_to_enu_flu, quats)):
        single = np.array([convert(list(row)) for row in batch])
        batched = convert(batch)
        assert single.tobytes() == batched.tobytes(), convert.__name__
