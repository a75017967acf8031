"""Per-call timings of the fpr_model algorithms (plain script, no ROS).

Usage: ``.venv/bin/python benchmarks/bench_model.py [--repeat 5] [--number 2000]``

Times M (CRBA), C (Coriolis matrix), g (gravity), J (Jacobian), RNEA (inverse dynamics), forward dynamics
and one RK4 step for n = 3, 6 and 12 legs (Table B.1 parameters, random state with legs in (10°, 80°)),
best of ``--repeat`` runs of ``--number`` calls each. Prints per-call microseconds, the M+C+g+J total against
the 150 µs target for n = 3, and the growth ratios relative to n = 3. Tests never assert on wall time.

The default timer is the process CPU time (``time.process_time``): on a shared machine it is far less noisy
than wall time for single-threaded numpy code; ``--wall`` uses ``time.perf_counter`` instead.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import timeit

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir, "src", "fpr_model"))

from fpr_model.dynamics import (  # noqa: E402
    coriolis_matrix,
    forward_dynamics,
    gravity,
    inverse_dynamics,
    mass_matrix,
    rk4_step,
)
from fpr_model.geometry import make_configuration  # noqa: E402
from fpr_model.kinematics import jacobian  # noqa: E402
from fpr_model.parameters import default_parameters  # noqa: E402

TARGET_US = 150.0  # M + C + g + J for n = 3
LEG_COUNTS = (3, 6, 12)


def time_call(function, number: int, repeat: int, timer=time.process_time) -> float:
    """Best per-call time in microseconds."""
    return min(timeit.repeat(function, number=number, repeat=repeat, timer=timer)) / number * 1e6


def measure(n: int, number: int, repeat: int, timer=time.process_time) -> dict[str, float]:
    params = default_parameters(n)
    rng = np.random.default_rng(0)
    angles = rng.uniform(np.radians(10), np.radians(80), n)
    q = make_configuration(rng.normal(size=3), rng.normal(size=4), angles)
    nu = rng.normal(size=6 + n)
    nu_dot = rng.normal(size=6 + n)
    tau = rng.normal(size=6 + n)
    calls = {
        "mass_matrix": lambda: mass_matrix(params, q),
        "coriolis_matrix": lambda: coriolis_matrix(params, q, nu),
        "gravity": lambda: gravity(params, q),
        "jacobian": lambda: jacobian(params, q),
        "inverse_dynamics (RNEA)": lambda: inverse_dynamics(params, q, nu, nu_dot),
        "forward_dynamics": lambda: forward_dynamics(params, q, nu, tau),
        "rk4_step": lambda: rk4_step(params, q, nu, tau, 1e-3),
    }
    for call in calls.values():  # warm the per-parameter cache
        call()
    results = {name: time_call(call, number if name != "rk4_step" else max(number // 4, 1), repeat, timer)
               for name, call in calls.items()}
    four = ("mass_matrix", "coriolis_matrix", "gravity", "jacobian")
    results["M + C + g + J"] = sum(results[k] for k in four)
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--number", type=int, default=2000)
    parser.add_argument("--wall", action="store_true", help="wall-clock timer instead of process CPU time")
    args = parser.parse_args(argv)
    timer = time.perf_counter if args.wall else time.process_time
    table = {n: measure(n, args.number, args.repeat, timer) for n in LEG_COUNTS}
    names = list(table[LEG_COUNTS[0]])
    print(f"fpr_model per-call {'wall' if args.wall else 'CPU'} times [µs], best of {args.repeat} "
          f"(python {platform.python_version()}, numpy {np.__version__}, {platform.machine()})")
    header = f"{'function':<26}" + "".join(f"{'n=' + str(n):>10}" for n in LEG_COUNTS)
    header += "".join(f"{'x n=' + str(n):>10}" for n in LEG_COUNTS[1:])
    print(header)
    for name in names:
        row = f"{name:<26}" + "".join(f"{table[n][name]:>10.1f}" for n in LEG_COUNTS)
        row += "".join(f"{table[n][name] / table[LEG_COUNTS[0]][name]:>10.2f}" for n in LEG_COUNTS[1:])
        print(row)
    total = table[3]["M + C + g + J"]
    print(f"M + C + g + J, n = 3: {total:.1f} µs "
          f"(target <= {TARGET_US:.0f} µs, ratio {total / TARGET_US:.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
