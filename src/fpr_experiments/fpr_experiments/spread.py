"""Do our results and the thesis's orderings survive another seed? ``ros2 run fpr_experiments spread``.

docs/results.md flies every row once, with each scenario's own seed, and calls an ordering *reproduced* when every
strict relation of the thesis's table holds in that one flight. One flight per row cannot tell a systematic
disagreement from luck: the seed draws the robot (fpr_sim's model mismatch: masses, CoM, inertias, leg lengths),
the rotors' thrust noise, the sensor noise, the fan's turbulence and the link's losses. This command flies the
experiments that have thesis values again with other seeds (each seed a different robot and noise realisation,
the realism values frozen) and reports, per thesis relation "a better than b", in how many seeds ours holds:

- **every seed**: reproduced, robustly;
- **no seed**: a systematic disagreement (the model, the controller or the thesis's value: to be explained);
- **some seeds**: within our seed-to-seed spread: one flight (ours, or the thesis's single hardware flight)
  cannot establish this relation; the table gives both differences beside our spread.

and, per metric with a thesis value, in how many seeds our value lies within ×0.5-×2 of the thesis's.

    ros2 run fpr_experiments spread --seeds own 1 2 --jobs 2     # flies, then writes docs/seed_spread.md
    ros2 run fpr_experiments spread --seeds own 1 2 --report-only  # rebuilds it from <output>/seed_*/

(through ``bash scripts/seed_spread.sh``: network isolation, DESIGN.md §6). ``own`` is each scenario's own seed,
the flight of docs/results.md. The flights of each seed land in ``<output>/seed_<seed>/<experiment>/`` like
``run all``'s (metrics.json, MCAP). The analysis below is ROS-free and reads only those metrics.json files.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import statistics
import sys
import time
from dataclasses import dataclass, field
from typing import Any

#: seeds flown when none are given: the results.md flight and two others
DEFAULT_SEEDS = ("own", "1", "2")
#: the band docs/results.md counts a metric "within" (ours / thesis)
RATIO_BAND = (0.5, 2.0)


def seed_label(seed: str) -> str:
    """``own`` or an integer seed, as the directory and the tables name it; ValueError otherwise."""
    if seed == "own":
        return seed
    try:
        return str(int(seed))
    except ValueError:
        raise ValueError(f"--seeds: '{seed}' is neither 'own' nor an integer") from None


def seed_dir(output_root: str, seed: str) -> str:
    return os.path.join(output_root, f"seed_{seed_label(seed)}")


def load_runs(output_root: str, seeds: list[str], names: list[str]) -> dict[str, dict[str, dict[str, Any]]]:
    """{seed: {experiment: its metrics.json summary}}; a missing file is left out (and said once)."""
    runs: dict[str, dict[str, dict[str, Any]]] = {}
    for seed in seeds:
        runs[seed] = {}
        for name in names:
            path = os.path.join(seed_dir(output_root, seed), name, "metrics.json")
            if not os.path.exists(path):
                print(f"[spread] no {path}: {name} / seed {seed} left out", flush=True)
                continue
            with open(path, encoding="utf-8") as stream:
                runs[seed][name] = json.load(stream)
    return runs


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and math.isfinite(value)


@dataclass
class PairRelation:
    """One strict relation of the thesis's table: ``better`` has the better (lower error, or higher
    ``success_rate``) value of ``metric`` than ``worse``; ours per seed (None: not measured in that seed)."""

    metric: str
    label: str
    better: str
    worse: str
    thesis_better: float
    thesis_worse: float
    higher_is_better: bool
    ours: dict[str, tuple[float, float] | None] = field(default_factory=dict)

    def _holds(self, values: tuple[float, float]) -> bool:
        a, b = values
        return a > b if self.higher_is_better else a < b

    @property
    def judged(self) -> list[str]:
        return [seed for seed, values in self.ours.items() if values is not None]

    @property
    def holding(self) -> list[str]:
        return [seed for seed in self.judged if self._holds(self.ours[seed])]

    @property
    def verdict(self) -> str:
        """``every seed`` / ``no seed`` / ``some seeds`` / ``not judged``."""
        judged, holding = self.judged, self.holding
        if not judged:
            return "not judged"
        if len(holding) == len(judged):
            return "every seed"
        return "no seed" if not holding else "some seeds"

    def relative_gap(self, better: float, worse: float) -> float:
        """(worse - better) / mean of the two, signed so that > 0 means the thesis's relation: a scale-free size
        of a difference, comparable between the thesis's flight and ours."""
        mean = 0.5 * (abs(better) + abs(worse))
        if mean == 0.0:
            return 0.0
        gap = (better - worse) if self.higher_is_better else (worse - better)
        return gap / mean

    @property
    def thesis_gap(self) -> float:
        return self.relative_gap(self.thesis_better, self.thesis_worse)

    @property
    def our_gaps(self) -> list[float]:
        return [self.relative_gap(*self.ours[seed]) for seed in self.judged]


