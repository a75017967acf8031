"""The kernels of the 1 kHz plant: the plain-float Python ones against their numpy / fpr_model definitions, and
the optional compiled kernel (fpr_sim._kernels, C) against the Python reference, its build and its selection.

The fixture ``kernel`` runs a test on both implementations; the compiled one fails (does not skip) when a C
compiler exists but the kernel is not available (a silently broken build must be seen).
"""

import hashlib
import logging

import numpy as np
import pytest
from fpr_model.rotations import quat_from_axis_angle, quat_multiply, quat_normalize, quat_to_rotmat
from fpr_sim._kernels import KERNEL_ENV, compiler_available, kernel_status, resolve_kernel
from fpr_sim.environment import Environment
from fpr_sim.plant import Plant
from fpr_sim.quadrotor import AttitudeCommand, Battery, QuadrotorFleet, mix
from fpr_sim.scalar_math import rotation_entries
from fpr_sim.scenario import scenario_from_dict
from fpr_sim.structure import StructureDynamics

from fpr_model import parameters
from fpr_sim import _kernels


def _require_compiled() -> None:
    if not kernel_status().available:
        if compiler_available():
            pytest.fail(f"a C compiler exists but the compiled kernel is unavailable: {kernel_status().reason}")
        pytest.skip("no C compiler on this machine: the compiled kernel cannot be built")


@pytest.fixture(params=["python", "compiled"])
def kernel(request) -> str:
    """The implementation under test."""
    if request.param == "compiled":
        _require_compiled()
    return request.param


def test_rotation_entries_are_fpr_model_rotmat():
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.normal(size=4)  # also non-unit: both use the quaternion as given
        assert np.allclose(np.reshape(rotation_entries(*q.tolist()), (3, 3)), quat_to_rotmat(q), atol=1e-15)
        q = quat_normalize(q)
        assert np.allclose(np.reshape(rotation_entries(*q.tolist()), (3, 3)), quat_to_rotmat(q), atol=1e-15)


def test_ground_point_force_matches_vectorized_contact():
    scenario = scenario_from_dict({})
    ground = Environment(scenario).ground
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.normal(size=(4, 2)), [-0.01, 0.02, -0.002, -0.03]])
    velocities = rng.normal(size=(4, 3))
    ground.anchors[:] = np.nan
    ground.anchors[0] = points[0, :2] + [0.001, 0.0]  # stuck, small stretch
    ground.anchors[3] = points[3, :2] + [0.5, 0.5]  # sliding (friction cone saturated)
    expected = ground.forces(points, velocities)
    anchors = ground.anchors.tolist()
    for k in range(4):
        got = ground.point_force(anchors[k], *points[k].tolist(), *velocities[k].tolist())
        assert np.allclose(got, expected[k], atol=1e-12)
    assert expected[1].tolist() == [0.0, 0.0, 0.0] and np.hypot(*expected[3, :2]) == pytest.approx(
        0.8 * expected[3, 2])


def test_board_force_scalar_matches_array_version():
    scenario = scenario_from_dict({"board": {"enabled": True, "point": [0.0, 0.0, 1.0], "normal": [0.1, 0.0, -1.0]}})
    env = Environment(scenario)
    for point, velocity in (([0.0, 0.1, 1.01], [0.3, -0.2, 0.1]), ([0.0, 0.0, 0.9], [0.0, 0.0, 0.0]),
                            ([0.02, 0.0, 1.003], [0.001, 0.0, 0.0])):
        force, normal = env.board_force(np.array(point), np.array(velocity))
        force_s, normal_s = env.board_force_scalar(tuple(point), tuple(velocity))
        assert normal_s == pytest.approx(normal, abs=1e-12)
        assert np.allclose(force_s, force, atol=1e-12)


