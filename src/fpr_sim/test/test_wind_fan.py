"""The wind generator's jet (scenario ``wind.fan``, environment.FanJet): mean profile, turbulence statistics and
seed, and its force on the robot in the dynamics and in the reported true wrench."""

import math

import numpy as np
import pytest
from fpr_sim.environment import FanJet
from fpr_sim.plant import Plant
from fpr_sim.scenario import FanConfig, scenario_from_dict

KMH = 1.0 / 3.6


def _fan(**overrides) -> FanConfig:
    fields = {"enabled": True, "position": [0.0, 0.0, 1.0], "direction": [1.0, 0.0, 0.0],
              "reference_point": [3.0, 0.0, 1.0], "speed": 26.0 * KMH} | overrides
    return scenario_from_dict({"wind": {"fan": fields}}).wind.fan


def _series(jet: FanJet, point, steps: int) -> np.ndarray:
    return np.array([jet.velocities(k * jet.dt, [point])[0] for k in range(steps)])


def test_mean_speed_at_the_reference_point_is_speed():
    for overrides in ({}, {"reference_point": [12.0, 0.3, 1.2]}, {"direction": [1.0, 1.0, 0.0], "diameter": 0.6,
                                                                 "reference_point": [4.0, 4.0, 1.0]}):
        jet = FanJet(_fan(**overrides), seed=1, dt=1e-3, reference_point=[0.0, 0.0, 0.0])
        assert jet.mean_speed(jet.reference_point) == pytest.approx(26.0 * KMH, rel=1e-12)
    # and on average with the turbulence (the mean of the along-axis component; 400 s of samples)
    jet = FanJet(_fan(), seed=3, dt=0.01, reference_point=[0.0, 0.0, 0.0])
    samples = _series(jet, [3.0, 0.0, 1.0], 40_000)
    assert samples[:, 0].mean() == pytest.approx(26.0 * KMH, rel=0.02)
    assert abs(samples[:, 1].mean()) < 0.15 and abs(samples[:, 2].mean()) < 0.15


def test_default_reference_is_the_given_point_and_the_outlet_aims_at_it():
    fan = scenario_from_dict({"wind": {"fan": {"enabled": True, "distance": 2.5, "direction": [0.0, 2.0, 0.0]}}})
    jet = FanJet(fan.wind.fan, seed=0, dt=1e-3, reference_point=[1.0, 1.0, 0.8])
    assert jet.reference_point == (1.0, 1.0, 0.8)
    assert np.allclose(jet.origin, [1.0, -1.5, 0.8]) and np.allclose(jet.axis, [0.0, 1.0, 0.0])


def test_jet_decays_away_from_the_axis_and_downstream():
    config = _fan(diameter=0.5, turbulence_intensity=0.0)
    jet = FanJet(config, seed=0, dt=1e-3, reference_point=[0.0, 0.0, 0.0])
    on_axis = jet.mean_speed([3.0, 0.0, 1.0])
    lateral = [jet.mean_speed([3.0, r, 1.0]) for r in (0.0, 0.1, 0.2, 0.4, 0.8)]
    assert lateral[0] == on_axis and all(a > b for a, b in zip(lateral, lateral[1:], strict=False))
    assert jet.mean_speed([3.0, 0.0, 2.0]) < 1e-3 * on_axis  # 1 m above the axis: out of the jet
    # far field (x > B·D = 2.9 m): U_c ∝ 1/x, half-width b = S·x (U = U_c/2 at r = b)
    for x in (4.0, 8.0):
        centre = jet.mean_speed([x, 0.0, 1.0])
        assert centre == pytest.approx(jet.outlet_speed * 5.8 * 0.5 / x, rel=1e-12)
        assert jet.mean_speed([x, 0.094 * x, 1.0]) == pytest.approx(0.5 * centre, rel=1e-12)
    # potential core: the outlet speed on the axis; nothing behind the outlet plane
    assert jet.mean_speed([1.0, 0.0, 1.0]) == pytest.approx(jet.outlet_speed)
    assert jet.mean_speed([-0.5, 0.0, 1.0]) == 0.0 and jet.mean_speed([0.0, 0.0, 1.0]) == 0.0
    assert np.abs(jet.velocities(0.0, [[5.0, 0.0, 5.0]])[0]).max() < 1e-12  # 4 m above the axis