def relations(runs: dict[str, dict[str, dict[str, Any]]], experiment: str) -> list[PairRelation]:
    """Every strict thesis relation between two variants of ``experiment`` (thesis ties are not judged, as in
    results.md), with ours per seed. Variants and metrics come from the first seed that has the experiment."""
    from fpr_experiments.thesis import HIGHER_IS_BETTER

    summaries = {seed: run[experiment] for seed, run in runs.items() if experiment in run}
    if not summaries:
        return []
    first = next(iter(summaries.values()))
    variants = list(first["variants"])
    metrics = list(first["variants"][variants[0]]["metrics"]) if variants else []
    out = []
    for metric in metrics:
        thesis = {v: first["variants"][v]["metrics"].get(metric, {}).get("thesis") for v in variants}
        higher = metric.split(".")[-1] in HIGHER_IS_BETTER
        ranked = [v for v in variants if _finite(thesis[v])]
        for a in ranked:
            for b in ranked:
                better = thesis[a] > thesis[b] if higher else thesis[a] < thesis[b]
                if not better:
                    continue
                label = first["variants"][a]["metrics"][metric].get("label", metric)
                relation = PairRelation(metric, label, a, b, float(thesis[a]), float(thesis[b]), higher)
                for seed, summary in summaries.items():
                    rows = summary["variants"]
                    values = [rows.get(v, {}).get("metrics", {}).get(metric, {}).get("ours") for v in (a, b)]
                    relation.ours[seed] = (float(values[0]), float(values[1])) if all(map(_finite, values)) \
                        else None
                out.append(relation)
    return out


def ratio_counts(runs: dict[str, dict[str, dict[str, Any]]], experiment: str,
                 excluded: set[str]) -> tuple[int, int, int, int]:
    """Over the metrics with a thesis value (calibration rows ``experiment/variant`` in ``excluded`` left out):
    (metrics, within ×0.5-×2 in every seed that measured them, in some, in none)."""
    per_metric: dict[tuple[str, str], list[bool]] = {}
    for run in runs.values():
        summary = run.get(experiment)
        if summary is None:
            continue
        for variant_id, variant in summary["variants"].items():
            if f"{experiment}/{variant_id}" in excluded:
                continue
            for metric, row in variant["metrics"].items():
                ratio = row.get("ratio")
                if row.get("thesis") is None:
                    continue
                per_metric.setdefault((variant_id, metric), []).append(
                    _finite(ratio) and RATIO_BAND[0] <= ratio <= RATIO_BAND[1])
    every = sum(1 for flags in per_metric.values() if flags and all(flags))
    none = sum(1 for flags in per_metric.values() if not any(flags))
    return len(per_metric), every, len(per_metric) - every - none, none


def _fmt(value: float, digits: int = 2) -> str:
    return f"{value:.{digits}f}" if math.isfinite(value) else "–"


def _percent(value: float) -> str:
    return f"{100.0 * value:+.0f} %"


def _labels(runs: dict[str, dict[str, dict[str, Any]]], experiment: str) -> dict[str, str]:
    for run in runs.values():
        if experiment in run:
            return {v: row["label"] for v, row in run[experiment]["variants"].items()}
    return {}


def _orderings_reproduced(runs, experiment: str, seed: str) -> str:
    summary = runs[seed].get(experiment)
    if summary is None:
        return "–"
    orderings = summary.get("orderings", [])
    return f"{sum(o['reproduced'] for o in orderings)}/{len(orderings)}"


