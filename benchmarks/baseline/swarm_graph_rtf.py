"""Issue 15's baseline flight, run inside a checkout of main as it was when the issue was filed (74a841e): its
one-process harness ``tests/swarm_graph.py`` (every node in one SingleThreadedExecutor in a background thread, the
simulator stepped in the caller's thread with its 0.5 s lockstep timeout), the flights of the issue's figures
(n = 3: ``ground_start`` + ``integration_flight``; n = 6: the n6_unequal scenario, model and ``steps_roll_legs``
of today's fpr_experiments, as benchmarks/bench_graph.py flies them). Copied there by benchmarks/before_after.sh
and run through that checkout's scripts/isolated.sh; prints one ``FPR_BASELINE {json}`` line.

    python tests/fpr_baseline_rtf.py --case n3_emulated --seconds 12 --config-root <fpr_experiments/config>
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from swarm_graph import SwarmGraph, SwarmOptions  # noqa: E402  (the baseline checkout's harness)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", required=True, choices=("n3_emulated", "n3_images", "n6_emulated", "n6_images"))
    parser.add_argument("--seconds", type=float, default=12.0)
    parser.add_argument("--config-root", required=True, help="today's src/fpr_experiments/config (n = 6 files)")
    args = parser.parse_args()
    n6 = args.case.startswith("n6")
    overrides: dict = {}
    script = os.path.join(os.path.dirname(HERE), "src", "fpr_control", "config", "joy_scripts",
                          "integration_flight.yaml")
    scenario = "ground_start.yaml"
    if n6:
        overrides = {kind: {"n": 6} for kind in ("controller", "pose_estimator", "teleop")}
        overrides["controller"]["model_file"] = os.path.join(args.config_root, "models", "fpr_n6_unequal.yaml")
        script = os.path.join(args.config_root, "joy_scripts", "steps_roll_legs.yaml")
        scenario = os.path.join(args.config_root, "scenarios", "n6_unequal.yaml")
    options = SwarmOptions(scenario=scenario, joy_script=script, emulated_cameras=args.case.endswith("emulated"),
                           real_time_factor=0.0, overrides=overrides)
    with SwarmGraph(options) as swarm:
        swarm.wait_for_discovery()
        wall, cpu, start = time.monotonic(), time.process_time(), swarm.sim_time
        swarm.run_until(lambda: swarm.sim_time >= args.seconds - 1e-9, wall_timeout=60.0 + 120.0 * args.seconds)
        wall, cpu = time.monotonic() - wall, time.process_time() - cpu
        simulated = swarm.sim_time - start
        swarm.wait_for_recorder()
        heights = swarm.recorder.truth_arrays()["position"][:, 2]
        print("FPR_BASELINE " + json.dumps({
            "case": args.case, "simulated": simulated, "wall": wall, "cpu": cpu, "rtf": simulated / wall,
            "cpu_per_sim_s": cpu / simulated, "timeouts": swarm.lockstep_timeouts, "errors": len(swarm.errors),
            "height_gain": float(heights.max() - heights[0]) if len(heights) else float("nan")}), flush=True)


if __name__ == "__main__":
    main()
