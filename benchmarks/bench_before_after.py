"""Issue 15 re-measured before and after on one machine: main as it was when the issue was filed (74a841e, its
one-process harness) against today's default runner (benchmarks/bench_graph.py, lever 6), the same flights,
alternated run by run. Start it with ``bash benchmarks/before_after.sh`` (it checks the baseline out and sets it up
outside the network isolation, then runs this script inside it).

Why: the issue's real-time-factor goals are absolute, but its baseline figures ("measured on main": n = 3
emulated 0.72-0.99, images 0.16, n = 6 emulated 0.48) came from another machine, and this project's VMs differ by
up to x2.2 from one session to the next (docs/benchmarks.md). The developers' guide asks to re-measure an issue's
numbers before and after. So each case prints: the baseline here (runs and mean), today's code here, the speed-up
here, the speed-up the goal asked for (goal / the issue's baseline) and the goal scaled to this machine by the
baseline (goal x baseline here / the issue's baseline). The scaling is a bracket, not a conversion: the baseline
is a two-thread harness (simulator + executor thread), today's runner one thread, and the speed of a VM differs
between the two kinds of work (on 2026-12-07 the baseline ran x1.5 slower than the issue's figure with images,
where OpenCV's C++ detection dominates, and x2.4-4 slower with emulated poses, where Python and rclpy do).

    bash benchmarks/before_after.sh [--cases n3_emulated,n3_images,n6_emulated] [--seconds 12] [--repeats 2]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)

#: the commit of main issue 15's figures were measured on (the last before fpr_experiments, b539823)
BASELINE_COMMIT = "74a841e"
#: case -> (the issue's baseline real-time factor on its machine: lowest, highest; None: not given), its goal
ISSUE = {"n3_emulated": ((0.72, 0.99), 3.0), "n3_images": ((0.16, 0.16), 2.0),
         "n6_emulated": ((0.48, 0.48), 1.5), "n6_images": (None, 0.8)}
#: the environment of today's workspace that must not leak into the baseline's (its isolated.sh sources its own;
#: the ROS wheels' bootstrapper, once it has set LD_LIBRARY_PATH to its venv's libraries, marks the environment done)
WORKSPACE_VARIABLES = ("VIRTUAL_ENV", "PYTHONPATH", "AMENT_PREFIX_PATH", "COLCON_PREFIX_PATH", "CMAKE_PREFIX_PATH",
                       "LD_LIBRARY_PATH", "FPR_ROOT", "PYTHONHOME", "_ROS_WHEELS_BOOTSTRAP_COMPLETE")
_NOW_LINE = re.compile(r"RTF\s+([\d.]+)\s+probe\s+(\d+)/(\d+) us\s+CPU/sim-s\s+([\d.]+)")
_CLIMBED = re.compile(r"climbed\s+([-\d.na]+) m")


def baseline_environment(root: str = ROOT) -> dict[str, str]:
    """This process's environment without today's workspace (venv, install, PYTHONPATH, PATH entries under
    ``root``): the baseline checkout's scripts/isolated.sh sources its own. The isolation variables stay."""
    environment = {key: value for key, value in os.environ.items() if key not in WORKSPACE_VARIABLES}
    environment["PATH"] = os.pathsep.join(entry for entry in os.environ.get("PATH", "").split(os.pathsep)
                                          if entry and not entry.startswith(root + os.sep))
    return environment


def run_baseline(baseline_dir: str, case: str, seconds: float) -> dict:
    """One flight of the baseline checkout (benchmarks/baseline/swarm_graph_rtf.py, copied into its tests/)."""
    command = ["bash", os.path.join(baseline_dir, "scripts", "isolated.sh"), "python",
               os.path.join(baseline_dir, "tests", "fpr_baseline_rtf.py"), "--case", case, "--seconds", str(seconds),
               "--config-root", os.path.join(ROOT, "src", "fpr_experiments", "config")]
    done = subprocess.run(command, env=baseline_environment(), capture_output=True, text=True, check=False)
    for line in done.stdout.splitlines():
        if line.startswith("FPR_BASELINE "):
            return json.loads(line.split(" ", 1)[1])
    raise RuntimeError(f"baseline {case}: no result (exit {done.returncode}); last output:\n"
                       + "\n".join((done.stdout + done.stderr).splitlines()[-15:]))


def run_now(case: str, seconds: float) -> dict:
    """One flight of today's default runner (bench_graph.py lever 6, in a process of its own)."""
    command = [sys.executable, os.path.join(HERE, "bench_graph.py"), "--cases", case, "--levers", "6",
               "--seconds", str(seconds)]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    for line in done.stdout.splitlines():
        match = _NOW_LINE.search(line)
        if match and line.startswith(case):
            climbed = _CLIMBED.search(line)
            return {"rtf": float(match[1]), "probe_us": (float(match[2]) + float(match[3])) / 2.0,
                    "cpu_per_sim_s": float(match[4]), "height_gain": float(climbed[1]) if climbed else math.nan}
    raise RuntimeError(f"today's {case}: no result (exit {done.returncode}); last output:\n"
                       + "\n".join((done.stdout + done.stderr).splitlines()[-15:]))


