"""How much command latency do the controllers keep control with? ``ros2 run fpr_experiments margin``.

The thesis's Ch. 3 robot flew its controllers on a ground computer that sent every setpoint over Wi-Fi and ROS 2 to
each companion computer, then over serial to the Pixhawk (l.4957-4959, l.9814-9820): a command uplink of at least
~10 ms that the thesis does not measure. fpr_sim's ``px4.command_latency`` L delays when each attitude/thrust
setpoint takes effect by L after it arrives at the emulated PX4 (fpr_sim README). This command flies experiments
with the ``hardware`` realism profile at several L and several seeds (each seed another robot of the model
mismatch and another realisation of the noise; the realism values frozen, nothing tuned) and reports, per variant
and L, in how many seeds the flight **kept control**: it completed and failed none of the safety checks
(fpr_experiments.catalog.DEFAULT_CHECKS and the experiment's overrides of them: tilt, height, excursion, ground
contact, NaN, the swarm's emergency response). A flight that lost it is listed with the first instant the swarm
entered its emergency response (or the safety checks it failed).

One flight per L and row (as docs/results.md's) cannot tell a latency margin from a flight that sits near a cliff
for any L; the seeds can::

    ros2 run fpr_experiments margin --experiment fig_3_4 --latencies 0 0.01 0.02 --seeds own 1 2 3 --jobs 2
    ros2 run fpr_experiments margin --experiment fig_3_4 ... --report-only   # rebuild from the flights' json
    ros2 run fpr_experiments margin ... --set actuation.motor_time_constant=0.025   # an ablation on every flight
    ros2 run fpr_experiments margin ... --param controller.smwo_epsilon=0.2          # a node parameter likewise

(through ``bash scripts/latency_margin.sh``: network isolation, DESIGN.md §6). Every flight runs in a process of
its own under ``scripts/isolated.sh`` (fpr_experiments.calibration's flight worker) and lands in
``<output>/L<ms>ms/seed_<seed>/<variant>/<experiment>/`` (metrics.json; no plots). The tables below are ROS-free:
they read only those metrics.json files.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import copy
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any

from fpr_experiments.spread import seed_label

#: seeds flown when none are given: docs/results.md's flight and three others
DEFAULT_SEEDS = ("own", "1", "2", "3")
#: [s] command latencies flown when none are given
DEFAULT_LATENCIES = (0.0, 0.01, 0.02)
#: experiments flown when none are given: the Ch. 3 flights whose margin the fpr_sim README discusses
DEFAULT_EXPERIMENTS = ("fig_3_4", "table_3_3")


def latency_label(latency: float) -> str:
    """``10ms`` for 0.01 s (directory names and table headers)."""
    return f"{1000.0 * latency:g}ms"


def check_latency(latency: float) -> float:
    """A command latency [s] the emulated PX4 accepts here: finite, >= 0 and below 0.5 s (its offboard-loss
    timeout: a setpoint stream later than that is no stream); ValueError otherwise."""
    if not (math.isfinite(latency) and 0.0 <= latency < 0.5):
        raise ValueError(f"--latencies: {latency} s must be finite, >= 0 and < 0.5 s")
    return latency


def flight_root(output_root: str, latency: float, seed: str, variant: str) -> str:
    """Where one flight's ``<experiment>/metrics.json`` lands."""
    return os.path.join(output_root, f"L{latency_label(latency)}", f"seed_{seed_label(seed)}", variant)


@dataclass(frozen=True)
class Flight:
    """One flight of the sweep."""

    experiment: str
    variant: str
    seed: str      #: 'own' or an integer, as text
    latency: float  #: [s] px4.command_latency


@dataclass
class Outcome:
    """What one flight did: ``kept`` control (None: no metrics.json, not flown or crashed), else when the swarm's
    emergency response started (``lost_at`` [s], None if it never did) and which safety checks failed."""

    kept: bool | None
    lost_at: float | None = None
    failures: list[str] = field(default_factory=list)
    why: str = ""  #: the first emergency's UAV and reason (its bridge's status), "" if none
    label: str = ""  #: the variant's label in the experiment's report
    commit: str = ""  #: the source commit the flight ran (its metrics.json)
    date: str = ""