def test_finite_board_contact_only_over_the_board():
    """A 30 x 20 cm board turned 45° in its plane (``edge``): contact only where the end-effector point's projection
    is inside the rectangle; both versions agree; the default board is unbounded (the former behaviour)."""
    board = {"enabled": True, "point": [0.0, 0.0, 1.0], "normal": [0.0, 0.0, -1.0], "size": [0.3, 0.2],
             "edge": [1.0, 1.0, 0.0]}
    env = Environment(scenario_from_dict({"board": board}))
    assert np.allclose(env.board_u, np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0))
    assert np.allclose(env.board_v, np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0))  # n × u
    # (x, y) -> over the board: u = (x + y)/√2 within ±0.15, v = (x − y)/√2 within ±0.10
    cases = {(0.0, 0.0): True, (0.1, 0.1): True, (-0.1, -0.1): True, (0.07, -0.07): True, (0.08, -0.08): False,
             (0.11, 0.11): False, (0.2, 0.0): False, (0.0, 0.2): False, (0.3, 0.0): False}
    for (x, y), inside in cases.items():
        point, velocity = np.array([x, y, 1.002]), np.array([0.1, 0.0, 0.05])
        force, normal = env.board_force(point, velocity)
        force_s, normal_s = env.board_force_scalar(tuple(point), tuple(velocity))
        assert (normal > 0.0) == inside, (x, y)
        assert normal_s == pytest.approx(normal, abs=1e-12) and np.allclose(force_s, force, atol=1e-12)
        assert env.board_force(point - [0.0, 0.0, 0.004], velocity)[1] == 0.0  # in front of the plane
    unbounded = Environment(scenario_from_dict({"board": {"enabled": True, "point": [0.0, 0.0, 1.0]}}))
    assert unbounded.board_force(np.array([50.0, -80.0, 1.001]), np.zeros(3))[1] == pytest.approx(5.0)
    with pytest.raises(ValueError, match="board.size"):
        scenario_from_dict({"board": {"size": [0.3, 0.0]}})
    with pytest.raises(ValueError, match="board.edge"):
        scenario_from_dict({"board": {"edge": [0.0, 0.0, 2.0]}})


def test_fleet_state_reads_copies_and_battery_accepts_lists(kernel):
    scenario = scenario_from_dict({})
    fleet = QuadrotorFleet(3, scenario.quadrotor, scenario.px4, scenario.battery, kernel=kernel)
    assert fleet.kernel == kernel
    quat = fleet.quat
    quat[0, 0] = 5.0  # a copy: the fleet is unchanged
    assert fleet.quat[0, 0] == 1.0
    fleet.rate = np.ones((3, 3))
    assert fleet.rate.shape == (3, 3) and fleet.rate.sum() == 9.0
    battery = Battery(scenario.battery, 3)
    battery.update([1.0, float("nan"), -2.0], 3600.0)
    assert battery.current[0] == pytest.approx(1.6) and np.isnan(battery.current[1]) and battery.current[2] == 0.0


def test_mix_rows_match_the_allocation_inverse():
    rng = np.random.default_rng(2)
    collective = rng.uniform(5.0, 30.0, 5)
    moments = rng.normal(0.0, 0.2, (5, 3))
    rotors = mix(collective, moments, 0.17, 0.016, np.full(5, 12.0))
    assert rotors.shape == (5, 4)
    free = (rotors > 1e-9).all(axis=1) & (rotors < 12.0 - 1e-9).all(axis=1)
    assert free.any()
    for t, f, m in zip(rotors[free], collective[free], moments[free], strict=True):
        assert t.sum() == pytest.approx(f)
        assert 0.17 * (t[1] - t[3]) == pytest.approx(m[0])
        assert 0.17 * (t[2] - t[0]) == pytest.approx(m[1])
        assert 0.016 * (-t[0] + t[1] - t[2] + t[3]) == pytest.approx(m[2])


# ------------------------------------------------------------------------------------------- compiled kernel


