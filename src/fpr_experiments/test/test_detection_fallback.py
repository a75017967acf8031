"""The thesis's motion-capture supervision of the marker detections (§4.4.2, fpr_experiments.detection_fallback):
a good detection passes unchanged, a false one (> 10 cm or > 10 deg from the motion capture) is replaced by an
emulated one, and after 0.5 s without a passed detection emulated ones come at the camera rate until the camera's
are back. Plain pytest on the ROS-free core, plus the graph's wiring."""

import math

import numpy as np
import pytest
from fpr_estimation.estimator import relative_pose_from_detection
from fpr_experiments.detection_fallback import DetectionFallback, FallbackConfig
from fpr_experiments.graph import CHECKED_MARKER_TOPIC, GraphOptions, describe_graph
from fpr_model.calibration import VisionCalibration, camera_T_marker_of, make_transform
from fpr_model.rotations import quat_from_rotvec, quat_to_rotmat, rotmat_to_quat

CALIBRATION = VisionCalibration()
N = 3
PLATFORM = (np.array([0.2, -0.1, 1.8]), quat_from_rotvec([0.05, -0.1, 0.4]))
#: each UAV's pose in the platform frame p_T_bi (below the platform, on its leg)
RELATIVE = [make_transform(quat_to_rotmat(quat_from_rotvec([0.1 * i, -0.2, 0.3 * i])),
                           [0.6 * math.cos(2.1 * i), 0.6 * math.sin(2.1 * i), -0.8]) for i in range(N)]


def _world_poses():
    """(positions, quaternions) in F0 of the UAVs for the platform pose PLATFORM and RELATIVE."""
    world_T_platform = make_transform(quat_to_rotmat(PLATFORM[1]), PLATFORM[0])
    poses = [world_T_platform @ T for T in RELATIVE]
    return [T[:3, 3] for T in poses], [rotmat_to_quat(T[:3, :3]) for T in poses]


def _fed(config=None, seed=0, until=1.0):
    core = DetectionFallback(N, config or FallbackConfig(), CALIBRATION, seed)
    positions, quats = _world_poses()
    for k in range(int(until * 100) + 1):  # 100 Hz motion capture
        core.on_mocap(0.01 * k, *PLATFORM, positions, quats)
    return core


def _detection(uav, offset=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0)):
    T = RELATIVE[uav - 1].copy()
    T[:3, 3] += np.asarray(offset, dtype=float)
    T[:3, :3] = T[:3, :3] @ quat_to_rotmat(quat_from_rotvec(np.asarray(rotation, dtype=float)))
    return camera_T_marker_of(T, CALIBRATION.body_T_camera, CALIBRATION.platform_T_marker)


def _relative(camera_T_marker):
    return relative_pose_from_detection(camera_T_marker, CALIBRATION)


def test_the_motion_capture_relative_pose_and_the_inverse_of_4_2():
    core = _fed()
    for uav in range(1, N + 1):
        stamp, T = core.mocap_relative_pose(uav, 0.5)
        assert stamp == pytest.approx(0.5) and np.allclose(T, RELATIVE[uav - 1], atol=1e-12)
        assert np.allclose(_relative(_detection(uav)), RELATIVE[uav - 1], atol=1e-12)


def test_a_good_detection_passes_unchanged_and_a_false_one_is_replaced():
    core = _fed(FallbackConfig(position_noise=0.0, angle_noise=0.0))
    good = _detection(1, offset=np.array([0.05, -0.05, 0.03]), rotation=np.radians([4.0, -4.0, 3.0]))
    decision = core.on_detection(1, 0.5, good)
    assert not decision.emulated and decision.camera_T_marker is good and decision.reason == ""
    for bad in (_detection(2, offset=np.array([0.0, 0.0, 0.12])), _detection(2, rotation=np.radians([0, 11.0, 0])),
                np.full((4, 4), np.nan)):
        decision = core.on_detection(2, 0.5, bad)
        assert decision.emulated and decision.reason.startswith("false detection")
        assert np.allclose(_relative(decision.camera_T_marker), RELATIVE[1], atol=1e-9)  # noise 0: the MOCAP pose
    assert core.passed == [1, 0, 0] and core.false_detections == [0, 3, 0] and core.emulated == [0, 3, 0]


