"""The scripted operator (ROS-free) on a toy platform that follows the velocity command, and the link outage."""

from __future__ import annotations

import numpy as np
import pytest
from fpr_experiments.link import LinkOutage
from fpr_experiments.pilot import Channel, Observation, Pilot, PilotConfig, Task, TaskPlan, pilot_from_script

#: the default teleop mapping's channels (fpr_control config/teleop.yaml)
CHANNELS = {"velocity_x": Channel(4, 0.5, minimum=-0.5, maximum=0.5),
            "velocity_y": Channel(3, 0.5, minimum=-0.5, maximum=0.5),
            "velocity_z": Channel(1, 0.3, minimum=-0.3, maximum=0.3),
            "yaw_rate": Channel(0, 0.5), "contact_force": Channel(2, -5.0, center=1.0, minimum=0.0, maximum=10.0)}
DEAD_ZONE = 0.08


def _fly(pilot: Pilot, start: np.ndarray, duration: float, yaw: float = 0.3, contact_height: float = np.inf,
         sag: float = 0.0, board_gone: tuple[float, float] = (np.inf, np.inf)):
    """A platform whose velocity in F_Fp is what the sticks ask (the teleop's dead zone, no dynamics), less a
    steady sink rate ``sag`` [m/s] (a decentralized controller without position integral under a thrust deficit:
    it tracks the asked climb speed short by the deficit over its damping gain). In ``board_gone`` [s] the board is
    not there (the platform slid off it): no contact, and the force trigger climbs at 0.1 m/s per N."""
    position, dt, events, samples = start.astype(float), 0.02, [], []
    for step in range(int(duration / dt)):
        t = step * dt
        gone = board_gone[0] <= t < board_gone[1]
        contact = 5.0 if position[2] >= contact_height and not gone else 0.0
        pilot.observe(Observation(t, position.copy(), yaw, contact))
        axes = pilot.axes(t)
        stick = {name: axes.get(c.axis, c.center) for name, c in CHANNELS.items()}

        def speed(name: str, stick=stick) -> float:
            value = stick[name] - CHANNELS[name].center
            return 0.0 if abs(value) < DEAD_ZONE else value * CHANNELS[name].scale

        flat = np.array([speed("velocity_x"), speed("velocity_y"), speed("velocity_z")])
        world = np.array([np.cos(yaw) * flat[0] - np.sin(yaw) * flat[1], np.sin(yaw) * flat[0] + np.cos(yaw) * flat[1],
                          flat[2]])
        pressed = -5.0 * (stick["contact_force"] - 1.0)  # the mapping: released +1 -> 0 N, -5 N per unit
        climb = 0.1 * pressed if gone else 0.0  # force / damping on nothing (10 N s/m)
        position = position + (world - [0.0, 0.0, sag - climb]) * dt
        if position[2] > contact_height and not gone:
            position[2] = contact_height
        events += pilot.take_events()
        samples.append((t, stick["contact_force"]))
    return position, events, samples


def test_goto_tasks_reach_their_targets_and_report_success():
    plan = TaskPlan(1.0, 60.0, [Task("goto", target=[0.6, 0.0, 2.1]), Task("goto", target=[-0.3, 0.5, 1.9])])
    pilot = Pilot(PilotConfig(seed=1), plan, CHANNELS)
    final, events, _ = _fly(pilot, np.array([0.0, 0.0, 2.0]), 40.0)
    ends = [e for e in events if e["event"] == "task_end"]
    assert [e["success"] for e in ends] == [True, True]
    assert [e["event"] for e in events if e["task"] == 1][:2] == ["task_start", "criterion_reached"]
    assert np.linalg.norm(final - [-0.3, 0.5, 1.9]) < 0.1  # holds the last target afterwards


