"""Realism effects of the plant (issue 11, "physics"; fpr_sim.plant_realism): model mismatch, actuation,
aerodynamics. Per effect: switching it on changes what it should and nothing else; the ideal profile (and the
hardware profile with the three effects off) is the plant of before; same seed -> same draws; the Python
reference and the compiled kernel agree with every effect on."""

import math

import numpy as np
import pytest
from fpr_model.battery import TABLE_C1
from fpr_model.parameters import default_parameters
from fpr_model.rotations import quat_from_rotvec, quat_to_rotvec
from fpr_model.selfcheck import _LIMITS, run_checks
from fpr_sim._kernels import compiler_available, kernel_status
from fpr_sim.plant import Plant, true_parameters
from fpr_sim.plant_realism import ThrustNoise, draw_actuation, draw_model_mismatch, ground_effect_gain, rotor_drag_force
from fpr_sim.quadrotor import AttitudeCommand, QuadrotorFleet
from fpr_sim.scenario import scenario_from_dict
from fpr_sim.structure import StructureState

_OFF = {"mismatch": {"enabled": False}, "actuation": {"enabled": False}, "aerodynamics": {"enabled": False}}
_HOVER = {"initial_state": {"mode": "hover", "leg_angles": 1.0}, "ground": {"enabled": False}}


def _require_compiled() -> None:
    if not kernel_status().available:
        if compiler_available():
            pytest.fail(f"a C compiler exists but the compiled kernel is unavailable: {kernel_status().reason}")
        pytest.skip("no C compiler on this machine")


def _only(section: str, **values) -> dict:
    """The hardware profile with every physics effect off but ``section`` (with ``values``)."""
    return {**_OFF, section: {"enabled": True, **values}}


def _run(plant: Plant, steps: int, thrust: float = 0.4) -> np.ndarray:
    n = plant.n
    plant.set_command(AttitudeCommand(plant.fleet.quat, np.full(n, thrust), np.ones(n, dtype=bool)))
    for _ in range(steps):
        plant.step()
    return plant._x


# ------------------------------------------------------------------------------------------------- ideal
@pytest.mark.parametrize("kernel", ["python", "compiled"])
def test_ideal_profile_and_effects_off_leave_the_plant_as_before(kernel):
    """Ideal: no realism computed, Table B.1 parameters, the scenario's own fleet configs. The hardware profile
    with the three physics sections off and PX4's default attitude gain (the profile's px4 section, calibration pass
    10) steps bit for bit like the ideal plant (its sensor/link sections do not touch the plant; its wind.uav_drag 0
    only matters in wind)."""
    if kernel == "compiled":
        _require_compiled()
    ideal = Plant(scenario_from_dict(_HOVER), kernel=kernel)
    assert not ideal.realism.active and ideal.fleet.rotor_factors is None and ideal._uav_force_list is None
    assert ideal.params == default_parameters(3)
    assert ideal.fleet.motor_tau == 0.008 and ideal.fleet.battery.config.internal_resistance == 0.015
    assert [[c.a_f, c.b_f] for c in ideal.fleet.coefficients] == [[8.02, -61.66], [8.22, -64.01], [8.15, -62.28]]
    switched_off = Plant(scenario_from_dict({**_HOVER, **_OFF, "px4": {"attitude_p_gain": [6.5, 6.5, 2.8]}},
                                            realism="hardware"), kernel=kernel)
    assert not switched_off.realism.active
    assert np.array_equal(_run(ideal, 200), _run(switched_off, 200))
    assert np.array_equal(ideal.fleet.rotors, switched_off.fleet.rotors)


