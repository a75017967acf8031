"""Ground teleop path cores: Joy mapping / dead zone / low-pass / limits, js_event decoding, Joy timelines."""

from __future__ import annotations

import math
import os
import threading

import numpy as np
import pytest
import yaml
from fpr_control.joy_timeline import timeline_from_dict
from fpr_control.joystick_device import (
    JS_EVENT_AXIS,
    JS_EVENT_BUTTON,
    JS_EVENT_INIT,
    JoystickDevice,
    JoystickState,
    pack_event,
)
from fpr_control.teleop_filter import (
    MODE_ARM,
    MODE_FLY,
    MODE_IDLE,
    MODE_KILL,
    MODE_LAND,
    TeleopFilter,
    apply_dead_zone,
    config_from_dict,
)

CONFIG_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config")
DT = 0.02


def _config():
    with open(os.path.join(CONFIG_DIR, "teleop.yaml"), encoding="utf-8") as stream:
        return config_from_dict(yaml.safe_load(stream), n=3)


def _rest_axes():
    axes = [0.0] * 8
    axes[2] = axes[5] = 1.0  # triggers released
    return axes


def _run(filt: TeleopFilter, t0: float, duration: float, axes, buttons=None):
    buttons = buttons if buttons is not None else [0] * 11
    out = None
    for k in range(int(round(duration / DT))):
        t = t0 + k * DT
        filt.joy(t, axes, buttons)
        out = filt.step(t, DT)
    return out


def test_dead_zone():
    assert apply_dead_zone(0.05, 0.08) == 0.0
    assert apply_dead_zone(-0.08, 0.08) == 0.0
    assert apply_dead_zone(1.0, 0.08) == pytest.approx(1.0)
    assert apply_dead_zone(-0.54, 0.08) == pytest.approx(-0.5)


def test_mapping_filter_time_constant_and_derivative():
    filt = TeleopFilter(_config())
    out = _run(filt, 0.0, 0.2, _rest_axes())
    initial = _config().channels["leg_angle"].initial
    assert np.allclose(out.platform_velocity, 0.0) and out.leg_angles == pytest.approx([initial] * 3)
    axes = _rest_axes()
    axes[4] = 1.0  # right stick up: v_x = +0.5 m/s
    axes[0] = 0.04  # inside the dead zone: no yaw rate
    tau = _config().time_constant
    out = _run(filt, 0.2, tau, axes)
    assert out.platform_velocity[0] == pytest.approx(0.5 * (1 - math.exp(-1.0)), rel=1e-9)  # 63.2 % at τ
    assert out.platform_acceleration[0] == pytest.approx((0.5 - out.platform_velocity[0]) / tau)
    assert out.yaw_rate == 0.0
    out = _run(filt, 0.2 + tau, 3.0, axes)
    assert out.platform_velocity[0] == pytest.approx(0.5, abs=1e-4)
    axes[3], axes[1], axes[0] = -1.0, 0.54, 1.0  # right: −y; left stick half up; full yaw left
    out = _run(filt, 3.5, 3.0, axes)
    assert out.platform_velocity[1] == pytest.approx(-0.5, abs=1e-3)
    assert out.platform_velocity[2] == pytest.approx(0.15, abs=1e-3)  # (0.54−0.08)/0.92 × 0.3
    assert out.yaw_rate == pytest.approx(0.5, abs=1e-3)