def test_the_trim_removes_the_steady_error_a_proportional_operator_leaves_under_a_sag():
    plan = TaskPlan(1.0, 60.0, [Task("hold", target=[0.0, 0.0, 2.0], duration=50.0)])
    heights = {}
    for trim_gain in (0.0, 0.5):
        pilot = Pilot(PilotConfig(seed=5, stick_noise=0.0, perception_noise=0.0, trim_gain=trim_gain), plan, CHANNELS)
        final, _, _ = _fly(pilot, np.array([0.0, 0.0, 2.0]), 40.0, sag=0.1)
        heights[trim_gain] = final[2]
    assert heights[0.0] == pytest.approx(2.0 - 0.1 / 1.0, abs=0.01)  # P only: asked climb 1/s * error = the sag
    assert heights[0.5] == pytest.approx(2.0, abs=0.01)


def test_the_trim_is_bounded_and_the_config_is_checked():
    plan = TaskPlan(0.0, 60.0, [Task("hold", target=[0.0, 0.0, 2.0], duration=50.0)])
    pilot = Pilot(PilotConfig(seed=6, stick_noise=0.0, perception_noise=0.0, trim_gain=0.5, trim_limit=0.05),
                  plan, CHANNELS)
    final, _, _ = _fly(pilot, np.array([0.0, 0.0, 2.0]), 40.0, sag=0.1)
    assert final[2] == pytest.approx(2.0 - 0.05, abs=0.01)  # the trim tops out at 0.05 m/s: the rest is P
    for bad in ({"trim_gain": -1.0}, {"trim_zone": float("nan")}, {"update_period": 0.0}):
        with pytest.raises(ValueError, match="pilot"):
            PilotConfig(**bad)


def test_an_unreachable_target_times_out_as_a_failure():
    plan = TaskPlan(0.0, 30.0, [Task("goto", target=[0.0, 0.0, 2.0], timeout=5.0, axes=["x", "y"])])
    pilot = Pilot(PilotConfig(seed=2), plan, CHANNELS)
    _, events, _ = _fly(pilot, np.array([0.0, 0.0, 1.0]), 10.0)  # z not driven: never within 10 cm
    end = next(e for e in events if e["event"] == "task_end")
    assert not end["success"] and "not reached" in end["reason"]


def test_push_aligns_climbs_to_contact_then_asks_for_the_force():
    plan = TaskPlan(0.0, 60.0, [Task("push", target=[0.0, 0.0, 2.2], align_radius=0.05, approach_speed=0.1,
                                     force=5.0, ramp=2.0, duration=5.0, axes=["z", "force"])])
    pilot = Pilot(PilotConfig(seed=3, stick_noise=0.0), plan, CHANNELS)
    _, events, samples = _fly(pilot, np.array([0.0, 0.0, 2.0]), 20.0, contact_height=2.1)
    kinds = [e["event"] for e in events]
    assert kinds[:2] == ["task_start", "contact"] and kinds[2] == "task_end" and events[2]["success"]
    forces = [-5.0 * (s - 1.0) for _, s in samples]  # the mapping: released +1 -> 0 N, scale -5 N per unit
    assert max(forces) == pytest.approx(5.0, abs=0.05)  # the trigger reached 5 N


def test_a_contact_lost_while_pressing_releases_the_force_and_approaches_again():
    """The platform slides off the board at 8 s (pressing on nothing it climbs at 0.5 m/s for as long as the
    trigger is held): the operator sees it 10 cm away from where it touched (0.2 s, plus the reaction delay),
    releases the trigger, comes back down to the board's height and presses again when the board is back."""
    plan = TaskPlan(0.0, 60.0, [Task("push", target=[0.0, 0.0, 2.2], approach_speed=0.1, force=5.0, ramp=1.0,
                                     duration=6.0, contact_loss_distance=0.1, axes=["z", "force"])])
    config = PilotConfig(seed=3, stick_noise=0.0)
    pilot = Pilot(config, plan, CHANNELS)
    final, events, samples = _fly(pilot, np.array([0.0, 0.0, 2.0]), 30.0, contact_height=2.1, board_gone=(8.0, 12.0))
    kinds = [e["event"] for e in events]
    assert kinds[:3] == ["task_start", "contact", "contact_lost"] and "contact" in kinds[3:]
    lost = next(e for e in events if e["event"] == "contact_lost")
    assert 8.2 <= lost["t"] <= 8.2 + config.reaction_delay + 2 * config.update_period + 1e-9
    assert lost["moved"] >= 0.1
    released = next(t for t, s in samples if t > 8.0 and -5.0 * (s - 1.0) < 0.05)
    assert released <= lost["t"] + config.update_period + 1e-9
    assert final[2] == pytest.approx(2.1, abs=1e-9)  # back on the board, not flown away
    end = next(e for e in events if e["event"] == "task_end")
    assert end["success"] and end["t"] > 12.0 + 1.0 + 6.0  # the force held 6 s from the new contact
    with pytest.raises(ValueError, match="contact_loss_time"):
        Task("push", contact_loss_time=0.0)
    with pytest.raises(ValueError, match="contact_loss_distance"):
        Task("push", contact_loss_distance=float("nan"))


