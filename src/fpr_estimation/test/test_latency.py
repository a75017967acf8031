"""Detection-latency compensation (fpr_estimation.latency): a detection captured L seconds before the filter's time
is carried forward by the UAV's rotation in between; off, it is applied as if current (the thesis's filter).
Plain pytest on the ROS-free cores."""

import numpy as np
import pytest
from fpr_estimation.estimator import EstimatorConfig, PoseEstimatorCore
from fpr_estimation.latency import AttitudeHistory
from fpr_model.calibration import make_transform
from fpr_model.rotations import (
    quat_conjugate,
    quat_from_rotvec,
    quat_multiply,
    quat_to_rotmat,
    quat_to_rotvec,
    rotmat_to_quat,
)

IMU_PERIOD = 0.004  # 250 Hz
YAW_RATE = 2.0  # [rad/s] a UAV turning fast (a swing, a yaw manoeuvre)
LATENCY = 0.06  # [s] the hardware profile's camera latency
#: the UAV's pose in the platform frame at t = 0 (p_T_bi)
START = make_transform(quat_to_rotmat(quat_from_rotvec([0.1, -0.2, 0.3])), [0.5, 0.1, -0.9])


def _attitude(t):
    """0i_q_bi(t): the UAV yawing at YAW_RATE about its body z from identity."""
    return quat_from_rotvec([0.0, 0.0, YAW_RATE * t])


def _true_relative(t):
    """p_T_bi(t) with the platform still: p_R_bi(t) = p_R_bi(0) · 0i_R_bi(t)."""
    return make_transform(START[:3, :3] @ quat_to_rotmat(_attitude(t)), START[:3, 3])


def _angle(qa, qb):
    return float(np.linalg.norm(quat_to_rotvec(quat_multiply(quat_conjugate(qa), qb))))


def test_history_interpolates_the_attitude_and_gives_the_rotation_since_a_stamp():
    history = AttitudeHistory(horizon=0.5)
    for k in range(101):
        history.add(k * IMU_PERIOD, _attitude(k * IMU_PERIOD))
    # between two samples: the slerp of a constant-rate rotation is exact
    t = 0.2 + 0.3 * IMU_PERIOD
    assert _angle(history.attitude_at(t), _attitude(t)) < 1e-12
    delta = history.rotation_since(0.4 - LATENCY)
    assert np.allclose(delta, quat_to_rotmat(quat_from_rotvec([0.0, 0.0, YAW_RATE * LATENCY])), atol=1e-12)
    assert np.allclose(history.rotation_since(0.4), np.eye(3)) and np.allclose(history.rotation_since(1.0), np.eye(3))
    # only the last horizon is kept (plus the sample before it, to interpolate at its start)
    for k in range(101, 251):
        history.add(k * IMU_PERIOD, _attitude(k * IMU_PERIOD))
    assert history.rotation_since(1.0 - 0.49) is not None and history.rotation_since(1.0 - 0.51) is None
    history.add(0.9, _attitude(0.0))  # a stamp going back changes nothing
    assert history.latest_stamp == pytest.approx(1.0)
    with pytest.raises(ValueError):
        AttitudeHistory(0.0)
    with pytest.raises(ValueError, match="latency_horizon"):
        EstimatorConfig(latency_horizon=float("nan"))


def _fly(compensate: bool, latency: float = LATENCY):
    """The UAV yaws for 1 s; exact detections at 20 Hz arrive ``latency`` after their capture. Returns the core and
    the innovation angles [rad] of the accepted detections after the first 0.3 s."""
    core = PoseEstimatorCore(EstimatorConfig(latency_compensation=compensate))
    angles = []
    for k in range(0, 251):
        t = k * IMU_PERIOD
        core.on_imu(t, _attitude(t), np.array([0.0, 0.0, YAW_RATE]))
        if k % 12 == 0 and t >= latency:  # a detection arrives: captured `latency` ago
            capture = t - latency
            measured = _true_relative(capture)
            if core.filter.initialized:
                predicted = core.filter.quaternion
                carried = measured[:3, :3] @ (core.attitudes.rotation_since(capture) if compensate else np.eye(3))
                angles.append((t, _angle(predicted, rotmat_to_quat(carried))))
            core.on_relative_pose(t, measured, capture_stamp=capture)
    return core, np.array([a for t, a in angles if t > 0.3])


