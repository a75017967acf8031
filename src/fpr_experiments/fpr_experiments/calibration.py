"""Calibration of fpr_sim's ``hardware`` realism profile on the thesis's calibration set (issue 11), ROS-free driver.

Honest calibration: the realism knobs are tuned on **two** thesis results only — Exp. I hover, Table 3.2's
impedance row (centralized, motion capture: model mismatch, actuation, motion capture) and Table 4.2's C row
(decentralized on the onboard cameras: vision and link) — then frozen; every other experiment of the suite is run
with them unchanged (``ros2 run fpr_experiments run all``), which is the validation.

Objective: the calibration set's metrics as ratios r = ours / thesis; the score is the geometric RMS error
``exp(sqrt(mean(ln(r)²)))`` (1 = exact; 2 = a typical factor of 2 off), averaged over ``seeds``. Search: coordinate
descent over the knobs of ``config/calibration/knobs.yaml`` (each a dotted scenario key and candidate values, tried
in order with the others at their current best), ``rounds`` passes. Every evaluation flies the calibration flights
in fresh processes, each under ``scripts/isolated.sh`` (its own network namespace, so parallel jobs share no port
and no DDS domain), ``jobs`` at a time.

Outputs (``--write``): ``docs/calibration.md`` (every evaluation: knob values, per-metric ratios, score) and
``src/fpr_sim/config/realism/hardware/90_calibrated.yaml`` (the chosen values: the last file of the profile, so it
wins over the first guesses of the effect files; a scenario's own values still win over it)::

    ros2 run fpr_experiments calibrate --jobs 2 --seeds own 0 --write     # (through scripts/calibrate.sh)

Seeds: ``own`` is each experiment's scenario seed, the flight the validation run makes; a value found on one
seed only can sit on a stability edge another seed falls over (the first calibration, on seed 0 alone, chose a
thrust noise with which Table 4.2's own seed 21 flips the decentralized robot at 45° legs).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import itertools
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

#: (experiment, variant) pairs the realism is tuned on; nothing else is (see the module doc)
CALIBRATION_SET: tuple[tuple[str, str], ...] = (("table_3_2", "impedance"), ("table_4_2", "communicating"))


@dataclass
class Knob:
    """A realism parameter the calibration may set: a dotted scenario key and its candidate values."""

    key: str
    values: list[Any]
    note: str = ""


@dataclass
class Evaluation:
    """One assignment of knob values flown on the calibration set."""

    assignment: dict[str, Any]
    ratios: dict[str, float] = field(default_factory=dict)   #: "experiment/variant/metric" -> mean ratio over seeds
    ours: dict[str, float] = field(default_factory=dict)
    thesis: dict[str, float] = field(default_factory=dict)
    failures: list[str] = field(default_factory=list)       #: flights that did not complete or failed a check
    wall_time_s: float = 0.0

    @property
    def score(self) -> float:
        return geometric_rms_error(list(self.ratios.values())) if not self.failures else math.inf


def geometric_rms_error(ratios: Sequence[float]) -> float:
    """``exp(sqrt(mean(ln(r)²)))`` over the finite, positive ratios (inf if there is none, or one is not)."""
    if not ratios or any(not (math.isfinite(r) and r > 0.0) for r in ratios):
        return math.inf
    return math.exp(math.sqrt(sum(math.log(r) ** 2 for r in ratios) / len(ratios)))


def safety_failures(failed_checks: Sequence[str]) -> list[str]:
    """The failed checks that disqualify a candidate: the safety ones (fpr_experiments.catalog.DEFAULT_CHECKS: flip,
    fly-away, ground contact, NaN). An experiment's own accuracy bounds are what the calibration moves towards the
    thesis; they do not disqualify (entries look like ``"roll_rmse_deg = 5.2 (<= 5): FAILED"``)."""
    from fpr_experiments.catalog import DEFAULT_CHECKS

    return [check for check in failed_checks if check.split(" ")[0].split(".")[-1] in DEFAULT_CHECKS]


def nested_overrides(assignment: dict[str, Any]) -> dict[str, Any]:
    """``{"actuation.thrust_noise": 0.02}`` -> ``{"actuation": {"thrust_noise": 0.02}}`` (a scenario overlay)."""
    out: dict[str, Any] = {}
    for key, value in assignment.items():
        parts = key.split(".")
        node = out
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ValueError(f"knob {key!r} collides with another knob's value at {part!r}")
        node[parts[-1]] = value
    return out


def load_knobs(path: str) -> list[Knob]:
    """The knobs file: ``knobs: [{key: actuation.thrust_noise, values: [0.0, 0.02, 0.05], note: ...}, ...]``."""
    import yaml

    with open(path, encoding="utf-8") as stream:
        data = yaml.safe_load(stream) or {}
    knobs = []
    for k, item in enumerate(data.get("knobs", [])):
        if not isinstance(item, dict) or set(item) - {"key", "values", "note"} or "key" not in item \
                or not isinstance(item.get("values"), list) or not item["values"]:
            raise ValueError(f"{path}: knobs[{k}] needs 'key' and a non-empty 'values' list (and an optional 'note')")
        knobs.append(Knob(str(item["key"]), list(item["values"]), str(item.get("note", ""))))
    if not knobs:
        raise ValueError(f"{path}: no knobs")
    return knobs


def coordinate_search(knobs: Sequence[Knob], evaluate: Callable[[dict[str, Any]], Evaluation], rounds: int = 1,
                      start: dict[str, Any] | None = None,
                      on_evaluation: Callable[[Evaluation], None] | None = None) -> tuple[Evaluation, list[Evaluation]]:
    """Coordinate descent: per knob, try each candidate with the others at their best so far; keep the best.

    Starts from ``start`` (default: every knob's first value). Assignments already flown are not flown again.
    Returns the best evaluation and the history (in the order flown)."""
    current = dict(start or {knob.key: knob.values[0] for knob in knobs})
    cache: dict[str, Evaluation] = {}
    history: list[Evaluation] = []

    def flown(assignment: dict[str, Any]) -> Evaluation:
        key = json.dumps(assignment, sort_keys=True)
        if key not in cache:
            cache[key] = evaluate(dict(assignment))
            history.append(cache[key])
            if on_evaluation:
                on_evaluation(cache[key])
        return cache[key]

    best = flown(current)
    for _ in range(max(1, rounds)):
        for knob in knobs:
            for value in knob.values:
                candidate = {**current, knob.key: value}
                result = flown(candidate)
                if result.score < best.score:
                    best, current = result, candidate
    return best, history


# ---------------------------------------------------------------------------------------------- flights
def _flight_command(experiment: str, variant: str, seed: int, overrides: dict[str, Any], output_root: str,
                    parameters: dict[str, dict[str, Any]] | None = None) -> list[str]:
    root = os.environ.get("FPR_ROOT") or os.getcwd()
    payload = json.dumps({"experiment": experiment, "variant": variant, "seed": seed, "overrides": overrides,
                          "output_root": output_root, "parameters": parameters or {}})
    return ["bash", os.path.join(root, "scripts", "isolated.sh"), sys.executable, "-m", "fpr_experiments.calibration",
            "--fly-one", payload]


def fly_isolated(experiment: str, variant: str, seed: int | None, overrides: dict[str, Any], output_root: str,
                 domain_id: int, parameters: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """One flight of ``variant`` with the hardware profile and the scenario ``overrides`` (nested, as
    :func:`nested_overrides` gives them; seed None: the scenario's own) and the node ``parameters``
    ({executable: {name: value}}, as ``run --param``; None: none) in its own process under
    ``scripts/isolated.sh`` (DDS domain ``domain_id``), its reports in ``output_root/<experiment>/`` (no plots);
    returns the variant's metrics.json entry (``completed`` False and ``error`` when the process failed). The
    calibration's flights and fpr_experiments.margin's."""
    env = dict(os.environ, FPR_IN_NETNS="0", ROS_DOMAIN_ID=str(domain_id))
    done = subprocess.run(_flight_command(experiment, variant, seed, overrides, output_root, parameters), env=env,
                          capture_output=True, text=True, check=False)
    path = os.path.join(output_root, experiment, "metrics.json")
    if done.returncode not in (0, 1) or not os.path.exists(path):
        tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
        return {"completed": False, "error": f"exit {done.returncode}: {' | '.join(tail)}", "metrics": {}}
    with open(path, encoding="utf-8") as stream:
        return json.load(stream)["variants"].get(variant, {"completed": False, "metrics": {}})


def make_evaluator(seeds: Sequence[int | None], jobs: int, work_dir: str,
                   cases: Sequence[tuple[str, str]] = CALIBRATION_SET) -> Callable[[dict[str, Any]], Evaluation]:
    """An ``evaluate(assignment)`` flying every case × seed (``jobs`` in parallel) with the hardware profile."""
    counter = itertools.count()

    def evaluate(assignment: dict[str, Any]) -> Evaluation:
        index = next(counter)
        overrides = nested_overrides(assignment)
        started = time.monotonic()
        flights = [(experiment, variant, seed) for experiment, variant in cases for seed in seeds]
        with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            futures = {flight: pool.submit(fly_isolated, *flight, overrides, os.path.join(
                work_dir, f"eval{index:03d}", f"{flight[0]}_{'own' if flight[2] is None else flight[2]}"),
                1 + (index * len(flights) + k) % 100) for k, flight in enumerate(flights)}
        evaluation = Evaluation(assignment)
        sums: dict[str, list[float]] = {}
        for (experiment, variant, seed), future in futures.items():
            entry = future.result()
            unsafe = safety_failures(entry.get("failed_checks", []))
            if not entry.get("completed") or unsafe:
                evaluation.failures.append(f"{experiment}/{variant} seed {seed}: "
                                           f"{entry.get('error') or unsafe or 'not completed'}")
            for metric, value in entry.get("metrics", {}).items():
                if isinstance(value, dict) and value.get("thesis") is not None and value.get("ours") is not None:
                    name = f"{experiment}/{variant}/{metric}"
                    sums.setdefault(name, []).append(float(value["ours"]))
                    evaluation.thesis[name] = float(value["thesis"])
        for name, values in sums.items():
            evaluation.ours[name] = sum(values) / len(values)
            thesis = evaluation.thesis[name]
            evaluation.ratios[name] = evaluation.ours[name] / thesis if thesis else math.nan
        evaluation.wall_time_s = time.monotonic() - started
        return evaluation

    return evaluate


def fly_one(payload: str) -> int:
    """Worker: run one calibration flight (``--fly-one`` JSON) with the hardware profile and the overrides."""
    from fpr_experiments.runner import run_experiment

    job = json.loads(payload)
    result = run_experiment(job["experiment"], seed=None if job["seed"] is None else int(job["seed"]),
                            variants=[job["variant"]],
                            output_root=job["output_root"], plots=False, log=False, realism="hardware",
                            scenario_overrides=job["overrides"],
                            parameter_overrides=job.get("parameters") or None)
    return 0 if result.passed else 1


# ---------------------------------------------------------------------------------------------- outputs
def _format_value(value: Any) -> str:
    return json.dumps(value) if not isinstance(value, float) else f"{value:.4g}"


def calibration_markdown(knobs: Sequence[Knob], history: Sequence[Evaluation], best: Evaluation,
                         seeds: Sequence[int], command: str, commit: str) -> str:
    """docs/calibration.md: the calibration set, the knobs, every evaluation, the chosen values."""
    lines = ["# Calibration of the `hardware` realism profile", "",
             f"Generated by `{command}` — do not edit by hand. Commit {commit}, "
             f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. Seeds {list(seeds)}.", "",
             "Tuned **only** on: " + ", ".join(f"`{e}` / `{v}`" for e, v in CALIBRATION_SET)
             + " (thesis Table 3.2 impedance row, Table 4.2 C row). Every other experiment is validation, flown with "
             "these values frozen (docs/results.md). Score = exp(sqrt(mean(ln(ours/thesis)²))) over the set's "
             "metrics (1 = exact, 2 = a typical factor of 2 off); a flight that does not complete or fails a safety "
             "check scores inf.", "",
             "## Knobs", "", "| key | candidates | note |", "|---|---|---|"]
    lines += [f"| `{k.key}` | {', '.join(_format_value(v) for v in k.values)} | {k.note} |" for k in knobs]
    metric_names = sorted(best.ratios)
    lines += ["", "## Evaluations (in the order flown)", "",
              "| # | " + " | ".join(f"`{k.key}`" for k in knobs) + " | " + " | ".join(metric_names) + " | score |",
              "|" + "---|" * (2 + len(knobs) + len(metric_names))]
    for k, evaluation in enumerate(history):
        cells = [_format_value(evaluation.assignment.get(knob.key)) for knob in knobs]
        ratios = [f"×{evaluation.ratios[m]:.2g}" if m in evaluation.ratios else "—" for m in metric_names]
        mark = " **best**" if evaluation is best else ""
        failures = "; ".join(evaluation.failures)[:120]
        score = f"inf ({failures})" if evaluation.failures else f"{evaluation.score:.3f}"
        lines.append(f"| {k} | " + " | ".join(cells) + " | " + " | ".join(ratios) + f" | {score}{mark} |")
    lines += ["", "## Chosen", "", "| metric | ours | thesis | ratio |", "|---|---|---|---|"]
    lines += [f"| {m} | {best.ours[m]:.3g} | {best.thesis[m]:.3g} | ×{best.ratios[m]:.2f} |" for m in metric_names]
    lines += ["", "Values written to `src/fpr_sim/config/realism/hardware/90_calibrated.yaml`:", "", "```yaml",
              _calibrated_yaml(best.assignment).rstrip(), "```", ""]
    return "\n".join(lines)


def _calibrated_yaml(assignment: dict[str, Any]) -> str:
    import yaml

    return yaml.safe_dump(nested_overrides(assignment), sort_keys=True, default_flow_style=False)


def write_outputs(root: str, knobs: Sequence[Knob], history: Sequence[Evaluation], best: Evaluation,
                  seeds: Sequence[int], command: str) -> list[str]:
    commit = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            check=False).stdout.strip() or "unknown"
    docs = os.path.join(root, "docs", "calibration.md")
    with open(docs, "w", encoding="utf-8") as stream:
        stream.write(calibration_markdown(knobs, history, best, seeds, command, commit))
    profile = os.path.join(root, "src", "fpr_sim", "config", "realism", "hardware", "90_calibrated.yaml")
    with open(profile, "w", encoding="utf-8") as stream:
        stream.write(f"# Generated by `{command}` (fpr_experiments.calibration) at commit {commit}: the values the "
                     "calibration chose\n# on its calibration set only (docs/calibration.md). Do not edit by hand; "
                     "rerun the calibration.\n")
        stream.write(_calibrated_yaml(best.assignment))
    return [docs, profile]


def _default_knobs_path() -> str:
    try:
        from ament_index_python.packages import get_package_share_directory

        installed = os.path.join(get_package_share_directory("fpr_experiments"), "config", "calibration", "knobs.yaml")
        if os.path.exists(installed):
            return installed
    except (ImportError, LookupError, ValueError):
        pass
    return os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config", "calibration",
                        "knobs.yaml")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ros2 run fpr_experiments calibrate", description=__doc__.split("\n\n")[0])
    parser.add_argument("--knobs", default=None, help="knobs YAML (default: the package's config/calibration)")
    parser.add_argument("--seeds", nargs="+", default=["own"],
                        help="seeds flown per evaluation (metrics averaged; every flight must be safe): integers and "
                             "'own' (each experiment's scenario seed, the one the validation flies); default: own")
    parser.add_argument("--jobs", type=int, default=2, help="flights in parallel (2 cores: 2)")
    parser.add_argument("--rounds", type=int, default=1, help="coordinate-descent passes over the knobs")
    parser.add_argument("--write", action="store_true",
                        help="write docs/calibration.md and fpr_sim's config/realism/hardware/90_calibrated.yaml")
    parser.add_argument("--fly-one", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    try:
        args.seeds = [None if seed == "own" else int(seed) for seed in args.seeds]
    except ValueError:
        print(f"calibrate: --seeds takes integers and 'own', got {args.seeds}", file=sys.stderr)
        return 2
    if args.fly_one is not None:
        from fpr_experiments.cli import pin_numeric_code

        pin_numeric_code("baseline", entry_point=argv is None)  # the same flight on every CPU, as `run`
        return fly_one(args.fly_one)
    try:
        knobs = load_knobs(args.knobs or _default_knobs_path())
    except (OSError, ValueError) as error:
        print(f"calibrate: {error}", file=sys.stderr)
        return 2
    root = os.environ.get("FPR_ROOT") or os.getcwd()
    work_dir = tempfile.mkdtemp(prefix="fpr_calibration_")
    count = [0]

    def progress(evaluation: Evaluation) -> None:
        count[0] += 1
        ratios = " ".join(f"{name.split('/')[-1]} ×{r:.2g}" for name, r in sorted(evaluation.ratios.items()))
        print(f"[calibrate] #{count[0]} {json.dumps(evaluation.assignment)} score {evaluation.score:.3f} "
              f"({evaluation.wall_time_s:.0f} s) {ratios} {'; '.join(evaluation.failures)}", flush=True)

    best, history = coordinate_search(knobs, make_evaluator(args.seeds, args.jobs, work_dir), rounds=args.rounds,
                                      on_evaluation=progress)
    print(f"[calibrate] best {json.dumps(best.assignment)} score {best.score:.3f}")
    if args.write:
        command = "ros2 run fpr_experiments calibrate " + " ".join(a for a in (argv or sys.argv[1:]))
        for path in write_outputs(root, knobs, history, best, args.seeds, command.strip()):
            print(f"[calibrate] wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