# ------------------------------------------------------------------------------------------------- mismatch
def test_mismatch_draws_stay_within_the_stated_tolerances_and_scenario_values_win():
    scenario = scenario_from_dict({**_OFF, "mismatch": {"enabled": True}, "plant": {"platform_mass": 0.3}},
                                  realism="hardware")
    config = scenario.mismatch
    base = default_parameters(3)
    params = true_parameters(scenario)
    assert params.platform_mass == 0.3  # stated in plant: wins over the draw
    assert np.all(np.abs(params.uav_masses - base.uav_masses) <= config.uav_mass)
    assert not np.array_equal(params.uav_masses, base.uav_masses)
    assert abs(params.leg_length - base.leg_length) <= config.leg_length and params.leg_length != base.leg_length
    assert abs(params.joint_offset - base.joint_offset) <= config.joint_offset
    assert np.all(np.abs(params.platform_com[:2]) <= config.platform_com_xy)
    assert np.all(np.abs(np.diag(params.platform_inertia) / np.diag(base.platform_inertia) - 1.0)
                  <= config.platform_inertia)
    plant = Plant(scenario, kernel="python")
    assert plant.params == params
    # only the parameters: thrust curve, motors, rotor factors, drag untouched
    assert [[c.a_f, c.b_f] for c in plant.fleet.coefficients] == [[8.02, -61.66], [8.22, -64.01], [8.15, -62.28]]
    assert plant.fleet.motor_tau == 0.008 and not plant.realism.has_factors and plant.realism.rotor_drag == 0.0
    inertia = np.array(plant.fleet.inertia) / [0.011, 0.011, 0.021] - 1.0
    assert np.all(np.abs(inertia) <= config.quadrotor_inertia) and np.any(inertia != 0.0)
    report = plant.mismatch_report()
    assert report["mismatch"]["leg_length"] == params.leg_length
    assert report["true_parameters"]["platform_mass"] == 0.3


def test_mismatch_keeps_the_model_self_check_on_the_true_parameters():
    params = true_parameters(scenario_from_dict({**_OFF, "mismatch": {"enabled": True}}, realism="hardware"))
    assert params != default_parameters(3)
    results = run_checks(params)
    for name, limit in _LIMITS.items():
        assert results[name] <= limit, name


def _energy_drift(dt: float, seed: int) -> float:
    scenario = scenario_from_dict({**_HOVER, **_OFF, "mismatch": {"enabled": True}, "seed": 4}, realism="hardware")
    plant = Plant(scenario, dt=dt, kernel="python")
    plant.fleet.hover_rotor_state(np.zeros(3))  # no thrust: the free passive TRUE structure under gravity
    rng = np.random.default_rng(seed)
    plant.set_state(StructureState(np.zeros(3), np.array([1.0, 0, 0, 0]), rng.uniform(0.6, 1.0, 3),
                                   rng.normal(0, 0.3, 3), rng.normal(0, 0.5, 3), rng.normal(0, 0.5, 3)))
    e0 = plant.structure.energy(plant.state)
    for _ in range(int(round(0.3 / dt))):
        plant.step()
    return abs(plant.structure.energy(plant.state) - e0)


def test_mismatched_structure_conserves_energy_with_rk4_order():
    coarse, fine = _energy_drift(2e-3, 1), _energy_drift(1e-3, 1)
    assert coarse < 1e-4
    # RK4: ~16x per halving, unless both drifts are already at round-off (then no order can show)
    assert fine < 1e-11 or coarse / max(fine, 1e-300) > 8.0


def test_same_seed_same_draws_other_seed_other_draws():
    def draws(seed):
        scenario = scenario_from_dict({"seed": seed}, realism="hardware")
        actuation = draw_actuation(scenario)
        noise = ThrustNoise(0.02, 0.05, 1e-3, 3, seed)
        return draw_model_mismatch(scenario), actuation.thrust_coefficients, actuation.rotor_gains, noise.next()

    assert draws(5) == draws(5)
    first, other = draws(5), draws(6)
    assert all(a != b for a, b in zip(first, other, strict=True))


# ------------------------------------------------------------------------------------------------- actuation
def test_thrust_curve_error_shifts_the_steady_thrust_by_the_predicted_amount():
    """Ideal attitudes (thrust = u·f_max(V) at once): the plant's thrust follows its true (C.2) curve, the
    bridge's normalization Table C.1: thrust / thrust_model = (a'V + b') / (a V + b)."""
    values = {"thrust_slope_error": 0.02, "thrust_offset_error": 1.0, "rotor_thrust_spread": 0.0, "thrust_noise": 0.0}
    scenario = scenario_from_dict({**_HOVER, **_only("actuation", **values)}, realism="hardware")
    plant = Plant(scenario, kernel="python")
    plant.ideal_attitude = True
    plant.set_command(AttitudeCommand(plant.fleet.quat, np.full(3, 0.35), np.ones(3, dtype=bool)))
    voltage = plant.fleet.battery.voltage()  # the controller update of the step reads it
    plant.step()
    true = draw_actuation(scenario).thrust_coefficients
    for i in range(3):
        table = TABLE_C1[i + 1]
        predicted = 0.35 * (true[i][0] * voltage[i] + true[i][1])
        assert plant.fleet.f_max[i] * 0.35 == pytest.approx(predicted, rel=1e-12)
        assert predicted != pytest.approx(0.35 * table.max_thrust(voltage[i]), rel=1e-3)
    assert plant.fleet.thrust() == pytest.approx(0.35 * plant.fleet.f_max, rel=1e-12)


