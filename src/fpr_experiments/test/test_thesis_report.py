"""Comparison with the thesis (ratios, orderings with ties, claims) and the reports (JSON, results.md, plots)."""

from __future__ import annotations

import json
import math
import os

import pytest
from fpr_experiments.catalog import experiment_from_dict, load_experiment
from fpr_experiments.metrics import compute_metrics
from fpr_experiments.plots import write_plots
from fpr_experiments.runner import CheckResult, ExperimentResult, VariantResult
from fpr_experiments.thesis import Ordering, compare, reference
from synthetic import synthetic_record

from fpr_experiments import report


def test_reference_values_come_from_the_bundled_spec_with_their_line():
    ref = reference("table_3_4", "3.4", "PD+C", "RMSE phi_p (roll)")
    assert (ref.value, ref.unit, ref.line) == (9.2, "deg", 5232)
    assert reference("table_4_3", "4.3", "Success rate", "NC-controller").value == pytest.approx(6 / 7)
    with pytest.raises(KeyError):
        reference("table_3_4", "3.4", "PID", "RMSE phi_p (roll)")  # excluded in the thesis: no value


def test_orderings_judge_strict_thesis_relations_only():
    tie = Ordering("force", {"fowo": 1.1, "sowo": 1.1, "smwo": 1.0}, {"fowo": 0.5, "sowo": 0.4, "smwo": 0.3})
    assert tie.reproduced  # smwo best in both; the fowo/sowo tie is not judged
    assert tie.text(tie.thesis) == "smwo < fowo = sowo"
    wrong = Ordering("force", {"a": 1.0, "b": 2.0}, {"a": 3.0, "b": 2.0})
    assert not wrong.reproduced
    rate = Ordering("success_rate", {"c": 5 / 7, "nc": 6 / 7}, {"c": 1.0, "nc": 0.9}, higher_is_better=True)
    assert rate.text(rate.thesis) == "nc > c" and not rate.reproduced


def test_compare_gives_ratio_and_ordering_per_metric():
    experiment = load_experiment("table_3_4")
    results = {"impedance": {"roll_rmse_deg": 0.53}, "pd": {"roll_rmse_deg": 1.07},
               "pd_compensated": {"roll_rmse_deg": 0.92}}
    comparisons, orderings = compare(experiment, results)
    roll = next(c for c in comparisons["pd"] if c.metric == "roll_rmse_deg")
    assert roll.thesis.value == 10.7 and roll.ratio == pytest.approx(0.1)
    ordering = next(o for o in orderings if o.metric == "roll_rmse_deg")
    assert ordering.reproduced  # impedance < PD+C < PD in both
    assert math.isnan(next(c for c in comparisons["pd"] if c.metric == "force_z_rmse_n").ratio)  # no value of ours


def _result(tmp_path, experiment, metrics_by_variant):
    variants = {}
    for variant_id, metrics in metrics_by_variant.items():
        variants[variant_id] = VariantResult(
            variant_id, metrics, [CheckResult("roll_rmse_deg", metrics.get("roll_rmse_deg", math.nan), {"max": 5.0})],
            str(tmp_path / variant_id), 20.0, 25.0, 2, True, [], synthetic_record())
    return ExperimentResult(experiment.id, variants, str(tmp_path))


def _hover_experiment(**extra):
    """A two-variant table_3_2 with one roll column (plus ``extra`` catalog keys)."""
    return experiment_from_dict({
        "id": "table_3_2", "title": "hover", "thesis": "Table 3.2", "scenario": "ground_start",
        "script": "integration_flight", "duration": 10.0,
        "variants": [{"id": "impedance", "label": "Impedance", "thesis_row": "Impedance"},
                     {"id": "pd", "label": "PD", "thesis_row": "PD"}],
        "metrics": [{"metric": "roll_rmse_deg", "table": "3.2", "column": "RMSE phi_p (roll)", "label": "roll"}],
        **extra})