def test_reference_point_outside_the_jet_is_refused():
    with pytest.raises(ValueError, match="not in the jet"):
        FanJet(_fan(reference_point=[-1.0, 0.0, 1.0]), seed=0, dt=1e-3, reference_point=[0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="wind.fan.direction"):
        scenario_from_dict({"wind": {"fan": {"direction": [0.0, 0.0, 0.0]}}})
    with pytest.raises(ValueError, match="wind.fan.diameter"):
        scenario_from_dict({"wind": {"fan": {"diameter": 0.0}}})
    with pytest.raises(ValueError, match="reference_point"):
        scenario_from_dict({"wind": {"fan": {"reference_point": "here"}}})
    with pytest.raises(ValueError, match=r"fan: unknown key\(s\) \['sped'\]"):
        scenario_from_dict({"wind": {"fan": {"sped": 3.0}}})


def test_turbulence_statistics_follow_the_configuration():
    """σ = I·U on each axis, autocorrelation exp(−lag/τ) (first order), zero mean."""
    intensity, tau, dt = 0.15, 0.1, 0.005
    jet = FanJet(_fan(turbulence_intensity=intensity, turbulence_time_constant=tau), seed=7, dt=dt,
                 reference_point=[0.0, 0.0, 0.0])
    samples = _series(jet, [3.0, 0.0, 1.0], 80_000)  # 400 s
    fluctuation = samples - samples.mean(axis=0)
    sigma = intensity * 26.0 * KMH
    assert np.allclose(fluctuation.std(axis=0), sigma, rtol=0.08)
    lag = int(round(tau / dt))
    for axis in range(3):
        u = fluctuation[:, axis]
        rho = float(np.mean(u[:-lag] * u[lag:]) / np.mean(u * u))
        assert rho == pytest.approx(math.exp(-1.0), abs=0.06)
        rho_short = float(np.mean(u[:-1] * u[1:]) / np.mean(u * u))
        assert rho_short == pytest.approx(math.exp(-dt / tau), abs=0.01)
    # the fluctuation scales with the local mean speed: off the axis it is smaller
    jet = FanJet(_fan(), seed=7, dt=dt, reference_point=[0.0, 0.0, 0.0])
    off_axis = _series(jet, [3.0, 0.6, 1.0], 20_000)
    assert off_axis.std(axis=0)[0] == pytest.approx(0.15 * jet.mean_speed([3.0, 0.6, 1.0]), rel=0.15)


def test_turbulence_is_reproducible_with_the_seed_and_independent_of_the_query_pattern():
    def jet(seed):
        return FanJet(_fan(), seed=seed, dt=1e-3, reference_point=[0.0, 0.0, 0.0])

    a, b, c = jet(5), jet(5), jet(6)
    every_step = [a.turbulence(k * 1e-3) for k in range(3000)]
    every_tenth = [b.turbulence(k * 1e-3) for k in range(0, 3000, 10)]
    assert every_step[::10] == every_tenth
    assert [c.turbulence(k * 1e-3) for k in range(3000)] != every_step
    assert a.turbulence(1.0) == every_step[-1]  # back in time: the latest sample
    quiet = FanJet(_fan(turbulence_intensity=0.0), seed=5, dt=1e-3, reference_point=[0.0, 0.0, 0.0])
    assert quiet.velocities(2.0, [[3.0, 0.0, 1.0]])[0] == pytest.approx((26.0 * KMH, 0.0, 0.0))


def _hover_plant(fan: dict, leg_angles: float = 0.7854, kernel: str | None = None) -> Plant:
    return Plant(scenario_from_dict({"initial_state": {"mode": "hover", "leg_angles": leg_angles},
                                     "ground": {"enabled": False}, "wind": {"fan": {"enabled": True} | fan}}),
                 kernel=kernel)


def test_ground_truth_wrench_includes_the_fan_force():
    """The robot at rest in the jet: τ_e's force is Σ c_k w_k over the platform, the legs' middles and the
    quadrotors (air velocities at those points); the fan blows along +x at the quadrotors' hover height, so
    the moment about P is a negative pitch (the thesis's signature, l.5251-5257, l.5412-5413)."""
    plant = _hover_plant({"speed": 13.0 * KMH, "turbulence_intensity": 0.0})
    wind = plant.scenario.wind
    n = plant.n
    air = np.reshape(plant._air_velocities(), (1 + 2 * n, 3))
    expected = wind.platform_drag * air[0] + wind.uav_drag * air[1:1 + n].sum(0) + wind.leg_drag * air[1 + n:].sum(0)
    wrench = plant.external_wrench()
    assert np.allclose(wrench[:3], expected, atol=1e-12)
    assert 1.8 < wrench[0] < 2.4 and wrench[4] < -1.0  # ≈ the thesis's 2 N / −2 N m at 13 km/h (Exp. IV Task 3)
    centroid = np.mean(plant.ground_truth().uav_positions, axis=0)
    assert plant.environment.fan.reference_point == pytest.approx(tuple(centroid))
    assert np.allclose(air[0], [plant.environment.fan.mean_speed(plant.state.position), 0.0, 0.0])
    # twice the speed, twice the force (linear drag)
    double = _hover_plant({"speed": 26.0 * KMH, "turbulence_intensity": 0.0}).external_wrench()
    assert np.allclose(double, 2.0 * wrench, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("kernel", ["python", "compiled"])
def test_fan_force_acts_in_the_dynamics_and_drops_out_of_the_jet(kernel):
    """With ideal attitudes holding the hover thrusts, the fan accelerates the robot along +x; placed 3 m
    beside the jet, the robot feels (almost) nothing."""
    from fpr_sim._kernels import kernel_status

    if kernel == "compiled" and not kernel_status().available:
        pytest.skip(kernel_status().reason)
    from fpr_model.dynamics import gravity, thrusts_from_wrench
    from fpr_sim.quadrotor import AttitudeCommand

    def run(offset):
        plant = _hover_plant({"speed": 26.0 * KMH, "reference_point": [0.0, 0.0, 0.76]}, kernel=kernel)
        state = plant.state
        state.position = state.position + offset
        plant.set_state(state)
        q = plant.state.configuration()
        forces = thrusts_from_wrench(plant.params, q, gravity(plant.params, q))
        plant.ideal_attitude = True
        plant.set_command(AttitudeCommand(plant.default_uav_attitudes(forces),
                                          np.linalg.norm(forces, axis=1) / plant.fleet.max_thrust(),
                                          np.ones(plant.n, dtype=bool)))
        wrench = plant.external_wrench()
        for _ in range(300):
            plant.step()
        return wrench, plant.state.velocity

    wrench_in, velocity_in = run(np.zeros(3))
    wrench_out, velocity_out = run(np.array([0.0, 3.0, 0.0]))
    assert wrench_in[0] > 3.0 and velocity_in[0] > 0.05
    assert abs(wrench_out[0]) < 0.01 and abs(velocity_out[0]) < 0.01 * velocity_in[0]


def test_truth_wrench_follows_the_turbulence_and_the_seed():
    plants = [_hover_plant({}) for _ in range(2)] + [Plant(scenario_from_dict({
        "seed": 9, "initial_state": {"mode": "hover", "leg_angles": 0.7854}, "ground": {"enabled": False},
        "wind": {"fan": {"enabled": True}}}))]
    forces = []
    for plant in plants:
        plant.ideal_attitude = True
        series = []
        for _ in range(200):
            plant.step()
            series.append(plant.external_wrench()[0])
        forces.append(np.array(series))
    assert np.array_equal(forces[0], forces[1]) and not np.allclose(forces[0], forces[2])
    assert forces[0].std() > 0.05  # turbulence visible in the reported wrench


def test_fan_schedule_switches_on_ramps_and_stops():
    """start_time / ramp_time / end_time: still air (no turbulence either) before the start and after the end, the
    mean speed ramping linearly from 0 in between; once on, the same seeded turbulence as an always-on fan."""
    point = [3.0, 0.0, 1.0]
    quiet = FanJet(_fan(turbulence_intensity=0.0, start_time=1.0, ramp_time=2.0, end_time=5.0), seed=2, dt=1e-3,
                   reference_point=[0.0, 0.0, 0.0])
    full = 26.0 * KMH
    for t, fraction in ((0.0, 0.0), (0.999, 0.0), (1.0, 0.0), (1.5, 0.25), (2.0, 0.5), (3.0, 1.0), (4.999, 1.0),
                        (5.0, 0.0), (9.0, 0.0)):
        assert quiet.speed_factor(t) == pytest.approx(fraction)
        assert quiet.velocities(t, [point])[0] == pytest.approx((fraction * full, 0.0, 0.0))
        assert quiet.mean_speed(point, t) == pytest.approx(fraction * full)
    assert quiet.mean_speed(point) == pytest.approx(full)  # the steady (full-speed) profile
    # turbulent: zero while off; on, the always-on fan's sequence times s(t) (a pure function of seed and step)
    scheduled = FanJet(_fan(start_time=1.0, ramp_time=2.0, end_time=5.0), seed=4, dt=1e-3,
                       reference_point=[0.0, 0.0, 0.0])
    always = FanJet(_fan(), seed=4, dt=1e-3, reference_point=[0.0, 0.0, 0.0])
    for k in range(0, 6000, 7):
        t = k * 1e-3
        got = np.array(scheduled.velocities(t, [point])[0])
        reference = np.array(always.velocities(t, [point])[0])
        assert np.allclose(got, scheduled.speed_factor(t) * reference, rtol=1e-12, atol=1e-12), t
        if not 1.0 < t < 5.0:
            assert np.all(got == 0.0)
    # during a (slow) ramp the fluctuation is I·s(t)·U (s from 1/4 to 1/2 over these 400 s)
    ramp = FanJet(_fan(ramp_time=1600.0), seed=8, dt=0.01, reference_point=[0.0, 0.0, 0.0])
    times = 400.0 + 0.01 * np.arange(40_000)
    samples = np.array([ramp.velocities(t, [point])[0] for t in times.tolist()]) / (times / 1600.0)[:, None]
    assert samples[:, 1].std() == pytest.approx(0.15 * full, rel=0.08)
    assert samples[:, 0].mean() == pytest.approx(full, rel=0.02)


def test_fan_schedule_keys_are_validated():
    fan = scenario_from_dict({"wind": {"fan": {"enabled": True}}}).wind.fan
    assert (fan.start_time, fan.ramp_time, fan.end_time) == (0.0, 0.0, math.inf)
    for bad, match in (({"start_time": -1.0}, "start_time"), ({"ramp_time": -0.5}, "ramp_time"),
                       ({"start_time": 5.0, "end_time": 5.0}, "end_time"), ({"ramp_time": ".inf"}, "ramp_time"),
                       ({"start": 1.0}, r"unknown key\(s\) \['start'\]")):
        with pytest.raises(ValueError, match=match):
            scenario_from_dict({"wind": {"fan": {"enabled": True} | bad}})


@pytest.mark.parametrize("kernel", ["python", "compiled"])
def test_fan_switched_on_while_hovering(kernel):
    """A hover in still air, the fan switched on at 0.1 s with a 0.1 s spin-up: no wind force before, the true
    wrench growing over the ramp to the always-on value, the robot pushed along +x only after the start."""
    from fpr_sim._kernels import kernel_status

    if kernel == "compiled" and not kernel_status().available:
        pytest.skip(kernel_status().reason)
    plant = _hover_plant({"speed": 13.0 * KMH, "turbulence_intensity": 0.0, "start_time": 0.1, "ramp_time": 0.1},
                         kernel=kernel)
    steady = _hover_plant({"speed": 13.0 * KMH, "turbulence_intensity": 0.0}).external_wrench()[0]
    from fpr_model.dynamics import gravity, thrusts_from_wrench
    from fpr_sim.quadrotor import AttitudeCommand

    q = plant.state.configuration()
    thrusts = thrusts_from_wrench(plant.params, q, gravity(plant.params, q))
    plant.ideal_attitude = True
    plant.set_command(AttitudeCommand(plant.default_uav_attitudes(thrusts),
                                      np.linalg.norm(thrusts, axis=1) / plant.fleet.max_thrust(),
                                      np.ones(plant.n, dtype=bool)))
    force, velocity = [], []
    for _ in range(300):
        plant.step()
        force.append(plant.external_wrench()[0])
        velocity.append(plant.state.velocity[0])
    assert max(abs(f) for f in force[:99]) < 1e-6 and max(abs(v) for v in velocity[:99]) < 1e-6  # still air
    assert force[149] == pytest.approx(0.5 * steady, rel=0.05)  # t = 0.15 s: half way up the ramp
    assert force[299] == pytest.approx(steady, rel=0.05) and velocity[299] > 100.0 * max(abs(v) for v in velocity[:99])
