"""Benchmarks of fpr_estimation (issue 5): renderer, ArUco detection + PnP, EKF/MEKF predict and update.

Run: .venv/bin/python benchmarks/bench_estimation.py   (ROS-free; inserts the src/<pkg> paths itself)
Prints median and p95 per-call times. Targets: detection + PnP <= 3 ms per 640x480 frame, EKF predict <= 50 us,
EKF update <= 100 us, renderer <= 2 ms per image.
"""

import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for package in ("fpr_model", "fpr_sim", "fpr_estimation"):
    sys.path.insert(0, os.path.join(ROOT, "src", package))

import numpy as np  # noqa: E402
from fpr_estimation.aruco import ArucoPoseDetector  # noqa: E402
from fpr_estimation.ekf import RelativePoseEKF  # noqa: E402
from fpr_estimation.estimator import EstimatorConfig, PoseEstimatorCore  # noqa: E402
from fpr_estimation.mekf import RelativePoseMEKF  # noqa: E402
from fpr_estimation.synthetic import uav_pose_in_platform  # noqa: E402
from fpr_model.calibration import VisionCalibration, camera_T_marker_of  # noqa: E402
from fpr_model.parameters import default_parameters  # noqa: E402
from fpr_model.rotations import quat_from_rotvec  # noqa: E402
from fpr_sim.camera_renderer import MarkerRenderer  # noqa: E402


def timeit(function, repeats):
    samples = np.empty(repeats)
    for k in range(repeats):
        start = time.perf_counter()
        function(k)
        samples[k] = time.perf_counter() - start
    return samples


def report(name, samples, target=None):
    median, p95 = np.median(samples) * 1e6, np.percentile(samples, 95) * 1e6
    extra = f"  (target <= {target:g} us: {'ok' if median <= target else 'MISSED'}, median/target "\
            f"{median / target:.2f})" if target else ""
    print(f"{name:44s} median {median:9.1f} us   p95 {p95:9.1f} us{extra}")


def _pose_error(T_estimated, T_true) -> tuple[float, float]:
    """Translation [m] and rotation angle [rad] between two marker poses in the camera frame."""
    dR = T_estimated[:3, :3].T @ T_true[:3, :3]
    angle = float(np.arccos(np.clip(0.5 * (np.trace(dR) - 1.0), -1.0, 1.0)))
    return float(np.linalg.norm(T_estimated[:3, 3] - T_true[:3, 3])), angle


def aruco_threshold_lever(renderer, poses, calibration) -> None:
    """The AprilTag quad detector's aprilTagMinWhiteBlackDiff (ArucoConfig.april_tag_min_white_black_diff) on the
    simulator's noisy frames (pixel noise sigma 2, its default) and on clean ones: time per frame, detection rate,
    median pose errors, OpenCV's default 5 against the project's 30 (ratios printed)."""
    from fpr_estimation.aruco import ArucoConfig

    rng = np.random.default_rng(1)
    cases = {}
    for kind, noise in (("clean", 0.0), ("noisy sigma 2", 2.0)):
        rendered = [(renderer.render(p, noise_sigma=noise, rng=rng), p) for p in poses[:120]]
        cases[kind] = [(f.image, p) for f, p in rendered if f.in_view]
    for kind, frames in cases.items():
        medians = {}
        for threshold in (5, 30):
            detector = ArucoPoseDetector(ArucoConfig(april_tag_min_white_black_diff=threshold))
            times = timeit(lambda k, d=detector, fr=frames: d.detect(fr[k % len(fr)][0], calibration.camera),
                           len(frames))
            errors = []
            for image, pose in frames:
                observation = detector.detect(image, calibration.camera)
                if observation is not None:
                    errors.append(_pose_error(observation.camera_T_marker, pose))
            errors = np.array(errors).reshape(-1, 2)
            medians[threshold] = np.median(times)
            report(f"ArUco {kind}, min white-black diff {threshold}", times)
            print(f"{'':44s} detected {len(errors)}/{len(frames)}, median error "
                  f"{1000 * np.median(errors[:, 0]):.2f} mm / {np.degrees(np.median(errors[:, 1])):.3f} deg")
        print(f"{'':44s} {kind}: 30 vs 5 = x{medians[5] / medians[30]:.1f} faster")


