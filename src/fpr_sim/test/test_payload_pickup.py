"""Payloads (scenario ``payloads``, environment.Environment.payload_mass): timed attach / release as before, and
pick-up by proximity (thesis §4.4.2 Scenario I: the platform centre brought to a hanging load lifts it), with
``hold_time``, several pick-ups in one run, the ground truth and both plant kernels."""

import math

import numpy as np
import pytest
from fpr_sim.environment import Environment
from fpr_sim.plant import Plant
from fpr_sim.scenario import scenario_from_dict

BALL = [0.5, 0.0, 1.6]


def _environment(payloads: list[dict]) -> Environment:
    return Environment(scenario_from_dict({"payloads": payloads}))


def test_timed_payloads_are_unchanged():
    """Without pickup_position the schedule is the former pure function of t: attach_time <= t < release_time,
    whatever the platform position (or none)."""
    payloads = [{"mass": 0.3, "attach_time": 1.0, "release_time": 2.0}, {"mass": 0.2, "attach_time": 1.5},
                {"mass": 0.1, "attach_time": 0.0, "release_time": 0.5}]
    env = _environment(payloads)
    other = _environment(payloads)
    for t in np.arange(0.0, 3.0, 0.001).tolist():
        expected = float(sum(p["mass"] for p in payloads
                             if p["attach_time"] <= t < p.get("release_time", math.inf)))
        assert env.payload_mass(t, [5.0, 5.0, 5.0]) == expected
        assert other.payload_mass(t) == expected
    assert math.isnan(env.pickup_times[0])
    changes = [(c.index, c.attached, c.pickup) for c in env.payload_changes]
    assert changes == [(2, True, False), (2, False, False), (0, True, False), (1, True, False), (0, False, False)]
    assert [c.time for c in env.payload_changes] == pytest.approx([0.0, 0.5, 1.0, 1.5, 2.0], abs=1.5e-3)
    # a timed payload with hold_time: released at min(release_time, attach_time + hold_time)
    env = _environment([{"mass": 0.3, "attach_time": 1.0, "release_time": 5.0, "hold_time": 0.5}])
    assert [env.payload_mass(t) for t in (0.9, 1.0, 1.49, 1.5, 3.0)] == [0.0, 0.3, 0.3, 0.0, 0.0]


def test_pickup_attaches_only_near_and_after_attach_time():
    env = _environment([{"mass": 0.4, "attach_time": 2.0, "pickup_position": BALL, "pickup_radius": 0.15}])
    near = [0.5, 0.0, 1.5]  # 10 cm below the ball
    far = [0.5, 0.0, 1.4]  # 20 cm
    assert env.payload_mass(1.0, near) == 0.0  # near, but before attach_time
    assert env.payload_mass(1.999, near) == 0.0
    assert env.payload_mass(2.5, far) == 0.0  # after attach_time, but too far
    assert env.payload_mass(2.6, None) == 0.0  # no position: nothing picked up
    assert math.isnan(env.pickup_times[0])
    assert env.payload_mass(3.0, near) == pytest.approx(0.4)
    assert env.pickup_times == [3.0]
    # held (release_time inf, no hold_time) wherever the platform goes
    assert env.payload_mass(10.0, [9.0, 9.0, 9.0]) == pytest.approx(0.4)
    (change,) = env.payload_changes
    assert change.attached and change.pickup and change.time == 3.0 and change.distance == pytest.approx(0.1)


def test_pickup_is_released_after_hold_time_or_release_time_and_attaches_once():
    env = _environment([{"mass": 0.4, "attach_time": 0.0, "pickup_position": BALL, "hold_time": 2.0,
                         "release_time": 100.0}])
    assert env.payload_mass(1.0, BALL) == pytest.approx(0.4)
    assert env.payload_mass(2.999, BALL) == pytest.approx(0.4)
    assert env.payload_mass(3.0, BALL) == 0.0  # hold_time after the pick-up at 1 s
    assert env.payload_mass(4.0, BALL) == 0.0  # still at the ball: not picked up again
    assert [(c.attached, c.time) for c in env.payload_changes] == [(True, 1.0), (False, 3.0)]
    # release_time first
    env = _environment([{"mass": 0.4, "pickup_position": BALL, "hold_time": 10.0, "release_time": 5.0}])
    assert env.payload_mass(4.0, BALL) == pytest.approx(0.4) and env.payload_mass(5.0, BALL) == 0.0
    # after release_time it can no longer be picked up
    env = _environment([{"mass": 0.4, "pickup_position": BALL, "release_time": 5.0}])
    assert env.payload_mass(6.0, BALL) == 0.0 and math.isnan(env.pickup_times[0])