def test_a_bounce_on_the_board_does_not_release_the_force():
    """Contact flickers (0.4 s off every 1 s) while the platform stays on the board: pressed throughout."""
    plan = TaskPlan(0.0, 60.0, [Task("push", target=[0.0, 0.0, 2.2], approach_speed=0.1, force=5.0, ramp=1.0,
                                     duration=6.0, axes=["z", "force"])])
    pilot = Pilot(PilotConfig(seed=3, stick_noise=0.0), plan, CHANNELS)
    position, events = np.array([0.0, 0.0, 2.0]), []
    for step in range(int(20.0 / 0.02)):
        t = step * 0.02
        touching = position[2] >= 2.1 and (t % 1.0) < 0.6
        pilot.observe(Observation(t, position.copy(), 0.3, 5.0 if touching else 0.0))
        axes = pilot.axes(t)
        climb = axes.get(CHANNELS["velocity_z"].axis, CHANNELS["velocity_z"].center) - CHANNELS["velocity_z"].center
        position[2] = min(2.1, position[2] + (climb * CHANNELS["velocity_z"].scale if abs(climb) >= DEAD_ZONE
                                              else 0.0) * 0.02)
        events += pilot.take_events()
    kinds = [e["event"] for e in events]
    assert "contact" in kinds and "contact_lost" not in kinds
    assert next(e for e in events if e["event"] == "task_end")["success"]


def test_the_operator_does_not_climb_before_alignment():
    plan = TaskPlan(0.0, 60.0, [Task("push", target=[1.0, 0.0, 2.5], align_radius=0.05, axes=["z", "force"])])
    pilot = Pilot(PilotConfig(seed=4, stick_noise=0.0), plan, CHANNELS)
    final, events, _ = _fly(pilot, np.array([0.0, 0.0, 2.0]), 10.0)  # x not driven: never aligned
    assert final[2] == pytest.approx(2.0, abs=0.02) and not any(e["event"] == "contact" for e in events)


def test_pilot_scripts_are_validated():
    config, plan = pilot_from_script({"pilot": {"reaction_delay": 0.3}, "tasks": {
        "start": 2.0, "end": 10.0, "list": [{"kind": "goto", "target": [0, 0, 2]}]}})
    assert config.reaction_delay == 0.3 and plan.tasks[0].kind == "goto"
    with pytest.raises(ValueError, match="unknown key"):
        pilot_from_script({"pilot": {"reaction": 0.3}})
    with pytest.raises(ValueError, match="task kind 'fly'"):
        pilot_from_script({"tasks": {"list": [{"kind": "fly"}]}})
    with pytest.raises(ValueError, match="no absolute axis channel"):
        Pilot(PilotConfig(), TaskPlan(0, 1, [Task("goto")]), {})


def test_link_outage_drops_only_inside_its_window():
    outage = LinkOutage(10.0, 13.0)
    assert [outage.passes(t) for t in (9.99, 10.0, 12.99, 13.0)] == [True, False, False, True]
    assert LinkOutage().passes(1e9)
    with pytest.raises(ValueError):
        LinkOutage(5.0, 4.0)
