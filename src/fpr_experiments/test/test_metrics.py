"""Flight metrics on synthetic flights whose errors are known exactly (ROS-free)."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from synthetic import FORCE_BIAS, LEG2_OFFSET, POSITION_OFFSET, RATE, ROLL_RIPPLE, N, synthetic_record

from fpr_experiments import metrics as fm


def test_hold_is_a_zero_order_hold_with_a_value_before_the_first_sample():
    held = fm.hold(np.array([-1.0, 0.0, 0.5, 1.0, 7.0]), np.array([0.0, 1.0]), np.array([4, 5]), before=-1)
    assert held.tolist() == [-1, 4, 4, 5, 5]
    assert fm.hold(np.array([1.0]), np.zeros(0), np.zeros(0), before=-7).tolist() == [-7]


def test_the_tracking_window_is_airborne_fly_and_offboard():
    record = synthetic_record()
    mask = fm.tracking_mask(record)
    t = record.truth.t[mask]
    # feet above 3 cm from 6.1 s (0.3 m/s climb), down again 0.1 s before the end of the descent at 18 s
    assert t[0] == pytest.approx(6.0 + fm.AIRBORNE_CLEARANCE / RATE, abs=0.02)
    assert t[-1] == pytest.approx(18.0 - fm.AIRBORNE_CLEARANCE / RATE, abs=0.02)


def test_metrics_of_a_synthetic_flight():
    m = fm.compute_metrics(synthetic_record())
    assert m["roll_rmse_deg"] == pytest.approx(math.degrees(ROLL_RIPPLE) / math.sqrt(2), rel=0.05)
    assert m["pitch_rmse_deg"] == pytest.approx(0.0, abs=1e-9)
    assert m["leg2_rmse_deg"] == pytest.approx(math.degrees(LEG2_OFFSET), rel=1e-6)
    assert m["legs_rmse_deg"] == pytest.approx(math.degrees(LEG2_OFFSET) / N, rel=1e-6)  # mean of per-leg RMSEs
    assert m["position_rmse_cm"] == pytest.approx(100.0 * POSITION_OFFSET, rel=0.02)
    assert m["position_xy_rmse_cm"] == pytest.approx(100.0 * POSITION_OFFSET, rel=1e-6)
    assert m["force_z_rmse_n"] == pytest.approx(FORCE_BIAS, rel=0.02)
    assert m["force_z_loaded_n"] - m["force_z_loaded_true_n"] == pytest.approx(FORCE_BIAS, abs=1e-6)
    assert m["force_z_loaded_true_n"] == pytest.approx(-9.81 * 0.2)
    assert m["uav3.force_z_rmse_n"] == pytest.approx(m["force_z_rmse_n"])
    assert m["max_abs_roll_deg"] == pytest.approx(11.0, abs=0.1)
    assert m["ground_contacts"] == 0.0 and m["nonfinite_samples"] == 0.0
    assert m["max_height_m"] == pytest.approx(1.0 + 4.0 * RATE, abs=0.01)
    assert m["fallback_fraction"] == pytest.approx(0.5 / 20.0, abs=1e-3)
    segments = fm.rate_segments(synthetic_record())
    assert [s.commanded for s in segments] == pytest.approx([RATE, -RATE], abs=1e-9)
    assert [s.achieved for s in segments] == pytest.approx([RATE, -RATE], abs=1e-3)


def test_worse_tracking_gives_larger_errors():
    record = synthetic_record()
    worse = copy.deepcopy(record)
    worse.truth.rpy[:, 1] += math.radians(2.0)
    worse.truth.legs[:, 0] -= math.radians(3.0)
    good, bad = fm.compute_metrics(record), fm.compute_metrics(worse)
    assert bad["pitch_rmse_deg"] == pytest.approx(2.0) and good["pitch_rmse_deg"] < 1e-9
    assert bad["leg1_rmse_deg"] == pytest.approx(3.0) and bad["legs_rmse_deg"] > good["legs_rmse_deg"]


def test_decentralized_flights_have_no_position_error_and_use_the_teleop_before_the_first_step():
    record = synthetic_record(ground_truth_mode=False)
    for uav in record.uavs:  # the first control periods report NaN (no state yet)
        uav.desired_legs[:10] = np.nan
        uav.desired_rpy[:10] = np.nan
    m = fm.compute_metrics(record)
    assert math.isnan(m["position_rmse_cm"]) and math.isnan(m["position_xy_rmse_cm"])
    assert m["legs_rmse_deg"] == pytest.approx(math.degrees(LEG2_OFFSET) / N, rel=1e-6)


def test_a_flight_that_never_took_off_has_no_tracking_window():
    record = synthetic_record()
    for uav in record.uavs:
        uav.bridge_state = np.minimum(uav.bridge_state, 2)  # never OFFBOARD
    m = fm.compute_metrics(record)
    assert m["tracking_time_s"] == 0.0 and math.isnan(m["roll_rmse_deg"])


def test_a_touch_down_while_the_controllers_fly_is_a_ground_contact():
    record = synthetic_record()
    dip = (record.truth.t > 12.0) & (record.truth.t < 12.5)
    record.truth.uav_positions[dip, 1, 2] = record.landing_gear_height  # UAV 2's feet on the ground
    assert fm.safety_metrics(record)["ground_contacts"] == 1.0
    record.truth.position[100, 0] = np.nan
    assert fm.safety_metrics(record)["nonfinite_samples"] == 1.0


def test_a_take_off_hop_is_not_a_ground_contact_but_is_reported():
    """FLY and OFFBOARD from 3 s, the climb at 6 s: the structure lifting 4 cm off at 4 s and settling back at
    4.5 s (a hop, before it was ever 15 cm up) is a take-off touch-down; the same after the climb is a contact."""
    record = synthetic_record()
    t = record.truth.t
    feet = record.truth.uav_positions[:, :, 2]
    hop = (t > 4.0) & (t < 4.5)
    feet[hop] += 0.04  # every UAV's feet 4 cm up (airborne: above AIRBORNE_CLEARANCE), then back on the ground
    m = fm.safety_metrics(record)
    assert m["takeoff_touchdowns"] == 1.0 and m["ground_contacts"] == 0.0
    assert fm.TAKEOFF_CLEARANCE > 0.04 + 1e-9  # the hop stays below the take-off clearance
    dip = (t > 12.0) & (t < 12.5)  # after the climb (0.3 m/s from 6 s: ~1.2 m up): the feet down again
    feet[dip, 1] = record.landing_gear_height
    m = fm.safety_metrics(record)
    assert m["takeoff_touchdowns"] == 1.0 and m["ground_contacts"] == 1.0


def test_swarm_emergencies_count_the_swarm_entering_its_emergency_response():
    record = synthetic_record()
    assert fm.safety_metrics(record)["swarm_emergencies"] == 0.0
    t = record.uavs[0].status_t
    emergency = record.names.emergency_state
    # UAV 2 enters at 12 s (its own cause), the peers follow within a status period; all rejoin at 14 s
    for uav, start in ((2, 12.0), (1, 12.1), (3, 12.2)):
        state = record.uavs[uav - 1].bridge_state.copy()
        state[(t >= start - 1e-9) & (t < 14.0)] = emergency
        record.uavs[uav - 1].bridge_state = state
    assert fm.safety_metrics(record)["swarm_emergencies"] == 1.0  # one root cause, followed: once
    state = record.uavs[0].bridge_state.copy()
    state[(t >= 16.0) & (t < 16.5)] = emergency  # again, UAV 1 alone
    record.uavs[0].bridge_state = state
    assert fm.safety_metrics(record)["swarm_emergencies"] == 2.0


def test_relative_pose_errors_and_detection_rate():
    record = synthetic_record()
    positions, quats = fm.true_relative_poses(record)
    for k, uav in enumerate(record.uavs):
        uav.marker_t = record.truth.t[::5].copy()       # 20 Hz
        uav.marker_position = positions[::5, k] + np.array([0.02, 0.0, 0.0])
        uav.marker_quat = quats[::5, k].copy()
        uav.marker_position[::4] += np.array([0.2, 0.0, 0.0])  # every 4th detection is 20 cm off: a failure
        uav.local_t = record.truth.t[::2].copy()
        uav.local_position = positions[::2, k] + np.array([0.0, 0.01, 0.0])
        uav.local_quat = quats[::2, k].copy()
    m = fm.compute_metrics(record)
    assert m["uav1.ekf_y_m"] == pytest.approx(0.01, rel=1e-6) and m["uav1.ekf_x_m"] == pytest.approx(0.0, abs=1e-9)
    assert m["uav2.ekf_yaw_deg"] == pytest.approx(0.0, abs=1e-6)
    assert m["uav1.aruco_x_m"] > 0.02
    assert m["uav3.detection_rate_pct"] == pytest.approx(75.0, abs=2.0)


def test_scripted_operator_tasks_give_the_success_rate():
    record = synthetic_record()
    record.events = [{"t": 5.0, "event": "task_end", "kind": "goto", "success": True},
                     {"t": 9.0, "event": "task_end", "kind": "goto", "success": False},
                     {"t": 12.0, "event": "task_end", "kind": "hold", "success": True},
                     {"t": 15.0, "event": "task_end", "kind": "goto", "success": True}]
    m = fm.compute_metrics(record)
    assert (m["tasks"], m["tasks_succeeded"]) == (3.0, 2.0)
    assert m["success_rate"] == pytest.approx(2.0 / 3.0)


def test_recovery_time_after_a_link_outage():
    record = synthetic_record()
    for uav in record.uavs:
        uav.fallback = (uav.diagnostics_t >= 10.0) & (uav.diagnostics_t < 13.2 + 0.02 * uav.uav_id)
    assert fm.recovery_time(record, 13.0) == pytest.approx(0.26, abs=0.021)
    for uav in record.uavs:  # back, then a fallback again once landed (stale estimates): not this recovery
        uav.fallback = ((uav.diagnostics_t >= 10.0) & (uav.diagnostics_t < 13.1)) | (uav.diagnostics_t >= 18.5)
    assert fm.recovery_time(record, 13.0) == pytest.approx(0.1, abs=0.021)
    for uav in record.uavs:
        uav.fallback = uav.diagnostics_t >= 10.0  # never back
    assert math.isnan(fm.recovery_time(record, 13.0))