@pytest.mark.parametrize("kernel", ["python", "compiled"])
def test_rotor_thrust_spread_yields_the_predicted_moment(kernel):
    """Equal rotor states T with gains k_j (3.41): m = [d(k2 − k4), d(k3 − k1), κ(−k1 + k2 − k3 + k4)]·T; from rest
    ω after a short step is m/I·dt."""
    if kernel == "compiled":
        _require_compiled()
    scenario = scenario_from_dict({})
    fleet = QuadrotorFleet(1, scenario.quadrotor, scenario.px4, scenario.battery, kernel=kernel)
    gains = [[1.03, 0.98, 0.99, 1.01]]
    fleet.hover_rotor_state(np.array([12.0]))
    fleet.rotor_factors = gains
    dt = 1e-5
    fleet.step(dt, [[0.0, 0.0, 0.0]])
    k1, k2, k3, k4 = gains[0]
    moment = np.array([0.17 * (k2 - k4), 0.17 * (k3 - k1), 0.016 * (-k1 + k2 - k3 + k4)]) * 3.0
    assert fleet.rate[0] == pytest.approx(moment / np.array([0.011, 0.011, 0.021]) * dt, rel=1e-6)
    assert fleet.thrust()[0] == pytest.approx(3.0 * sum(gains[0]), rel=1e-12)
    assert fleet.battery.current[0] == pytest.approx(1.6 * 12.0)  # the motors' state draws the current


def test_hardware_actuation_sets_the_motor_lag_and_battery_resistance():
    plant = Plant(scenario_from_dict(_HOVER, realism="hardware"), kernel="python")
    actuation = plant.scenario.actuation
    ideal = scenario_from_dict(_HOVER)
    assert plant.fleet.motor_tau == actuation.motor_time_constant > ideal.quadrotor.motor_time_constant
    assert plant.fleet.battery.config.internal_resistance == actuation.battery_internal_resistance == 0.030
    gains = np.array(plant.realism.rotor_gains)
    assert np.all(np.abs(gains - 1.0) <= actuation.rotor_thrust_spread) and np.ptp(gains) > 0.0
    # hover start: the rotors are set so that the produced thrusts are the hover thrusts (zero moment)
    produced = np.array(plant.fleet.rotors) * gains
    assert np.allclose(produced, produced[:, :1], rtol=1e-12)


def _roll_step_response(scenario, step_deg: float = 10.0, duration: float = 1.0) -> tuple[float, float, float]:
    """One vehicle of ``scenario``'s fleet (PX4 attitude + rate loop at its controller rate, its motor lag), no
    structure: a roll step of ``step_deg`` from hover. Returns (t to 63 % [s], t to 90 % [s], overshoot [-])."""
    fleet = QuadrotorFleet(1, scenario.quadrotor, scenario.px4, scenario.battery, kernel="python")
    fleet.hover_rotor_state(np.array([10.0]))
    command = AttitudeCommand(quat_from_rotvec(np.array([math.radians(step_deg), 0.0, 0.0]))[None, :],
                              np.array([10.0 / float(fleet.f_max[0])]), np.array([True]))
    dt, per_control = 1e-3, max(1, round(1.0 / (scenario.px4.controller_rate * 1e-3)))
    roll = []
    for k in range(int(duration / dt)):
        if k % per_control == 0:
            fleet.control(command)
        fleet.step(dt, np.zeros((1, 3)))
        roll.append(math.degrees(quat_to_rotvec(np.array(fleet.quat_list()[0]))[0]))
    roll = np.array(roll)
    t = (np.arange(len(roll)) + 1) * dt
    return float(t[np.argmax(roll >= 0.632 * step_deg)]), float(t[np.argmax(roll >= 0.9 * step_deg)]), \
        float(roll.max() / step_deg - 1.0)


def test_hardware_px4_attitude_gain_is_aggressive_and_damped():
    """The profile's PX4 attitude gain (calibration pass 10: MC_ROLL_P 9, the thesis's "aggressive" gains) makes the
    emulated attitude loop faster than PX4's default 6.5 with the profile's own motor lag, still without ringing
    (fpr_sim README, "PX4 attitude loop"); the ideal profile keeps PX4's defaults."""
    from dataclasses import replace

    hardware, ideal = scenario_from_dict(_HOVER, realism="hardware"), scenario_from_dict(_HOVER)
    assert list(ideal.px4.attitude_p_gain) == [6.5, 6.5, 2.8]
    assert hardware.px4.attitude_p_gain[:2] == [9.0, 9.0] and hardware.px4.attitude_p_gain[2] == 2.8
    default_gain = replace(hardware, px4=replace(hardware.px4, attitude_p_gain=[6.5, 6.5, 2.8]))
    t63, t90, overshoot = _roll_step_response(hardware)
    t63_default, t90_default, _ = _roll_step_response(default_gain)
    assert t63 < 0.9 * t63_default and t90 < 0.9 * t90_default  # measured 101 / 251 ms against 123 / 306 ms
    assert overshoot < 0.02  # measured 0.8 %


