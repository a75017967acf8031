"""fpr_experiments.spread: the seed-spread analysis of the thesis's orderings and ratios (ROS-free core; the
command's --report-only path on hand-made metrics.json files)."""

from __future__ import annotations

import json
import math
import os

import pytest

from fpr_experiments import spread


def _summary(experiment: str, values: dict[str, dict[str, tuple[float, float | None]]], *,
             seed: int | None = None, failed: tuple[str, ...] = ()) -> dict:
    """A metrics.json summary: {variant: {metric: (ours, thesis)}}; orderings as report.py computes them."""
    from fpr_experiments.thesis import Ordering

    variants = {}
    for variant, metrics in values.items():
        rows = {}
        for metric, (ours, thesis) in metrics.items():
            rows[metric] = {"ours": ours, "thesis": thesis, "label": f"{metric} label",
                            "ratio": None if thesis is None else ours / thesis}
        variants[variant] = {"label": variant.upper(), "metrics": rows, "passed": variant not in failed,
                             "failed_checks": ["max_abs_roll_deg = 40 (<= 30): FAILED"] if variant in failed else []}
    metrics = list(next(iter(values.values())))
    orderings = []
    for metric in metrics:
        thesis = {v: m[metric][1] for v, m in values.items() if m[metric][1] is not None}
        ours = {v: values[v][metric][0] for v in thesis}
        if len(thesis) >= 2 and len(set(thesis.values())) >= 2:
            orderings.append({"metric": metric, "reproduced": Ordering(metric, thesis, ours).reproduced})
    return {"experiment": experiment, "title": f"{experiment} title", "commit": "abc1234",
            "date": "2026-12-04 02:00 UTC", "seed": seed, "variants": variants, "orderings": orderings}


def _runs() -> dict:
    # thesis: imp (1.0) < pd (2.0) on roll; pd (3.0) < imp (4.0) on legs; a tie on force (not judged)
    def experiment(roll_imp, roll_pd, legs_imp, legs_pd, seed=None, failed=()):
        return {"table_x": _summary("table_x", {
            "imp": {"roll": (roll_imp, 1.0), "legs": (legs_imp, 4.0), "force": (0.5, 1.0), "extra": (9.0, None)},
            "pd": {"roll": (roll_pd, 2.0), "legs": (legs_pd, 3.0), "force": (0.7, 1.0), "extra": (8.0, None)},
        }, seed=seed, failed=failed)}
    return {
        "own": experiment(1.1, 2.5, 2.0, 5.0),           # roll holds, legs reversed
        "1": experiment(1.2, 1.9, 2.1, 6.0, seed=1),      # roll holds, legs reversed
        "2": experiment(2.2, 2.0, 2.2, 7.0, seed=2, failed=("pd",)),  # roll reversed, legs reversed
    }


def test_relations_judge_every_strict_thesis_pair_in_every_seed():
    pairs = {p.metric: p for p in spread.relations(_runs(), "table_x")}
    assert set(pairs) == {"roll", "legs"}  # force is a thesis tie, extra has no thesis value
    roll, legs = pairs["roll"], pairs["legs"]
    assert (roll.better, roll.worse) == ("imp", "pd") and (legs.better, legs.worse) == ("pd", "imp")
    assert roll.holding == ["own", "1"] and roll.verdict == "some seeds"
    assert legs.holding == [] and legs.verdict == "no seed"
    assert roll.thesis_gap == pytest.approx((2.0 - 1.0) / 1.5)
    assert roll.our_gaps[2] == pytest.approx((2.0 - 2.2) / 2.1)  # negative: the relation fails in seed 2


def test_a_relation_holding_in_every_seed_and_a_seed_without_the_metric():
    runs = _runs()
    for seed in ("1", "2"):
        runs[seed]["table_x"]["variants"]["pd"]["metrics"]["roll"]["ours"] = 3.0
    runs["2"]["table_x"]["variants"]["imp"]["metrics"]["roll"]["ours"] = math.nan  # a flight that measured nothing
    roll = next(p for p in spread.relations(runs, "table_x") if p.metric == "roll")
    assert roll.judged == ["own", "1"] and roll.verdict == "every seed"


def test_higher_is_better_metrics_reverse_the_relation():
    runs = {"own": {"t": _summary("t", {"a": {"success_rate": (0.9, 0.8)}, "b": {"success_rate": (0.5, 0.6)}})}}
    (pair,) = spread.relations(runs, "t")
    assert (pair.better, pair.worse, pair.higher_is_better, pair.verdict) == ("a", "b", True, "every seed")
    assert pair.thesis_gap > 0.0


def test_ratio_counts_band_per_seed_and_excluded_rows():
    runs = _runs()
    # ratios: roll imp 1.1/1.2/2.2 -> in, in, out (some); roll pd 1.25/0.95/1.0 (every); legs imp 0.5,0.525,0.55
    # (every); legs pd 1.67/2.0/2.33 -> in,in,out (some); force 0.5 every; force pd 0.7 every
    assert spread.ratio_counts(runs, "table_x", set()) == (6, 4, 2, 0)
    assert spread.ratio_counts(runs, "table_x", {"table_x/pd"}) == (3, 2, 1, 0)


def test_markdown_states_seeds_verdicts_and_failed_flights():
    text = spread.spread_markdown(_runs(), ["table_x", "absent"], "ros2 run fpr_experiments spread --seeds own 1 2")
    assert "Seeds own, 1, 2" in text
    assert "| table_x | 1/2, 1/2, 0/2 | 0 / 1 / 1 (of 2) | 4 / 2 / 0 (of 6) |" in text
    assert "IMP < PD (1.00 < 2.00) | +67 % | +78 %, +45 %, -10 % | 2/3: **some seeds** |" in text
    assert "PD < IMP (3.00 < 4.00)" in text and "0/3: **no seed**" in text
    assert "PD (seed 2): max_abs_roll_deg = 40 (<= 30): FAILED" in text
    assert "absent" not in text.split("## Overview")[1].split("\n\n")[1]


def test_seed_labels_are_own_or_integers():
    assert spread.seed_label("own") == "own" and spread.seed_label("07") == "7"
    with pytest.raises(ValueError, match="neither 'own' nor an integer"):
        spread.seed_label("seven")


def test_report_only_rebuilds_from_metrics_json(tmp_path, capsys):
    for seed, run in _runs().items():
        directory = tmp_path / f"seed_{seed}" / "table_3_4"
        os.makedirs(directory)
        (directory / "metrics.json").write_text(json.dumps(run["table_x"]), encoding="utf-8")
    out = tmp_path / "seed_spread.md"
    status = spread.main(["--report-only", "--seeds", "own", "1", "2", "3", "--experiment", "table_3_4",
                          "--output-dir", str(tmp_path), "--results", str(out)])
    assert status == 0
    text = out.read_text(encoding="utf-8")
    assert "--experiment table_3_4" in text and "| table_3_4 | 1/2, 1/2, 0/2, – |" in text
    assert "table_3_4 / seed 3 left out" in capsys.readouterr().out


def test_usage_errors_are_one_line_and_exit_2(tmp_path, capsys):
    assert spread.main(["--report-only", "--seeds", "own", "own", "--output-dir", str(tmp_path)]) == 2
    assert "names a seed twice" in capsys.readouterr().err
    assert spread.main(["--report-only", "--experiment", "no_such", "--output-dir", str(tmp_path)]) == 2
    assert "no_such" in capsys.readouterr().err