def _failed_flights(runs, experiment: str) -> list[str]:
    out = []
    for seed, run in runs.items():
        summary = run.get(experiment)
        if summary is None:
            continue
        out += [f"{row['label']} (seed {seed}): {', '.join(row.get('failed_checks', [])) or 'incomplete'}"
                for row in summary["variants"].values() if not row.get("passed", True)]
    return out


def spread_markdown(runs: dict[str, dict[str, dict[str, Any]]], names: list[str], command: str) -> str:
    """docs/seed_spread.md: the overview (per experiment: orderings reproduced per seed, thesis relations holding
    in every / some / no seed, metrics within ×0.5-×2 in every / some / no seed), then per experiment every
    relation with the thesis's difference beside ours per seed."""
    from fpr_experiments.calibration import CALIBRATION_SET
    from fpr_experiments.report import provenance

    excluded = {f"{e}/{v}" for e, v in CALIBRATION_SET}
    seeds = list(runs)
    summaries = [s for run in runs.values() for s in run.values()]
    out = ["# Seed spread: do our results and the thesis's orderings survive another seed?", "",
           f"Generated by `{command}` — do not edit by hand. {provenance(summaries)}. "
           f"Seeds {', '.join(seeds)} (`own` = each "
           "scenario's own seed, the flights of docs/results.md). Each seed is another robot (fpr_sim's model "
           "mismatch draws) and another realisation of the thrust, sensor, wind and link noise; the realism values "
           "are frozen (docs/calibration.md), nothing was tuned on these flights. A thesis relation *a < b* (a "
           "better) is judged in every seed that measured both rows; thesis ties are not judged. Gap = (worse − "
           "better) / their mean: positive when the relation holds, comparable between the thesis's single "
           "hardware flight and ours.", "",
           "Reading: **every seed** = reproduced robustly; **no seed** = a systematic disagreement, to be "
           "explained by a modelling difference or the thesis's value; **some seeds** = the relation lies within "
           "our seed-to-seed spread, so one flight (ours, or the thesis's) cannot establish it.", "",
           "## Overview", "",
           f"| experiment | orderings reproduced per seed ({', '.join(seeds)}) | thesis relations holding in every / "
           "some / no seed | metrics within ×0.5-×2 in every / some / no seed |", "|---|---|---|---|"]
    totals = [0] * 7
    sections: list[str] = []
    for name in names:
        pairs = relations(runs, name)
        metrics, every, some, none = ratio_counts(runs, name, excluded)
        if not pairs and not metrics:
            continue
        verdicts = [p.verdict for p in pairs]
        counts = [verdicts.count("every seed"), verdicts.count("some seeds"), verdicts.count("no seed")]
        judged = sum(counts)
        totals = [a + b for a, b in zip(totals, [*counts, judged, every, some, none], strict=True)]
        per_seed = ", ".join(_orderings_reproduced(runs, name, seed) for seed in seeds)
        out.append(f"| {name} | {per_seed} | {counts[0]} / {counts[1]} / {counts[2]} (of {judged}) | "
                   f"{every} / {some} / {none} (of {metrics}) |")
        sections += _experiment_section(runs, name, pairs, seeds)
    out += [f"| **all** | | **{totals[0]} / {totals[1]} / {totals[2]}** (of {totals[3]}) | "
            f"**{totals[4]} / {totals[5]} / {totals[6]}** (of {totals[4] + totals[5] + totals[6]}) |", "",
            "Calibration rows (" + ", ".join(f"`{e}` / `{v}`" for e, v in CALIBRATION_SET)
            + ") are left out of the metric counts, as in docs/results.md; their relations to the other rows are "
            "judged.", ""]
    return "\n".join(out + sections) + "\n"