def test_compiled_kernel_is_built_and_selected_wherever_a_c_compiler_exists(monkeypatch):
    """Not a skip when the build is broken: with a compiler on the machine the library must load, be fresh
    (built from this plant_kernel.c) and be what a default plant uses."""
    if not compiler_available():
        pytest.skip("no C compiler on this machine")
    status = kernel_status()
    assert status.available, status.reason
    built_from = _kernels._library().lib.fpr_kernel_source_hash().decode()
    assert built_from == hashlib.sha256(_kernels._SOURCE.read_bytes()).hexdigest()
    monkeypatch.delenv(KERNEL_ENV, raising=False)
    plant = Plant(scenario_from_dict({}))
    assert (plant.kernel, plant.structure.kernel, plant.fleet.kernel) == ("compiled",) * 3
    assert plant._compiled is not None and plant.fleet._compiled is not None


def test_kernel_selection_by_argument_and_environment(monkeypatch):
    monkeypatch.setenv(KERNEL_ENV, "python")
    assert resolve_kernel() == "python"
    plant = Plant(scenario_from_dict({}))
    assert (plant.kernel, plant.structure.kernel, plant.fleet.kernel) == ("python",) * 3
    assert plant._compiled is None and plant.fleet._compiled is None and plant.structure._compiled is None
    monkeypatch.setenv(KERNEL_ENV, "fast")
    with pytest.raises(ValueError, match="auto, compiled, python"):
        Plant(scenario_from_dict({}))
    with pytest.raises(ValueError, match="valid choices"):
        resolve_kernel("numba")
    monkeypatch.setenv(KERNEL_ENV, " Auto ")
    assert resolve_kernel() == ("compiled" if kernel_status().available else "python")
    assert resolve_kernel("python") == "python"  # the argument wins over the environment
    if kernel_status().available:  # a robot larger than the kernel's arrays: Python, or an error if insisted
        too_many = _kernels._library().max_legs + 1
        assert resolve_kernel("auto", too_many) == "python"
        with pytest.raises(RuntimeError, match="exceeds"):
            resolve_kernel("compiled", too_many)


def test_missing_library_falls_back_to_python_with_one_info_line(monkeypatch, caplog):
    monkeypatch.delenv(KERNEL_ENV, raising=False)
    monkeypatch.setattr(_kernels, "_library_path", lambda: None)
    monkeypatch.setattr(_kernels, "_announced", False)
    _kernels._load.cache_clear()
    try:
        with caplog.at_level(logging.INFO, logger="fpr_sim.kernels"):
            plant = Plant(scenario_from_dict({}))
            Plant(scenario_from_dict({}), kernel="auto")
        records = [r for r in caplog.records if r.name == "fpr_sim.kernels"]
        assert [r.levelno for r in records] == [logging.INFO]
        assert "pure-Python plant" in records[0].getMessage() and "not built" in records[0].getMessage()
        assert (plant.kernel, plant.structure.kernel, plant.fleet.kernel) == ("python",) * 3
        plant.step()
        assert plant.steps == 1
        with pytest.raises(RuntimeError, match="requested but unavailable"):
            Plant(scenario_from_dict({}), kernel="compiled")
    finally:
        _kernels._load.cache_clear()


def test_stale_library_is_refused(monkeypatch, tmp_path, caplog):
    _require_compiled()
    edited = tmp_path / "plant_kernel.c"
    edited.write_bytes(_kernels._SOURCE.read_bytes() + b"/* edited after the build */\n")
    monkeypatch.setattr(_kernels, "_SOURCE", edited)
    _kernels._load.cache_clear()
    try:
        with caplog.at_level(logging.WARNING, logger="fpr_sim.kernels"):
            status = kernel_status()
        assert not status.available and "stale" in status.reason
        assert any("stale" in r.getMessage() for r in caplog.records)
    finally:
        _kernels._load.cache_clear()


def _random_accelerate_inputs(rng, n):
    angles = rng.uniform(0.2, 1.4, n)
    return (np.cos(angles).tolist(), np.sin(angles).tolist(), rng.normal(0.0, 1.0, 6 + n).tolist(),
            rng.normal(0.0, 5.0, 3).tolist(), rng.normal(0.0, 2.0, 6 + n).tolist())