def test_several_pickups_one_per_task():
    """Three hanging loads (Table 4.3's tennis-ball tasks, Sc. I's load): each picked up once, at its own place,
    held for its hold_time; the masses add while two are carried."""
    balls = [[0.5, 0.0, 1.6], [0.0, 0.5, 1.6], [-0.5, 0.0, 1.6]]
    env = _environment([{"mass": 0.05, "attach_time": 0.0, "pickup_position": balls[0], "hold_time": 3.0},
                        {"mass": 0.1, "attach_time": 0.0, "pickup_position": balls[1], "hold_time": 3.0},
                        {"mass": 0.4, "attach_time": 5.0, "pickup_position": balls[2], "pickup_radius": 0.05}])
    at = {"0": balls[0], "1": balls[1], "2": balls[2], "2-near": [-0.5, 0.0, 1.52], "away": [0.0, 0.0, 1.0]}
    path = [(0.0, "away"), (1.0, "0"), (1.5, "away"), (2.0, "1"), (3.0, "0"), (3.5, "2"), (4.5, "away"),
            (5.0, "2-near"), (6.0, "2"), (8.0, "away")]
    masses = [env.payload_mass(t, at[where]) for t, where in path]
    assert masses == pytest.approx([0.0, 0.05, 0.05, 0.15, 0.15, 0.15, 0.1, 0.0, 0.4, 0.4])
    assert env.pickup_times == [1.0, 2.0, 6.0]
    # the changes at the calls that saw them (the plant calls every step)
    assert [(c.index, c.attached, c.time) for c in env.payload_changes] == [
        (0, True, 1.0), (1, True, 2.0), (0, False, 4.5), (1, False, 5.0), (2, True, 6.0)]


def test_pickup_keys_are_validated():
    scenario = scenario_from_dict({"payloads": [{"pickup_position": BALL}]})
    payload = scenario.payloads[0]
    assert payload.pickup_radius == 0.15 and payload.hold_time == 0.0 and payload.release_time == math.inf
    assert scenario_from_dict({"payloads": [{}]}).payloads[0].pickup_position is None
    for bad, match in (({"pickup_position": [0.0, 1.0]}, "pickup_position"),
                       ({"pickup_position": BALL, "pickup_radius": 0.0}, "pickup_radius"),
                       ({"hold_time": -1.0}, "hold_time"), ({"mass": -0.1}, "mass"),
                       ({"pickup_positon": BALL}, r"unknown key\(s\) \['pickup_positon'\]")):
        with pytest.raises(ValueError, match=match):
            scenario_from_dict({"payloads": [bad]})


def _hold_hover_thrusts(plant: Plant) -> None:
    """Ideal attitudes holding the hover thrusts of the current state (the robot floats)."""
    from fpr_model.dynamics import gravity, thrusts_from_wrench
    from fpr_sim.quadrotor import AttitudeCommand

    q = plant.state.configuration()
    forces = thrusts_from_wrench(plant.params, q, gravity(plant.params, q))
    plant.ideal_attitude = True
    plant.set_command(AttitudeCommand(plant.default_uav_attitudes(forces),
                                      np.linalg.norm(forces, axis=1) / plant.fleet.max_thrust(),
                                      np.ones(plant.n, dtype=bool)))


@pytest.mark.parametrize("kernel", ["python", "compiled"])
def test_plant_picks_up_when_the_platform_reaches_the_load(kernel):
    """In the plant: the hovering platform is placed under the ball at 0.1 s; the payload attaches at that step
    (ground truth payload_mass, its weight in the true τ_e), is released hold_time later, and the two kernels
    agree."""
    from fpr_sim._kernels import kernel_status

    if kernel == "compiled" and not kernel_status().available:
        pytest.skip(kernel_status().reason)
    scenario = scenario_from_dict({
        "initial_state": {"mode": "hover", "position": [0.0, 0.0, 1.5], "leg_angles": 0.8},
        "ground": {"enabled": False},
        "payloads": [{"mass": 0.4, "attach_time": 0.05, "pickup_position": BALL, "hold_time": 0.1}]})
    plant = Plant(scenario, kernel=kernel)
    plant.ideal_attitude = True
    masses, wrench_z = [], []
    for k in range(300):
        if k == 100:
            state = plant.state
            state.position = np.array([0.5, 0.0, 1.52])
            plant.set_state(state)
        plant.step()
        truth = plant.ground_truth()
        masses.append(truth.payload_mass)
        wrench_z.append(truth.external_wrench[2])
    masses = np.array(masses)  # masses[k]: after step k, which started at t = k ms
    assert np.all(masses[:100] == 0.0) and np.all(masses[100:199] == 0.4) and np.all(masses[201:] == 0.0)
    assert plant.environment.pickup_times == [pytest.approx(0.1)]
    assert wrench_z[150] == pytest.approx(-0.4 * plant.params.gravity, abs=1e-9)
    assert wrench_z[50] == pytest.approx(0.0, abs=1e-9)


def test_both_kernels_follow_the_same_pickup_trajectory():
    """A pick-up while flying through the ball: identical schedule and trajectories with both kernels."""
    from fpr_sim._kernels import kernel_status

    if not kernel_status().available:
        pytest.skip(kernel_status().reason)
    scenario = {"initial_state": {"mode": "hover", "position": [0.0, 0.0, 1.5], "leg_angles": 0.8},
                "ground": {"enabled": False},
                "payloads": [{"mass": 0.3, "pickup_position": [0.02, 0.0, 1.5], "pickup_radius": 0.01,
                              "hold_time": 0.05}]}
    plants = [Plant(scenario_from_dict(scenario), kernel=k) for k in ("python", "compiled")]
    for plant in plants:
        _hold_hover_thrusts(plant)
        state = plant.state
        state.velocity = np.array([0.3, 0.0, 0.0])
        plant.set_state(state)
    for _ in range(200):
        for plant in plants:
            plant.step()
        assert plants[0].structure.payload_mass == plants[1].structure.payload_mass
        assert np.allclose(plants[1]._x, plants[0]._x, rtol=1e-9, atol=1e-9)
    python, compiled = (p.environment for p in plants)
    assert python.pickup_times == compiled.pickup_times and 0.01 < python.pickup_times[0] < 0.06
    assert len(python.payload_changes) == 2
