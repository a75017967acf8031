"""Realism through the experiments (ROS-free): the catalog key ``realism`` and the CLI's ``--realism`` (an unknown
profile is one line listing the profiles, exit 2), the effective scenario of a run (profile and
``scenario_overrides`` deep-merged, written to the report folder) and the report's realism summary."""

from __future__ import annotations

import pytest
import yaml
from fpr_experiments.catalog import DEFAULT_REALISM, experiment_from_dict, load_all
from fpr_experiments.cli import run_main
from fpr_experiments.report import REALISM_SECTIONS, _realism_text, realism_summary
from fpr_experiments.runner import effective_scenario, graph_options
from fpr_sim.scenario import load_scenario, realism_profiles

BASE = {"id": "x", "title": "t", "scenario": "ground_start", "script": "integration_flight", "duration": 10.0,
        "variants": [{"id": "a"}], "metrics": [{"metric": "roll_rmse_deg"}]}
PROFILES_LINE = "unknown realism profile 'rough'; profiles: ideal, hardware"


def test_experiments_default_to_the_catalog_default_profile():
    assert DEFAULT_REALISM in realism_profiles()
    assert experiment_from_dict(dict(BASE)).realism == DEFAULT_REALISM
    assert experiment_from_dict({**BASE, "realism": "hardware"}).realism == "hardware"
    assert all(e.realism in realism_profiles() for e in load_all())