def test_value_channels_rates_and_clamping():
    filt = TeleopFilter(_config())
    axes = _rest_axes()
    axes[6] = 1.0  # d-pad: roll at +5 deg/s
    out = _run(filt, 0.0, 1.0, axes)
    assert math.degrees(filt.targets["roll"]) == pytest.approx(5.0, abs=0.11)
    out = _run(filt, 1.0, 10.0, axes)  # held long: clamped at 20 deg
    assert math.degrees(out.roll) == pytest.approx(20.0, abs=1e-3)
    buttons = [0] * 11
    buttons[5] = 1  # RB: legs up at 10 deg/s, clamped at 80 deg
    out = _run(filt, 11.0, 10.0, _rest_axes(), buttons)
    assert np.degrees(out.leg_angles) == pytest.approx([80.0] * 3, abs=1e-3)
    buttons = [0] * 11
    buttons[4] = 1
    out = _run(filt, 21.0, 10.0, _rest_axes(), buttons)
    assert np.degrees(out.leg_angles) == pytest.approx([15.0] * 3, abs=1e-3)
    axes = _rest_axes()
    axes[2] = -1.0  # left trigger fully pressed: 10 N, the maximum
    out = _run(filt, 31.0, 5.0, axes)
    assert out.contact_force == pytest.approx(10.0, abs=1e-3)
    axes[2] = 0.0  # half pressed: 5 N
    out = _run(filt, 36.0, 5.0, axes)
    assert out.contact_force == pytest.approx(5.0, abs=0.01)


def test_buttons_and_modes():
    filt = TeleopFilter(_config())
    assert filt.step(0.0, DT).mode == MODE_IDLE

    def press(index, t):
        buttons = [0] * 11
        buttons[index] = 1
        filt.joy(t, _rest_axes(), buttons)
        out = filt.step(t, DT)
        filt.joy(t + DT, _rest_axes(), [0] * 11)
        return out.mode

    assert press(2, 0.1) == MODE_IDLE  # fly before arm: refused
    assert press(0, 0.2) == MODE_ARM
    assert press(2, 0.3) == MODE_FLY
    buttons = [0] * 11
    buttons[2] = 1
    filt.joy(0.4, _rest_axes(), buttons)  # held: one edge only
    assert filt.step(0.4, DT).mode == MODE_FLY
    assert press(1, 0.5) == MODE_LAND
    assert press(6, 0.6) == MODE_KILL
    assert press(2, 0.7) == MODE_KILL  # kill latches until arm
    assert press(0, 0.8) == MODE_ARM


def test_bad_joy_is_ignored_and_silence_stops():
    filt = TeleopFilter(_config())
    axes = _rest_axes()
    axes[4] = 1.0
    _run(filt, 0.0, 3.0, axes)
    bad = list(axes)
    bad[4] = float("nan")
    assert "NaN" in filt.joy(3.0, bad, [0] * 11)
    assert "axes" in filt.joy(3.0, [0.0] * 6, [0] * 11)
    assert "buttons" in filt.joy(3.0, axes, [0] * 3)
    out = filt.step(3.0, DT)
    assert out.platform_velocity[0] == pytest.approx(0.5, abs=1e-3)  # the last good sample holds
    roll_axes = list(axes)
    roll_axes[6] = 1.0
    _run(filt, 3.0, 1.0, roll_axes)
    # the last sample (d-pad held) stays in force until the Joy is declared silent after joy_timeout = 0.5 s
    for k in range(26):
        out = filt.step(4.0 + k * DT, DT)
    assert out.joy_stale
    roll = filt.targets["roll"]
    assert math.degrees(roll) == pytest.approx(5.0 + 2.5, abs=0.2)
    for k in range(26, 60):
        out = filt.step(4.0 + k * DT, DT)
    assert filt.targets["velocity_x"] == 0.0 and out.platform_velocity[0] < 0.1
    assert filt.targets["roll"] == roll  # values hold


def test_feasibility_hook_clamps_leg_angle():
    calls = []

    def leg_range(roll, pitch):
        calls.append((roll, pitch))
        return math.radians(30.0), math.radians(40.0)

    filt = TeleopFilter(_config(), leg_range)
    buttons = [0] * 11
    buttons[5] = 1
    out = _run(filt, 0.0, 5.0, _rest_axes(), buttons)
    assert calls and np.degrees(out.leg_angles) == pytest.approx([40.0] * 3, abs=1e-3)