def test_experiment_report_json_results_markdown_and_claims(tmp_path):
    experiment = _hover_experiment(claims=[{"text": "impedance tracks roll within 1 deg", "line": 5102,
                                            "lhs": "roll_rmse_deg", "op": "<", "rhs": 1.0}])
    result = _result(tmp_path, experiment, {"impedance": {"roll_rmse_deg": 0.2}, "pd": {"roll_rmse_deg": math.nan}})
    summary = report.write_experiment_report(experiment, result, str(tmp_path), plots=False)
    written = json.loads((tmp_path / "metrics.json").read_text())
    row = written["variants"]["impedance"]["metrics"]["roll_rmse_deg"]
    assert row["thesis"] == 4.6 and row["ratio"] == pytest.approx(0.2 / 4.6) and "l.5117" in row["thesis_ref"]
    assert written["variants"]["pd"]["metrics"]["roll_rmse_deg"]["ours"] is None  # NaN -> null
    assert not written["variants"]["pd"]["passed"]  # its check could not pass on a NaN
    assert [c["holds"] for c in written["claims"]] == [True, False]
    text = report.results_markdown([summary], {"table_3_2": experiment}, "ros2 run fpr_experiments run all")
    assert "## table_3_2: hover" in text and "| Impedance | 0.20 / 4.60 (×0.043) |" in text
    assert "PD ⚠" in text and "do not edit by hand" in text
    table = report.format_experiment_table(experiment, summary)
    assert "thesis 4.60" in table and "CHECKS FAILED" in table
    assert "Take-off hops" not in text


def test_take_off_hops_are_stated_beside_the_table(tmp_path):
    """A flight whose structure hopped at take-off (takeoff_touchdowns > 0, not a check) says so in results.md."""
    experiment = _hover_experiment()
    result = _result(tmp_path, experiment, {"impedance": {"roll_rmse_deg": 4.0, "takeoff_touchdowns": 2.0},
                                            "pd": {"roll_rmse_deg": 9.0, "takeoff_touchdowns": 0.0}})
    summary = report.write_experiment_report(experiment, result, str(tmp_path), plots=False)
    assert json.loads((tmp_path / "metrics.json").read_text())["variants"]["impedance"]["takeoff_touchdowns"] == 2
    text = report.results_markdown([summary], {"table_3_2": experiment}, "ros2 run fpr_experiments run all")
    assert "Take-off hops (a UAV's feet back on the ground before the robot first climbed 15 cm" in text
    assert "Impedance: 2." in text and "PD: 0" not in text


def test_the_cameras_are_stated_without_plots_too(tmp_path):
    """Without plots the runner keeps no flight record; the experiment's metrics.json and results.md still say
    which cameras flew (from the variant's own metrics.json), not a blank."""
    from dataclasses import replace

    experiment = experiment_from_dict({
        "id": "table_3_2", "title": "hover", "thesis": "Table 3.2", "scenario": "ground_start",
        "script": "integration_flight", "duration": 10.0,
        "variants": [{"id": "impedance", "label": "Impedance", "thesis_row": "Impedance"}],
        "metrics": [{"metric": "roll_rmse_deg", "table": "3.2", "column": "RMSE phi_p (roll)", "label": "roll"}]})
    result = _result(tmp_path, experiment, {"impedance": {"roll_rmse_deg": 0.2}})
    result.variants["impedance"] = replace(result.variants["impedance"], record=None)
    os.makedirs(tmp_path / "impedance")
    (tmp_path / "impedance" / "metrics.json").write_text(json.dumps({"cameras": "images"}))
    summary = report.write_experiment_report(experiment, result, str(tmp_path), plots=False)
    assert summary["cameras"] == "images"
    assert json.loads((tmp_path / "metrics.json").read_text())["cameras"] == "images"
    text = report.results_markdown([summary], {"table_3_2": experiment}, "ros2 run fpr_experiments run all")
    assert "Run: one process, images cameras" in text


def test_plots_of_a_synthetic_flight(tmp_path):
    paths = write_plots(synthetic_record(), str(tmp_path), dpi=40)
    names = {p.split("/")[-1] for p in paths}
    assert {"position.png", "attitude_legs.png", "wrench.png", "modes.png", "thrusts.png"} <= names
    assert all((tmp_path / name).stat().st_size > 5000 for name in names)
    assert compute_metrics(synthetic_record())["tracking_time_s"] > 5.0