def outcome_of(experiment_json: dict[str, Any], variant: str, variant_json: dict[str, Any] | None) -> Outcome:
    """The :class:`Outcome` of ``variant`` from its experiment's metrics.json (and the variant's own, for the
    emergencies' times)."""
    from fpr_experiments.calibration import safety_failures

    entry = experiment_json.get("variants", {}).get(variant)
    if entry is None:
        return Outcome(kept=None)
    failures = safety_failures(entry.get("failed_checks", []))
    if not entry.get("completed", False):
        failures = ["did not complete", *failures]
    emergencies = (variant_json or {}).get("emergencies") or []
    first = min(emergencies, key=lambda e: float(e["t"]), default=None)
    lost_at = None if first is None else float(first["t"])
    why = "" if first is None else f"uav{first.get('uav', '?')}: {str(first.get('reason', '')).strip()}"
    return Outcome(kept=not failures, lost_at=lost_at, failures=failures, why=why,
                   label=str(entry.get("label", variant)),
                   commit=str(experiment_json.get("commit", "unknown")), date=str(experiment_json.get("date", "")))


def load_outcomes(output_root: str, flights: list[Flight]) -> dict[Flight, Outcome]:
    """Every flight's :class:`Outcome` from ``output_root`` (a missing file: ``kept`` None)."""
    outcomes = {}
    for flight in flights:
        directory = os.path.join(flight_root(output_root, flight.latency, flight.seed, flight.variant),
                                 flight.experiment)
        path = os.path.join(directory, "metrics.json")
        if not os.path.exists(path):
            outcomes[flight] = Outcome(kept=None)
            continue
        with open(path, encoding="utf-8") as stream:
            experiment_json = json.load(stream)
        entry = experiment_json.get("variants", {}).get(flight.variant, {})
        variant_path = os.path.join(directory, str(entry.get("report_dir", flight.variant)), "metrics.json")
        variant_json = None
        if os.path.exists(variant_path):
            with open(variant_path, encoding="utf-8") as stream:
                variant_json = json.load(stream)
        outcomes[flight] = outcome_of(experiment_json, flight.variant, variant_json)
    return outcomes


def _cell(outcomes: list[tuple[str, Outcome]]) -> str:
    """``3/4 (lost: own at 128 s)`` for the seeds of one variant and latency."""
    flown = [(seed, o) for seed, o in outcomes if o.kept is not None]
    if not flown:
        return "–"
    kept = sum(1 for _, o in flown if o.kept)
    lost = []
    for seed, o in flown:
        if o.kept:
            continue
        lost.append(f"{seed} at {o.lost_at:.0f} s" if o.lost_at is not None else f"{seed}: {o.failures[0]}")
    text = f"**{kept}/{len(flown)}**"
    return text + (f" (lost: {'; '.join(lost)})" if lost else "")