def _experiment_section(runs, name: str, pairs: list[PairRelation], seeds: list[str]) -> list[str]:
    labels = _labels(runs, name)
    title = next((run[name]["title"] for run in runs.values() if name in run), "")
    out = [f"## {name}: {title}", ""]
    if pairs:
        out += ["| metric | thesis relation | thesis gap | our gap per seed (" + ", ".join(seeds) + ") | holds in |",
                "|---|---|---|---|---|"]
        for p in pairs:
            gaps = {seed: p.relative_gap(*p.ours[seed]) for seed in p.judged}
            cells = ", ".join(_percent(gaps[seed]) if seed in gaps else "–" for seed in seeds)
            sign = ">" if p.higher_is_better else "<"
            verdict = f"{len(p.holding)}/{len(p.judged)}: **{p.verdict}**"
            out.append(f"| {p.label} | {labels.get(p.better, p.better)} {sign} {labels.get(p.worse, p.worse)} "
                       f"({_fmt(p.thesis_better)} {sign} {_fmt(p.thesis_worse)}) | {_percent(p.thesis_gap)} | "
                       f"{cells} | {verdict} |")
        out.append("")
        spread = [statistics.pstdev(p.our_gaps) for p in pairs if len(p.judged) >= 2]
        if spread:
            out += [f"Our gaps' seed-to-seed standard deviation: median {_percent(statistics.median(spread))[1:]} "
                    f"(per relation, over the seeds that measured it).", ""]
    failed = _failed_flights(runs, name)
    if failed:
        out += ["Flights whose checks failed (their metrics still count): " + "; ".join(failed) + ".", ""]
    return out


def spread_experiments() -> list[str]:
    """The experiments with thesis values (a table column): the ones whose ratios or orderings can move."""
    from fpr_experiments.catalog import load_all

    return [e.id for e in load_all() if any(column.table for column in e.metrics)]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ros2 run fpr_experiments spread", description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", nargs="+", default=list(DEFAULT_SEEDS),
                        help="'own' (each scenario's seed) and/or integers (default: %(default)s)")
    parser.add_argument("--jobs", type=int, default=2, help="experiments flown in parallel (default %(default)s)")
    parser.add_argument("--realism", default="hardware", metavar="PROFILE",
                        help="realism profile of every flight (default %(default)s, as docs/results.md)")
    parser.add_argument("--experiment", action="append", default=None,
                        help="only this experiment (repeatable; default: every one with thesis values)")
    parser.add_argument("--output-dir", default=None,
                        help="reports root of the flights (default: <$FPR_REPORTS or ./reports>/seeds)")
    parser.add_argument("--results", default=None, help="default <repo>/docs/seed_spread.md")
    parser.add_argument("--report-only", action="store_true", help="fly nothing: rebuild from the metrics.json")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from fpr_experiments import cli
    from fpr_experiments.catalog import check_realism, load_experiment
    from fpr_experiments.runner import default_output_root

    try:
        seeds = [seed_label(s) for s in args.seeds]
        if len(set(seeds)) != len(seeds):
            raise ValueError(f"--seeds: {' '.join(args.seeds)} names a seed twice")
        check_realism(args.realism, "--realism")
        names = args.experiment or spread_experiments()
        experiments = [load_experiment(name) for name in names]
        output_root = args.output_dir or os.path.join(default_output_root(), "seeds")
        results = args.results or os.path.join(os.environ.get("FPR_ROOT") or os.getcwd(), "docs", "seed_spread.md")
        command = ("ros2 run fpr_experiments spread --seeds " + " ".join(seeds)
                   + (f" --realism {args.realism}" if args.realism != "hardware" else "")
                   + "".join(f" --experiment {n}" for n in args.experiment or []))
        if not args.report_only:
            start = time.monotonic()
            for k, seed in enumerate(seeds):
                print(f"\n===== seed {seed} [{k + 1}/{len(seeds)}]: {len(names)} experiments "
                      f"({time.monotonic() - start:.0f} s so far) =====", flush=True)
                run_args = cli._parser().parse_args(
                    ["all", "--jobs", str(max(1, args.jobs)), "--no-plots", "--realism", args.realism]
                    + ([] if seed == "own" else ["--seed", seed]))
                failed = cli._run_parallel(experiments, run_args, seed_dir(output_root, seed))
                if failed:
                    print(f"[spread] seed {seed}: checks failed in {', '.join(failed)} (their metrics still count)",
                          flush=True)
        runs = load_runs(output_root, seeds, names)
        os.makedirs(os.path.dirname(os.path.abspath(results)), exist_ok=True)
        with open(results, "w", encoding="utf-8") as stream:
            stream.write(spread_markdown(runs, names, command))
        stamp = datetime.datetime.now(datetime.UTC).strftime("%H:%M UTC")
        print(f"wrote {results} ({stamp})", flush=True)
        return 0
    except (ValueError, FileNotFoundError) as error:  # UnknownNameError is a ValueError
        print(f"error: {error}", file=sys.stderr, flush=True)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