def test_a_late_detection_is_carried_to_the_filter_time():
    """At 2 rad/s and 60 ms, an uncompensated detection is 0.12 rad (6.9 deg) behind the UAV: the filter settles
    between the two and never agrees with either; compensated, it agrees with the truth at the filter's time."""
    compensated, innovations = _fly(True)
    assert compensated.compensated_detections > 10 and compensated.uncompensated_detections == 0
    assert compensated.last_latency == pytest.approx(LATENCY, abs=1e-9)
    assert innovations.max() < 2e-3  # the prediction and the carried detection agree (gyro = attitude here)
    truth = quat_multiply(quat_from_rotvec([0.1, -0.2, 0.3]), _attitude(1.0))
    assert _angle(compensated.filter.quaternion, truth) < 2e-3

    late, _ = _fly(False)
    assert late.compensated_detections == 0
    assert _angle(late.filter.quaternion, truth) > 0.03  # pulled back towards the 60 ms old attitudes


def test_no_capture_stamp_or_no_latency_changes_nothing():
    core, _ = _fly(True, latency=0.0)
    reference, _ = _fly(False, latency=0.0)
    assert np.allclose(core.filter.x, reference.filter.x, atol=1e-12)
    plain = PoseEstimatorCore()
    plain.on_imu(0.0, _attitude(0.0), np.zeros(3))
    plain.on_relative_pose(0.0, START)  # no capture stamp: nothing to compensate
    assert plain.compensated_detections == 0 and plain.uncompensated_detections == 0


def test_a_detection_older_than_the_horizon_is_applied_uncompensated_and_said():
    core = PoseEstimatorCore(EstimatorConfig(latency_horizon=0.1))
    for k in range(0, 101):
        core.on_imu(k * IMU_PERIOD, _attitude(k * IMU_PERIOD), np.array([0.0, 0.0, YAW_RATE]))
    core.take_events()
    core.on_relative_pose(0.4, _true_relative(0.2), capture_stamp=0.2)
    assert core.uncompensated_detections == 1 and core.compensated_detections == 0
    events = core.take_events()
    assert [e.kind for e in events] == ["latency"] and "without latency compensation" in events[0].message
    assert "0.200 s before the filter's time (more than latency_horizon 0.1 s)" in events[0].message


def test_a_detection_from_before_the_imu_stream_says_so():
    """At start-up (or after an IMU gap) the history is younger than the horizon: the detection is older than the
    first attitude kept, not older than the horizon, and the warning says which."""
    core = PoseEstimatorCore(EstimatorConfig(latency_horizon=0.5))
    for k in range(10, 21):
        core.on_imu(k * IMU_PERIOD, _attitude(k * IMU_PERIOD), np.array([0.0, 0.0, YAW_RATE]))
    core.take_events()
    first = 10 * IMU_PERIOD
    core.on_relative_pose(20 * IMU_PERIOD, _true_relative(first - 0.01), capture_stamp=first - 0.01)
    assert core.uncompensated_detections == 1
    message = core.take_events()[0].message
    assert "before the oldest IMU attitude kept" in message and "latency_horizon" not in message


def test_an_imu_gap_forgets_the_attitudes():
    """Across a gap the filter did not integrate, a detection captured before it cannot be carried over it."""
    core = PoseEstimatorCore()
    for k in range(0, 51):
        core.on_imu(k * IMU_PERIOD, _attitude(k * IMU_PERIOD), np.array([0.0, 0.0, YAW_RATE]))
    assert len(core.attitudes) > 1
    assert "gap" in core.on_imu(0.4, _attitude(0.4), np.array([0.0, 0.0, YAW_RATE]))
    assert len(core.attitudes) == 1
    core.on_relative_pose(0.4, _true_relative(0.15), capture_stamp=0.15)
    assert core.uncompensated_detections == 1
