"""Sensor realism (issue 11): each effect changes what it should and nothing else, seeded, the ideal unchanged."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from fpr_model.calibration import invert_transform
from fpr_model.rotations import quat_from_rotvec, quat_multiply
from fpr_sim.camera_renderer import MarkerRenderer
from fpr_sim.cameras import CameraRig, platform_T_bodies
from fpr_sim.plant import Plant
from fpr_sim.scenario import CameraConfig, MotionCaptureConfig, scenario_from_dict
from fpr_sim.sensors import DelayLine, MotionCapture, UavSensors

HOVER = {"initial_state": {"mode": "hover", "leg_angles": 0.8}, "ground": {"enabled": False}}


@pytest.fixture(scope="module")
def truth():
    return Plant(scenario_from_dict(HOVER)).ground_truth()


def _moving(truth):
    """The hover truth with relative motion: UAV body rates and velocities, a platform rate."""
    state = replace(truth.state, rate=np.array([0.3, -0.2, 0.1]), velocity=np.array([0.2, 0.0, 0.1]))
    return replace(truth, state=state, uav_rates=np.tile([1.0, -0.8, 0.5], (3, 1)),
                   uav_velocities=np.tile([-0.3, 0.2, 0.0], (3, 1)))


# ---- IMU ----------------------------------------------------------------------------------------------
def _imu(sensors_overrides: dict | None = None, seed: int = 3) -> UavSensors:
    scenario = scenario_from_dict({**HOVER, "seed": seed, "sensors": sensors_overrides or {}})
    return UavSensors(scenario, np.zeros((3, 3)))


def _samples(sensors: UavSensors, count: int = 200, dt: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    q = np.array([1.0, 0.0, 0.0, 0.0])
    rates, forces = [], []
    for k in range(count):
        s = sensors.sample(0, q, np.zeros(3), np.array([0.0, 0.0, 9.81]), np.zeros(3), np.zeros(3), t=k * dt)
        rates.append(s.rate)
        forces.append(s.specific_force)
    return np.array(rates), np.array(forces)


def test_ideal_imu_is_the_historical_model():
    """White noise and a constant gyro bias drawn from SeedSequence(seed).spawn(n), in the same order as before."""
    sensors = _imu()
    rng = np.random.default_rng(np.random.SeedSequence(3).spawn(3)[0])
    c = sensors.config
    bias = rng.normal(0.0, c.gyro_bias, 3)
    rates, forces = _samples(sensors, count=5)
    for k in range(5):
        rng.normal(0.0, c.attitude_noise, 3)
        assert rates[k] == pytest.approx(bias + rng.normal(0.0, c.gyro_noise, 3), abs=0.0)
        assert forces[k] == pytest.approx(np.array([0.0, 0.0, 9.81]) + rng.normal(0.0, c.accel_noise, 3), abs=0.0)
        rng.normal(0.0, c.position_noise, 3)
        rng.normal(0.0, c.velocity_noise, 3)


def test_accel_bias_shifts_only_the_accelerometer_by_a_constant():
    ideal_rates, ideal_forces = _samples(_imu())
    rates, forces = _samples(_imu({"accel_bias": 0.1}))
    assert np.array_equal(rates, ideal_rates)
    offset = forces - ideal_forces
    assert np.allclose(offset, offset[0], atol=1e-12) and 0.0 < np.abs(offset[0]).max() < 0.5


def test_tilt_from_accel_bias_is_the_accelerometer_s_view_of_the_vertical():
    """sensors.tilt_from_accel_bias: PX4's attitude estimate q̂ = q ∘ exp(δ), δ = share · (b_y, −b_x, 0) / g; the
    reported attitude carries it; off (0), nothing changes."""
    assert _imu({"accel_bias": 0.1}).attitude_estimate_error(0) is None
    sensors = _imu({"accel_bias": 0.1, "tilt_from_accel_bias": 0.5, "attitude_noise": 0.0})
    for i in range(3):
        bx, by, _ = sensors.accel_bias[i]
        assert sensors.attitude_estimate_error(i) == pytest.approx(0.5 * np.array([by, -bx, 0.0]) / 9.81, abs=1e-15)
    # the estimate's vertical, seen in its own body frame, is the direction of the measured specific force at rest
    full = _imu({"accel_bias": 0.1, "tilt_from_accel_bias": 1.0, "attitude_noise": 0.0, "accel_noise": 0.0})
    from fpr_model.rotations import quat_to_rotmat
    level = np.array([1.0, 0.0, 0.0, 0.0])
    sample = full.sample(0, level, np.zeros(3), np.array([0.0, 0.0, 9.81]), np.zeros(3), np.zeros(3))
    up_estimated = quat_to_rotmat(sample.quat_local).T @ np.array([0.0, 0.0, 1.0])
    measured = sample.specific_force / np.linalg.norm(sample.specific_force)
    assert up_estimated[:2] == pytest.approx(measured[:2], abs=5e-4)  # first order in |b|/g ≈ 0.01
    ideal = _imu({"accel_bias": 0.1, "attitude_noise": 0.0}).sample(0, level, np.zeros(3), np.zeros(3),
                                                                    np.zeros(3), np.zeros(3))
    assert np.array_equal(ideal.quat_local, level)


def test_attitude_estimate_quats_follow_the_bias_random_walk():
    """The cached (exp(δ), exp(−δ)) equal a fresh computation of δ, also after the accelerometer bias walked."""
    sensors = _imu({"accel_bias": 0.1, "tilt_from_accel_bias": 1.0, "accel_bias_random_walk": 0.05,
                    "imu_misalignment": 0.02})
    assert _imu({"accel_bias": 0.1}).attitude_estimate_quats(0) is None
    for t in (0.0, 0.5, 2.0):
        sensors.advance_biases(1, t)
        forward, backward = sensors.attitude_estimate_quats(1)
        error = sensors.attitude_estimate_error(1)
        assert np.array_equal(forward, quat_from_rotvec(error)) and np.array_equal(backward, quat_from_rotvec(-error))
        assert np.allclose(quat_multiply(forward, backward), [1.0, 0.0, 0.0, 0.0], atol=1e-15)
    first = sensors.attitude_estimate_quats(0)[0].copy()  # cached now
    sensors.advance_biases(0, 0.0)
    sensors.advance_biases(0, 1.0)  # the walk moved δ_0: the cache follows
    assert not np.array_equal(sensors.attitude_estimate_quats(0)[0], first)


def test_imu_misalignment_is_a_constant_tilt_of_the_imu_frame_seen_consistently():
    """sensors.imu_misalignment: a constant per-UAV tilt μ (body x, y) of the IMU frame off the thrust axis; PX4
    reports the IMU frame's attitude q ∘ exp(μ) and the IMU measures in it, so the reported vertical and the
    measured specific force agree at rest; seeded, its own stream (the white noise is unchanged)."""
    from fpr_model.rotations import quat_to_rotmat

    plain = _imu({"attitude_noise": 0.0, "accel_noise": 0.0})
    sensors = _imu({"imu_misalignment": 0.03, "attitude_noise": 0.0, "accel_noise": 0.0})
    again = _imu({"imu_misalignment": 0.03, "attitude_noise": 0.0, "accel_noise": 0.0})
    tilted = np.array([0.9, 0.1, -0.3, 0.3]) / np.linalg.norm([0.9, 0.1, -0.3, 0.3])
    for i in range(3):
        mu = sensors.attitude_estimate_error(i)
        assert mu[2] == 0.0 and 0.0 < np.linalg.norm(mu) < 0.2
        assert np.array_equal(mu, again.attitude_estimate_error(i))
        at_rest = quat_to_rotmat(tilted).T @ np.array([0.0, 0.0, 9.81])  # true specific force, thrust-axis frame
        sample = sensors.sample(i, tilted, np.zeros(3), at_rest, np.zeros(3), np.zeros(3))
        up_reported = quat_to_rotmat(sample.quat_local).T @ np.array([0.0, 0.0, 1.0])
        measured = sample.specific_force - sensors.accel_bias[i]
        assert up_reported == pytest.approx(measured / 9.81, abs=1e-12)
        reference = plain.sample(i, tilted, np.zeros(3), at_rest, np.zeros(3), np.zeros(3))
        assert np.linalg.norm(reference.specific_force - sample.specific_force) > 0.05  # it moved by g·|μ|
    assert plain.attitude_estimate_error(0) is None


@pytest.mark.parametrize("value", [0.2, float("inf"), float("nan"), -0.01])
def test_imu_misalignment_outside_the_first_order_range_is_refused(value):
    """The attitude error is modelled to first order in μ: a σ above 0.1 rad, or not finite, is refused in one line."""
    with pytest.raises(ValueError, match="sensors.imu_misalignment: "):
        scenario_from_dict({**HOVER, "sensors": {"imu_misalignment": value}})
    scenario_from_dict({**HOVER, "sensors": {"imu_misalignment": 0.1}})


def _hover_attitudes(share: float, seconds: float = 0.3) -> tuple[list, list, list]:
    """Hover start (the PX4s hold their hover setpoint, no FPR controller): per UAV the true attitude, the attitude
    PX4 reports (noise-free) and its tilt δ after ``seconds``."""
    from fpr_sim.simulation import Simulation, SimulationOptions

    scenario = scenario_from_dict({"initial_state": {"mode": "hover", "armed": True}, "ground": {"enabled": False},
                                   "cameras": {"enabled": False}, "seed": 4,
                                   "sensors": {"accel_bias": 0.1, "tilt_from_accel_bias": share,
                                               "attitude_noise": 0.0}})
    sim = Simulation(scenario, SimulationOptions(local_base_port=0, remote_base_port=0, lockstep=False))
    try:
        sim.advance(seconds)
        sensors = sim.sensors
        true = [sim.plant.fleet.quat[i] for i in range(3)]
        reported = [sensors.to_world_attitude(i, sensors.sample(i, q, np.zeros(3), np.zeros(3), np.zeros(3),
                                                                np.zeros(3)).quat_local) for i, q in enumerate(true)]
        tilts = [sensors.attitude_estimate_error(i) for i in range(3)]
        return true, reported, tilts
    finally:
        sim.close()


def test_px4_tracks_its_attitude_estimate_so_the_thrust_axis_is_off_by_the_tilt():
    """With the tilt in PX4's estimate the attitude loops bring the ESTIMATE where the unbiased loops bring the
    true attitude: what PX4 reports matches the unbiased flight's truth, and the true attitude is off by |δ|
    (0.3-0.8° here for a 0.1 m/s² bias), as the thrust axis is."""
    from fpr_model.rotations import quat_error

    def angle(a, b):
        return 2.0 * float(np.linalg.norm(quat_error(a, b)[1:]))

    true_0, reported_0, tilts_0 = _hover_attitudes(0.0)
    true_1, reported_1, tilts_1 = _hover_attitudes(1.0)
    assert tilts_0 == [None, None, None]
    for i in range(3):
        tilt = float(np.linalg.norm(tilts_1[i]))
        assert tilt > 2e-3
        assert angle(reported_0[i], true_0[i]) < 1e-12  # noise-free and unbiased: the truth
        assert angle(reported_1[i], true_0[i]) < 0.2 * tilt  # PX4 believes it flies the unbiased attitude
        assert angle(true_1[i], true_0[i]) == pytest.approx(tilt, rel=0.2)


def test_bias_random_walks_grow_with_simulation_time_and_change_nothing_else():
    _, ideal_forces = _samples(_imu())
    ideal_rates, _ = _samples(_imu())
    rates, forces = _samples(_imu({"gyro_bias_random_walk": 0.01}), count=500)
    assert np.array_equal(forces[:200], ideal_forces)
    drift = rates[:200] - ideal_rates
    assert drift[0] == pytest.approx(np.zeros(3), abs=0.0) and np.abs(drift[-1]).max() > 0.0
    # Wiener process: the spread over many UAVs and seeds after T s is σ √T (here 0.01 √10 = 0.032 rad/s)
    finals = []
    for seed in range(40):
        sensors = _imu({"gyro_bias_random_walk": 0.01, "gyro_bias": 0.0}, seed=seed)
        start = sensors.gyro_bias.copy()
        sensors.advance_biases(0, 0.0)
        for t in np.arange(1, 501) * 0.02:
            sensors.advance_biases(0, float(t))
        finals.append(sensors.gyro_bias[0] - start[0])
    assert np.std(finals) == pytest.approx(0.01 * np.sqrt(10.0), rel=0.25)
    _, accel_walk = _samples(_imu({"accel_bias_random_walk": 0.05}), count=500)
    assert np.abs(accel_walk[-1] - accel_walk[0]).max() > 0.0


def test_imu_realism_is_deterministic_per_seed():
    overrides = {"accel_bias": 0.1, "gyro_bias_random_walk": 0.001, "accel_bias_random_walk": 0.003}
    a, b, c = (_samples(_imu(overrides, seed=s)) for s in (5, 5, 6))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[1], c[1])


# ---- cameras: rendered ------------------------------------------------------------------------------
def test_ideal_rendering_is_the_effect_free_renderer(truth):
    config = CameraConfig(pixel_noise=2.0, blur_sigma=0.5)
    rig = CameraRig(config, 3, seed=0)
    renderer = MarkerRenderer(rig.calibration.camera, marker_size=rig.calibration.marker_size)
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence([0, 7]).spawn(3)]
    for i, (frame, T) in enumerate(zip(rig.render(truth), platform_T_bodies(truth), strict=True)):
        expected = renderer.render(rig.camera_T_marker(T), blur_sigma=0.5, noise_sigma=2.0, rng=rngs[i])
        assert np.array_equal(frame.image, expected.image)


def _frames(config: CameraConfig, truth, seed: int = 1):
    return [f.image for f in CameraRig(config, 3, seed=seed).render(truth)]


def test_motion_blur_follows_the_relative_motion(truth):
    base = CameraConfig(pixel_noise=0.0)
    blurred = replace(base, exposure_time=0.02)
    # at rest nothing moves during the exposure: the same image
    assert all(np.array_equal(a, b) for a, b in zip(_frames(base, truth), _frames(blurred, truth), strict=True))
    moving = _moving(truth)
    sharp, smeared = _frames(base, moving), _frames(blurred, moving)
    for a, b in zip(sharp, smeared, strict=True):
        assert not np.array_equal(a, b)
        # blur lowers the local contrast (gradient energy) of the marker
        assert np.abs(np.diff(b.astype(float), axis=1)).sum() < np.abs(np.diff(a.astype(float), axis=1)).sum()
        assert a.mean() == pytest.approx(b.mean(), abs=0.5)  # the light is only moved around


def test_photometric_variation_changes_each_frame_and_is_seeded(truth):
    base = CameraConfig(pixel_noise=0.0)
    lit = replace(base, contrast_variation=0.2, brightness_variation=10.0, lighting_gradient=30.0)
    plain = _frames(base, truth)
    a, b, c = _frames(lit, truth), _frames(lit, truth), _frames(lit, truth, seed=2)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not any(np.array_equal(x, y) for x, y in zip(a, plain, strict=True))
    assert not any(np.array_equal(x, y) for x, y in zip(a, c, strict=True))


def test_occlusion_darkens_part_of_the_marker_and_draws_from_its_own_stream(truth):
    base = CameraConfig(pixel_noise=0.0, contrast_variation=0.2)
    plain = _frames(base, truth)
    occluded = _frames(replace(base, occlusion_probability=1.0, occlusion_shade=0.0), truth)
    for a, b in zip(plain, occluded, strict=True):
        changed = a != b
        assert 20 < changed.sum() < 0.5 * 640 * 480 and np.all(b[changed] <= a[changed])
    # a never-firing occlusion draws its variates but leaves the other effects' draws (and images) alone
    never = _frames(replace(base, occlusion_probability=1e-12), truth)
    assert all(np.array_equal(a, b) for a, b in zip(plain, never, strict=True))


def test_calibration_error_moves_the_true_camera_within_its_tolerance(truth):
    config = CameraConfig(pixel_noise=0.0, intrinsics_tolerance=0.02, principal_point_tolerance=8.0,
                          mounting_angle_tolerance=0.035, mounting_translation_tolerance=0.005)
    rig = CameraRig(config, 3, seed=4)
    nominal = rig.calibration
    for true in rig.true_cameras:
        assert abs(true.camera.fx / nominal.camera.fx - 1.0) <= 0.02 and abs(true.camera.cx - nominal.camera.cx) <= 8
        assert true.camera != nominal.camera
        offset = true.body_T_camera[:3, 3] - nominal.body_T_camera[:3, 3]
        assert 0.0 < np.abs(offset).max() <= 0.005 + 1e-12
        angle = np.arccos(np.clip((np.trace(true.body_T_camera[:3, :3].T @ nominal.body_T_camera[:3, :3]) - 1) / 2,
                                  -1, 1))
        assert 0.0 < angle <= 3 * 0.035
    assert rig.true_cameras[0].camera != rig.true_cameras[1].camera  # per UAV
    assert not any(np.array_equal(a, b) for a, b in zip(_frames(CameraConfig(pixel_noise=0.0), truth),
                                                         _frames(config, truth, seed=4), strict=True))


# ---- cameras: emulated ---------------------------------------------------------------------------------
def test_emulated_misses_keep_the_other_detections_unchanged(truth):
    base = CameraConfig(emulated=True)
    full, lossy = CameraRig(base, 3, seed=2), CameraRig(replace(base, detection_probability=0.9), 3, seed=2)
    kept = total = 0
    for _ in range(400):
        for a, b in zip(full.emulate(truth), lossy.emulate(truth), strict=True):
            total += 1
            if b is not None:
                kept += 1
                assert np.array_equal(a.camera_T_marker, b.camera_T_marker)
    assert kept / total == pytest.approx(0.9, abs=0.03)


def test_emulated_calibration_error_is_a_constant_bias(truth):
    config = CameraConfig(emulated=True, position_noise=0.0, angle_noise=0.0, intrinsics_tolerance=0.03,
                          principal_point_tolerance=10.0, mounting_angle_tolerance=0.05,
                          mounting_translation_tolerance=0.01)
    rig = CameraRig(config, 3, seed=4)
    exact = CameraRig(replace(config, intrinsics_tolerance=0.0, principal_point_tolerance=0.0,
                              mounting_angle_tolerance=0.0, mounting_translation_tolerance=0.0), 3, seed=4)
    first, second = rig.emulate(truth), rig.emulate(truth)
    for a, b, e, T in zip(first, second, exact.emulate(truth), platform_T_bodies(truth), strict=True):
        assert np.allclose(e.platform_T_body, T, atol=1e-12)
        error = np.linalg.norm(a.platform_T_body[:3, 3] - T[:3, 3])
        assert 0.002 < error < 0.15
        assert np.allclose(a.platform_T_body, b.platform_T_body, atol=1e-9)
        # what the estimator reconstructs is the measured C_T_M through the NOMINAL calibration (4.2)
        implied = rig.platform_T_marker @ invert_transform(a.camera_T_marker) @ invert_transform(rig.body_T_camera)
        assert np.allclose(implied, a.platform_T_body, atol=1e-12)


# ---- motion capture and the delay line -----------------------------------------------------------------
def test_ideal_motion_capture_is_the_exact_truth(truth):
    assert MotionCapture(MotionCaptureConfig(), seed=0).measure(truth) is truth
    assert MotionCapture(MotionCaptureConfig(latency=0.1, position_noise=1.0), seed=0).latency == 0.0


def test_motion_capture_noise_and_dropouts(truth):
    config = MotionCaptureConfig(enabled=True, position_noise=0.001, attitude_noise=0.003, dropout_probability=0.1)
    mocap = MotionCapture(config, seed=1)
    frames = [mocap.measure(truth) for _ in range(1000)]
    kept = [f for f in frames if f is not None]
    assert len(kept) / len(frames) == pytest.approx(0.9, abs=0.03)
    errors = np.array([f.uav_positions - truth.uav_positions for f in kept])
    assert errors.std() == pytest.approx(0.001, rel=0.1)
    assert np.array_equal(kept[0].uav_thrusts, truth.uav_thrusts) and kept[0].time == truth.time
    noisy_quat = kept[0].state.quat
    assert 0.0 < np.linalg.norm(noisy_quat - truth.state.quat) < 0.05
    # the dropouts do not change the noise of the frames (separate streams): the same first noise draw
    no_drop = MotionCapture(replace(config, dropout_probability=0.0), seed=1).measure(truth)
    first_kept = next(f for f in (MotionCapture(config, seed=1).measure(truth) for _ in range(5)) if f is not None)
    assert np.array_equal(no_drop.state.position, first_kept.state.position)


def test_delay_line_releases_in_due_order():
    line = DelayLine()
    line.push(0.060, "b")
    line.push(0.012, "a")
    line.push(0.060, "c")
    assert line.pop_due(0.0) == [] and line.pop_due(0.012) == ["a"] and line.pop_due(0.1) == ["b", "c"]
    assert len(line) == 0


# ---- the hardware profile --------------------------------------------------------------------------------
def test_hardware_profile_switches_the_sensor_effects_on_and_a_scenario_value_wins():
    hardware = scenario_from_dict({}, realism="hardware")
    assert hardware.sensors.gyro_noise == 0.015 and hardware.sensors.accel_bias_random_walk == 0.003
    assert hardware.cameras.latency == pytest.approx(0.06) and hardware.cameras.detection_probability == 0.91
    assert hardware.motion_capture.enabled and hardware.motion_capture.latency == pytest.approx(0.012)
    own = scenario_from_dict({"cameras": {"latency": 0.0}, "motion_capture": {"enabled": False}}, realism="hardware")
    assert own.cameras.latency == 0.0 and not own.motion_capture.enabled and own.cameras.exposure_time > 0.0
    ideal = scenario_from_dict({})
    assert ideal.cameras == CameraConfig() and not ideal.motion_capture.enabled


@pytest.mark.parametrize("overrides", [{"cameras": {"latency": -0.01}}, {"cameras": {"occlusion_probability": 1.5}},
                                       {"motion_capture": {"rate": 0.0}}, {"sensors": {"accel_bias": -1.0}},
                                       {"sensors": {"tilt_from_accel_bias": 1.5}}])
def test_invalid_sensor_values_are_refused(overrides):
    with pytest.raises(ValueError):
        scenario_from_dict(overrides)


def test_perturbation_helper_is_a_right_multiplied_small_rotation():
    from fpr_sim.sensors import _perturb

    q = quat_from_rotvec(np.array([0.1, 0.2, 0.3]))
    assert np.allclose(_perturb(q, np.array([0.0, 0.0, 0.01])), quat_multiply(q, quat_from_rotvec([0, 0, 0.01])))


# ---- the simulator node: stamps, publication times, the motion-capture topic ---------------------------
def _run_node(tmp_path, scenario: dict, seconds: float = 0.6):
    """Step a SimulatorNode for ``seconds`` with its publishers recording (publication time, message); also the
    ground truth at every /clock tick (time -> GroundTruth)."""
    rclpy = pytest.importorskip("rclpy")
    import yaml
    from rclpy.parameter import Parameter

    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(scenario))
    rclpy.init()
    try:
        from fpr_sim.simulator import SimulatorNode

        node = SimulatorNode(parameter_overrides=[
            Parameter("scenario_file", value=str(path)), Parameter("real_time_factor", value=0.0),
            Parameter("local_base_port", value=0), Parameter("remote_base_port", value=0)])
        published: dict[str, list] = {}

        def record(name, publisher):
            published[name] = []
            publisher.publish = lambda msg: published[name].append((node.sim.time, msg))

        record("marker", node.marker_pubs[0]) if node.marker_pubs else record("image", node.image_pubs[0])
        record("truth", node.truth_pub)
        record("mocap", node.mocap_pub)
        truths = {}
        while node.sim.time < seconds:
            node.step()
            truths[round(node.sim.time, 6)] = node.sim.ground_truth()
        node.destroy_node()
        return published, truths, node
    finally:
        rclpy.shutdown()


def _seconds(stamp) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def test_camera_latency_shifts_publication_from_the_exposure_stamp_exactly(tmp_path):
    scenario = {**HOVER, "cameras": {"emulated": True, "position_noise": 0.0, "angle_noise": 0.0, "latency": 0.02}}
    published, truths, node = _run_node(tmp_path, scenario)
    markers = published["marker"]
    assert len(markers) >= 8
    for sent, msg in markers:
        stamp = _seconds(msg.header.stamp)
        assert sent - stamp == pytest.approx(0.02, abs=1e-6)
        # the content is the state at the stamp (exposure instant), not at publication
        expected = node.cameras.camera_T_marker(platform_T_bodies(truths[round(stamp, 6)])[0])
        p = msg.pose.position
        assert [p.x, p.y, p.z] == pytest.approx(expected[:3, 3].tolist(), abs=1e-9)
    ideal, _, _ = _run_node(tmp_path, {**scenario, "cameras": {**scenario["cameras"], "latency": 0.0}})
    assert all(sent == pytest.approx(_seconds(m.header.stamp), abs=1e-6) for sent, m in ideal["marker"])
    assert [m.pose for _, m in ideal["marker"][:5]] == [m.pose for _, m in markers[:5]]


def test_ideal_motion_capture_copies_the_ground_truth_and_enabled_it_is_late_and_noisy(tmp_path):
    published, _, _ = _run_node(tmp_path, HOVER, seconds=0.2)
    assert [m for _, m in published["mocap"]] == [m for _, m in published["truth"]]
    assert [t for t, _ in published["mocap"]] == [t for t, _ in published["truth"]]
    mocap = {"enabled": True, "latency": 0.012, "position_noise": 0.001, "rate": 100.0}
    published, truths, _ = _run_node(tmp_path, {**HOVER, "motion_capture": mocap}, seconds=0.3)
    frames = published["mocap"]
    assert len(frames) >= 25
    for sent, msg in frames:
        stamp = _seconds(msg.header.stamp)
        assert sent - stamp == pytest.approx(0.012, abs=1e-6)
        true = truths[round(stamp, 6)].state.position
        p = msg.platform_pose.position
        assert 0.0 < np.linalg.norm([p.x - true[0], p.y - true[1], p.z - true[2]]) < 0.01
    # /fpr/ground_truth stays the exact truth
    for sent, msg in published["truth"]:
        assert msg.platform_pose.position.z == truths[round(sent, 6)].state.position[2]