def test_an_unknown_profile_in_an_experiment_is_one_line_listing_the_profiles(tmp_path, capsys):
    with pytest.raises(ValueError, match=PROFILES_LINE):
        experiment_from_dict({**BASE, "realism": "rough"})
    path = tmp_path / "x.yaml"
    path.write_text(yaml.safe_dump({**BASE, "realism": "rough"}))
    assert run_main([str(path), "--output-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert PROFILES_LINE in err and len(err.splitlines()) == 1


def test_cli_realism_flag_is_checked_before_anything_flies(tmp_path, capsys):
    assert run_main(["table_3_2", "--realism", "rough", "--output-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"error: --realism: {PROFILES_LINE}"
    assert list(tmp_path.iterdir()) == []  # nothing flown, nothing written


def test_effective_scenario_deep_merges_the_overrides_and_names_the_profile(tmp_path):
    path = effective_scenario("hover", 5, str(tmp_path / "scenario.yaml"), "hardware",
                              {"link": {"loss": 0.2}, "sensors": {"gyro_noise": 0.01}})
    data = yaml.safe_load(open(path, encoding="utf-8"))
    assert data["seed"] == 5 and data["realism"] == "hardware" and data["link"] == {"loss": 0.2}
    scenario = load_scenario(path)
    assert scenario.realism == "hardware" and scenario.sensors.gyro_noise == 0.01
    hardware = load_scenario("hover", realism="hardware")
    # the override wins, the rest of the profile's link stays
    assert scenario.link.loss == 0.2 and scenario.link.enabled and scenario.link.latency_min == \
        hardware.link.latency_min
    assert scenario.initial_state == hardware.initial_state  # the named scenario's own values are kept
    with pytest.raises(ValueError, match="unknown key"):
        effective_scenario("hover", None, str(tmp_path / "bad.yaml"), None, {"link": {"los": 0.2}})


def test_graph_options_take_the_experiments_profile_or_the_callers():
    experiment = experiment_from_dict({**BASE, "realism": "hardware"})
    variant = experiment.variants[0]
    assert graph_options(experiment, variant, "ground_start", "emulated", 3).realism == "hardware"
    assert graph_options(experiment, variant, "ground_start", "emulated", 3, realism="ideal").realism == "ideal"


def test_realism_summary_states_the_profile_and_every_realism_section():
    summary = realism_summary(load_scenario("hover", realism="hardware"))
    assert summary["profile"] == "hardware"
    assert set(summary["sections"]) == set(REALISM_SECTIONS)
    assert summary["sections"]["link"]["enabled"] is True and "latency_min" in summary["sections"]["link"]
    assert "gyro_noise" in summary["sensors"] and "position_noise" in summary["cameras"]
    ideal = realism_summary(load_scenario("hover"))
    assert ideal["profile"] == "ideal" and not any(s["enabled"] for s in ideal["sections"].values())
    assert "hardware (effects on: " in _realism_text(summary) and "link)" in _realism_text(summary)
    assert "ideal (effects on: none)" in _realism_text(ideal)
    # PX4's attitude estimate is named when it is on (hardware since calibration pass 8), not in the ideal profile
    assert "PX4's attitude estimate: accelerometer-bias tilt share 1," in _realism_text(summary)
    assert "attitude estimate" not in _realism_text(ideal)
    # the mismatch's draws are named as plant parameters off the model (they were reported as "none" before)
    assert "drawn off Table B.1 by the model mismatch (" in _realism_text(summary)
    assert "drawn off" not in _realism_text(ideal) and "set by the scenario: none." in _realism_text(ideal)


def test_realism_summary_states_the_plant_draws():
    """The report says what the hardware profile drew for the run's plant (true masses, thrust curves, ...)."""
    hardware = realism_summary(load_scenario("hover", realism="hardware"))
    draws = hardware["plant_draws"]
    assert draws["mismatch"] and len(draws["thrust_coefficients"]) == 3
    assert realism_summary(load_scenario("hover"))["plant_draws"] == {}


def test_run_all_jobs_runs_each_experiment_isolated_longest_first(monkeypatch, tmp_path):
    """``run all --jobs 2``: one isolated process per experiment, longest flight first, failures collected."""
    from types import SimpleNamespace

    import fpr_experiments.cli as cli

    started = []

    class FakeProcess:
        def __init__(self, command, stdout, stderr, env):
            started.append((command, env))
            self.returncode = 1 if command[6] == "short" else 0

        def poll(self):
            return self.returncode

    import subprocess

    monkeypatch.setattr(subprocess, "Popen", FakeProcess)
    monkeypatch.setattr(cli.time, "sleep", lambda _s: None)
    experiments = [SimpleNamespace(id=name, duration=d, variants=[SimpleNamespace(duration=0.0)] * k)
                   for name, d, k in (("short", 10.0, 1), ("long", 50.0, 3), ("mid", 40.0, 1))]
    args = cli._parser().parse_args(["all", "--jobs", "2", "--seed", "3", "--realism", "ideal"])
    failed = cli._run_parallel(experiments, args, str(tmp_path))
    assert [c[6] for c, _ in started] == ["long", "mid", "short"]
    for command, env in started:
        assert command[1].endswith("scripts/isolated.sh") and env["FPR_IN_NETNS"] == "0"
        assert command[7:] == ["--output-dir", str(tmp_path), "--seed", "3", "--realism", "ideal"]
    assert len({env["ROS_DOMAIN_ID"] for _, env in started}) == 3
    assert failed == ["short"]
    assert cli._command_line(args) == "ros2 run fpr_experiments run all --seed 3 --realism ideal --jobs 2"


def test_set_overrides_parse_as_a_nested_yaml_overlay_and_pass_to_every_experiment_run():
    """``--set KEY=VALUE`` (ablations): dotted keys nest, values are YAML, and ``run all --jobs`` hands them on."""
    import fpr_experiments.cli as cli

    assert cli.scenario_overrides(None) is None
    assert cli.scenario_overrides(["actuation.thrust_noise=0.02", "actuation.enabled=false",
                                   "link.latency=[0.01, 0.02]"]) == {
        "actuation": {"thrust_noise": 0.02, "enabled": False}, "link": {"latency": [0.01, 0.02]}}
    for bad in ("actuation.thrust_noise", "=3", "actuation..noise=1", "a=[1,"):
        with pytest.raises(ValueError, match="--set"):
            cli.scenario_overrides([bad])
    args = cli._parser().parse_args(["all", "--jobs", "2", "--set", "link.latency=[0.01, 0.02]"])
    assert cli._experiment_flags(args) == ["--set", "link.latency=[0.01, 0.02]"]
    assert cli._command_line(args) == "ros2 run fpr_experiments run all --set 'link.latency=[0.01, 0.02]' --jobs 2"


def test_param_overrides_parse_per_executable_and_pass_to_every_experiment_run():
    """``--param EXECUTABLE.NAME=VALUE`` (ablations of the onboard software): values are YAML, the executable must
    be one of the graph's, ``run all --jobs`` hands them on, and the run lays them over the variant's."""
    import fpr_experiments.cli as cli
    from fpr_experiments.catalog import load_experiment
    from fpr_experiments.runner import with_parameter_overrides

    assert cli.parameter_overrides(None) is None
    assert cli.parameter_overrides(["pose_estimator.filter=mekf", "pose_estimator.platform_rate=true",
                                    "controller.observer=sowo"]) == {
        "pose_estimator": {"filter": "mekf", "platform_rate": True}, "controller": {"observer": "sowo"}}
    for bad in ("pose_estimator.filter", "filter=mekf", ".filter=mekf", "pose_estimator.=1", "pose_estimator.a=[1,"):
        with pytest.raises(ValueError, match="--param"):
            cli.parameter_overrides([bad])
    with pytest.raises(ValueError, match="no executable 'pose_estimatr'"):
        cli.parameter_overrides(["pose_estimatr.filter=mekf"])
    args = cli._parser().parse_args(["all", "--jobs", "2", "--param", "pose_estimator.filter=mekf"])
    assert cli._experiment_flags(args) == ["--param", "pose_estimator.filter=mekf"]
    # the variant's own parameters stay, the override wins where both set one (table_4_6 sets gate_mode off)
    experiment = load_experiment("table_4_6")
    variant = with_parameter_overrides(experiment.variants[0], {"pose_estimator": {"filter": "mekf"},
                                                                "controller": {"observer": "sowo"}})
    resolved = experiment.resolved(variant)["parameters"]
    assert resolved["pose_estimator"] == {"gate_mode": "off", "filter": "mekf"}
    assert resolved["controller"] == {"observer": "sowo"}  # the experiment's fowo, overridden
    assert with_parameter_overrides(experiment.variants[0], None) is experiment.variants[0]


def test_cli_set_with_an_unknown_scenario_key_is_one_line_before_anything_flies(tmp_path, capsys):
    assert run_main(["table_3_2", "--set", "actuation.thrust_nosie=0.1", "--output-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "thrust_nosie" in err
    assert not list(tmp_path.rglob("*.mcap"))  # nothing flown
