"""Bumpless rejoin (fpr_control.rejoin, issue 12): the reference while the setpoints are not flown and after."""

from __future__ import annotations

import math

import numpy as np
import pytest
from closed_loop import command
from fpr_control.controller import Controller, ControllerConfig, gains_from_dict
from fpr_control.information import LocalEstimate, PeerInfo
from fpr_control.rejoin import RejoinConfig, RejoinRamp
from fpr_model.parameters import default_parameters

DT = 0.02
CFG = RejoinConfig(leg_rate=math.radians(8.0), attitude_rate=math.radians(5.0))


def test_the_first_take_off_is_not_touched():
    ramp = RejoinRamp(CFG)
    cmd = command(3, roll=0.1, leg=0.8)
    for flown in (False, False, True, True):  # warm-up before the first OFFBOARD, then flown
        assert ramp.apply(flown, DT, cmd, 0.0, 0.0, None) is cmd
    assert ramp.was_flown and not ramp.active


def test_suspended_follows_the_measured_configuration_then_ramps_to_the_command_at_the_rates():
    ramp = RejoinRamp(CFG)
    cmd = command(3, roll=0.0, pitch=0.0, leg=math.radians(45.0))
    cmd.platform_velocity = np.array([0.2, 0.0, 0.0])
    ramp.apply(True, DT, cmd, 0.0, 0.0, None)
    assert ramp.needs_measurement(False)
    folded = np.radians([12.0, 20.0, 14.0])
    held = ramp.apply(False, DT, cmd, math.radians(-15.0), math.radians(5.0), folded)  # PX4 Hold: legs folded
    assert ramp.suspended and held.leg_angles == pytest.approx(folded)
    assert (held.roll, held.pitch) == pytest.approx((math.radians(-15.0), math.radians(5.0)))
    assert np.all(held.platform_velocity == 0.0) and np.all(held.leg_rates == 0.0)  # nothing to chase meanwhile
    legs, rolls, steps = [], [], 0
    out = ramp.apply(True, DT, cmd, 0.0, 0.0, None)
    while ramp.ramping:
        legs.append(out.leg_angles.copy())
        rolls.append(out.roll)
        assert out.platform_velocity == pytest.approx(cmd.platform_velocity)  # the stick passes
        out = ramp.apply(True, DT, cmd, 0.0, 0.0, None)
        steps += 1
        assert steps < 1000
    assert out is cmd  # handed over: the operator's command again
    legs = np.array(legs)
    assert np.abs(np.diff(legs, axis=0)).max() <= CFG.leg_rate * DT + 1e-12
    assert np.abs(np.diff(rolls)).max() <= CFG.attitude_rate * DT + 1e-12
    # slowest channel: the leg from 12 deg to 45 deg at 8 deg/s (roll from -15 deg at 5 deg/s takes 3 s)
    assert steps * DT == pytest.approx(33.0 / 8.0, abs=2 * DT)


def test_a_moving_command_is_reached_and_measured_legs_are_needed_while_suspended():
    ramp = RejoinRamp(CFG)
    ramp.apply(True, DT, command(3), 0.0, 0.0, None)
    with pytest.raises(ValueError):
        ramp.apply(False, DT, command(3), 0.0, 0.0, None)
    with pytest.raises(ValueError):
        RejoinConfig(leg_rate=0.0)


PARAMS = default_parameters(3)


def _controller() -> Controller:
    gains = gains_from_dict({}, 3)
    return Controller(PARAMS, ControllerConfig(uav_id=1, mode="communicating", gains=gains, rejoin=CFG))


def _local(leg: float, roll: float = 0.0) -> LocalEstimate:
    return LocalEstimate(leg_angle=leg, platform_roll=roll, platform_pitch=0.0, attitude=np.array([1.0, 0, 0, 0]),
                         velocity=np.zeros(3), relative_yaw=0.0, uav_yaw=0.0, valid=True)


def test_the_controller_holds_its_integrators_and_rejoins_from_the_measured_legs():
    controller = _controller()
    cmd = command(3, leg=math.radians(45.0))
    t = 0.0
    for _ in range(20):  # flying normally, the peers' zeta fresh
        for j in (2, 3):
            controller.receive_info(PeerInfo(j, math.radians(45.0), np.zeros(3), np.array([1.0, 0, 0, 0]), 11.0), t)
        out = controller.step(t, _local(math.radians(44.0)), cmd, flown=True)
        t += DT
    integral = controller.pid.integral.copy()
    for _ in range(50):  # PX4 holds: the legs fold, the peers say so in their zeta
        for j in (2, 3):
            controller.receive_info(PeerInfo(j, math.radians(20.0), np.zeros(3), np.array([1.0, 0, 0, 0]), 11.0), t)
        out = controller.step(t, _local(math.radians(15.0), roll=-0.2), cmd, flown=False)
        t += DT
    assert np.array_equal(controller.pid.integral, integral)  # no wind-up while not flown
    assert out.desired.leg_angles == pytest.approx(np.radians([15.0, 20.0, 20.0]))  # own estimate + peers' zeta
    assert out.desired.roll == pytest.approx(-0.2)
    out = controller.step(t, _local(math.radians(15.0), roll=-0.2), cmd, flown=True)
    assert controller.rejoin.ramping
    step = CFG.leg_rate * DT
    assert out.desired.leg_angles == pytest.approx(np.radians([15.0, 20.0, 20.0]) + step)
