"""Target-approach law (4.39) core (thesis §4.4.2 Scenario II) and its use through the teleop filter (no ROS)."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
import yaml
from fpr_control.target_approach import (
    TargetApproach,
    TargetApproachConfig,
    approach_config_from_teleop,
    approach_law,
    limit_planar_velocity,
    relative_yaw_from_quaternion,
    validate_target,
)
from fpr_control.teleop_filter import MODE_FLY, TeleopFilter, config_from_dict

CONFIG_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config")
DT = 0.02
IDENTITY = (1.0, 0.0, 0.0, 0.0)


def _teleop_config():
    with open(os.path.join(CONFIG_DIR, "teleop.yaml"), encoding="utf-8") as stream:
        return config_from_dict(yaml.safe_load(stream), n=3)


def _yaw_quat(yaw: float) -> tuple[float, float, float, float]:
    return math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)


def test_law_4_39_thesis_gains():
    vx, vy, yaw_rate = approach_law((1.0, -0.5), 0.4, 0.4, 0.25)
    assert (vx, vy, yaw_rate) == pytest.approx((0.4, -0.2, 0.1))
    assert approach_law((0.0, 0.0), 0.0, 0.4, 0.25) == (0.0, 0.0, 0.0)


def test_planar_limit_keeps_the_direction():
    limits = (-0.5, 0.5)
    assert limit_planar_velocity(2.0, 1.0, limits, limits) == pytest.approx((0.5, 0.25))
    assert limit_planar_velocity(-0.4, 1.6, limits, limits) == pytest.approx((-0.125, 0.5))
    assert limit_planar_velocity(0.3, -0.2, limits, limits) == pytest.approx((0.3, -0.2))  # inside: unchanged
    assert limit_planar_velocity(-1.0, 0.5, (-0.25, 1.0), limits) == pytest.approx((-0.25, 0.125))  # asymmetric
    assert limit_planar_velocity(0.0, 0.0, (0.1, 0.5), limits) == pytest.approx((0.1, 0.0))  # 0 excluded: clip


def test_relative_yaw_from_the_quaternion():
    for yaw in (0.0, 0.7, -2.5, math.pi - 1e-6):
        assert relative_yaw_from_quaternion(*_yaw_quat(yaw)) == pytest.approx(yaw, abs=1e-9)
    w, x, y, z = _yaw_quat(0.3)
    assert relative_yaw_from_quaternion(2 * w, 2 * x, 2 * y, 2 * z) == pytest.approx(0.3)  # scale-free


@pytest.mark.parametrize("position, orientation, frame, words", [
    ((math.nan, 0.0, 0.0), IDENTITY, "flat_platform", "NaN"),
    ((0.0, math.inf, 0.0), IDENTITY, "flat_platform", "NaN"),
    ((0.0, 0.0, 0.0), (math.nan, 0.0, 0.0, 0.0), "flat_platform", "NaN"),
    ((150.0, 0.0, 0.0), IDENTITY, "flat_platform", "implausible"),
    ((60.0, 60.0, 60.0), IDENTITY, "flat_platform", "implausible"),
    ((1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0), "flat_platform", "unit quaternion"),
    ((1.0, 0.0, 0.0), IDENTITY, "world", "frame_id"),
    ((1.0, 0.0, 0.0), IDENTITY, "", "frame_id"),
])
def test_invalid_targets_are_refused(position, orientation, frame, words):
    reason = validate_target(position, orientation, frame, 100.0)
    assert reason is not None and words in reason


def test_valid_target_accepted():
    assert validate_target((1.0, -2.0, 0.3), _yaw_quat(0.2), "flat_platform", 100.0) is None


def test_freshness_refusal_and_one_report_per_change():
    approach = TargetApproach(TargetApproachConfig(timeout=0.5))
    assert approach.command(0.0) is None and approach.take_reports() == []  # nothing yet, nothing to say
    assert approach.receive(0.0, (1.0, -0.5, 0.2), _yaw_quat(0.4)) is None
    cmd = approach.command(0.02)
    assert (cmd.velocity_x, cmd.velocity_y, cmd.yaw_rate) == pytest.approx((0.4, -0.2, 0.1))
    assert cmd.as_targets() == {"velocity_x": cmd.velocity_x, "velocity_y": cmd.velocity_y,
                                "yaw_rate": cmd.yaw_rate}
    reports = approach.take_reports()
    assert len(reports) == 1 and reports[0][0] == "info" and "(4.39)" in reports[0][1]
    assert approach.command(0.5) is not None  # age = timeout: still fresh
    for t in (0.52, 0.6, 1.0):
        assert approach.command(t) is None
    reports = approach.take_reports()
    assert len(reports) == 1 and reports[0][0] == "warning" and "stale" in reports[0][1]
    assert "back to the sticks" in reports[0][1]
    approach.receive(1.1, (2.0, 0.0, 0.0), IDENTITY)  # back
    assert approach.command(1.12).velocity_x == pytest.approx(0.8)
    assert len(approach.take_reports()) == 1
    # a refused pose drops the held target at once (no waiting for the timeout)
    reason = approach.receive(1.14, (float("nan"), 0.0, 0.0), IDENTITY)
    assert reason is not None and approach.command(1.16) is None
    reports = approach.take_reports()
    assert len(reports) == 1 and "refused" in reports[0][1]
    approach.receive(1.18, (500.0, 0.0, 0.0), IDENTITY)  # refused again while already lost: no new report
    assert approach.command(1.2) is None and approach.take_reports() == []
    # the clock went back (restarted simulation): the old target is not fresh
    approach.receive(2.0, (1.0, 0.0, 0.0), IDENTITY)
    assert approach.command(2.0) is not None and approach.command(0.1) is None


def test_clamped_to_the_mapping_limits():
    config = approach_config_from_teleop(_teleop_config(), 0.4, 0.25, 0.5)
    assert config.velocity_x_limits == (-0.5, 0.5) and config.yaw_rate_limits == (-0.5, 0.5)
    approach = TargetApproach(config)
    approach.receive(0.0, (4.0, 3.0, -1.0), _yaw_quat(3.0))  # λ_p p = (1.6, 1.2) m/s, λ_ψ ψ = 0.75 rad/s
    cmd = approach.command(0.0)
    assert (cmd.velocity_x, cmd.velocity_y) == pytest.approx((0.5, 0.375))  # towards the target, |v_x| = 0.5
    assert cmd.yaw_rate == pytest.approx(0.5)


def test_config_validation():
    with pytest.raises(ValueError):
        TargetApproachConfig(lambda_p=-0.1)
    with pytest.raises(ValueError):
        TargetApproachConfig(timeout=0.0)
    with pytest.raises(ValueError):
        TargetApproachConfig(lambda_psi=math.nan)


# --------------------------------------------------------------------------------------------------------
# Through the teleop filter: the hybrid scheme of Scenario II
def _joy(filt, t, axes, buttons):
    assert filt.joy(t, axes, buttons) is None


def _rest_axes():
    axes = [0.0] * 8
    axes[2] = axes[5] = 1.0  # triggers released
    return axes


def _fly(filt, t):
    """Arm (A) then fly (X): rising edges, one step each."""
    for button in (0, 2):
        buttons = [0] * 11
        buttons[button] = 1
        _joy(filt, t, _rest_axes(), buttons)
        filt.step(t, DT)
        t += DT
        _joy(filt, t, _rest_axes(), [0] * 11)
        filt.step(t, DT)
        t += DT
    assert filt.mode == MODE_FLY
    return t


def test_filter_takes_xy_and_yaw_rate_from_the_law_the_rest_from_the_operator():
    config = _teleop_config()
    filt = TeleopFilter(config)
    approach = TargetApproach(approach_config_from_teleop(config))
    axes = _rest_axes()
    axes[4] = 1.0  # stick: v_x = +0.5 m/s
    axes[1] = 1.0  # stick: v_z = +0.3 m/s
    axes[2] = -1.0  # trigger fully pressed: f^d_c = 10 N
    axes[6] = 1.0  # d-pad: roll up at 5 deg/s

    # before FLY, the law is not used even with a fresh target
    t = 0.0
    approach.receive(t, (-0.5, 1.0, 0.0), _yaw_quat(-0.8))
    _joy(filt, t, axes, [0] * 11)
    out = filt.step(t, DT, external=approach.command(t).as_targets())
    assert out.external_channels == () and out.platform_velocity[0] > 0.0
    t = _fly(filt, t + DT)

    tau = config.time_constant
    out = None
    for _ in range(int(round(3.0 / DT))):
        approach.receive(t, (-0.5, 1.0, 0.0), _yaw_quat(-0.8))
        _joy(filt, t, axes, [0] * 11)
        previous = out
        out = filt.step(t, DT, external=approach.command(t).as_targets())
        t += DT
    assert out.external_channels == ("velocity_x", "velocity_y", "yaw_rate")
    # (4.39) after the low-pass: −0.2, +0.4 m/s, −0.2 rad/s; the operator's v_z, f^d_c and roll
    assert out.platform_velocity == pytest.approx([-0.2, 0.4, 0.3], abs=2e-3)
    assert out.yaw_rate == pytest.approx(-0.2, abs=2e-3)
    assert out.contact_force == pytest.approx(10.0, abs=0.05)
    assert out.roll > previous.roll > 0.0
    # χ̇_d of the replaced channels is the filter's (target − χ_d)/τ
    assert out.platform_acceleration[0] == pytest.approx((-0.2 - out.platform_velocity[0]) / tau, abs=1e-12)
    assert out.yaw_acceleration == pytest.approx((-0.2 - out.yaw_rate) / tau, abs=1e-12)

    # one step after the law engages from the sticks' value, the filter moves by α (no jump)
    filt2 = TeleopFilter(config)
    t2 = _fly(filt2, 0.0)
    _joy(filt2, t2, axes, [0] * 11)
    before = filt2.step(t2, DT)
    _joy(filt2, t2 + DT, axes, [0] * 11)
    after = filt2.step(t2 + DT, DT, external={"velocity_x": -0.2})
    alpha = 1.0 - math.exp(-DT / tau)
    assert after.platform_velocity[0] == pytest.approx(before.platform_velocity[0]
                                                       + alpha * (-0.2 - before.platform_velocity[0]))

    # target lost: the sticks again (v_x back towards +0.5)
    for _ in range(int(round(3.0 / DT))):
        _joy(filt, t, axes, [0] * 11)
        cmd = approach.command(t)
        out = filt.step(t, DT, external=cmd.as_targets() if cmd is not None else None)
        t += DT
    assert out.external_channels == ()
    assert out.platform_velocity == pytest.approx([0.5, 0.0, 0.3], abs=2e-3) and abs(out.yaw_rate) < 2e-3


def test_filter_silent_joystick_stops_the_law_too():
    config = _teleop_config()
    filt = TeleopFilter(config)
    t = _fly(filt, 0.0)
    out = None
    for _ in range(int(round(2.0 / DT))):  # no Joy after FLY: stale after 0.5 s
        out = filt.step(t, DT, external={"velocity_x": 0.3, "velocity_y": 0.1, "yaw_rate": 0.2})
        t += DT
    assert out.joy_stale and out.external_channels == ()
    assert np.abs(out.platform_velocity).max() < 2e-3 and abs(out.yaw_rate) < 2e-3


def test_filter_clamps_and_ignores_bad_external_values():
    config = _teleop_config()
    filt = TeleopFilter(config)
    t = _fly(filt, 0.0)
    _joy(filt, t, _rest_axes(), [0] * 11)
    out = filt.step(t, DT, external={"velocity_x": 7.0, "velocity_y": math.nan, "no_such_channel": 1.0})
    assert out.external_channels == ("velocity_x",)
    assert filt.targets["velocity_x"] == 0.5 and filt.targets["velocity_y"] == 0.0