def test_feasibility_hook_with_fpr_model():
    from fpr_model.feasibility import feasible_leg_angle_range
    from fpr_model.parameters import default_parameters

    params = default_parameters(3)
    result = feasible_leg_angle_range(params, 0.0, 0.0, 2.0, 1.0)
    assert result is not None
    low, high = result
    assert 0.0 < low < math.radians(45.0) < high < math.pi / 2


# ------------------------------------------------------------------------------------------------------------
def test_js_event_decoding():
    state = JoystickState()
    data = (pack_event(0, 0, JS_EVENT_AXIS | JS_EVENT_INIT, 0) + pack_event(0, 0, JS_EVENT_BUTTON | JS_EVENT_INIT, 3)
            + pack_event(10, -32767, JS_EVENT_AXIS, 1) + pack_event(20, 1, JS_EVENT_BUTTON, 0))
    assert state.feed(data[:13]) == 1  # one whole event and a partial one
    assert state.feed(data[13:]) == 3
    assert state.axes == [0.0, 1.0]  # stick up (negative raw) -> +1, ROS joy convention
    assert state.buttons == [1, 0, 0, 0]
    assert state.feed(pack_event(0, 5, 0x40, 1) + pack_event(0, 5, JS_EVENT_AXIS, 200)) == 0
    assert state.garbage == 2


def test_joystick_device_reads_a_fifo(tmp_path):
    path = str(tmp_path / "js0")
    os.mkfifo(path)
    device = JoystickDevice(path, invert_axes=False)
    device.open()
    writer = threading.Thread(target=lambda: open(path, "wb").write(
        pack_event(1, 16384, JS_EVENT_AXIS, 2) + pack_event(2, 1, JS_EVENT_BUTTON, 1)))
    writer.start()
    writer.join(5.0)
    changed = 0
    for _ in range(100):
        changed += device.poll()
        if changed >= 2:
            break
    device.close()
    assert changed == 2
    assert device.state.axes[2] == pytest.approx(0.5, abs=1e-4) and device.state.buttons == [0, 1]


def test_joy_timeline():
    timeline = timeline_from_dict({
        "axes_count": 8, "buttons_count": 11,
        "keyframes": [{"t": 0.0, "axes": {2: 1.0}}, {"t": 1.0, "buttons": {0: 1}},
                      {"t": 2.0, "axes": {4: 1.0}, "ramp": True}, {"t": 3.0, "buttons": {0: 0}}]})
    axes, buttons = timeline.sample(0.5)
    assert axes[2] == 1.0 and buttons[0] == 0 and len(axes) == 8 and len(buttons) == 11
    axes, buttons = timeline.sample(1.5)
    assert axes[4] == pytest.approx(0.5) and buttons[0] == 1
    axes, buttons = timeline.sample(10.0)
    assert axes[4] == 1.0 and buttons[0] == 0
    with pytest.raises(ValueError):
        timeline_from_dict({"keyframes": [{"t": 1.0}, {"t": 0.5}]})
    with pytest.raises(ValueError):
        timeline_from_dict({"axes_count": 2, "keyframes": [{"t": 0.0, "axes": {5: 0.1}}]})


@pytest.mark.parametrize("name", sorted(os.listdir(os.path.join(CONFIG_DIR, "joy_scripts"))))
def test_example_scripts_drive_the_teleop_filter(name):
    with open(os.path.join(CONFIG_DIR, "joy_scripts", name), encoding="utf-8") as stream:
        timeline = timeline_from_dict(yaml.safe_load(stream))
    filt = TeleopFilter(_config())
    modes = set()
    for k in range(int((timeline.duration + 2.0) / DT)):
        t = k * DT
        axes, buttons = timeline.sample(t)
        assert filt.joy(t, axes, buttons) is None
        modes.add(filt.step(t, DT).mode)
    assert {MODE_ARM, MODE_FLY} <= modes
