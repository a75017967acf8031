"""The plain-float kernels of the 1 kHz plant against their numpy / fpr_model definitions."""

import numpy as np
import pytest
from fpr_model.rotations import quat_normalize, quat_to_rotmat
from fpr_sim.environment import Environment
from fpr_sim.quadrotor import Battery, QuadrotorFleet, mix
from fpr_sim.scalar_math import rotation_entries
from fpr_sim.scenario import scenario_from_dict


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


def test_fleet_state_reads_copies_and_battery_accepts_lists():
    scenario = scenario_from_dict({})
    fleet = QuadrotorFleet(3, scenario.quadrotor, scenario.px4, scenario.battery)
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
