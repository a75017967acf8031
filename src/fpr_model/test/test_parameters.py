"""Tests of fpr_model.parameters: Table B.1 defaults, YAML loading, validation naming the field."""

import dataclasses
import os

import numpy as np
import pytest
from fpr_model.parameters import (
    FprParameters,
    default_parameters,
    leg_mass_properties,
    load_parameters,
    parameters_from_dict,
    parameters_to_dict,
)

PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(PACKAGE, "config", "fpr_parameters.yaml")


def test_table_b1_defaults():
    p = default_parameters()
    assert p.n == 3
    assert (p.platform_radius, p.leg_length, p.joint_offset) == (0.127, 1.043, 0.069)
    assert p.joint_offset_angle == pytest.approx(np.pi / 4)
    assert (p.platform_mass, p.leg_mass) == (0.250, 0.066)
    assert np.array_equal(p.platform_com, [0, 0, 0.010]) and np.array_equal(p.leg_com, [0.599, 0, 0])
    assert np.array_equal(p.platform_inertia, np.diag([5.4e-4, 5.4e-4, 1e-3]))
    assert np.array_equal(p.leg_inertia, np.diag([1.6e-6, 0.035, 0.035]))
    assert np.array_equal(p.uav_masses, [1.007, 1.028, 1.018])
    assert p.total_mass == pytest.approx(3.501, abs=1e-12)
    assert p.total_mass * p.gravity == pytest.approx(34.345, abs=1e-3)


def test_other_n_uses_mean_uav_mass():
    p = default_parameters(6)
    assert p.uav_masses.shape == (6,)
    assert np.allclose(p.uav_masses, np.mean([1.007, 1.028, 1.018]))


def test_leg_mass_properties_point_mass_at_tip():
    p = default_parameters()
    legs = leg_mass_properties(p)
    l = p.leg_length
    assert np.allclose(legs.masses, 0.066 + p.uav_masses)
    assert np.allclose(legs.first_moments[1], [0.066 * 0.599 + 1.028 * l, 0, 0])
    assert np.allclose(legs.inertias[2], np.diag([1.6e-6, 0.035 + 1.018 * l**2, 0.035 + 1.018 * l**2]))


def test_yaml_config_equals_defaults_and_round_trip(tmp_path):
    assert load_parameters(CONFIG) == default_parameters()
    d = parameters_to_dict(default_parameters(4))
    assert parameters_from_dict(d) == default_parameters(4)
    path = tmp_path / "p.yaml"
    path.write_text("/**:\n  ros__parameters:\n    n: 4\n    leg_length: 1.1\n"
                    "    platform_inertia: [1, 0, 0, 0, 2, 0, 0, 0, 3]\n")
    p = load_parameters(str(path))
    assert p.n == 4 and p.leg_length == 1.1 and p.uav_masses.shape == (4,)
    assert np.array_equal(p.platform_inertia, np.diag([1.0, 2.0, 3.0]))
    p = parameters_from_dict({"leg_inertia": [[1e-6, 0, 0], [0, 0.03, 0], [0, 0, 0.03]]})
    assert p.leg_inertia[1, 1] == 0.03


def test_unknown_key_is_refused_with_valid_names():
    with pytest.raises(ValueError, match="legs_length") as info:
        parameters_from_dict({"legs_length": 1.0})
    assert "leg_length" in str(info.value) and "uav_masses" in str(info.value)


@pytest.mark.parametrize(
    "change, field",
    [
        ({"n": 2}, "n"),
        ({"platform_mass": 0.0}, "platform_mass"),
        ({"leg_mass": -1.0}, "leg_mass"),
        ({"leg_length": float("nan")}, "leg_length"),
        ({"platform_radius": -0.1}, "platform_radius"),
        ({"platform_inertia": [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]}, "platform_inertia"),
        ({"leg_inertia": [1.0, -1.0, 1.0]}, "leg_inertia"),
        ({"uav_masses": [1.0, 1.0]}, "uav_masses"),
        ({"uav_masses": [1.0, 0.0, 1.0]}, "uav_masses"),
        ({"platform_com": [0.0, np.inf, 0.0]}, "platform_com"),
        ({"leg_com": [0.0, 0.0]}, "leg_com"),
        ({"gravity": -9.81}, "gravity"),
        ({"joint_offset": -0.01}, "joint_offset"),
    ],
)
def test_invalid_parameters_name_the_field(change, field):
    with pytest.raises(ValueError, match=f"FprParameters.{field}"):
        dataclasses.replace(default_parameters(), **change)


def test_immutable():
    p = default_parameters()
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.leg_length = 2.0
    with pytest.raises(ValueError):
        p.uav_masses[0] = 3.0
    assert isinstance(p, FprParameters)
    assert p == default_parameters() and hash(p) == hash(default_parameters())
    assert p != dataclasses.replace(p, gravity=0.0)
