"""fpr_sim benchmark: cost of the hardware realism profile's physics effects (model mismatch, actuation, ground
effect, rotor drag; fpr_sim.plant_realism) on one plant step, ideal vs hardware, in one run, as a ratio, for the
compiled kernel (and the Python reference). The hover scenario keeps the ground enabled (ground effect evaluated).
Then the rendered cameras (fpr_sim.cameras.CameraRig.render, n = 3 640 × 480 frames from the hover state): the time
per frame, ideal vs hardware (occlusion, photometric changes, lighting gradient, blur, calibration error), with the
frame's last pass in the compiled kernel and in the numpy/OpenCV reference.

    bash scripts/isolated.sh python benchmarks/bench_realism.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for package in ("fpr_model", "fpr_sim", "fpr_px4_bridge"):
    sys.path.insert(0, str(ROOT / "src" / package))

import numpy as np  # noqa: E402
from fpr_sim._kernels import kernel_status  # noqa: E402
from fpr_sim.cameras import CameraRig  # noqa: E402
from fpr_sim.plant import Plant  # noqa: E402
from fpr_sim.quadrotor import AttitudeCommand  # noqa: E402
from fpr_sim.scenario import scenario_from_dict  # noqa: E402

KERNELS = ("compiled", "python") if kernel_status().available else ("python",)
SCENARIO = {"initial_state": {"mode": "hover", "leg_angles": 1.0, "position": [0.0, 0.0, 1.5]}}
PROFILES = ("ideal", "hardware")


def _plant(profile: str, kernel: str) -> Plant:
    plant = Plant(scenario_from_dict(SCENARIO, realism=profile), kernel=kernel)
    hover = plant.fleet.thrust() / plant.fleet.max_thrust()
    plant.set_command(AttitudeCommand(plant.fleet.quat, hover, np.ones(plant.n, dtype=bool)))
    return plant


def _step_time(profile: str, kernel: str, steps: int) -> float:
    """Seconds per plant step over ``steps`` steps from the hover start (a fresh plant)."""
    plant = _plant(profile, kernel)
    start = time.perf_counter()
    for _ in range(steps):
        plant.step()
    return (time.perf_counter() - start) / steps


def _frame_time(profile: str, kernel: str, renders: int) -> float:
    """Seconds per rendered frame of CameraRig.render (all n cameras) from the hover state."""
    scenario = scenario_from_dict(SCENARIO, realism=profile)
    plant = Plant(scenario)
    rig = CameraRig(scenario.cameras, plant.n, scenario.seed, kernel=kernel)
    truth = plant.ground_truth()
    start = time.perf_counter()
    for _ in range(renders):
        rig.render(truth)
    return (time.perf_counter() - start) / (renders * plant.n)


def main() -> None:
    for kernel in KERNELS:
        steps = 3000 if kernel == "compiled" else 600
        best = {profile: float("inf") for profile in PROFILES}
        for _ in range(5):  # interleaved rounds, best of 5 (the machine is shared)
            for profile in PROFILES:
                best[profile] = min(best[profile], _step_time(profile, kernel, steps))
        ratio = best["hardware"] / best["ideal"]
        print(f"plant step ({kernel}): ideal {best['ideal'] * 1e6:.1f} us, hardware {best['hardware'] * 1e6:.1f} us,"
              f" ratio hardware/ideal {ratio:.2f}")
    for kernel in KERNELS:
        best = {profile: float("inf") for profile in PROFILES}
        for _ in range(5):
            for profile in PROFILES:
                best[profile] = min(best[profile], _frame_time(profile, kernel, 100))
        print(f"camera frame (640 x 480, last pass {kernel}): ideal {best['ideal'] * 1e3:.3f} ms, hardware "
              f"{best['hardware'] * 1e3:.3f} ms, hardware - ideal {(best['hardware'] - best['ideal']) * 1e3:.3f} ms")


if __name__ == "__main__":
    main()
