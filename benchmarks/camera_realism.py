"""Camera realism (issue 11, sensors): detection rate and raw ArUco accuracy over a rendered hover, ideal vs
hardware, beside the thesis's Tables 4.6 / 4.8; and the render + detect time per frame, ideal vs hardware.

    bash scripts/isolated.sh python benchmarks/camera_realism.py [accuracy|timing|regions|all] [--seconds 10]

Accuracy: a synthetic hover of the bundled ``hover`` scenario's robot (:func:`hover_truths`: leg angles 45° ± 3°,
platform roll / pitch ± 2°, ± 2 cm, each UAV's attitude ± 2° about its hover attitude, sinusoids of 0.4-1.7 Hz with
their exact rates, so motion blur sees a flight-like relative motion; the plant's kinematics give the UAV poses:
without controllers the simulated robot would not hover), every camera frame rendered through each UAV's true
camera and detected by fpr_estimation's ArucoPoseDetector with the NOMINAL calibration (as the aruco_detector +
pose_estimator do); the relative pose ``p_T_b = p_T_M (C_T_M)⁻¹ (b_T_C)⁻¹`` (4.2) against the truth at the
frame's stamp. Error per axis: position [m] in F_p, rotation [deg] as the rotation vector of R_trueᵀ R_est
(≈ roll, pitch, yaw for small errors). A successful detection (Table 4.8): position error < 10 cm and rotation
error < 10°. The emulated detections are measured likewise.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np
from fpr_estimation.aruco import ArucoPoseDetector
from fpr_model.calibration import invert_transform
from fpr_model.rotations import euler_zyx_to_quat, quat_from_rotvec, quat_multiply, quat_to_rotvec, rotmat_to_quat
from fpr_sim.cameras import CameraRig, platform_T_bodies
from fpr_sim.plant import GroundTruth, Plant
from fpr_sim.scenario import load_scenario
from fpr_sim.structure import StructureState

#: Table 4.6 ArUco rows (RMSE x, y, z [m], roll, pitch, yaw [deg]) and Table 4.8 Scenario I / II [%]
THESIS_ARUCO = {1: (0.036, 0.023, 0.038, 2.078, 2.968, 3.728), 2: (0.037, 0.041, 0.044, 2.627, 1.822, 1.942),
                3: (0.037, 0.051, 0.040, 3.644, 2.691, 1.678)}
THESIS_RATE = {1: (93.1, 95.3), 2: (88.3, 89.4), 3: (88.7, 91.2)}


def _errors(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """[dx, dy, dz] (m, F_p) and the rotation vector of R_trueᵀ R_est (deg)."""
    rotvec = quat_to_rotvec(rotmat_to_quat(truth[:3, :3].T @ estimate[:3, :3]))
    return np.concatenate([estimate[:3, 3] - truth[:3, 3], np.degrees(rotvec)])


def hover_truths(seconds: float, rate: float = 20.0) -> list[GroundTruth]:
    """Ground truths of the synthetic hover (module doc) at ``rate`` [Hz] for ``seconds``."""
    plant = Plant(load_scenario("hover"))
    n, base_quats = plant.scenario.n, plant.fleet.quat.copy()
    out = []
    for k in range(int(round(seconds * rate))):
        t = k / rate
        w = 2.0 * np.pi * np.array([0.5, 0.7, 0.4, 1.3, 1.7])
        a = np.radians(2.0)
        roll, pitch = a * np.sin(w[1] * t), a * np.sin(w[1] * t + 1.0)
        legs = np.radians(45.0) + np.radians(3.0) * np.sin(w[0] * t + np.arange(n))
        state = StructureState(
            position=np.array([0.02 * np.sin(w[2] * t), 0.02 * np.cos(w[2] * t), 1.5]),
            quat=euler_zyx_to_quat(roll, pitch, 0.0), leg_angles=legs,
            velocity=np.array([0.02 * w[2] * np.cos(w[2] * t), -0.02 * w[2] * np.sin(w[2] * t), 0.0]),
            rate=np.array([a * w[1] * np.cos(w[1] * t), a * w[1] * np.cos(w[1] * t + 1.0), 0.0]),
            leg_rates=np.radians(3.0) * w[0] * np.cos(w[0] * t + np.arange(n)))
        plant.set_state(state)
        phases = np.arange(n)[:, None] + np.arange(3)[None, :]
        wiggle = a * np.sin(w[3] * t + phases)
        plant.fleet.quat = np.array([quat_multiply(base_quats[i], quat_from_rotvec(wiggle[i])) for i in range(n)])
        plant.fleet.rate = a * w[3] * np.cos(w[3] * t + phases)
        out.append(replace(plant.ground_truth(), time=t))
    return out


def measure(realism: str, seconds: float, emulated: bool = False) -> dict[int, dict]:
    """Per UAV: frames, successful detections, RMSE per axis over the successful ones."""
    scenario = load_scenario("hover", realism=realism)
    rig = CameraRig(scenario.cameras, scenario.n, scenario.seed)
    detectors = [ArucoPoseDetector() for _ in range(scenario.n)]
    calibration = rig.calibration
    nominal_inverse = invert_transform(calibration.body_T_camera)
    results = {i: {"frames": 0, "ok": 0, "errors": []} for i in range(scenario.n)}
    for truth in hover_truths(seconds, scenario.cameras.rate):
        true_poses = platform_T_bodies(truth)
        if emulated:
            estimates = [None if d is None else d.platform_T_body for d in rig.emulate(truth)]
        else:
            estimates = []
            for i, frame in enumerate(rig.render(truth)):
                observation = detectors[i].detect(frame.image, calibration.camera)
                estimates.append(None if observation is None else calibration.platform_T_marker
                                 @ invert_transform(observation.camera_T_marker) @ nominal_inverse)
        for i, (estimate, T) in enumerate(zip(estimates, true_poses, strict=True)):
            results[i]["frames"] += 1
            if estimate is None:
                continue
            error = _errors(estimate, T)
            if np.linalg.norm(error[:3]) < 0.10 and np.linalg.norm(error[3:]) < 10.0:
                results[i]["ok"] += 1
                results[i]["errors"].append(error)
    return results


def report_accuracy(seconds: float) -> None:
    print(f"rendered hover ({seconds:g} s, 20 Hz): detection rate [%] and raw ArUco RMSE x y z [cm], "
          "roll pitch yaw [deg]")
    for label, realism, emulated in (("ideal", "ideal", False), ("hardware", "hardware", False),
                                     ("emulated ideal", "ideal", True), ("emulated hardware", "hardware", True)):
        for i, r in measure(realism, seconds, emulated).items():
            rate = 100.0 * r["ok"] / max(r["frames"], 1)
            errors = np.array(r["errors"]) if r["errors"] else np.full((1, 6), np.nan)
            rmse = np.sqrt(np.mean(errors ** 2, axis=0))
            print(f"  {label:18s} uav{i + 1}: rate {rate:5.1f}  RMSE {100 * rmse[0]:4.1f} {100 * rmse[1]:4.1f} "
                  f"{100 * rmse[2]:4.1f} cm  {rmse[3]:4.2f} {rmse[4]:4.2f} {rmse[5]:4.2f} deg")
    for uav, values in THESIS_ARUCO.items():
        print(f"  {'thesis':18s} uav{uav}: rate {THESIS_RATE[uav][0]:5.1f}/{THESIS_RATE[uav][1]:4.1f}  RMSE "
              f"{100 * values[0]:4.1f} {100 * values[1]:4.1f} {100 * values[2]:4.1f} cm  {values[3]:4.2f} "
              f"{values[4]:4.2f} {values[5]:4.2f} deg")


def report_timing(frames: int = 100) -> None:
    """Render, then detect, per frame (3 UAVs), ideal vs hardware, over the same hover states."""
    truths = hover_truths(frames / 20.0)
    render, detect = {}, {}
    for realism in ("ideal", "hardware"):
        scenario = load_scenario("hover", realism=realism)
        rig = CameraRig(scenario.cameras, scenario.n, scenario.seed)
        # one detector per camera, as on the robot (each keeps its own region of interest)
        detectors = [ArucoPoseDetector() for _ in range(scenario.n)]
        rig.render(truths[0])
        start = time.perf_counter()
        images = [frame.image for truth in truths for frame in rig.render(truth)]
        render[realism] = (time.perf_counter() - start) / len(images)
        start = time.perf_counter()
        for k, image in enumerate(images):
            detectors[k % scenario.n].detect(image, rig.calibration.camera)
        detect[realism] = (time.perf_counter() - start) / len(images)
    for name, times in (("render", render), ("detect", detect)):
        print(f"{name} per frame: ideal {1e3 * times['ideal']:.2f} ms, hardware {1e3 * times['hardware']:.2f} ms, "
              f"ratio hardware/ideal {times['hardware'] / times['ideal']:.2f}")


def report_region_misses(seconds: float) -> None:
    """Per profile: what the whole-frame search after a region-of-interest miss finds (fpr_estimation.aruco's
    fallback), over the rendered hover, one detector per camera."""
    for realism in ("ideal", "hardware"):
        scenario = load_scenario("hover", realism=realism)
        rig = CameraRig(scenario.cameras, scenario.n, scenario.seed)
        detectors = [ArucoPoseDetector() for _ in range(scenario.n)]
        hits = rescued = lost = whole = 0
        whole_time = 0.0
        for truth in hover_truths(seconds, scenario.cameras.rate):
            for i, frame in enumerate(rig.render(truth)):
                detector, image = detectors[i], frame.image
                region = detector.roi
                found_in_region = False
                if region is not None:
                    x0, y0, x1, y1 = region
                    found_in_region = detector._find(image[y0:y1, x0:x1]) is not None
                    hits += found_in_region
                if not found_in_region:  # what detect() does next: the whole frame
                    start = time.perf_counter()
                    found = detector._find(image) is not None
                    whole_time += time.perf_counter() - start
                    whole += 1
                    if region is not None:
                        rescued += found
                        lost += not found
                detector.detect(image, rig.calibration.camera)  # the detector's own state (region, hold)
        print(f"{realism}: region hits {hits}; after a region miss the whole frame found the marker {rescued} times, "
              f"nothing {lost} times; whole-frame searches {whole} at {1e3 * whole_time / max(whole, 1):.2f} ms mean")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", nargs="?", default="all", choices=("accuracy", "timing", "regions", "all"))
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    if args.what in ("accuracy", "all"):
        report_accuracy(args.seconds)
    if args.what in ("timing", "all"):
        report_timing()
    if args.what in ("regions", "all"):
        report_region_misses(args.seconds)


if __name__ == "__main__":
    main()
