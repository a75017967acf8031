"""Plant acceptance: hover with J^-T g and ideal attitudes, free fall at g, resting on the ground, battery."""

import numpy as np
import pytest
from fpr_model.dynamics import gravity, thrusts_from_wrench
from fpr_sim.plant import Plant
from fpr_sim.quadrotor import AttitudeCommand, mix
from fpr_sim.scenario import scenario_from_dict


def test_hover_with_ideal_attitudes_stays_within_1mm_for_10s():
    plant = Plant(scenario_from_dict({"initial_state": {"mode": "hover", "leg_angles": 0.8},
                                      "ground": {"enabled": False}}))
    plant.ideal_attitude = True
    q = plant.state.configuration()
    forces = thrusts_from_wrench(plant.params, q, gravity(plant.params, q))
    quats = plant.default_uav_attitudes(forces)
    start = plant.state
    worst = 0.0
    for k in range(10000):
        if k % 4 == 0:  # the battery sags: the PX4 user re-normalizes with the present f_max (C.1)
            u = np.linalg.norm(forces, axis=1) / plant.fleet.max_thrust()
            plant.set_command(AttitudeCommand(quats, u, np.ones(3, dtype=bool)))
        plant.step()
        if k % 100 == 0:
            worst = max(worst, np.abs(plant.state.position - start.position).max())
    end = plant.state
    worst = max(worst, np.abs(end.position - start.position).max())
    assert plant.time == pytest.approx(10.0)
    assert worst < 1e-3
    assert np.abs(end.leg_angles - start.leg_angles).max() < 1e-3


def test_zero_thrust_falls_at_g():
    plant = Plant(scenario_from_dict({"initial_state": {"mode": "hover"}, "ground": {"enabled": False}}))
    plant.fleet.hover_rotor_state(np.zeros(3))
    z0 = plant.state.position[2]
    for _ in range(500):
        plant.step()
    state = plant.state
    assert state.velocity[2] == pytest.approx(-9.81 * 0.5, rel=1e-9)
    assert state.position[2] - z0 == pytest.approx(-0.5 * 9.81 * 0.25, rel=1e-9)
    assert np.abs(state.leg_rates).max() < 1e-9


def test_resting_on_the_ground_stays_put_and_reports_ground_wrench():
    plant = Plant(scenario_from_dict({"initial_state": {"mode": "ground", "leg_angles": 1.0}}))
    start = plant.state
    for _ in range(1500):
        plant.step()
    end = plant.state
    assert np.abs(end.position - start.position).max() < 1e-3
    assert np.abs(end.leg_angles - start.leg_angles).max() < 1e-3
    truth = plant.ground_truth()
    # the ground carries the whole weight
    assert truth.external_wrench[2] == pytest.approx(plant.params.total_mass * 9.81, rel=1e-2)


def test_mixer_inverts_3_41_and_saturates():
    moments = np.array([[0.1, -0.2, 0.03]])
    rotors = mix(np.array([20.0]), moments, 0.17, 0.016, np.array([10.0]))
    t1, t2, t3, t4 = rotors[0]
    assert rotors.sum() == pytest.approx(20.0)
    assert 0.17 * (t2 - t4) == pytest.approx(0.1)
    assert 0.17 * (t3 - t1) == pytest.approx(-0.2)
    assert 0.016 * (-t1 + t2 - t3 + t4) == pytest.approx(0.03)
    capped = mix(np.array([60.0]), moments, 0.17, 0.016, np.array([10.0]))
    assert capped.max() <= 10.0 and capped.min() >= 0.0


def test_battery_voltage_drops_and_thrust_follows_table_c1():
    plant = Plant(scenario_from_dict({"initial_state": {"mode": "hover"}, "ground": {"enabled": False},
                                      "battery": {"capacity": 0.01}}))
    fleet = plant.fleet
    v0 = fleet.battery.voltage().copy()
    f0 = fleet.max_thrust()
    assert f0[0] == pytest.approx(8.02 * v0[0] - 61.66)
    fleet.battery.update(np.full(3, 10.0), 10.0)
    assert np.all(fleet.battery.voltage() < v0)
    assert np.all(fleet.max_thrust() < f0)


def test_hover_start_holds_the_hover_thrust_with_the_battery_under_load():
    """A hover start is a vehicle that has been flying: its battery voltage is the loaded one from t = 0, so the
    PX4 hold thrust normalized at t = 0 gives the hover thrusts (before: f_max(12.4 V) at t = 0, then the sag of the
    first step cut the thrust by 5.8 %)."""
    from fpr_sim.simulation import Simulation, SimulationOptions

    scenario = scenario_from_dict({"initial_state": {"mode": "hover", "armed": True}, "ground": {"enabled": False},
                                   "cameras": {"enabled": False}})
    sim = Simulation(scenario, SimulationOptions(local_base_port=0, remote_base_port=0, lockstep=False))
    try:
        plant = sim.plant
        hover = plant.fleet.thrust()
        v0 = plant.fleet.battery.voltage()
        assert np.all(v0 < plant.scenario.battery.full_voltage - 0.2)  # 1.6 A/N · 11.4 N · 15 mΩ ≈ 0.27 V of sag
        sim.advance(0.1)
        assert plant.fleet.battery.voltage() == pytest.approx(v0, abs=2e-3)  # only the charge drawn in 0.1 s
        assert plant.fleet.thrust() == pytest.approx(hover, rel=2e-3)
    finally:
        sim.close()