def scaled_goal(case: str, baseline_here: float) -> tuple[float, float] | None:
    """The goal scaled to this machine by the baseline: goal x baseline here / the issue's baseline (a range when
    the issue gave one), or None when the issue gave no baseline for the case."""
    issue_baseline, goal = ISSUE[case]
    if issue_baseline is None:
        return None
    low, high = issue_baseline
    return goal * baseline_here / high, goal * baseline_here / low


def report(results: dict[str, dict[str, list[dict]]]) -> str:
    """The markdown table of docs/benchmarks.md's before/after section."""
    lines = ["| case | issue: baseline on its machine, goal | baseline here: runs (mean) | today here: runs (mean) "
             "| × here | × the goal asked | goal scaled to this machine | today ÷ scaled goal |",
             "|---|---|---|---|---|---|---|---|"]
    for case, runs in results.items():
        before = [r["rtf"] for r in runs["before"]]
        after = [r["rtf"] for r in runs["after"]]
        mean_before, mean_after = statistics.fmean(before), statistics.fmean(after)
        issue_baseline, goal = ISSUE[case]
        scaled = scaled_goal(case, mean_before)
        if issue_baseline is None:
            asked, issue_text, scaled_text, verdict = "–", f"not given, ≥ {goal}", "–", "–"
        else:
            low, high = issue_baseline
            asked = (f"×{goal / high:.1f}-{goal / low:.1f}" if low != high else f"×{goal / low:.1f}")
            issue_text = (f"{low}-{high}" if low != high else f"{low}") + f", ≥ {goal}"
            scaled_text = (f"{scaled[0]:.2f}-{scaled[1]:.2f}" if low != high else f"{scaled[0]:.2f}")
            verdict = (f"{mean_after / scaled[1]:.2f}-{mean_after / scaled[0]:.2f}" if low != high
                       else f"{mean_after / scaled[0]:.2f}")
        lines.append(f"| {case} | {issue_text} | {', '.join(f'{v:.3f}' for v in before)} ({mean_before:.3f}) | "
                     f"{', '.join(f'{v:.2f}' for v in after)} ({mean_after:.2f}) | ×{mean_after / mean_before:.1f} "
                     f"| {asked} | {scaled_text} | {verdict} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline-dir", required=True, help="the baseline checkout, set up (before_after.sh)")
    parser.add_argument("--cases", default="n3_emulated,n3_images,n6_emulated",
                        help="comma-separated: " + ", ".join(ISSUE))
    parser.add_argument("--seconds", type=float, default=12.0, help="simulated seconds per flight")
    parser.add_argument("--repeats", type=int, default=2, help="flights per case and side, alternated")
    args = parser.parse_args()
    cases = [case for case in args.cases.split(",") if case]
    unknown = [case for case in cases if case not in ISSUE]
    if unknown:
        parser.error(f"unknown case(s) {unknown}; choose from {list(ISSUE)}")
    if not (math.isfinite(args.seconds) and 1.0 <= args.seconds <= 600.0) or not 1 <= args.repeats <= 20:
        parser.error("--seconds: 1-600 simulated seconds; --repeats: 1-20 flights per case and side")
    if os.environ.get("FPR_IN_NETNS") != "1":
        parser.error("run it through the network isolation: bash benchmarks/before_after.sh")
    checked_out = subprocess.run(["git", "-C", args.baseline_dir, "rev-parse", "HEAD"], capture_output=True,
                                 text=True, check=False).stdout.strip()
    if not checked_out.startswith(BASELINE_COMMIT):
        parser.error(f"{args.baseline_dir} holds {checked_out or 'no git checkout'}, not {BASELINE_COMMIT}, the "
                     f"commit the issue's figures belong to (bash benchmarks/before_after.sh sets it up)")
    from bench_graph import reference_step_us

    print(f"# before: main at {BASELINE_COMMIT} ({args.baseline_dir}); after: this checkout's default runner; "
          f"{args.seconds:g} s simulated per flight, {args.repeats} alternated flights per case and side; "
          f"load average {os.getloadavg()[0]:.2f} at the start", flush=True)
    results: dict[str, dict[str, list[dict]]] = {case: {"before": [], "after": []} for case in cases}
    for repeat in range(args.repeats):
        for case in cases:
            probe = reference_step_us()
            before = run_baseline(args.baseline_dir, case, args.seconds)
            before["probe_us"] = (probe + reference_step_us()) / 2.0
            results[case]["before"].append(before)
            print(f"{case:12s} before  RTF {before['rtf']:5.3f}  CPU/sim-s {before['cpu_per_sim_s']:5.2f}  "
                  f"probe {before['probe_us']:3.0f} us  climbed {before['height_gain']:4.2f} m  "
                  f"timeouts {before['timeouts']}  callback errors {before['errors']}  "
                  f"(flight {repeat + 1}/{args.repeats})", flush=True)
            after = run_now(case, args.seconds)
            results[case]["after"].append(after)
            print(f"{case:12s} after   RTF {after['rtf']:5.2f}  CPU/sim-s {after['cpu_per_sim_s']:5.2f}  "
                  f"probe {after['probe_us']:3.0f} us  climbed {after['height_gain']:4.2f} m", flush=True)
    print(f"# load average {os.getloadavg()[0]:.2f} at the end\n")
    print(report(results))


if __name__ == "__main__":
    main()