def test_emulated_detections_carry_the_section_4_4_1_noise_seeded():
    errors = []
    core = _fed(seed=7)
    for _ in range(2000):
        T = _relative(core.on_detection(3, 0.5, _detection(3, offset=np.array([0.5, 0.0, 0.0]))).camera_T_marker)
        errors.append(T[:3, 3] - RELATIVE[2][:3, 3])
    assert np.std(errors, axis=0) == pytest.approx([0.02] * 3, rel=0.1)
    again = _fed(seed=7).on_detection(3, 0.5, _detection(3, offset=np.array([0.5, 0.0, 0.0])))
    first = _fed(seed=7).on_detection(3, 0.5, _detection(3, offset=np.array([0.5, 0.0, 0.0])))
    other = _fed(seed=8).on_detection(3, 0.5, _detection(3, offset=np.array([0.5, 0.0, 0.0])))
    assert np.array_equal(again.camera_T_marker, first.camera_T_marker)
    assert not np.array_equal(other.camera_T_marker, first.camera_T_marker)


def test_lost_detections_are_emulated_at_the_camera_rate_until_the_camera_is_back():
    core = _fed(until=5.0)
    given = {uav: [] for uav in range(1, N + 1)}
    for k in range(0, 1251):  # 5 s, called at 250 Hz; UAV 1 sees the marker at 20 Hz until 1 s and from 3 s on
        now = 0.004 * k
        if k % 12 == 0 and not 1.0 < now < 3.0:
            assert not core.on_detection(1, now, _detection(1)).emulated
        for uav in given:
            due = core.due(uav, now)
            if due is not None:
                given[uav].append(now)
                assert np.allclose(_relative(due[1])[:3, 3], RELATIVE[uav - 1][:3, 3], atol=0.12)
    # UAV 1: lost from ~1.46 s (0.5 s after its last detection at 0.96 s) to its next one at 3.024 s
    assert given[1] and given[1][0] == pytest.approx(0.96 + 0.504) and 3.0 < given[1][-1] < 3.024
    assert len(given[1]) == pytest.approx(20 * (3.024 - given[1][0]), abs=1)
    assert not core.lost[0]
    # UAVs 2 and 3 never see the marker: 0.5 s of grace from the first call, then 20 Hz
    for uav in (2, 3):
        assert given[uav][0] == pytest.approx(0.504) and len(given[uav]) == pytest.approx(20 * 4.5, abs=2)
    assert core.lost[1] and core.lost_for(2, 5.0) == pytest.approx(5.0)


def test_without_motion_capture_nothing_is_emulated_and_bad_inputs_are_refused():
    core = DetectionFallback(N)
    assert not core.on_detection(1, 0.1, _detection(1, offset=np.array([1.0, 0.0, 0.0]))).emulated
    assert core.due(2, 0.0) is None and core.due(2, 2.0) is None  # lost, but nothing to emulate from
    positions, quats = _world_poses()
    assert "NaN" in core.on_mocap(0.0, PLATFORM[0], [np.nan, 0, 0, 0], positions, quats)  # refused, said
    assert "non-unit" in core.on_mocap(0.0, PLATFORM[0], [0.0, 0, 0, 0], positions, quats)
    assert "UAV poses" in core.on_mocap(0.0, *PLATFORM, positions[:2], quats[:2])
    assert core.mocap_relative_pose(1, 0.0) is None
    assert core.on_mocap(0.0, *PLATFORM, positions, quats) is None and core.mocap_relative_pose(1, 0.0) is not None
    for bad in ({"lost_timeout": 0.0}, {"rate": math.inf}, {"position_noise": -0.1}, {"max_angle_error": math.nan}):
        with pytest.raises(ValueError):
            FallbackConfig(**bad)


def test_the_graph_puts_the_fallback_between_the_cameras_and_the_estimators():
    for cameras in ("emulated", "images"):
        specs = describe_graph(GraphOptions(cameras=cameras, detection_fallback=True, realism="hardware"))
        fallback = [s for s in specs if s.executable == "detection_fallback"]
        assert len(fallback) == 1 and fallback[0].parameters["output_topic"] == CHECKED_MARKER_TOPIC
        assert fallback[0].parameters["n"] == 3 and fallback[0].parameters["use_sim_time"]
        estimators = [s for s in specs if s.executable == "pose_estimator"]
        assert all(s.remappings == [("marker", CHECKED_MARKER_TOPIC)] for s in estimators)
    plain = describe_graph(GraphOptions())
    assert not any(s.executable == "detection_fallback" for s in plain)
    assert all(s.remappings == [] for s in plain if s.executable == "pose_estimator")
    with pytest.raises(ValueError, match="detection_fallback"):
        GraphOptions(backend="real", cameras="images", detection_fallback=True).validate()