@pytest.mark.parametrize("n", [3, 4, 6])
def test_compiled_structure_acceleration_matches_the_reference(n):
    _require_compiled()
    params = parameters.parameters_from_dict({"n": n})
    fast = StructureDynamics(params, payload_mass=0.25, kernel="compiled")
    rng = np.random.default_rng(n)
    for _ in range(20):
        inputs = _random_accelerate_inputs(rng, n)
        expected = fast.accelerate_python(*inputs)
        assert np.allclose(fast.accelerate(*inputs), expected, rtol=1e-12, atol=1e-12)
    fast.set_payload_mass(0.0)  # a new basis: the kernel follows it
    inputs = _random_accelerate_inputs(rng, n)
    assert np.allclose(fast.accelerate(*inputs), fast.accelerate_python(*inputs), rtol=1e-12, atol=1e-12)


def test_structure_acceleration_solves_indefinite_and_refuses_singular_mass_matrices(kernel):
    """Outside the physical (positive definite) case both implementations fall back to a general solve, and
    both raise numpy's LinAlgError for a singular matrix."""
    fast = StructureDynamics(parameters.default_parameters(), kernel=kernel)
    inputs = _random_accelerate_inputs(np.random.default_rng(7), 3)
    reference = StructureDynamics(parameters.default_parameters(), kernel="python")
    indefinite = fast._basis.copy()  # the leg terms kept, the constant part made indefinite
    indefinite[0] = np.diag(np.linspace(-2.0, 3.0, 9) + 0.05).ravel()
    fast._basis = reference._basis = indefinite
    assert np.linalg.eigvalsh(reference.body_mass_matrix(np.arctan2(inputs[1], inputs[0]))).min() < 0.0
    assert np.allclose(fast.accelerate(*inputs), reference.accelerate(*inputs), rtol=1e-12, atol=1e-12)
    fast._basis = np.zeros_like(indefinite)
    fast._leg_basis_stack = np.zeros_like(fast._leg_basis_stack)
    with pytest.raises(np.linalg.LinAlgError):
        fast.accelerate(*inputs)


def _fleets(n=3, kernels=("python", "compiled")):
    scenario = scenario_from_dict({"n": n})
    return [QuadrotorFleet(n, scenario.quadrotor, scenario.px4, scenario.battery, kernel=k) for k in kernels]


def _fleet_state(fleet) -> np.ndarray:
    return np.concatenate([fleet.quat.ravel(), fleet.rate.ravel(), fleet.rotors.ravel(),
                           fleet.rotor_commands.ravel(), fleet.rate_integral.ravel(), fleet.previous_rate.ravel(),
                           fleet.rate_setpoint.ravel(), fleet.battery.charge_used, fleet.battery.current])


def test_compiled_controller_and_quadrotor_step_match_the_reference():
    """PX4 attitude P / rate PID / airmode-off mixer (saturating commands, disarmed and landed vehicles, rate
    feed-forward, NaN thrust) and the RK4 of (2.92) with motors and battery, compiled vs Python."""
    _require_compiled()
    n = 4
    rng = np.random.default_rng(11)
    python, compiled = _fleets(n)
    for fleet in (python, compiled):
        fleet.hover_rotor_state(np.full(n, 12.0))
    for k in range(200):
        if k % 4 == 0:
            tilt = rng.normal(0.0, 0.6 if k % 40 == 0 else 0.1, (n, 3))
            quats = np.array([quat_multiply(quat_from_axis_angle(t / np.linalg.norm(t), np.linalg.norm(t)),
                                            python.quat[i]) for i, t in enumerate(tilt)])
            thrust = rng.uniform(0.0, 1.2, n)
            thrust[rng.integers(n)] = np.nan if k % 20 == 0 else thrust[0]
            armed = rng.uniform(size=n) > 0.15
            feedforward = rng.normal(0.0, 0.5, (n, 3)) if k % 8 == 0 else None
            landed = (rng.uniform(size=n) > 0.7).tolist()
            command = AttitudeCommand(quats, thrust, armed, feedforward)
            for fleet in (python, compiled):
                fleet.control(command, landed=landed)
            assert np.allclose(_fleet_state(compiled), _fleet_state(python), rtol=1e-12, atol=1e-12)
        moments = rng.normal(0.0, 0.05, (n, 3))
        for fleet in (python, compiled):
            fleet.step(1e-3, moments)
        assert np.allclose(_fleet_state(compiled), _fleet_state(python), rtol=1e-11, atol=1e-12), k
    assert np.ptp(python.rotors) > 1.0 and np.abs(python.rate).max() > 0.1  # it did move