def margin_markdown(outcomes: dict[Flight, Outcome], experiments: list[str], variants: dict[str, list[str]],
                    latencies: list[float], seeds: list[str], command: str, settings: list[str] = ()) -> str:
    """docs/latency_margin.md: per experiment a table, one row per variant, one column per latency, each cell the
    seeds that kept control out of those flown, and when the others lost it."""
    flown = [o for o in outcomes.values() if o.kept is not None]
    commits = ", ".join(sorted({o.commit for o in flown})) or "–"
    dates = sorted(o.date for o in flown if o.date)
    when = f"{dates[0]} to {dates[-1]}" if dates else "–"
    lines = ["# Latency margin: command uplink latency against loss of control, over seeds", "",
             f"Generated by `{command}` — do not edit by hand. Flights at commit {commits}; {when}. Every flight uses "
             "the `hardware` realism profile with `px4.command_latency` L (each attitude/thrust setpoint takes "
             "effect L after it reaches the emulated PX4; fpr_sim README) and the seed of its column's cell "
             "(`own` = the scenario's own seed, the flight of docs/results.md; each seed is another robot of the "
             "model mismatch and another realisation of the noise). A flight **kept control** when it completed "
             "and failed no safety check (tilt, height, excursion, ground contact, NaN, the swarm's emergency "
             "response); for the others, the first instant the swarm entered its emergency response (simulated "
             "time from the start), or the first safety check they failed.", "",
             f"Seeds: {', '.join(seeds)}. Latencies: {', '.join(latency_label(v) for v in latencies)}. "
             + (f"Overrides in every flight (an ablation, not the profile nor the nodes' defaults): "
                f"{', '.join(settings)}." if settings else
                "Overrides: none (the hardware profile and the nodes' defaults, as docs/results.md flies them)."),
             ""]
    for experiment in experiments:
        lines += [f"## {experiment}", "",
                  "| variant | " + " | ".join(f"L = {latency_label(v)}" for v in latencies) + " |",
                  "|---|" + "---|" * len(latencies)]
        for variant in variants[experiment]:
            label = next((o.label for f, o in outcomes.items()
                          if f.experiment == experiment and f.variant == variant and o.label), variant)
            cells = [_cell([(seed, outcomes.get(Flight(experiment, variant, seed, latency), Outcome(kept=None)))
                            for seed in seeds]) for latency in latencies]
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
        reasons: dict[str, list[str]] = {}
        for flight, outcome in outcomes.items():
            if flight.experiment == experiment and outcome.kept is False and outcome.why:
                label = outcome.label or flight.variant
                reasons.setdefault(outcome.why, []).append(
                    f"{label} seed {flight.seed} L = {latency_label(flight.latency)}")
        if reasons:
            lines += ["", "Why (the first emergency's UAV and the reason its bridge gave):"]
            lines += [f"- {why}: {', '.join(sorted(which))}" for why, which in sorted(reasons.items())]
        lines.append("")
    return "\n".join(lines)


def flight_overrides(latency: float, overrides: dict[str, Any] | None) -> dict[str, Any]:
    """The scenario overlay of one flight: ``overrides`` (nested, as ``--set`` gives them) with
    ``px4.command_latency`` set to ``latency`` (ValueError if ``overrides`` sets it too)."""
    merged = copy.deepcopy(overrides or {})
    px4 = merged.setdefault("px4", {})
    if not isinstance(px4, dict) or "command_latency" in px4:
        raise ValueError("--set px4.command_latency: the latencies are --latencies")
    px4["command_latency"] = latency
    return merged


def _fly(flight: Flight, output_root: str, domain_id: int, overrides: dict[str, Any] | None,
         parameters: dict[str, dict[str, Any]] | None) -> Outcome:
    from fpr_experiments.calibration import fly_isolated

    root = flight_root(output_root, flight.latency, flight.seed, flight.variant)
    fly_isolated(flight.experiment, flight.variant, None if flight.seed == "own" else int(flight.seed),
                 flight_overrides(flight.latency, overrides), root, domain_id, parameters)
    return load_outcomes(output_root, [flight])[flight]


