"""Benchmark of fpr_model.feasibility (thesis Ch. 5): per-call times and ratios to the spec targets.

Run: .venv/bin/python benchmarks/bench_feasibility.py   (no ROS needed)
Targets (spec §4.3 F10 and issue 7): one margin evaluation <= 1 ms, one optimal search <= 200 ms,
the 19×19×89 orientation grid < 60 s.
"""

from __future__ import annotations

import math
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src", "fpr_model"))

import numpy as np  # noqa: E402
from fpr_model.parameters import default_parameters  # noqa: E402

from fpr_model import feasibility as fz  # noqa: E402


def per_call(fn, repeats: int) -> float:
    """Best-of-5 mean time per call [s]."""
    best = math.inf
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(repeats):
            fn()
        best = min(best, (time.perf_counter() - start) / repeats)
    return best


def main() -> None:
    params = default_parameters()
    start = time.perf_counter()
    fz.available_thrust_set.cache_clear()
    ats = fz.available_thrust_set()
    ats_time = time.perf_counter() - start
    flat = fz.platform_orientation_quat(0.0, 0.0)
    inclined = fz.platform_orientation_quat(math.radians(10), math.radians(25))
    rows = []
    rows.append(("ATS build (17 vertices, qhull, uncached)", ats_time, None))
    rows.append(("margin evaluation, 1 config (feasibility_margins)",
                 per_call(lambda: fz.feasibility_margins(params, ats, inclined, math.radians(45)), 300), 1e-3))
    curve_time = per_call(lambda: fz.margin_curve(params, ats, inclined), 20)
    rows.append(("margin curve, 89 leg angles (margin_curve)", curve_time, None))
    rows.append(("  = per leg angle inside the sweep", curve_time / 89, 1e-3))
    rows.append(("optimal search, flat (optimal_leg_angles)",
                 per_call(lambda: fz.optimal_leg_angles(params, ats, flat), 20), 0.2))
    rows.append(("optimal search, inclined", per_call(lambda: fz.optimal_leg_angles(params, ats, inclined), 20), 0.2))
    rows.append(("feasible_leg_angle_range, cache miss (new 1° cell)", _miss_time(params), 0.02))
    rows.append(("feasible_leg_angle_range, cache hit",
                 per_call(lambda: fz.feasible_leg_angle_range(params, 0.1, 0.2, 5.0, 4.0), 2000), 0.02))
    q = fz.equal_leg_configuration(params, inclined, math.radians(45))
    from fpr_model.kinematics import jacobian

    W = jacobian(params, q).T
    rows.append(("decomposed AWS F_p, M_p, M_l (3 hulls of 4913 points)",
                 per_call(lambda: fz.decomposed_wrench_sets(ats, W), 3), None))
    start = time.perf_counter()
    angles = np.radians(np.arange(0.0, 90.0 + 1e-9, 5.0))
    fz.orientation_grid(params, ats, angles, angles)
    rows.append(("orientation grid 19×19 × 89 leg angles", time.perf_counter() - start, 60.0))

    print(f"{'benchmark':<58} {'time':>12} {'target':>10} {'ratio':>7}")
    for name, seconds, target in rows:
        shown = f"{seconds * 1e3:9.3f} ms" if seconds < 1 else f"{seconds:9.3f} s "
        if target is None:
            print(f"{name:<58} {shown:>12}")
        else:
            tshown = f"{target * 1e3:g} ms" if target < 1 else f"{target:g} s"
            print(f"{name:<58} {shown:>12} {tshown:>10} {seconds / target:7.3f}")


def _miss_time(params) -> float:
    """Mean time of calls that each land in a new orientation cell (cache misses)."""
    fz.clear_leg_angle_range_cache()
    rolls = np.radians(np.arange(0.0, 40.0, 1.0))
    start = time.perf_counter()
    for roll in rolls:
        fz.feasible_leg_angle_range(params, roll, 0.2, 5.0, 4.0)
    return (time.perf_counter() - start) / rolls.size


if __name__ == "__main__":
    main()