def test_thrust_noise_is_a_unit_gauss_markov_scaled_by_sigma():
    sigma, tau, dt = 0.02, 0.05, 1e-3
    noise = ThrustNoise(sigma, tau, dt, 3, seed=1)
    samples = (np.array([noise.next() for _ in range(60000)]) - 1.0) / sigma
    assert samples.shape == (60000, 12)
    assert abs(samples.mean()) < 0.1 and samples.std() == pytest.approx(1.0, abs=0.08)
    lag = int(round(tau / dt))
    correlation = np.mean(samples[lag:] * samples[:-lag]) / np.mean(samples * samples)
    assert correlation == pytest.approx(math.exp(-1.0), abs=0.08)


def test_thrust_noise_common_share_correlates_a_uavs_rotors_only():
    """ρ = 0.7: each rotor keeps σ and the time constant, two rotors of one UAV correlate by ρ, rotors of two UAVs
    not at all, so a UAV's collective varies by σ √(ρ + (1 − ρ)/4); ρ = 0 is the former sequence, bit for bit."""
    sigma, tau, dt, rho = 0.02, 0.05, 1e-3, 0.7
    noise = ThrustNoise(sigma, tau, dt, 3, seed=1, common=rho)
    samples = (np.array([noise.next() for _ in range(60000)]) - 1.0) / sigma
    assert samples.std(axis=0) == pytest.approx(np.ones(12), abs=0.1)
    corr = np.corrcoef(samples.T)
    same = [corr[4 * i + j, 4 * i + k] for i in range(3) for j in range(4) for k in range(j + 1, 4)]
    other = [corr[4 * i + j, 4 * m + k] for i in range(3) for m in range(i + 1, 3) for j in range(4) for k in range(4)]
    assert np.mean(same) == pytest.approx(rho, abs=0.05) and max(abs(c) for c in other) < 0.15
    collective = samples.reshape(-1, 3, 4).mean(axis=2)
    assert collective.std(axis=0) == pytest.approx(np.full(3, math.sqrt(rho + (1 - rho) / 4)), abs=0.1)
    # ρ = 0: the per-rotor recursion on the stream SeedSequence([seed, 23]), as before the common share existed
    zero, a = ThrustNoise(sigma, tau, dt, 3, seed=5, common=0.0), math.exp(-dt / tau)
    rng = np.random.default_rng(np.random.SeedSequence([5, 23]))
    xi, draws = rng.standard_normal(12), rng.standard_normal((512, 12))
    for k in range(512):
        xi = a * xi + math.sqrt(1.0 - a * a) * draws[k]
        assert zero.next() == (1.0 + sigma * xi).tolist()


# ------------------------------------------------------------------------------------------------- aerodynamics
def test_ground_effect_law_and_clamp():
    radius = 0.1016
    assert ground_effect_gain(radius, radius) == pytest.approx(16.0 / 15.0, rel=1e-15)  # 1/(1 − 1/16)
    assert ground_effect_gain(0.01, radius) == pytest.approx(4.0 / 3.0, rel=1e-15)  # clamped at z = R/2
    assert ground_effect_gain(1.0, 0.0) == 1.0
    assert 1.0 < ground_effect_gain(2.0, radius) < 1.001


@pytest.mark.parametrize("height", [0.15, 0.3, 0.8])
def test_ground_effect_raises_the_thrust_by_the_law(height):
    """Each quadrotor's produced thrust is its rotor state times 1/(1 − (R/4z)²), z its rotor plane's height."""
    aero = {"rotor_radius": 0.1016, "rotor_height": 0.03, "rotor_drag": 0.0}
    scenario = scenario_from_dict({"initial_state": {"mode": "hover", "leg_angles": 1.0}, **_only("aerodynamics",
                                                                                                  **aero)},
                                  realism="hardware")
    plant = Plant(scenario, kernel="python")
    state = plant.state
    tips, _ = plant._tip_kinematics(plant._x)
    state.position = state.position + [0.0, 0.0, height - tips[:, 2].min()]
    plant.set_state(state)
    tips, _ = plant._tip_kinematics(plant._x)
    plant.fleet.hover_rotor_state(np.full(3, 12.0))
    plant.ideal_attitude = False
    plant._realism_inputs()
    expected = [1.0 / (1.0 - (0.1016 / (4.0 * (z + 0.03))) ** 2) for z in tips[:, 2]]
    assert plant.fleet.thrust() == pytest.approx(12.0 * np.array(expected), rel=1e-12)
    assert plant._uav_force_list is None