def fly_all(flights: list[Flight], output_root: str, jobs: int, overrides: dict[str, Any] | None = None,
            parameters: dict[str, dict[str, Any]] | None = None) -> None:
    """Fly every flight with the scenario ``overrides`` (nested) and node ``parameters``, ``jobs`` at a time
    (each in its own isolated process), one line per flight."""
    started = time.monotonic()
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = {pool.submit(_fly, flight, output_root, 1 + k % 100, overrides, parameters): flight
                   for k, flight in enumerate(flights)}
        for done, future in enumerate(concurrent.futures.as_completed(futures), start=1):
            flight, outcome = futures[future], future.result()
            verdict = {True: "kept control", False: "LOST control", None: "no result"}[outcome.kept]
            if outcome.kept is False and outcome.lost_at is not None:
                verdict += f" at {outcome.lost_at:.0f} s"
            print(f"[margin] {done}/{len(flights)} {flight.experiment}/{flight.variant} seed {flight.seed} "
                  f"L {latency_label(flight.latency)}: {verdict} ({time.monotonic() - started:.0f} s)", flush=True)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ros2 run fpr_experiments margin", description=__doc__.split("\n\n")[0])
    parser.add_argument("--experiment", action="append", default=None,
                        help=f"experiment to fly (repeatable; default: {', '.join(DEFAULT_EXPERIMENTS)})")
    parser.add_argument("--variant", action="append", default=None,
                        help="only this variant (repeatable; default: every variant of each experiment)")
    parser.add_argument("--latencies", nargs="+", type=float, default=list(DEFAULT_LATENCIES),
                        help="command latencies L [s] (default: %(default)s)")
    parser.add_argument("--seeds", nargs="+", default=list(DEFAULT_SEEDS),
                        help="'own' (each scenario's seed) and/or integers (default: %(default)s)")
    parser.add_argument("--set", dest="overrides", action="append", default=None, metavar="KEY=VALUE",
                        help="override one scenario value in every flight (repeatable; dotted key, YAML value), "
                             "e.g. --set actuation.motor_time_constant=0.025: an ablation of the margin")
    parser.add_argument("--param", dest="parameters", action="append", default=None, metavar="EXECUTABLE.NAME=VALUE",
                        help="override one node parameter of every node of an executable in every flight "
                             "(repeatable; YAML value), e.g. --param controller.smwo_epsilon=0.2")
    parser.add_argument("--jobs", type=int, default=2, help="flights in parallel (default %(default)s)")
    parser.add_argument("--output-dir", default=None,
                        help="reports root of the flights (default: <$FPR_REPORTS or ./reports>/margin)")
    parser.add_argument("--results", default=None, help="default <repo>/docs/latency_margin.md")
    parser.add_argument("--report-only", action="store_true", help="fly nothing: rebuild from the metrics.json")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from fpr_experiments.catalog import load_experiment
    from fpr_experiments.cli import parameter_overrides, scenario_overrides
    from fpr_experiments.runner import default_output_root

    try:
        overrides = scenario_overrides(args.overrides)
        flight_overrides(0.0, overrides)  # refuses a --set of the latency itself
        parameters = parameter_overrides(args.parameters)
        seeds = [seed_label(s) for s in args.seeds]
        latencies = [check_latency(v) for v in args.latencies]
        if len(set(seeds)) != len(seeds) or len(set(latencies)) != len(latencies):
            raise ValueError("--seeds / --latencies: a value is given twice")
        names = args.experiment or list(DEFAULT_EXPERIMENTS)
        variants: dict[str, list[str]] = {}
        for name in names:
            known = [v.id for v in load_experiment(name).variants]
            chosen = [v for v in known if args.variant is None or v in args.variant]
            if not chosen:
                raise ValueError(f"{name}: none of the variants {args.variant} (it has {', '.join(known)})")
            variants[name] = chosen
        flights = [Flight(name, variant, seed, latency) for latency in latencies for seed in seeds
                   for name in names for variant in variants[name]]
        output_root = args.output_dir or os.path.join(default_output_root(), "margin")
        results = args.results or os.path.join(os.environ.get("FPR_ROOT") or os.getcwd(), "docs",
                                               "latency_margin.md")
        command = ("ros2 run fpr_experiments margin" + "".join(f" --experiment {n}" for n in names)
                   + "".join(f" --variant {v}" for v in args.variant or [])
                   + " --latencies " + " ".join(f"{v:g}" for v in latencies) + " --seeds " + " ".join(seeds)
                   + "".join(f" --set {o}" for o in args.overrides or [])
                   + "".join(f" --param {p}" for p in args.parameters or []))
        if not args.report_only:
            print(f"[margin] {len(flights)} flights, {args.jobs} at a time, into {output_root}", flush=True)
            fly_all(flights, output_root, args.jobs, overrides, parameters)
        outcomes = load_outcomes(output_root, flights)
        os.makedirs(os.path.dirname(os.path.abspath(results)), exist_ok=True)
        with open(results, "w", encoding="utf-8") as stream:
            stream.write(margin_markdown(outcomes, names, variants, latencies, seeds, command,
                                         [*(args.overrides or []), *(args.parameters or [])]))
        print(f"wrote {results}", flush=True)
        return 0
    except (ValueError, FileNotFoundError) as error:  # UnknownNameError is a ValueError
        print(f"error: {error}", file=sys.stderr, flush=True)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
