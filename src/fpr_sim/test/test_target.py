"""Emulated relative target pose (fpr_sim.target, /fpr/target): frames, yaw wrapping, noise and seed."""

import math

import numpy as np
import pytest
from fpr_model.rotations import euler_zyx_to_quat, quat_to_euler_zyx
from fpr_sim.scenario import scenario_from_dict
from fpr_sim.target import TargetEmulator, platform_yaw, relative_target_pose, wrap_angle


def test_wrap_angle_is_half_open():
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3.0 * math.pi) == pytest.approx(math.pi)
    assert wrap_angle(6.0) == pytest.approx(6.0 - 2.0 * math.pi)
    assert wrap_angle(-0.25) == -0.25


def test_relative_pose_in_the_flat_platform_frame_of_a_rotated_platform():
    """Platform yawed +90°: F_Fp x is world +y. A target 1 m along world +x and 0.4 m above is at (0, −1, 0.4)
    in F_Fp; roll and pitch do not enter (F_Fp keeps z up); the relative yaw is ψ_t − ψ_p."""
    platform = np.array([0.5, -0.2, 1.5])
    target = platform + [1.0, 0.0, 0.4]
    for roll, pitch in ((0.0, 0.0), (0.3, -0.2), (-0.5, 0.4)):
        quat = euler_zyx_to_quat(roll, pitch, math.pi / 2)
        pose = relative_target_pose(platform, quat, target, 0.3)
        assert np.allclose(pose.position, [0.0, -1.0, 0.4], atol=1e-12)
        assert pose.yaw == pytest.approx(0.3 - math.pi / 2)
        assert np.allclose(pose.quat, [math.cos(0.5 * pose.yaw), 0.0, 0.0, math.sin(0.5 * pose.yaw)])
        assert quat_to_euler_zyx(pose.quat)[2] == pytest.approx(pose.yaw)
    # a general yaw: Fp p_t = Rz(ψ)ᵀ (p_t − P)
    psi = -2.4
    pose = relative_target_pose(platform, euler_zyx_to_quat(0.1, 0.05, psi), [2.0, 1.0, 1.8], 2.9)
    d = np.array([2.0, 1.0, 1.8]) - platform
    rz = np.array([[math.cos(psi), -math.sin(psi), 0.0], [math.sin(psi), math.cos(psi), 0.0], [0.0, 0.0, 1.0]])
    assert np.allclose(pose.position, rz.T @ d, atol=1e-12)
    assert pose.yaw == pytest.approx(2.9 + 2.4 - 2.0 * math.pi)  # 5.3 rad wrapped into (−π, π]
    assert platform_yaw(euler_zyx_to_quat(0.1, 0.05, psi)) == pytest.approx(psi)


def test_emulated_target_noise_and_seed():
    config = scenario_from_dict({"target": {"enabled": True, "position": [1.0, 2.0, 3.0], "yaw": 0.5}}).target
    assert (config.position_noise, config.yaw_noise, config.rate) == (0.02, math.radians(2.0), 50.0)
    platform, quat = np.array([0.8, 2.1, 2.5]), euler_zyx_to_quat(0.0, 0.0, 1.0)
    exact = relative_target_pose(platform, quat, config.position, config.yaw)
    emulator = TargetEmulator(config, seed=4)
    samples = [emulator.measure(platform, quat) for _ in range(4000)]
    positions = np.array([s.position for s in samples])
    yaws = np.array([s.yaw for s in samples])
    assert np.allclose(positions.mean(axis=0), exact.position, atol=0.002)
    assert np.allclose(positions.std(axis=0), 0.02, rtol=0.08)
    assert yaws.mean() == pytest.approx(exact.yaw, abs=0.003)
    assert yaws.std() == pytest.approx(math.radians(2.0), rel=0.08)
    again = TargetEmulator(config, seed=4).measure(platform, quat)
    other = TargetEmulator(config, seed=5).measure(platform, quat)
    assert np.array_equal(again.position, samples[0].position) and again.yaw == samples[0].yaw
    assert not np.array_equal(other.position, samples[0].position)
    quiet = scenario_from_dict({"target": {"position": [1.0, 2.0, 3.0], "position_noise": 0.0,
                                           "yaw_noise": 0.0}}).target
    sample = TargetEmulator(quiet, seed=0).measure(platform, quat)
    assert np.allclose(sample.position, relative_target_pose(platform, quat, quiet.position, 0.0).position)


def test_target_keys_are_checked():
    assert not scenario_from_dict({}).target.enabled
    with pytest.raises(ValueError, match=r"target: unknown key\(s\) \['yawn'\]"):
        scenario_from_dict({"target": {"yawn": 1.0}})
    with pytest.raises(ValueError, match="target.rate"):
        scenario_from_dict({"target": {"rate": 0.0}})
    with pytest.raises(ValueError, match="target: position"):
        scenario_from_dict({"target": {"position": [1.0, 2.0]}})
