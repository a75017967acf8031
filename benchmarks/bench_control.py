"""Benchmarks of fpr_control (issue 6): one controller step (state reconstruction + model terms + observer + law
+ thrust distribution + setpoint), per mode, for n = 3 and n = 6; plus the parts.

Run: .venv/bin/python benchmarks/bench_control.py   (ROS-free; inserts the src/<pkg> paths itself)
Prints median and p95 per-call times. Targets for n = 3: <= 1 ms per step (issue 6: headroom for 50 Hz on a
Raspberry Pi 4), <= 0.35 ms median in every mode (issue "Speed and determinism", hot paths).
"""

import math
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for package in ("fpr_model", "fpr_control"):
    sys.path.insert(0, os.path.join(ROOT, "src", package))

import numpy as np  # noqa: E402
from fpr_control.controller import Controller, ControllerConfig, GroundTruth, gains_from_dict  # noqa: E402
from fpr_control.information import LocalEstimate, PeerInfo  # noqa: E402
from fpr_control.laws import compute_model_terms  # noqa: E402
from fpr_control.observers import ObserverGains, make_observer  # noqa: E402
from fpr_control.reference import TeleopReference  # noqa: E402
from fpr_model.dynamics import thrusts_from_wrench  # noqa: E402
from fpr_model.kinematics import forward_kinematics, jacobian_at, uav_velocities  # noqa: E402
from fpr_model.parameters import default_parameters  # noqa: E402
from fpr_model.rotations import euler_zyx_to_quat  # noqa: E402


def timeit(function, repeats):
    samples = np.empty(repeats)
    for k in range(repeats):
        start = time.perf_counter()
        function()
        samples[k] = time.perf_counter() - start
    return np.median(samples), np.percentile(samples, 95)


def report(name, stats, reference=None):
    median, p95 = stats
    ratio = f"  ({median / reference:5.2f}x n=3)" if reference else ""
    print(f"{name:52s} median {median * 1e6:8.1f} us   p95 {p95 * 1e6:8.1f} us{ratio}")
    return median


def setup(n, mode, observer="fowo", state_source="local"):
    params = default_parameters(n)
    rng = np.random.default_rng(1)
    quat = euler_zyx_to_quat(0.05, -0.03, 0.0)
    q = np.concatenate([np.zeros(3), quat, np.full(n, math.radians(45.0)) + rng.normal(0, 0.02, n)])
    nu = forward_kinematics(params, q, rng.normal(0, 0.05, (n, 3)))
    velocities = uav_velocities(params, q, nu)
    controller = Controller(params, ControllerConfig(uav_id=1, mode=mode, gains=gains_from_dict({}, n),
                                                     observer=observer, state_source=state_source))
    now = [0.0]
    for j in range(1, n + 1):
        controller.receive_info(PeerInfo(j, float(q[6 + j]), velocities[j - 1], np.array([1.0, 0, 0, 0]), 11.0), 0.0)
    local = LocalEstimate(float(q[7]), 0.05, -0.03, np.array([1.0, 0, 0, 0]), velocities[0], 0.0, 0.3)
    cmd = TeleopReference.hold(0.05, -0.03, np.full(n, math.radians(45.0)))
    cmd.mode = 2
    gt = GroundTruth(np.array([0, 0, 1.0]), quat, nu[:3], nu[3:6], q[7:], nu[6:], np.tile([1.0, 0, 0, 0], (n, 1)))

    def step():
        now[0] += 0.02
        for j in range(1, n + 1):  # keep the peers fresh (ζ handling is part of a control period)
            controller.receive_info(PeerInfo(j, float(q[6 + j]), velocities[j - 1], np.array([1.0, 0, 0, 0]), 11.0),
                                    now[0])
        out = controller.step(now[0], local, cmd, gt)
        assert out.state_ok and out.active_mode == mode, (out.warning, out.active_mode)

    return params, q, nu, step


def bench_parts(n, repeats, reference):
    params, q, nu, _ = setup(n, "communicating")
    v = np.ones((n, 3))
    observer = make_observer("fowo", ObserverGains(), n)
    P, beta = np.ones(6 + n), np.ones(6 + n)
    parts = (
        ("  part: model terms M, C, g, J", lambda: compute_model_terms(params, q, nu)),
        ("  part: J and J^+ once per step (jacobian_at)", lambda: jacobian_at(params, q).inverse),
        ("  part: thrusts_from_wrench (fpr_model)", lambda: thrusts_from_wrench(params, q, np.ones(6 + n))),
        ("  part: FKM forward_kinematics (fpr_model)", lambda: forward_kinematics(params, q, v)),
        ("  part: FOWO update", lambda: observer.update(P, beta, 0.02)),
    )
    for name, function in parts:
        median = report(name, timeit(function, repeats), reference.get(name))
        reference.setdefault(name, median)


def main():
    repeats = 2000
    print(f"fpr_control benchmark, {repeats} calls each (numpy {np.__version__})")
    reference = {}
    for n in (3, 6):
        print(f"--- n = {n}")
        for mode, observer, source in (("communicating", "fowo", "local"), ("non_communicating", "fowo", "local"),
                                       ("impedance", "fowo", "local"), ("impedance", "smwo", "local"),
                                       ("centralized", "fowo", "ground_truth"),
                                       ("impedance", "fowo", "ground_truth")):
            params, q, nu, step = setup(n, mode, observer, source)
            step()
            name = f"controller step {mode}/{observer}/{source}"
            median = report(name, timeit(step, repeats), reference.get(name))
            reference.setdefault(name, median)
        bench_parts(n, repeats, reference)


if __name__ == "__main__":
    main()