def test_simulation_ground_truth_is_evaluated_once_per_step_and_never_stale():
    """Simulation.ground_truth(): one evaluation per physics step, shared (the telemetry and the node's
    publishers); equal to a fresh evaluation at every step, the hover start's truth included (the start changes
    the plant after the first evaluation)."""
    from fpr_sim.simulation import Simulation, SimulationOptions

    scenario = scenario_from_dict({"initial_state": {"mode": "hover", "armed": True}, "ground": {"enabled": False},
                                   "cameras": {"enabled": False}, "wind": {"velocity": [2.0, 0.0, 0.0]}})
    sim = Simulation(scenario, SimulationOptions(local_base_port=0, remote_base_port=0, lockstep=False))
    try:
        for _ in range(12):
            shared = sim.ground_truth()
            assert sim.ground_truth() is shared  # the same object within a step
            fresh = sim.plant.ground_truth()
            assert shared.time == fresh.time == sim.time
            for name in ("uav_positions", "uav_quats", "uav_velocities", "uav_rates", "uav_specific_forces",
                         "uav_thrusts", "external_wrench", "battery_voltages"):
                np.testing.assert_array_equal(getattr(shared, name), getattr(fresh, name), err_msg=name)
            np.testing.assert_array_equal(shared.state.configuration(), fresh.state.configuration())
            sim.step()
            assert sim.ground_truth() is not shared  # a new step, a new evaluation
    finally:
        sim.close()


def _folding_run(stops: dict, seconds: float = 3.0, kernel: str | None = None):
    """Hovering at legs 60°, no ground, every PX4 flying LEVEL at 90 % of its hover share (what a per-UAV
    AUTO.LAND does): the legs lose the inward thrust component that held them and fold. Returns the plant and
    the extreme leg angles [rad] and leg rates seen."""
    plant = Plant(scenario_from_dict({"initial_state": {"mode": "hover", "leg_angles": np.radians(60.0)},
                                      "ground": {"enabled": False}, "joint_stops": stops}), kernel=kernel)
    q = plant.state.configuration()
    thrust = 0.9 * np.linalg.norm(thrusts_from_wrench(plant.params, q, gravity(plant.params, q)), axis=1)
    level = plant.default_uav_attitudes()
    low, high, finite = np.inf, -np.inf, True
    for k in range(int(round(seconds / plant.dt))):
        if k % 4 == 0:
            plant.set_command(AttitudeCommand(level, thrust / plant.fleet.max_thrust(), np.ones(3, dtype=bool)))
        plant.step()
        angles = plant.state.leg_angles
        finite = finite and bool(np.isfinite(plant._x).all() and np.isfinite(plant.fleet.quat).all())
        if not finite:
            break
        low, high = min(low, angles.min()), max(high, angles.max())
    return plant, low, high, finite


def test_joint_stops_hold_folding_legs_and_keep_the_state_finite():
    """Integration defect: nothing limited the revolute leg joints, so a run that folds the legs (per-UAV
    AUTO.LAND: level attitudes, reduced thrust) sent them through −530° and the plant diverged. With the
    mechanical stops (default [10°, 92°], JointStopConfig) the legs end against the lower stop, within a small
    penetration, and the state stays finite; the stop moment is reported in the true external wrench."""
    free, free_low, _, _ = _folding_run({"enabled": False})
    assert free_low < np.radians(-30.0)  # without stops the legs fold through the platform plane
    plant, low, high, finite = _folding_run({})
    stops = plant.scenario.joint_stops
    assert finite
    penetration = np.radians(2.0)
    assert stops.lower - penetration < low and high < stops.upper + penetration
    assert low < stops.lower + np.radians(1.0)  # it did reach the stop
    moments = plant.joint_stop_moments()
    assert np.allclose(plant.external_wrench()[6:], moments + _without_stops(plant).external_wrench()[6:])
    print(f"\n[stops] folding run: legs {np.degrees(low):.2f}°..{np.degrees(high):.2f}° with stops at "
          f"{np.degrees(stops.lower):.0f}°/{np.degrees(stops.upper):.0f}° (without stops: "
          f"{np.degrees(free_low):.0f}°); stop moments now {np.round(moments, 2)} N m")


def _without_stops(plant: Plant) -> Plant:
    """A plant in the same state with the stops disabled (for the wrench comparison)."""
    data = {"initial_state": {"mode": "hover"}, "ground": {"enabled": False}, "joint_stops": {"enabled": False}}
    other = Plant(scenario_from_dict(data), kernel="python")
    other.set_state(plant.state)
    return other


def test_joint_stop_moment_is_a_unilateral_damped_penalty():
    from fpr_sim.plant import joint_stop_moment

    args = (0.2, 1.5, 1000.0, 10.0)
    assert joint_stop_moment(0.1, 0.0, *args) == pytest.approx(100.0)  # pushes up below the lower stop
    assert joint_stop_moment(0.1, -2.0, *args) == pytest.approx(120.0)  # more while still entering
    assert joint_stop_moment(0.19, 5.0, *args) == 0.0  # leaving fast: never pulls
    assert joint_stop_moment(1.6, 0.0, *args) == pytest.approx(-100.0)
    assert joint_stop_moment(1.51, -5.0, *args) == 0.0
    assert joint_stop_moment(0.8, 3.0, *args) == 0.0  # free between the stops