def test_controller_refuses_bad_attitudes_alike(kernel):
    """A NaN or zero attitude raises fpr_model's ValueError on both paths; a single (4,) target is broadcast."""
    fleet, reference = _fleets(kernels=(kernel, "python"))
    target = quat_normalize(np.array([0.99, 0.05, -0.03, 0.1]))
    for f in (fleet, reference):
        f.control(AttitudeCommand(target, np.full(3, 0.5), np.ones(3, dtype=bool)))
    assert np.allclose(fleet.rotor_commands, reference.rotor_commands, rtol=1e-12)
    with pytest.raises(ValueError, match="NaN or inf"):
        fleet.control(AttitudeCommand(np.full((3, 4), np.nan), np.full(3, 0.5), np.ones(3, dtype=bool)))
    fleet.quat = np.zeros((3, 4))
    with pytest.raises(ValueError, match="zero quaternion"):
        fleet.control(AttitudeCommand(np.tile(target, (3, 1)), np.full(3, 0.5), np.ones(3, dtype=bool)))


_STEP_SCENARIOS = {
    "on_ground_armed_wind": {"initial_state": {"mode": "ground", "leg_angles": 0.9},
                             "wind": {"velocity": [0.5, -0.3, 0.0]}},
    "hover_wrench_payload": {"n": 4, "initial_state": {"mode": "hover", "leg_angles": 0.8},
                             "ground": {"enabled": False},
                             "payloads": [{"mass": 0.2, "attach_time": 0.01, "release_time": 0.08}],
                             "external_wrenches": [{"start": 0.0, "end": 0.05, "force": [0.3, 0.0, -0.5],
                                                    "moment": [0.0, 0.01, 0.0]}]},
    "pickup_payload_fan_schedule": {
        "initial_state": {"mode": "hover", "leg_angles": 0.8}, "ground": {"enabled": False},
        "payloads": [{"mass": 0.3, "attach_time": 0.02, "pickup_position": [0.0, 0.0, 1.5], "pickup_radius": 0.2,
                      "hold_time": 0.05}],
        "wind": {"fan": {"enabled": True, "speed": 5.0, "start_time": 0.03, "ramp_time": 0.05, "end_time": 0.12}}},
    "board_contact": {"initial_state": {"mode": "hover", "leg_angles": 0.8}, "ground": {"enabled": False},
                      "board": {"enabled": True, "point": [0.0, 0.0, 1.5], "normal": [0.1, 0.0, -1.0]}},
    "fan_turbulent_finite_board": {
        "initial_state": {"mode": "hover", "leg_angles": 0.8}, "ground": {"enabled": False},
        "wind": {"velocity": [0.2, 0.0, 0.0], "fan": {"enabled": True, "speed": 6.0, "diameter": 0.8,
                                                      "direction": [1.0, 0.3, 0.1], "turbulence_intensity": 0.3,
                                                      "turbulence_time_constant": 0.02}},
        "board": {"enabled": True, "point": [0.02, 0.0, 1.5], "normal": [0.1, 0.0, -1.0], "size": [0.3, 0.3],
                  "edge": [1.0, 0.5, 0.0]}},
}


