"""Issue 12, bounded inputs: the controller's own command limits, ζ plausibility and one publisher per uav_id
(ROS-free cores: fpr_control.command_limits, fpr_control.information)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fpr_control.command_limits import CommandLimits, bound_command
from fpr_control.controller import Controller, ControllerConfig, gains_from_dict
from fpr_control.information import InfoPlausibility, InformationTable, LocalEstimate, PeerInfo
from fpr_control.reference import TeleopReference
from fpr_model.parameters import default_parameters
from fpr_model.rotations import euler_zyx_to_quat

LIMITS = CommandLimits()


def _command(**fields) -> TeleopReference:
    base = dict(platform_velocity=np.array([0.3, -0.2, 0.1]), platform_acceleration=np.array([0.5, 0.0, 0.0]),
                yaw_rate=0.2, yaw_acceleration=0.3, roll=math.radians(10.0), roll_rate=0.05,
                pitch=math.radians(-5.0), pitch_rate=-0.05, leg_angles=np.radians([60.0, 45.0, 75.0]),
                leg_rates=np.array([0.1, -0.1, 0.0]), contact_force=5.0, mode=2)
    base.update(fields)
    return TeleopReference(**base)


def test_valid_commands_pass_unchanged_including_the_thesis_experiment_ranges():
    for legs in ([30.0] * 3, [75.0] * 3, [15.0] * 3, [80.0] * 3):
        for roll, pitch in ((0.0, 0.0), (20.0, -20.0), (10.0, 25.0), (-30.0, 30.0)):  # Exp. IV: 10 / 25 deg
            command = _command(leg_angles=np.radians(legs), roll=math.radians(roll), pitch=math.radians(pitch))
            result = bound_command(command, LIMITS)
            assert result.command is command and result.refused is None and result.clamped == []
    # the teleop's extremes: full stick on every axis, its low-pass derivatives, 10 N
    extreme = _command(platform_velocity=np.array([0.5, 0.5, 0.3]), platform_acceleration=np.array([1.0, 1.0, 0.6])
                       / 0.3, yaw_rate=0.5, yaw_acceleration=0.5 / 0.3, contact_force=10.0)
    assert bound_command(extreme, LIMITS).command is extreme


@pytest.mark.parametrize("fields, why", [
    (dict(leg_angles=np.radians([150.0, 60.0, 60.0])), "leg angle 1 150.0 deg outside the joint stops"),
    (dict(leg_angles=np.radians([60.0, 5.0, 60.0])), "leg angle 2 5.0 deg outside the joint stops"),
    (dict(roll=math.radians(80.0)), "roll 80.0 deg beyond 2 x its limit 30.0 deg"),
    (dict(pitch=math.radians(-61.0)), "pitch -61.0 deg beyond"),
    (dict(platform_velocity=np.array([1e9, 0.0, 0.0])), "|platform velocity| 1e+09 m/s beyond"),
    (dict(platform_acceleration=np.array([0.0, 0.0, 13.0])), "|platform acceleration| 13 m/s^2 beyond"),
    (dict(yaw_rate=1e9), "yaw rate 1e+09 rad/s beyond"),
    (dict(roll_rate=3.0), "roll rate 3 rad/s beyond"),
    (dict(leg_rates=np.array([0.0, 0.0, -2.5])), "leg rate 3 -2.5 rad/s beyond"),
    (dict(yaw_acceleration=-20.0), "yaw acceleration -20 rad/s^2 beyond"),
    (dict(contact_force=1e9), "contact force 1e+09 N outside [-15, 30] N"),
    (dict(contact_force=-20.0), "contact force -20 N outside"),
    (dict(mode=9), "mode 9 is not a TeleopCommand.MODE_*"),
])
def test_absurd_commands_are_refused_with_the_reason(fields, why):
    result = bound_command(_command(**fields), LIMITS)
    assert result.command is None and why in result.refused


def test_all_fields_1e9_is_refused():
    n = 3
    absurd = TeleopReference(np.full(3, 1e9), np.full(3, 1e9), 1e9, 1e9, 1e9, 1e9, 1e9, 1e9, np.full(n, 1e9),
                             np.full(n, 1e9), 1e9, 2)
    assert bound_command(absurd, LIMITS).command is None


def test_slightly_out_of_range_values_are_clamped_to_the_limit():
    command = _command(leg_angles=np.radians([85.0, 12.0, 60.0]), roll=math.radians(35.0),
                       platform_velocity=np.array([1.2, 0.0, 0.9]), yaw_rate=-1.5, contact_force=18.0)
    result = bound_command(command, LIMITS)
    out = result.command
    assert out is not None and result.refused is None
    np.testing.assert_allclose(np.degrees(out.leg_angles), [80.0, 15.0, 60.0])
    assert out.roll == pytest.approx(math.radians(30.0)) and out.yaw_rate == -1.0 and out.contact_force == 15.0
    assert np.linalg.norm(out.platform_velocity) == pytest.approx(1.0)  # scaled, direction kept
    np.testing.assert_allclose(out.platform_velocity / 1.0, np.array([1.2, 0.0, 0.9]) / 1.5)
    assert len(result.clamped) == 6 and "roll 35.0 deg -> 30.0 deg" in result.clamped
    assert command.roll == pytest.approx(math.radians(35.0))  # the input is not modified
    assert bound_command(_command(contact_force=-1.0), LIMITS).command.contact_force == 0.0


def test_command_limits_validation():
    with pytest.raises(ValueError):
        CommandLimits(leg_angle_min=math.radians(5.0))  # below the joint stop
    with pytest.raises(ValueError):
        CommandLimits(max_speed=0.0)
    with pytest.raises(ValueError):
        CommandLimits(refuse_ratio=0.5)


def test_the_controller_saturates_each_thrust_at_its_f_max_even_for_an_absurd_command():
    """The controller's thrust ceiling (3.36)-(3.38): an unbounded command reaching the law still gives a thrust
    in [0, max_thrust] (the node bounds commands first; this is the last line)."""
    n = 3
    params = default_parameters(n)
    controller = Controller(params, ControllerConfig(uav_id=1, mode="non_communicating",
                                                     gains=gains_from_dict({}, n), max_thrust=25.0))
    local = LocalEstimate(math.radians(60.0), 0.0, 0.0, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), 0.0, 0.0)
    absurd = _command(platform_velocity=np.array([0.0, 0.0, 1e3]), platform_acceleration=np.array([0.0, 0.0, 1e3]))
    out = controller.step(0.0, local, absurd)
    assert out.state_ok and out.thrust_saturated and out.thrust == pytest.approx(25.0)


# ---- ζ plausibility -------------------------------------------------------------------------------------
def _zeta(uav_id=2, leg=60.0, velocity=(0.0, 0.0, 0.0), yaw=0.0, thrust=11.0) -> PeerInfo:
    return PeerInfo(uav_id, math.radians(leg), np.array(velocity, dtype=float), euler_zyx_to_quat(0.0, 0.0, yaw),
                    thrust)


def test_implausible_zeta_is_refused_and_counts_as_missing_then_accepted_again():
    table = InformationTable(3, 1, timeout=0.2)
    assert table.update(_zeta(2), 0.0) is None and table.update(_zeta(3), 0.0) is None
    for bad, why in ((_zeta(2, leg=150.0), "leg angle 150.0 deg outside [7, 90] deg"),
                     (_zeta(2, leg=3.0), "outside"),
                     (_zeta(2, velocity=(1e3, 0.0, 0.0)), "speed 1e+03 m/s above 10 m/s"),
                     (_zeta(2, thrust=1e9), "thrust 1e+09 N above 50 N"),
                     (_zeta(2, leg=90.0), "leg angle jumps 30.0 deg in 0.020 s"),
                     (_zeta(2, yaw=math.radians(60.0)), "attitude turns 60.0 deg in 0.020 s"),
                     (_zeta(2, velocity=(0.0, 3.0, 0.0)), "velocity jumps 3 m/s in 0.020 s")):
        reason = table.update(bad, 0.02)
        assert reason is not None and why in reason and "counted as missing" in reason
    assert table.get(2).leg_angle == pytest.approx(math.radians(60.0))  # never replaced
    assert table.update(_zeta(3), 0.1) is None
    assert not table.all_fresh(0.25)  # ζ_2 is 0.25 s old: the NC fallback applies
    assert table.take_announcements() == []
    assert table.update(_zeta(2, leg=61.0), 0.26) is None  # a physical change: accepted, announced once
    assert table.take_returns() == ["zeta_2 accepted again after 7 refused"] and table.take_announcements() == []
    # the jump bound grows with the time since the last accepted ζ: a lasting genuine change is taken
    assert table.update(_zeta(2, leg=90.0), 0.28) is not None  # 29 deg > 20 rad/s * 0.02 s + 5 deg
    assert table.update(_zeta(2, leg=90.0), 0.30) is None  # 29 deg < 20 rad/s * 0.04 s + 5 deg


def test_plausible_motion_is_accepted_every_period():
    table = InformationTable(3, 1, timeout=0.2)
    for k in range(100):  # legs 30 -> 75 deg in 2 s, 1.5 m/s, yawing 1 rad/s
        t = 0.02 * k
        zeta = _zeta(2, leg=30.0 + 22.5 * t, velocity=(1.5, 0.0, 0.2), yaw=1.0 * t)
        assert table.update(zeta, t, sequence=k + 1) is None


# ---- one publisher per uav_id ------------------------------------------------------------------------
def test_a_second_publisher_of_a_peer_id_is_refused_and_announced_once():
    table = InformationTable(3, 1, timeout=0.2)
    for k in range(50):  # UAV 2's controller: sequence numbers 101.. (it started 2 s before)
        assert table.update(_zeta(2), 0.02 * k, sequence=101 + k) is None
    t = 1.0
    stored = table.get(2)
    for k in range(20):  # an intruder claiming uav_id 2 starts: its own writer counts from 1
        assert table.update(_zeta(2, leg=62.0), t, sequence=1 + k) is None
        assert table.update(_zeta(2), t, sequence=151 + k) is None  # the genuine one goes on
        t += 0.02
    assert table.get(2) is not stored and table.get(2).leg_angle == pytest.approx(math.radians(60.0))
    lines = table.take_announcements()
    assert lines == ["zeta_2: a second publisher claims it (sequence 1, the established one's last 150): refused"]
    assert table.intruder_messages == 20
    # a second intruder is announced too, once
    for k in range(3):
        table.update(_zeta(2), t, sequence=5000 + k)
    assert len(table.take_announcements()) == 1


def test_a_restarted_publisher_takes_over_after_the_old_one_is_silent():
    table = InformationTable(3, 1, timeout=0.2)
    for k in range(10):
        table.update(_zeta(2), 0.02 * k, sequence=500 + k)
    assert table.update(_zeta(2), 0.5, sequence=1) is None  # 0.32 s silent: still an intruder
    assert "second publisher" in table.take_announcements()[0]
    assert table.update(_zeta(2), 1.3, sequence=40) is None  # silent 1.12 s >= publisher_timeout 1 s
    assert "takes over" in table.take_announcements()[0]
    assert table.ages(1.3)[1] == 0.0


def test_relay_forwarding_several_ids_and_losses_are_one_stream_each():
    table = InformationTable(3, 1, timeout=0.2)
    seq = 0
    for k in range(200):
        for j in (1, 2, 3):
            seq += 1
            if (k * 3 + j) % 7 == 0:
                continue  # best-effort losses
            table.update(_zeta(j), 0.02 * k, sequence=seq)
    assert table.intruder_messages == 0 and table.take_announcements() == []


def test_a_forged_echo_of_the_own_id_is_refused_entirely():
    table = InformationTable(3, 1, timeout=0.2, own_writer_direct=True)
    t = 0.0
    for _ in range(30):
        table.note_own_publication()
        assert table.update(_zeta(1), t, sequence=table.own_publications) is None
        t += 0.02
    assert table.own_echo_age(t) == pytest.approx(0.02)
    for k in range(200):  # a forger claiming uav_id 1, never the own writer's sequence numbers
        table.update(_zeta(1), t, sequence=1000 + k)
        t += 0.02
    assert table.own_echo_age(t) > 0.2 and not table.all_fresh(t)  # our own echo is missing: fallback
    lines = table.take_announcements()
    assert len(lines) == 1 and "forged echo of this controller's own zeta" in lines[0]
    assert table.update(_zeta(1), t, sequence=table.own_publications + 1) is None  # not published yet: forged
    assert table.own_echo_age(t) > 0.2
    table.note_own_publication()
    assert table.update(_zeta(1), t, sequence=table.own_publications) is None  # the genuine echo again
    assert table.own_echo_age(t) == 0.0


def test_plausibility_validation():
    with pytest.raises(ValueError):
        InfoPlausibility(max_speed=0.0)
    with pytest.raises(ValueError):
        InfoPlausibility(leg_angle_min=2.0, leg_angle_max=1.0)
