"""fpr_experiments.compare_runs: two runs' metrics.json side by side (ROS-free)."""

from __future__ import annotations

import json
import os

import pytest
from fpr_experiments.compare_runs import load_run, main, metric_rows, report


def _summary(values: dict[str, float], reproduced: bool, failed: list[str] | None = None, runner="one process"):
    return {"commit": "abc1234", "runner": runner, "date": "2026-12-07 10:00 UTC",
            "variants": {"c": {"label": "C-controller", "failed_checks": failed or [], "metrics": {
                metric: {"ours": value, "thesis": 4.0, "label": f"{metric} [deg]"}
                for metric, value in values.items()}}},
            "orderings": [{"metric": "roll", "label": "roll [deg]", "thesis": "C < NC", "ours": "C < NC",
                           "reproduced": reproduced}]}


def _write(root, name: str, summary: dict) -> None:
    os.makedirs(os.path.join(root, name), exist_ok=True)
    with open(os.path.join(root, name, "metrics.json"), "w", encoding="utf-8") as stream:
        json.dump(summary, stream)


def test_rows_ratios_bands_orderings_and_checks(tmp_path):
    one, two = tmp_path / "one", tmp_path / "two"
    _write(one, "table_4_2", _summary({"roll": 4.0, "pitch": 1.0, "legs": float("nan")}, True))
    _write(two, "table_4_2", _summary({"roll": 5.0, "pitch": 3.0, "legs": 2.0}, False, ["max_tilt 40 > 30"],
                                      runner="overlapped (two processes)"))
    _write(one, "only_here", _summary({"roll": 1.0}, True))
    reference, other = load_run(str(one)), load_run(str(two))
    rows = {r["metric"]: r for r in metric_rows(reference, other)}
    assert set(rows) == {"roll", "pitch", "legs"}  # only_here is not in both
    assert rows["roll"]["ratio"] == pytest.approx(1.25) and rows["legs"]["ratio"] is None
    assert rows["pitch"]["reference_in_band"] is False and rows["pitch"]["other_in_band"] is True  # 1/4, 3/4
    text = report(reference, other, ("one process", "overlapped"), "compare_runs one two", intro="Both: run all.")
    assert "\n\nBoth: run all.\n\n" in text and "runner one process, seed own, commit abc1234" in text
    assert ": one process 1 / 2, overlapped 2 / 2; in band in one run only: 1" in text
    assert "the thesis's claims holding: one process 0 / 0" in text
    reference["table_4_2"]["claims"] = [{"text": "C < NC", "line": 7, "variant": "C", "holds": True},
                                        {"text": "only here", "line": 8, "variant": "C", "holds": True}]
    other["table_4_2"]["claims"] = [{"text": "C < NC", "line": 7, "variant": "C", "holds": False}]
    assert "claims holding: one process 1 / 1, overlapped 0 / 1" in report(reference, other, ("one process",
                                                                                              "overlapped"), "c")
    assert "thesis orderings reproduced: one process 1 / 1, overlapped 0 / 1" in text
    assert "table_4_2 / C-controller: one process: ok — overlapped: max_tilt 40 > 30" in text
    assert "| table_4_2 | C-controller | pitch [deg] | 1 | 3 | 3 | 4 |" in text
    assert "runner overlapped (two processes)" in text


def test_calibration_rows_are_left_out_of_the_band_counts(tmp_path):
    one = tmp_path / "one"
    summary = _summary({"roll": 4.0}, True)
    summary["variants"] = {"impedance": summary["variants"]["c"]}
    _write(one, "table_3_2", summary)  # Table 3.2's impedance row: a calibration row (fpr_experiments.calibration)
    run = load_run(str(one))
    assert metric_rows(run, run)[0]["calibration"]
    assert "table_4_2/communicating left out, as in docs/results.md): reference 0 / 0" in report(run, run, ("reference",
                                                                                                      "other"), "c")


def test_main_writes_the_report_and_refuses_an_empty_root(tmp_path, capsys):
    one = tmp_path / "one"
    _write(one, "table_3_2", _summary({"roll": 4.0}, True))
    output = tmp_path / "out.md"
    assert main([str(one), str(one), "--labels", "a", "b", "--output", str(output)]) == 0
    assert "ratio b / a: median 1.000, 1 of 1 within" in output.read_text()
    (tmp_path / "empty").mkdir()
    assert main([str(one), str(tmp_path / "empty")]) == 2
    assert "holds no <experiment>/metrics.json" in capsys.readouterr().err