@pytest.mark.parametrize("name", sorted(_STEP_SCENARIOS))
def test_compiled_plant_step_matches_the_reference_from_disturbed_states(name):
    """Randomly disturbed states (sliding feet and yaw friction on the ground, board impact, wrench and
    payload switching, ideal attitudes for a while): 150 steps of both implementations side by side."""
    _require_compiled()
    rng = np.random.default_rng(len(name))
    plants = [Plant(scenario_from_dict(_STEP_SCENARIOS[name]), kernel=k) for k in ("python", "compiled")]
    state = plants[0].state
    state.velocity = rng.normal(0.0, 0.3, 3)
    state.rate = rng.normal(0.0, 0.5, 3)
    state.leg_rates = rng.normal(0.0, 0.5, plants[0].n)
    rates = rng.normal(0.0, 1.0, (plants[0].n, 3))
    n = plants[0].n
    command = AttitudeCommand(plants[0].fleet.quat, np.full(n, 0.45), np.ones(n, dtype=bool),
                              rng.normal(0.0, 0.3, (n, 3)))
    for plant in plants:
        plant.set_state(state)
        plant.fleet.rate = rates
        plant.set_command(command)
    for k in range(150):
        for plant in plants:
            plant.ideal_attitude = 60 <= k < 70
            plant.step()
        python, compiled = plants
        for a, b in ((python._x, compiled._x), (_fleet_state(python.fleet), _fleet_state(compiled.fleet)),
                     (python._tip_acceleration, compiled._tip_acceleration)):
            assert np.allclose(b, a, rtol=1e-9, atol=1e-9), k
        assert np.array_equal(np.isnan(python.environment.ground.anchors),
                              np.isnan(compiled.environment.ground.anchors))
        assert np.allclose(compiled.environment.ground.anchors, python.environment.ground.anchors, atol=1e-9,
                           equal_nan=True)
        assert np.allclose(compiled._yaw_anchors, python._yaw_anchors, atol=1e-9, equal_nan=True)
        assert compiled._contact_force == pytest.approx(python._contact_force, abs=1e-7)
        assert compiled._ground_active == python._ground_active
    truth = [p.ground_truth() for p in plants]
    assert np.allclose(truth[1].external_wrench, truth[0].external_wrench, atol=1e-8)


def test_compiled_plant_step_matches_the_reference_in_the_joint_stops():
    """The legs' mechanical stops (plant.joint_stop_moment, same formula in plant_kernel.c), both engaged: one leg
    below the lower stop and entering it, one above the upper stop, on the ground with wind; 400 steps side by
    side, and the stops did act."""
    _require_compiled()
    scenario = {"initial_state": {"mode": "ground", "leg_angles": 0.9}, "wind": {"velocity": [0.4, 0.0, 0.0]},
                "joint_stops": {"lower": 0.3, "upper": 1.2, "stiffness": 1500.0, "damping": 8.0}}
    plants = [Plant(scenario_from_dict(scenario), kernel=k) for k in ("python", "compiled")]
    state = plants[0].state
    state.leg_angles = np.array([0.28, 1.23, 0.9])
    state.leg_rates = np.array([-1.5, 2.0, 0.3])
    state.position = state.position + [0.0, 0.0, 0.05]
    command = AttitudeCommand(plants[0].fleet.quat, np.full(3, 0.3), np.ones(3, dtype=bool))
    for plant in plants:
        plant.set_state(state)
        plant.set_command(command)
    engaged = np.zeros(3, dtype=bool)
    for k in range(400):
        for plant in plants:
            plant.step()
        python, compiled = plants
        engaged |= python.joint_stop_moments() != 0.0
        for a, b in ((python._x, compiled._x), (_fleet_state(python.fleet), _fleet_state(compiled.fleet))):
            assert np.allclose(b, a, rtol=1e-9, atol=1e-9), k
    assert engaged[0] and engaged[1]
    assert np.isfinite(plants[0]._x).all()


def _plants_sliding_towards_a_board(board: dict) -> list[Plant]:
    """Python and compiled plants hovering at 0.8 rad legs, moving +x at 0.5 m/s towards a 30 × 30 cm board
    facing down (``board`` overrides its keys), the same state and command in both."""
    board = {"enabled": True, "normal": [0.0, 0.0, -1.0], "size": [0.3, 0.3], "edge": [1.0, 0.0, 0.0], **board}
    scenario = {"initial_state": {"mode": "hover", "leg_angles": 0.8}, "ground": {"enabled": False}, "board": board}
    plants = [Plant(scenario_from_dict(scenario), kernel=k) for k in ("python", "compiled")]
    state = plants[0].state
    state.velocity = np.array([0.5, 0.0, 0.0])
    n = plants[0].n
    command = AttitudeCommand(plants[0].fleet.quat, np.full(n, 0.45), np.ones(n, dtype=bool))
    for plant in plants:
        plant.set_state(state)
        plant.set_command(command)
    return plants