def test_rotor_drag_is_in_the_rotor_plane_and_proportional_to_thrust():
    axis = (0.0, math.sin(0.2), math.cos(0.2))
    force = np.array(rotor_drag_force(0.022, 12.0, axis, (1.0, -0.5, 0.3), (0.2, 0.0, 0.0)))
    relative = np.array([0.8, -0.5, 0.3])
    in_plane = relative - (relative @ np.array(axis)) * np.array(axis)
    assert force == pytest.approx(-0.022 * 12.0 * in_plane, rel=1e-12)
    assert abs(force @ np.array(axis)) < 1e-15
    assert rotor_drag_force(0.022, 24.0, axis, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0))[0] == pytest.approx(
        2.0 * rotor_drag_force(0.022, 12.0, axis, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0))[0])


def test_rotor_drag_replaces_the_isotropic_uav_drag_and_enters_the_external_wrench():
    scenario = scenario_from_dict({**_HOVER, **_only("aerodynamics", rotor_radius=0.0),
                                   "wind": {"velocity": [2.0, 0.0, 0.0]}}, realism="hardware")
    assert scenario.wind.uav_drag == 0.0  # the profile's rotor drag replaces it: not counted twice
    plant = Plant(scenario, kernel="python")
    plant.set_command(AttitudeCommand(plant.fleet.quat, plant.fleet.thrust() / plant.fleet.max_thrust(),
                                      np.ones(3, dtype=bool)))
    plant.step()
    drag = np.array(plant._uav_force_list)
    assert np.all(drag[:, 0] > 0.0)  # pushed downwind
    thrust = plant.fleet.thrust()
    assert np.linalg.norm(drag, axis=1) == pytest.approx(0.022 * thrust * 2.0, rel=0.1)
    assert plant.external_wrench()[0] == pytest.approx(drag[:, 0].sum() + 0.05 * 2.0 + 3 * 0.02 * 2.0, rel=0.05)


# ------------------------------------------------------------------------------------------------- kernels
@pytest.mark.parametrize("start", ["ground", "hover_wind"])
def test_compiled_plant_matches_the_reference_with_every_effect(start):
    """The hardware profile (mismatch, actuation with noise, ground effect, rotor drag): 200 steps of both
    kernels side by side from a disturbed state."""
    _require_compiled()
    data = ({"initial_state": {"mode": "ground", "leg_angles": 0.9}} if start == "ground"
            else {**_HOVER, "wind": {"velocity": [1.5, -0.5, 0.0]}})
    plants = [Plant(scenario_from_dict(data, realism="hardware"), kernel=k) for k in ("python", "compiled")]
    assert plants[0].realism.has_factors and plants[0].realism.rotor_drag > 0.0
    rng = np.random.default_rng(3)
    state = plants[0].state
    state.velocity = rng.normal(0.0, 0.3, 3)
    state.leg_rates = rng.normal(0.0, 0.3, 3)
    rates = rng.normal(0.0, 0.5, (3, 3))
    command = AttitudeCommand(plants[0].fleet.quat, np.full(3, 0.4), np.ones(3, dtype=bool))
    for plant in plants:
        plant.set_state(state)
        plant.fleet.rate = rates
        plant.set_command(command)
    for k in range(200):
        for plant in plants:
            plant.step()
        python, compiled = plants
        assert np.allclose(compiled._x, python._x, rtol=1e-9, atol=1e-9), k
        assert np.allclose(compiled.fleet.rotors, python.fleet.rotors, rtol=1e-9, atol=1e-9), k
        assert np.allclose(compiled.fleet.rate, python.fleet.rate, rtol=1e-9, atol=1e-9), k
    truth = [p.ground_truth() for p in plants]
    assert np.allclose(truth[1].uav_thrusts, truth[0].uav_thrusts, rtol=1e-9)
    assert np.allclose(truth[1].external_wrench, truth[0].external_wrench, atol=1e-8)
