"""Scenario files: every shipped scenario loads; unknown keys are refused with the list of valid keys."""

from pathlib import Path

import pytest
from fpr_sim.scenario import load_scenario, scenario_from_dict

SCENARIOS = sorted((Path(__file__).resolve().parents[1] / "config" / "scenarios").glob("*.yaml"))


def test_there_are_scenarios():
    assert len(SCENARIOS) >= 4


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_shipped_scenarios_load(path):
    scenario = load_scenario(str(path))
    assert scenario.name == path.stem
    assert scenario.leg_angles().shape == (scenario.n,)


def test_unknown_top_level_key_lists_valid_keys():
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['windd'\]; valid keys are .*'wind'"):
        scenario_from_dict({"windd": {}})


def test_unknown_nested_key_lists_valid_keys():
    with pytest.raises(ValueError, match=r"initial_state: unknown key\(s\) \['pos'\].*'position'"):
        scenario_from_dict({"initial_state": {"pos": [0, 0, 1]}})
    with pytest.raises(ValueError, match=r"payloads\[0\]: unknown key"):
        scenario_from_dict({"payloads": [{"mas": 1.0}]})


def test_bad_values_refused():
    with pytest.raises(ValueError, match="expected a number"):
        scenario_from_dict({"battery": {"capacity": "big"}})
    with pytest.raises(ValueError, match="leg_angles"):
        scenario_from_dict({"initial_state": {"leg_angles": 2.0}})
    with pytest.raises(ValueError, match="NaN"):
        scenario_from_dict({"ground": {"stiffness": float("nan")}})


def test_plant_overrides_reach_true_parameters():
    from fpr_sim.plant import true_parameters

    params = true_parameters(scenario_from_dict({"plant": {"platform_mass": 0.4, "leg_length": 1.0}}))
    assert params.platform_mass == 0.4 and params.leg_length == 1.0
    with pytest.raises(ValueError, match="valid keys"):
        true_parameters(scenario_from_dict({"plant": {"platform_mas": 0.4}}))


def test_joint_stops_keys_and_ranges():
    default = scenario_from_dict({}).joint_stops
    assert default.enabled and 0.0 < default.lower < default.upper <= 1.7
    disabled = scenario_from_dict({"joint_stops": {"enabled": False}}).joint_stops
    assert not disabled.enabled
    custom = scenario_from_dict({"joint_stops": {"lower": 0.2, "upper": 1.5, "stiffness": 500, "damping": 2}})
    assert (custom.joint_stops.lower, custom.joint_stops.stiffness) == (0.2, 500.0)
    with pytest.raises(ValueError, match=r"joint_stops: unknown key\(s\) \['stifness'\].*'stiffness'"):
        scenario_from_dict({"joint_stops": {"stifness": 100.0}})
    for bad in ({"lower": 1.0, "upper": 0.5}, {"lower": -0.1}, {"upper": 4.0}, {"stiffness": -1.0},
                {"damping": -0.5}):
        with pytest.raises(ValueError, match="joint_stops"):
            scenario_from_dict({"joint_stops": bad})


def test_fan_board_and_target_defaults_keep_the_former_behaviour():
    import math

    scenario = scenario_from_dict({})
    fan = scenario.wind.fan
    assert not fan.enabled and fan.position is None and fan.reference_point is None
    assert fan.speed == 26.0 / 3.6 and fan.direction == [1.0, 0.0, 0.0]
    assert scenario.board.size == [math.inf, math.inf] and not scenario.target.enabled
    custom = scenario_from_dict({"wind": {"fan": {"enabled": True, "position": [-3, 0, 1], "speed": 3.61,
                                                  "reference_point": None}},
                                 "board": {"size": [0.3, ".inf"], "edge": [0, 1, 0]},
                                 "target": {"enabled": True, "position": [0.1, 0.0, 1.85], "yaw": 0.3}})
    assert custom.wind.fan.position == [-3.0, 0.0, 1.0] and custom.wind.fan.reference_point is None
    assert custom.board.size == [0.3, math.inf] and custom.target.yaw == 0.3
    with pytest.raises(ValueError, match="wind.fan.position"):
        scenario_from_dict({"wind": {"fan": {"position": 3.0}}})


def test_bundled_scenarios_resolve_by_name_with_or_without_yaml():
    from fpr_sim.scenario import scenario_path

    assert load_scenario("hover").name == "hover"
    assert load_scenario("ground_start.yaml").name == "ground_start"
    assert scenario_path("hover").endswith("hover.yaml")
    with pytest.raises(FileNotFoundError, match=r"scenario 'hoover': no such file.*bundled: .*ground_start.*hover"):
        load_scenario("hoover")


def test_realism_profiles_overlay_under_the_scenario(tmp_path, monkeypatch):
    """A profile is a scenario overlay: its values apply where the scenario is silent, the scenario's win."""
    import fpr_sim.scenario as scenario_module

    profile_dir = tmp_path / "realism" / "rough"
    profile_dir.mkdir(parents=True)
    (profile_dir / "10_a.yaml").write_text("sensors: {gyro_noise: 0.5, accel_noise: 0.7}\nseed: 9\n")
    (profile_dir / "20_b.yaml").write_text("sensors: {accel_noise: 0.9}\n")
    monkeypatch.setattr(scenario_module, "realism_dir", lambda: str(tmp_path / "realism"))
    assert scenario_module.realism_profiles() == ["ideal", "rough"]
    rough = scenario_from_dict({"realism": "rough", "sensors": {"gyro_noise": 0.1}})
    assert rough.realism == "rough"
    assert rough.sensors.gyro_noise == 0.1          # the scenario's own value wins
    assert rough.sensors.accel_noise == 0.9         # later file wins over the earlier one
    assert rough.seed == 9
    ideal = scenario_from_dict({"realism": "rough"}, realism="ideal")   # the caller's profile wins over the file's
    assert ideal.realism == "ideal" and ideal.sensors == scenario_from_dict({}).sensors
    with pytest.raises(ValueError, match="unknown profile 'nope'.*ideal, rough"):
        scenario_from_dict({}, realism="nope")


def test_bundled_hardware_profile_loads():
    from fpr_sim.scenario import realism_profiles

    assert "hardware" in realism_profiles()
    assert scenario_from_dict({}, realism="hardware").realism == "hardware"
    assert scenario_from_dict({}).realism == "ideal"