def test_compiled_plant_step_matches_the_reference_across_a_board_edge():
    """The end-effector point starts beside a finite board, behind its plane, and slides over it: no contact
    first (an unbounded board would push at once), then contact; Python and C side by side."""
    _require_compiled()
    plants = _plants_sliding_towards_a_board({"point": [0.17, 0.0, 1.548]})
    contact = []
    for k in range(120):
        for plant in plants:
            plant.step()
        python, compiled = plants
        assert np.allclose(compiled._x, python._x, rtol=1e-9, atol=1e-9), k
        assert compiled._contact_force == pytest.approx(python._contact_force, abs=1e-7)
        contact.append(python._contact_force)
    contact = np.array(contact)
    assert (contact[:30] == 0.0).all() and contact[50:].max() > 1.0  # over the board from x = 0.02 m (40 ms)
    truth = [p.ground_truth() for p in plants]
    assert np.allclose(truth[1].external_wrench, truth[0].external_wrench, atol=1e-8)


def test_board_contact_only_within_its_contact_depth():
    """An end-effector pressed into the face is pushed out; one behind the board (deeper than
    ``BoardConfig.contact_depth``, e.g. after passing beside it and coming back over it) feels nothing — before, the
    whole prism behind the rectangle pushed out through the face: 35 cm behind it, a 1,750 N force. Both versions;
    ``inf`` keeps the former prism."""
    board = {"enabled": True, "point": [0.0, 0.0, 2.1], "normal": [0.0, 0.0, -1.0], "size": [0.3, 0.3]}
    env = Environment(scenario_from_dict({"board": board}))
    assert env.board.contact_depth == 0.05
    velocity = np.array([0.0, 0.0, 0.0])
    for depth, expected in ((0.002, 10.0), (0.049, 245.0), (0.051, 0.0), (0.35, 0.0)):
        point = np.array([0.05, -0.05, 2.1 + depth])
        force, normal = env.board_force(point, velocity)
        force_s, normal_s = env.board_force_scalar(tuple(point), tuple(velocity))
        assert normal == pytest.approx(expected) and normal_s == pytest.approx(expected), depth
        assert np.allclose(force_s, force, atol=1e-12)
    prism = Environment(scenario_from_dict({"board": {**board, "contact_depth": ".inf"}}))
    assert prism.board_force(np.array([0.05, -0.05, 2.45]), velocity)[1] == pytest.approx(1750.0)
    for bad in (0.0, -0.01):
        with pytest.raises(ValueError, match="board.contact_depth"):
            scenario_from_dict({"board": {**board, "contact_depth": bad}})


def test_compiled_plant_ignores_a_board_it_is_behind():
    """The C kernel reads ``contact_depth`` too: the end-effector, ~35 cm behind the board's plane, slides over
    the rectangle from beside it: no contact in either version; with ``contact_depth: inf`` (the former prism) the
    same flight meets a force of hundreds of newtons."""
    _require_compiled()

    def contact_forces(contact_depth) -> list[tuple[float, float]]:
        plants = _plants_sliding_towards_a_board({"point": [0.17, 0.0, 1.2], "contact_depth": contact_depth})
        forces = []
        for _ in range(60):
            for plant in plants:
                plant.step()
            forces.append((plants[0]._contact_force, plants[1]._contact_force))
            assert np.allclose(plants[1]._x, plants[0]._x, rtol=1e-9, atol=1e-9)
        return forces

    assert all(python == 0.0 and compiled == 0.0 for python, compiled in contact_forces(0.05))
    prism = contact_forces(".inf")
    assert max(python for python, _ in prism) > 300.0
    assert all(compiled == pytest.approx(python, abs=1e-6) for python, compiled in prism)
