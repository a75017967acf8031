"""fpr_experiments.margin: the latency-margin sweep's outcomes and report (ROS-free; the command's --report-only
path on hand-made metrics.json files)."""

from __future__ import annotations

import json
import os

import pytest

from fpr_experiments import margin


def _write_flight(root: str, flight: margin.Flight, *, completed: bool = True, failed: tuple[str, ...] = (),
                  emergencies: tuple[float, ...] = ()) -> None:
    """The two metrics.json files a flight leaves: the experiment's summary and the variant's own."""
    directory = os.path.join(margin.flight_root(root, flight.latency, flight.seed, flight.variant), flight.experiment)
    os.makedirs(os.path.join(directory, "report"), exist_ok=True)
    summary = {"experiment": flight.experiment, "commit": "abc1234", "date": "2026-12-07 07:00 UTC",
               "variants": {flight.variant: {"label": flight.variant.upper(), "completed": completed,
                                             "passed": completed and not failed, "failed_checks": list(failed),
                                             "report_dir": "report"}}}
    with open(os.path.join(directory, "metrics.json"), "w", encoding="utf-8") as stream:
        json.dump(summary, stream)
    with open(os.path.join(directory, "report", "metrics.json"), "w", encoding="utf-8") as stream:
        json.dump({"emergencies": [{"t": t, "uav": 2, "own": True, "reason": "tilt"} for t in emergencies]},
                  stream)


def test_a_flight_keeps_control_unless_it_fails_a_safety_check_or_does_not_complete(tmp_path):
    root = str(tmp_path)
    calm = margin.Flight("fig_3_4", "observers", "own", 0.0)
    slow = margin.Flight("fig_3_4", "observers", "1", 0.0)  # an accuracy bound failed: still in control
    flipped = margin.Flight("fig_3_4", "observers", "own", 0.01)
    crashed = margin.Flight("fig_3_4", "observers", "1", 0.01)
    missing = margin.Flight("fig_3_4", "observers", "2", 0.01)
    _write_flight(root, calm)
    _write_flight(root, slow, failed=("roll_rmse_deg = 5.2 (<= 5): FAILED",))
    _write_flight(root, flipped, failed=("max_abs_roll_deg = 180 (<= 30): FAILED",
                                         "swarm_emergencies = 1 (<= 0): FAILED"), emergencies=(128.4, 130.0))
    _write_flight(root, crashed, completed=False)
    outcomes = margin.load_outcomes(root, [calm, slow, flipped, crashed, missing])
    assert outcomes[calm].kept and outcomes[slow].kept and outcomes[calm].lost_at is None
    assert outcomes[flipped].kept is False and outcomes[flipped].lost_at == pytest.approx(128.4)
    assert outcomes[flipped].why == "uav2: tilt"
    assert outcomes[flipped].failures == ["max_abs_roll_deg = 180 (<= 30): FAILED",
                                          "swarm_emergencies = 1 (<= 0): FAILED"]
    assert outcomes[crashed].kept is False and outcomes[crashed].failures == ["did not complete"]
    assert outcomes[missing].kept is None
    assert outcomes[calm].label == "OBSERVERS" and outcomes[calm].commit == "abc1234"


def test_the_report_counts_the_seeds_that_kept_control_per_latency(tmp_path):
    root = str(tmp_path)
    seeds, latencies = ["own", "1"], [0.0, 0.02]
    flights = [margin.Flight("table_3_3", v, s, lat) for lat in latencies for s in seeds for v in ("fowo", "sowo")]
    for flight in flights:
        lost = flight.variant == "sowo" and (flight.seed == "own" or flight.latency > 0.0)
        _write_flight(root, flight, failed=("swarm_emergencies = 1 (<= 0): FAILED",) if lost else (),
                      emergencies=(9.7,) if lost else ())
    text = margin.margin_markdown(margin.load_outcomes(root, flights), ["table_3_3"],
                                  {"table_3_3": ["fowo", "sowo"]}, latencies, seeds, "ros2 run fpr_experiments margin")
    assert "| FOWO | **2/2** | **2/2** |" in text
    assert "| SOWO | **1/2** (lost: own at 10 s) | **0/2** (lost: own at 10 s; 1 at 10 s) |" in text
    assert "- uav2: tilt: SOWO seed 1 L = 20ms, SOWO seed own L = 0ms, SOWO seed own L = 20ms" in text
    assert "| variant | L = 0ms | L = 20ms |" in text
    assert "Flights at commit abc1234; 2026-12-07 07:00 UTC to 2026-12-07 07:00 UTC" in text
    assert "Overrides: none" in text
    ablation = margin.margin_markdown(margin.load_outcomes(root, flights), ["table_3_3"],
                                      {"table_3_3": ["fowo", "sowo"]}, latencies, seeds, "margin --set x.y=1",
                                      ["actuation.motor_time_constant=0.025"])
    assert "(an ablation, not the profile nor the nodes' defaults): actuation.motor_time_constant=0.025." in ablation


def test_the_command_rebuilds_the_report_from_the_flights_and_refuses_bad_values(tmp_path, capsys):
    root, results = str(tmp_path / "flights"), str(tmp_path / "margin.md")
    _write_flight(root, margin.Flight("fig_3_4", "observers", "own", 0.01), emergencies=())
    assert margin.main(["--experiment", "fig_3_4", "--latencies", "0.01", "--seeds", "own", "--output-dir", root,
                        "--results", results, "--report-only"]) == 0
    with open(results, encoding="utf-8") as stream:
        text = stream.read()
    assert "## fig_3_4" in text and "**1/1**" in text
    assert "`ros2 run fpr_experiments margin --experiment fig_3_4 --latencies 0.01 --seeds own`" in text
    for bad in (["--latencies", "-0.01"], ["--latencies", "nan"], ["--latencies", "0.6"], ["--seeds", "one"],
                ["--seeds", "1", "1"], ["--experiment", "no_such_experiment"],
                ["--experiment", "table_3_3", "--variant", "no_such_variant"],
                ["--set", "px4.command_latency=0.02"], ["--set", "novalue"], ["--param", "nonode.x=1"]):
        assert margin.main([*bad, "--output-dir", root, "--results", results, "--report-only"]) == 2
    assert "error:" in capsys.readouterr().err


def test_every_flight_gets_its_latency_beside_the_ablation_s_overrides():
    overrides = {"actuation": {"motor_time_constant": 0.025}, "px4": {"offboard_loss_timeout": 0.5}}
    merged = margin.flight_overrides(0.02, overrides)
    assert merged == {"actuation": {"motor_time_constant": 0.025},
                      "px4": {"offboard_loss_timeout": 0.5, "command_latency": 0.02}}
    assert "command_latency" not in overrides["px4"]  # the caller's overlay is not changed
    assert margin.flight_overrides(0.0, None) == {"px4": {"command_latency": 0.0}}
    with pytest.raises(ValueError, match="--latencies"):
        margin.flight_overrides(0.01, {"px4": {"command_latency": 0.03}})
