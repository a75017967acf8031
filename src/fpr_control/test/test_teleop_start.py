"""The teleop starts from the robot's configuration: reported leg angles (teleop_start) and the filter's
behaviour before / after FLY (teleop_filter ``start_from_robot``). Plain pytest, no rclpy."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
import yaml
from fpr_control.joy_timeline import timeline_from_dict
from fpr_control.teleop_filter import (
    LEG_SOURCE_CONFIGURED,
    LEG_SOURCE_INFO,
    LEG_SOURCE_INFO_STALE,
    MODE_ARM,
    MODE_FLY,
    MODE_IDLE,
    MODE_LAND,
    TeleopFilter,
    config_from_dict,
)
from fpr_control.teleop_start import LegAngleEstimate, ReportedLegAngles, ReportedLegAnglesConfig

CONFIG_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config")
DT = 0.02
RB, LB, A, B, X = 5, 4, 0, 1, 2


def _config():
    with open(os.path.join(CONFIG_DIR, "teleop.yaml"), encoding="utf-8") as stream:
        return config_from_dict(yaml.safe_load(stream), n=3)


def _rest_axes():
    axes = [0.0] * 8
    axes[2] = axes[5] = 1.0  # triggers released
    return axes


def _buttons(*pressed):
    buttons = [0] * 11
    for index in pressed:
        buttons[index] = 1
    return buttons


class Driver:
    """Steps a start-from-robot filter at 50 Hz with a given Joy state and measured leg angle."""

    def __init__(self, start_from_robot=True, leg_range=None):
        self.filter = TeleopFilter(_config(), leg_range, start_from_robot=start_from_robot)
        self.t = 0.0

    def run(self, duration, axes=None, buttons=None, measured=None):
        axes = axes if axes is not None else _rest_axes()
        buttons = buttons if buttons is not None else _buttons()
        outputs = []
        for _ in range(max(int(round(duration / DT)), 1)):
            self.filter.joy(self.t, axes, buttons)
            outputs.append(self.filter.step(self.t, DT, measured))
            self.t += DT
        return outputs

    def press(self, button, measured=None):
        """One rising edge (held one tick, released one tick); returns the outputs of both ticks."""
        return self.run(DT, buttons=_buttons(button), measured=measured) + self.run(DT, measured=measured)


# ------------------------------------------------------------------------------------------------ teleop_start
def test_reported_leg_angles_mean_freshness_and_bad_vectors():
    reported = ReportedLegAngles(ReportedLegAnglesConfig(n=3, timeout=0.5, smoothing=0.0))
    assert reported.update(0.0, DT) is None  # nothing received yet
    assert reported.receive(1, 1.00, True, 0.0) is None
    assert reported.receive(2, 1.06, True, 0.1) is None
    assert reported.receive(3, 0.20, False, 0.1) is None  # the sender says invalid: skipped, not an error
    assert "outside" in reported.receive(4, 1.0, True, 0.1)
    assert "outside" in reported.receive(0, 1.0, True, 0.1)
    assert "not in" in reported.receive(3, float("nan"), True, 0.1)
    assert "not in" in reported.receive(3, float("inf"), True, 0.1)
    assert "not in" in reported.receive(3, -0.1, True, 0.1)
    assert "not in" in reported.receive(3, 2.0, True, 0.1)
    assert reported.update(0.2, DT) == LegAngleEstimate(pytest.approx(1.03), 2)  # UAVs 1 and 2 only
    assert reported.update(0.55, DT) == LegAngleEstimate(pytest.approx(1.06), 1)  # UAV 1's θ_1 is 0.55 s old
    assert reported.update(0.65, DT) is None  # all stale
    with pytest.raises(ValueError):
        ReportedLegAnglesConfig(n=3, timeout=0.0)
    with pytest.raises(ValueError):
        ReportedLegAnglesConfig(n=3, smoothing=-1.0)


def test_reported_leg_angles_smoothing_starts_at_the_first_mean_and_restarts_after_a_gap():
    tau = 1.0
    reported = ReportedLegAngles(ReportedLegAnglesConfig(n=3, timeout=0.5, smoothing=tau))
    for uav_id in (1, 2, 3):
        reported.receive(uav_id, 1.0, True, 0.0)
    assert reported.update(0.0, DT).leg_angle == pytest.approx(1.0)  # no ramp from zero
    t = 0.0
    for _ in range(50):  # the mean steps to 1.1: first-order response, 1 s
        t += DT
        for uav_id in (1, 2, 3):
            reported.receive(uav_id, 1.1, True, t)
        estimate = reported.update(t, DT)
    assert estimate.uav_count == 3
    assert estimate.leg_angle == pytest.approx(1.1 - 0.1 * math.exp(-1.0), abs=1e-9)
    assert reported.update(t + 1.0, DT) is None  # silent for 1 s > timeout
    reported.receive(2, 0.9, True, t + 1.0)
    assert reported.update(t + 1.0, DT).leg_angle == pytest.approx(0.9)  # restarted, no old bias


def test_reported_leg_angles_average_out_estimate_noise():
    """Per-UAV estimates jitter by ~0.5° (std) on the resting robot: the smoothed mean stays within 0.3°."""
    rng = np.random.default_rng(7)
    truth = math.radians(60.0)
    reported = ReportedLegAngles(ReportedLegAnglesConfig(n=3))
    worst, t = 0.0, 0.0
    for k in range(400):
        t = k * DT
        for uav_id in (1, 2, 3):
            reported.receive(uav_id, truth + math.radians(0.5) * rng.standard_normal(), True, t)
        estimate = reported.update(t, DT)
        if t >= 1.0:
            worst = max(worst, abs(estimate.leg_angle - truth))
    assert 0.0 < math.degrees(worst) < 0.3


# ------------------------------------------------------------------------------------------------ the filter
def test_before_fly_the_command_follows_the_robot_and_ignores_configuration_inputs():
    config = _config()
    assert math.degrees(config.channels["leg_angle"].initial) == pytest.approx(60.0)  # the simulator's rest
    drive = Driver()
    measured = math.radians(52.0)
    axes = _rest_axes()
    axes[6] = axes[7] = 1.0  # d-pad held: would ramp roll and pitch
    out = drive.run(1.0, axes=axes, buttons=_buttons(RB), measured=measured)[-1]  # RB held: would raise legs
    assert out.mode == MODE_IDLE
    assert out.leg_angles == pytest.approx([measured] * 3, abs=1e-12)
    assert out.leg_rates == pytest.approx([0.0] * 3, abs=1e-12)  # χ̇_d = 0: no filter transient
    assert (out.roll, out.pitch, out.roll_rate, out.pitch_rate) == (0.0, 0.0, 0.0, 0.0)
    assert drive.filter.leg_source == LEG_SOURCE_INFO
    drive.press(A, measured)
    outputs = drive.run(0.5, measured=math.radians(58.0))  # armed: the legs still follow
    assert outputs[-1].mode == MODE_ARM
    assert np.degrees(outputs[-1].leg_angles) == pytest.approx([58.0] * 3, abs=1e-9)
    assert all(np.all(o.leg_rates == 0.0) for o in outputs)
    velocity_axes = _rest_axes()
    velocity_axes[1] = 1.0  # the velocity channels are the operator's, flying or not
    assert drive.run(2.0, axes=velocity_axes, measured=math.radians(58.0))[-1].platform_velocity[2] == \
        pytest.approx(0.3, abs=1e-3)


def test_at_fly_the_operator_takes_over_from_the_measured_value_without_a_jump():
    drive = Driver()
    measured = math.radians(58.0)
    drive.run(0.5, measured=measured)
    drive.press(A, measured)
    drive.run(0.2, measured=measured)
    drive.filter.take_reports()
    fly = drive.press(X, measured)
    assert [o.mode for o in fly] == [MODE_FLY, MODE_FLY]
    reports = drive.filter.take_reports()
    assert reports == [f"FLY: common leg angle starts at 58.0 deg ({LEG_SOURCE_INFO})"]
    for o in fly:
        assert o.leg_angles == pytest.approx([measured] * 3, abs=1e-12) and np.all(o.leg_rates == 0.0)
    # flying: the measurement no longer matters, the operator's RB raises the legs at 10°/s through the LPF
    out = drive.run(1.0, buttons=_buttons(RB), measured=math.radians(40.0))[-1]
    assert math.degrees(drive.filter.targets["leg_angle"]) == pytest.approx(68.0, abs=0.01)
    assert math.degrees(out.leg_rates[0]) > 5.0  # rate mode through the low-pass, as before
    axes = _rest_axes()
    axes[6] = 1.0
    drive.run(1.0, axes=axes)  # roll from 0 at 5°/s
    assert math.degrees(drive.filter.targets["roll"]) == pytest.approx(5.0, abs=0.11)
    # land, then re-engage FLY from LAND: the operator's values hold (no follow while landing)
    assert drive.press(B, math.radians(45.0))[-1].mode == MODE_LAND
    drive.run(0.5, measured=math.radians(45.0))
    assert math.degrees(drive.filter.targets["leg_angle"]) == pytest.approx(68.0, abs=0.01)
    assert drive.press(X, math.radians(45.0))[-1].mode == MODE_FLY
    assert drive.filter.take_reports() == []  # FLY from LAND: nothing new to report
    # land, re-arm: follows the robot again
    drive.press(B)
    drive.press(A, math.radians(45.0))
    out = drive.run(0.1, measured=math.radians(45.0))[-1]
    assert np.degrees(out.leg_angles) == pytest.approx([45.0] * 3) and out.roll == 0.0


def test_measured_leg_angle_is_clamped_to_the_limits_and_the_feasible_range():
    drive = Driver()
    out = drive.run(0.1, measured=math.radians(85.0))[-1]
    assert np.degrees(out.leg_angles) == pytest.approx([80.0] * 3)  # configured maximum
    out = drive.run(0.1, measured=math.radians(5.0))[-1]
    assert np.degrees(out.leg_angles) == pytest.approx([15.0] * 3)  # configured minimum
    feasible = Driver(leg_range=lambda roll, pitch: (math.radians(30.0), math.radians(50.0)))
    out = feasible.run(0.1, measured=math.radians(60.0))[-1]
    assert np.degrees(out.leg_angles) == pytest.approx([50.0] * 3)


def test_without_a_measurement_the_configured_value_holds_and_is_reported():
    drive = Driver()
    out = drive.run(0.5)[-1]
    assert np.degrees(out.leg_angles) == pytest.approx([60.0] * 3)
    assert drive.filter.leg_source == LEG_SOURCE_CONFIGURED
    drive.run(0.1, measured=float("nan"))  # non-finite: unknown, not followed
    assert drive.filter.leg_source == LEG_SOURCE_CONFIGURED and drive.filter.take_reports() == []
    assert np.degrees(drive.run(0.1)[-1].leg_angles) == pytest.approx([60.0] * 3)
    drive.press(A)
    drive.press(X)
    assert drive.filter.take_reports() == [f"FLY: common leg angle starts at 60.0 deg ({LEG_SOURCE_CONFIGURED})"]


def test_a_measurement_that_goes_stale_before_fly_holds_its_last_value():
    drive = Driver()
    drive.run(0.5, measured=math.radians(55.0))
    assert drive.filter.take_reports() == [f"leg angle command: {LEG_SOURCE_INFO}, 55.0 deg"]
    out = drive.run(0.5)[-1]
    assert np.degrees(out.leg_angles) == pytest.approx([55.0] * 3) and np.all(out.leg_rates == 0.0)
    assert drive.filter.take_reports() == [f"leg angle command: {LEG_SOURCE_INFO_STALE}, 55.0 deg"]
    drive.press(A)
    drive.press(X)
    assert drive.filter.take_reports() == [f"FLY: common leg angle starts at 55.0 deg ({LEG_SOURCE_INFO_STALE})"]


def test_start_from_robot_off_keeps_the_mapping_behaviour():
    drive = Driver(start_from_robot=False)
    axes = _rest_axes()
    axes[6] = 1.0
    out = drive.run(1.0, axes=axes, buttons=_buttons(RB), measured=math.radians(40.0))[-1]
    assert math.degrees(drive.filter.targets["leg_angle"]) == pytest.approx(70.0, abs=0.01)  # 60 + 10°/s
    assert math.degrees(drive.filter.targets["roll"]) == pytest.approx(5.0, abs=0.11)
    assert math.degrees(out.leg_rates[0]) > 0.0
    drive.press(A)
    drive.press(X)
    assert drive.filter.take_reports() == ["FLY: common leg angle starts at 70.0 deg (initial_legs_from_info off)"]


@pytest.mark.parametrize("name", ["integration_flight.yaml", "takeoff_hover_land.yaml", "roll_and_legs.yaml",
                                  "push_force.yaml", "integration_hover.yaml"])
@pytest.mark.parametrize("resting_deg", [45.0, 60.0])
def test_joy_scripts_arm_and_fly_without_a_configuration_jump(name, resting_deg):
    """Each scripted flight from a robot resting at ``resting_deg``: up to the first leg / roll / pitch input
    after FLY, the command equals the resting configuration with zero rates."""
    with open(os.path.join(CONFIG_DIR, "joy_scripts", name), encoding="utf-8") as stream:
        timeline = timeline_from_dict(yaml.safe_load(stream))
    drive = Driver()
    measured = math.radians(resting_deg)
    flew = False
    for k in range(int((timeline.duration + 1.0) / DT)):
        t = k * DT
        axes, buttons = timeline.sample(t)
        drive.filter.joy(t, axes, buttons)
        out = drive.filter.step(t, DT, measured)
        configuration_input = buttons[RB] or buttons[LB] or axes[6] or axes[7]
        if out.mode == MODE_FLY:
            flew = True
            if configuration_input:
                break
        assert np.degrees(out.leg_angles) == pytest.approx([resting_deg] * 3, abs=1e-9), f"t = {t:.2f} s"
        assert np.all(out.leg_rates == 0.0) and out.roll == 0.0 and out.pitch == 0.0
    assert flew
