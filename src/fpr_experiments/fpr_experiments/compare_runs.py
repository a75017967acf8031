"""Two runs of the experiments suite side by side: ``ros2 run fpr_experiments compare_runs``.

Each run is a reports root as ``run all`` writes it (``<root>/<experiment>/metrics.json``). For every metric of
every variant flown in both: the two values, their ratio, and the thesis's value; per run, how many metrics lie
within ×0.5-×2 of the thesis, how many of the thesis's orderings hold and which checks fail. Uses: the overlapped
layout against the one-process runner (docs/results_overlapped.md: the same suite with one /clock period of added
control latency), a controller or a parameter change against the current code, two machines. ROS-free: it reads
the metrics.json files only.

    ros2 run fpr_experiments compare_runs REFERENCE_ROOT OTHER_ROOT [--labels "one process" "overlapped"]
        [--output docs/results_overlapped.md]
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import statistics
import sys
from typing import Any

from fpr_experiments.calibration import CALIBRATION_SET

#: the band docs/results.md counts a metric "within" (ours / thesis)
RATIO_BAND = (0.5, 2.0)
#: two runs "agree" on a metric when their ratio lies within this band
AGREEMENT_BAND = (0.8, 1.25)


def load_run(root: str) -> dict[str, dict[str, Any]]:
    """{experiment: its metrics.json summary} of a reports root (experiments without one are left out)."""
    if not os.path.isdir(root):
        raise FileNotFoundError(f"no reports root {root}")
    run = {}
    for name in sorted(os.listdir(root)):
        path = os.path.join(root, name, "metrics.json")
        if os.path.isfile(path):
            with open(path, encoding="utf-8") as stream:
                run[name] = json.load(stream)
    if not run:
        raise FileNotFoundError(f"{root} holds no <experiment>/metrics.json")
    return run


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _in_band(value: Any, thesis: Any) -> bool | None:
    if not (_finite(value) and _finite(thesis)) or thesis == 0:
        return None
    return RATIO_BAND[0] <= value / thesis <= RATIO_BAND[1]


def metric_rows(reference: dict, other: dict) -> list[dict[str, Any]]:
    """One row per (experiment, variant, metric) in both runs: values, ratio other / reference (None when not both
    finite or the reference is 0), thesis value, and whether each run is within :data:`RATIO_BAND` of it."""
    rows = []
    for name in sorted(set(reference) & set(other)):
        for variant, entry in reference[name]["variants"].items():
            other_entry = other[name]["variants"].get(variant)
            if other_entry is None:
                continue
            for metric, values in entry["metrics"].items():
                other_values = other_entry["metrics"].get(metric)
                if other_values is None:
                    continue
                a, b = values["ours"], other_values["ours"]
                ratio = b / a if _finite(a) and _finite(b) and a != 0 else None
                rows.append({"experiment": name, "variant": entry.get("label", variant), "metric": metric,
                             "calibration": (name, variant) in CALIBRATION_SET,
                             "label": values.get("label", metric), "reference": a, "other": b, "ratio": ratio,
                             "thesis": values.get("thesis"), "reference_in_band": _in_band(a, values.get("thesis")),
                             "other_in_band": _in_band(b, values.get("thesis"))})
    return rows


def _number(value: Any) -> str:
    if not _finite(value):
        return "–" if value is None else str(value)
    return f"{value:.3g}" if abs(value) < 1000 else f"{value:.0f}"


def _run_line(label: str, run: dict) -> str:
    summaries = list(run.values())
    commits = sorted({s.get("commit", "?") for s in summaries})
    runners = sorted({s.get("runner", "?") for s in summaries})
    seeds = sorted({"own" if s.get("seed") is None else str(s["seed"]) for s in summaries})
    dates = sorted(s.get("date", "") for s in summaries)
    quick = " (quick)" if any(s.get("quick") for s in summaries) else ""
    return (f"- **{label}**: {len(run)} experiments{quick}, runner {', '.join(runners)}, seed {', '.join(seeds)}, "
            f"commit {', '.join(commits)}, flown {dates[0]} – {dates[-1]}")


def report(reference: dict, other: dict, labels: tuple[str, str], command: str, intro: str = "") -> str:
    """The markdown comparison (module doc)."""
    rows = metric_rows(reference, other)
    ratios = [r["ratio"] for r in rows if r["ratio"] is not None and r["ratio"] > 0]
    logs = [abs(math.log(r)) for r in ratios]
    agree = sum(AGREEMENT_BAND[0] <= r <= AGREEMENT_BAND[1] for r in ratios)
    with_thesis = [r for r in rows if r["reference_in_band"] is not None and r["other_in_band"] is not None
                   and not r["calibration"]]
    a, b = labels
    lines = [f"# Experiments suite: {b} against {a}", "",
             f"Generated by `{command}` on {datetime.datetime.now(datetime.UTC).strftime('%Y-%m-%d %H:%M UTC')} "
             "(fpr_experiments.compare_runs: it reads the two runs' metrics.json; rerun it on new runs).", "",
             *([intro, ""] if intro else []), _run_line(a, reference), _run_line(b, other), "", "## Summary", "",
             f"- {len(rows)} metrics flown in both; ratio {b} / {a}: median {statistics.median(ratios):.3f}, "
             f"{agree} of {len(ratios)} within ×{AGREEMENT_BAND[0]:g}-×{AGREEMENT_BAND[1]:g}, median |log ratio| "
             f"{statistics.median(logs):.3f}, largest {max(ratios, key=lambda r: abs(math.log(r))):.3f}"
             if ratios else f"- {len(rows)} metrics flown in both, none with two finite values",
             f"- metrics within ×{RATIO_BAND[0]:g}-×{RATIO_BAND[1]:g} of the thesis (the calibration rows "
             f"{', '.join('/'.join(pair) for pair in CALIBRATION_SET)} left out, as in docs/results.md): {a} "
             f"{sum(r['reference_in_band'] for r in with_thesis)} / {len(with_thesis)}, {b} "
             f"{sum(r['other_in_band'] for r in with_thesis)} / {len(with_thesis)}; in band in one run only: "
             f"{sum(r['reference_in_band'] != r['other_in_band'] for r in with_thesis)}"]
    orderings = []
    for name in sorted(set(reference) & set(other)):
        theirs = {o["metric"]: o for o in other[name].get("orderings", [])}
        for ordering in reference[name].get("orderings", []):
            if ordering["metric"] in theirs:
                orderings.append((name, ordering, theirs[ordering["metric"]]))
    claims = []  # the same claim (text, thesis line, variant) in both runs
    for name in sorted(set(reference) & set(other)):
        theirs = {(c["text"], c.get("line"), c.get("variant")): c for c in other[name].get("claims", [])}
        claims += [(c, theirs[key]) for c in reference[name].get("claims", [])
                   if (key := (c["text"], c.get("line"), c.get("variant"))) in theirs]
    lines.append(f"- the thesis's claims holding: {a} {sum(bool(c['holds']) for c, _ in claims)} / {len(claims)}, "
                 f"{b} {sum(bool(d['holds']) for _, d in claims)} / {len(claims)}")
    lines.append(f"- thesis orderings reproduced: {a} {sum(o[1]['reproduced'] for o in orderings)} / {len(orderings)}"
                 f", {b} {sum(o[2]['reproduced'] for o in orderings)} / {len(orderings)}; reproduced in one run "
                 f"only: {sum(o[1]['reproduced'] != o[2]['reproduced'] for o in orderings)}")
    failing = []
    for name in sorted(set(reference) & set(other)):
        for variant, entry in reference[name]["variants"].items():
            other_entry = other[name]["variants"].get(variant, {})
            ours, theirs = entry.get("failed_checks", []), other_entry.get("failed_checks", [])
            if ours or theirs:
                failing.append(f"  - {name} / {entry.get('label', variant)}: {a}: {'; '.join(ours) or 'ok'} — {b}: "
                               f"{'; '.join(theirs) or 'ok'}")
    lines.append("- failed checks: none" if not failing else "- failed checks:")
    lines += failing
    if orderings:
        lines += ["", "## Orderings", "", f"| experiment | metric | thesis | {a} | {b} |", "|---|---|---|---|---|"]
        for name, mine, theirs in orderings:
            marks = [" ✓" if o["reproduced"] else "" for o in (mine, theirs)]
            lines.append(f"| {name} | {mine['label']} | {mine['thesis']} | {mine['ours']}{marks[0]} | "
                         f"{theirs['ours']}{marks[1]} |")
    lines += ["", "## Every metric", "", f"| experiment | variant | metric | {a} | {b} | {b} / {a} | thesis |",
              "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['experiment']} | {r['variant']} | {r['label']} | {_number(r['reference'])} | "
                     f"{_number(r['other'])} | {_number(r['ratio'])} | {_number(r['thesis'])} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ros2 run fpr_experiments compare_runs", description=__doc__.split("\n\n")[0])
    parser.add_argument("reference", help="reports root of the reference run (run all --output-dir)")
    parser.add_argument("other", help="reports root of the run compared with it")
    parser.add_argument("--labels", nargs=2, default=("reference", "other"), metavar=("REFERENCE", "OTHER"),
                        help="the two runs' names in the report")
    parser.add_argument("--output", default=None, help="write the markdown here (default: print it)")
    parser.add_argument("--intro", default="", help="a paragraph under the title: how the two runs were made")
    args = parser.parse_args(argv)
    try:
        reference, other = load_run(args.reference), load_run(args.other)
    except (FileNotFoundError, json.JSONDecodeError, KeyError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    command = (f"ros2 run fpr_experiments compare_runs <{args.labels[0]} run> <{args.labels[1]} run> --labels "
               f"'{args.labels[0]}' '{args.labels[1]}'")
    text = report(reference, other, tuple(args.labels), command, args.intro)
    if args.output:
        with open(args.output, "w", encoding="utf-8") as stream:
            stream.write(text)
        print(f"wrote {args.output}")
    else:
        print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