def aruco_roi_lever(renderer, calibration) -> None:
    """The region of interest (ArucoConfig.roi_margin, fpr_estimation.aruco's module doc) against whole-frame
    search, on frame sequences as a camera sees them: 30 configurations, 8 frames each at 20 Hz while the platform
    rolls 0.2° per frame, the simulator's pixel noise σ 2. Time per frame, detections, median pose errors."""
    from fpr_estimation.aruco import ArucoConfig

    rng = np.random.default_rng(7)
    params = default_parameters()
    sequences = []
    for _ in range(30):
        legs = rng.uniform(np.radians(45), np.radians(75), 3)
        roll0, pitch = rng.uniform(-np.radians(8), np.radians(8), 2)
        uav = int(rng.integers(3))
        frames = []
        for k in range(8):
            pose = uav_pose_in_platform(params, legs, roll0 + np.radians(0.2 * k), pitch)[0][uav]
            truth = camera_T_marker_of(pose, calibration.body_T_camera, calibration.platform_T_marker)
            frame = renderer.render(truth, noise_sigma=2.0, rng=rng)
            if frame.in_view:
                frames.append((frame.image, truth))
        sequences.append(frames)
    medians = {}
    for margin in (0.0, 0.5):
        times, errors, count = [], [], 0
        for frames in sequences:
            detector = ArucoPoseDetector(ArucoConfig(roi_margin=margin))
            for image, truth in frames:
                count += 1
                start = time.perf_counter()
                observation = detector.detect(image, calibration.camera)
                times.append(time.perf_counter() - start)
                if observation is not None:
                    errors.append(_pose_error(observation.camera_T_marker, truth))
        errors = np.array(errors).reshape(-1, 2)
        medians[margin] = np.median(times)
        report(f"ArUco sequences, roi_margin {margin:g}", np.array(times))
        print(f"{'':44s} detected {len(errors)}/{count}, median error {1000 * np.median(errors[:, 0]):.2f} mm / "
              f"{np.degrees(np.median(errors[:, 1])):.3f} deg, mean {1e3 * np.mean(times):.2f} ms per frame")
    print(f"{'':44s} region of interest vs whole frame: x{medians[0.0] / medians[0.5]:.1f} faster (median)")


def main():
    calibration = VisionCalibration()
    rng = np.random.default_rng(0)
    params = default_parameters()
    poses = []
    for _ in range(100):
        legs = rng.uniform(np.radians(45), np.radians(75), 3)
        roll, pitch = rng.uniform(-np.radians(10), np.radians(10), 2)
        for pose in uav_pose_in_platform(params, legs, roll, pitch)[0]:
            poses.append(camera_T_marker_of(pose, calibration.body_T_camera, calibration.platform_T_marker))
    renderer = MarkerRenderer(calibration.camera)
    render_times = timeit(lambda k: renderer.render(poses[k % len(poses)]), 300)
    noisy_times = timeit(lambda k: renderer.render(poses[k % len(poses)], blur_sigma=0.8, noise_sigma=3.0, rng=rng),
                         300)
    frames = [renderer.render(p) for p in poses]
    frames = [f.image for f in frames if f.in_view]
    detector = ArucoPoseDetector()
    detect_times = timeit(lambda k: detector.detect(frames[k % len(frames)], calibration.camera), 300)
    empty = np.full((480, 640), 110, np.uint8)
    empty_times = timeit(lambda k: detector.detect(empty, calibration.camera), 100)

    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, opencv {__import__('cv2').__version__}, "
          f"{os.cpu_count()} cpus")
    report("renderer, 640x480 mono8", render_times, 2000)
    report("renderer + blur 0.8 px + noise 3", noisy_times)
    report("ArUco detect + IPPE PnP (marker in view)", detect_times, 3000)
    report("ArUco detect, no marker", empty_times)
    aruco_threshold_lever(renderer, poses, calibration)
    aruco_roi_lever(renderer, calibration)

    q0 = quat_from_rotvec([0.1, 0.2, -1.0])
    rate = np.array([0.1, -0.2, 0.3])
    position = np.array([0.5, -0.2, -0.9])
    for filt, name in ((RelativePoseEKF(), "EKF"), (RelativePoseMEKF(estimate_gyro_bias=False), "MEKF"),
                       (RelativePoseMEKF(estimate_gyro_bias=True), "MEKF + gyro bias")):
        filt.initialize(position, q0)
        report(f"{name} predict", timeit(lambda k, filt=filt: filt.predict(rate, 0.005), 5000), 50)

        def update(k, filt=filt):
            innovation, _, _ = filt.innovation(position, q0)
            filt.correct(innovation)

        report(f"{name} innovation + update", timeit(update, 5000), 100)
    core = PoseEstimatorCore(EstimatorConfig())
    pose = np.eye(4)
    pose[:3, 3] = position
    for k in range(core.config.reinit.consistent_detections):  # it initialises on K consistent detections
        core.on_relative_pose(0.01 * k, pose)
    assert core.filter.initialized, "the benchmark's core did not initialise"
    core.on_imu(0.04, np.array([1.0, 0, 0, 0]), rate)
    report("pipeline on_imu (predict + checks)", timeit(lambda k: core.on_imu(0.04 + 0.005 * (k + 1), np.array(
        [1.0, 0, 0, 0]), rate), 5000))
    report("pipeline on_relative_pose (gate + update)", timeit(lambda k: core.on_relative_pose(1.0, pose), 5000))
    report("pipeline output (50 Hz, with reconstruction)", timeit(lambda k: core.output(1.0), 5000))


if __name__ == "__main__":
    main()
