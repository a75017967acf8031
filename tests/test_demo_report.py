"""The demo's report (demo/): flight metrics and plots on synthetic arrays (ROS-free), and the MCAP log round
trip with real rclpy serialization (no node is started). The demo flight itself is not run here: the swarm
flight test (test_swarm_flight.py) covers the flight."""

from __future__ import annotations

import copy
import json
import math
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "demo"))
import flight_report as fr  # noqa: E402

N = 3
RATE = 0.3                       # [m/s] commanded climb / descent
ROLL_RIPPLE = math.radians(1.0)  # amplitude of the synthetic roll error (sinusoid): RMSE = amplitude / sqrt(2)
LEG2_OFFSET = math.radians(0.5)  # constant error of leg 2
NAMES = fr.StateNames(teleop_mode={0: "IDLE", 1: "ARM", 2: "FLY", 3: "LAND"},
                      bridge_state={1: "IDLE", 2: "ARMING", 4: "OFFBOARD", 5: "LANDING"},
                      controller_mode={1: "COMMUNICATING", 2: "NON_COMMUNICATING"}, fly_mode=2, offboard_state=4)


def _synthetic_record() -> fr.FlightRecord:
    """20 s: ARM at 1 s, FLY at 2 s (all bridges OFFBOARD at 3 s), climb 6-10 s, roll step 11-13 s, descend
    14-18 s, LAND at 18 s. The truth follows the command exactly except a roll ripple, a leg-2 offset and a
    fixed 0.1 s lag of the vertical motion."""
    t_cmd = np.arange(0.0, 20.0, 0.02)
    mode = np.select([t_cmd < 1.0, t_cmd < 2.0, t_cmd < 18.0], [0, 1, 2], 3)
    vz = np.where((t_cmd >= 6.0) & (t_cmd < 10.0), RATE, 0.0) - np.where((t_cmd >= 14.0) & (t_cmd < 18.0), RATE, 0.0)
    roll = np.clip((t_cmd - 11.0) / 2.0, 0.0, 1.0) * math.radians(10.0)
    command = fr.CommandSeries(t=t_cmd, mode=mode, velocity=np.column_stack([0 * t_cmd, 0 * t_cmd, vz]),
                               roll=roll, pitch=0 * t_cmd, legs=np.full((len(t_cmd), N), math.radians(60.0)))
    t = np.arange(0.0, 20.0, 0.01)
    z = 1.0 + np.interp(t - 0.1, t_cmd, np.concatenate([[0.0], np.cumsum(vz[:-1] * 0.02)]))
    rpy = np.column_stack([np.interp(t, t_cmd, roll) + ROLL_RIPPLE * np.sin(2 * np.pi * t), 0 * t, 0 * t])
    legs = np.full((len(t), N), math.radians(60.0))
    legs[:, 1] += LEG2_OFFSET
    truth = fr.TruthSeries(t=t, position=np.column_stack([0 * t, 0 * t, z]),
                           velocity=np.column_stack([0 * t, 0 * t, np.interp(t - 0.1, t_cmd, vz)]), rpy=rpy,
                           legs=legs, thrusts=np.full((len(t), N), 11.5))
    t_status = np.arange(0.0, 20.0, 0.1)
    state = np.select([t_status < 1.0, t_status < 3.0, t_status < 18.0], [1, 2, 4], 5)
    t_diag = np.arange(0.0, 20.0, 0.02)
    uavs = [fr.UavSeries(uav_id=i, status_t=t_status, bridge_state=state, diagnostics_t=t_diag,
                         active_mode=np.where(t_diag < 0.5, 2, 1), fallback=t_diag < 0.5, setpoint_t=t_diag,
                         setpoint_thrust=np.full(len(t_diag), 11.6)) for i in range(1, N + 1)]
    return fr.FlightRecord(n=N, truth=truth, command=command, uavs=uavs, names=NAMES, scenario="synthetic.yaml",
                           script="synthetic_script.yaml", controller_mode="communicating", cameras="emulated",
                           sim_time=20.0, wall_time=25.0, lockstep_timeouts=2)


# ------------------------------------------------------------------------------------------------ metrics
def test_hold_is_a_zero_order_hold_with_a_value_before_the_first_sample():
    held = fr.hold(np.array([-1.0, 0.0, 0.5, 1.0, 7.0]), np.array([0.0, 1.0]), np.array([4, 5]), before=-1)
    assert held.tolist() == [-1, 4, 4, 5, 5]
    assert fr.hold(np.array([1.0]), np.zeros(0), np.zeros(0), before=-7).tolist() == [-7]


def test_metrics_of_a_synthetic_flight():
    m = fr.compute_metrics(_synthetic_record())
    assert m.offboard_time == pytest.approx(3.0)
    # airborne (z > lowest + 5 cm) from ~6.27 s to the end of the descent, while FLY and OFFBOARD
    assert m.tracking_window[0] == pytest.approx(6.0 + 0.1 + 0.05 / RATE, abs=0.03)
    assert m.tracking_window[1] == pytest.approx(18.0 - 0.05 / RATE + 0.1, abs=0.05)
    assert m.roll.rmse == pytest.approx(math.degrees(ROLL_RIPPLE) / math.sqrt(2), rel=0.05)
    assert m.roll.max_abs == pytest.approx(math.degrees(ROLL_RIPPLE), rel=0.01)
    assert m.pitch.rmse == pytest.approx(0.0, abs=1e-12)
    assert [e.rmse for e in m.legs_each] == pytest.approx([0.0, math.degrees(LEG2_OFFSET), 0.0], abs=1e-9)
    assert m.legs.rmse == pytest.approx(math.degrees(LEG2_OFFSET) / math.sqrt(N), rel=1e-6)
    # the 0.1 s lag of a 0.3 m/s step: |error| = 0.3 m/s for 0.1 s at the speed changes inside the window
    assert m.vertical_velocity.max_abs == pytest.approx(RATE, abs=1e-9)
    assert [s.commanded for s in m.rate_segments] == pytest.approx([RATE, -RATE], abs=1e-9)
    assert [s.achieved for s in m.rate_segments] == pytest.approx([RATE, -RATE], abs=1e-3)
    assert m.rate_segments[0].start == pytest.approx(7.0, abs=0.03)  # RATE_SETTLE after the start
    assert m.max_height_gain == pytest.approx(4.0 * RATE, abs=0.01)
    assert m.fallback_periods == [25] * N and m.fallback_periods_tracking == [0] * N
    assert m.final_bridge_states == ["LANDING"] * N
    assert m.real_time_factor == pytest.approx(0.8)
    assert m.lockstep_timeouts == 2


def test_worse_tracking_gives_larger_errors():
    record = _synthetic_record()
    worse = copy.deepcopy(record)
    worse.truth.rpy[:, 1] += math.radians(2.0)
    worse.truth.legs[:, 0] -= math.radians(3.0)
    good, bad = fr.compute_metrics(record), fr.compute_metrics(worse)
    assert bad.pitch.rmse == pytest.approx(2.0) and good.pitch.rmse < 1e-9
    assert bad.legs_each[0].rmse == pytest.approx(3.0) and bad.legs.rmse > good.legs.rmse


def test_a_flight_that_never_took_off_reports_no_tracking():
    record = _synthetic_record()
    record.truth.position[:, 2] = 1.0
    for uav in record.uavs:
        uav.bridge_state = np.minimum(uav.bridge_state, 2)  # never OFFBOARD
    m = fr.compute_metrics(record)
    assert m.offboard_time is None and m.tracking_window is None
    assert m.roll is None and m.legs is None and m.legs_each == []
    assert "n/a" in fr.format_summary(m)


def test_an_empty_record_still_reports(tmp_path):
    empty = fr.FlightRecord(
        n=N, truth=fr.TruthSeries(t=np.zeros(0), position=np.zeros((0, 3)), velocity=np.zeros((0, 3)),
                                  rpy=np.zeros((0, 3)), legs=np.zeros((0, N)), thrusts=np.zeros((0, N))),
        command=fr.CommandSeries(t=np.zeros(0), mode=np.zeros(0, dtype=int), velocity=np.zeros((0, 3)),
                                 roll=np.zeros(0), pitch=np.zeros(0), legs=np.zeros((0, N))),
        uavs=[fr.UavSeries(uav_id=i, status_t=np.zeros(0), bridge_state=np.zeros(0, dtype=int),
                           diagnostics_t=np.zeros(0), active_mode=np.zeros(0, dtype=int),
                           fallback=np.zeros(0, dtype=bool), setpoint_t=np.zeros(0), setpoint_thrust=np.zeros(0))
              for i in range(1, N + 1)], names=NAMES, completed=False)
    m = fr.compute_metrics(empty)
    assert m.offboard_time is None and m.rate_segments == [] and not m.completed
    assert math.isnan(m.real_time_factor)
    fr.write_metrics_json(m, str(tmp_path / "metrics.json"))
    assert json.loads((tmp_path / "metrics.json").read_text())["real_time_factor"] is None  # NaN -> null
    assert "INCOMPLETE" in fr.format_summary(m)
    assert len(fr.write_plots(empty, str(tmp_path), dpi=40)) == 5


def test_summary_json_and_plots_are_written(tmp_path):
    record = _synthetic_record()
    m = fr.compute_metrics(record)
    summary = fr.format_summary(m)
    for expected in ("roll error RMSE / max", "climb 7.0-10.0 s", "descent", "lockstep timeouts", "0.80"):
        assert expected in summary, summary
    fr.write_metrics_json(m, str(tmp_path / "metrics.json"))
    data = json.loads((tmp_path / "metrics.json").read_text())
    assert data["roll"]["unit"] == "deg" and data["roll"]["rmse"] == pytest.approx(m.roll.rmse)
    assert len(data["rate_segments"]) == 2 and data["offboard_time"] == pytest.approx(3.0)
    paths = fr.write_plots(record, str(tmp_path), dpi=50)
    assert [os.path.basename(p) for p in paths] == ["height_velocity.png", "roll_pitch.png", "leg_angles.png",
                                                    "thrusts.png", "modes.png"]
    for path in paths:
        with open(path, "rb") as stream:
            assert stream.read(8) == b"\x89PNG\r\n\x1a\n"
        assert os.path.getsize(path) > 5000


# ------------------------------------------------------------------------------------------------ MCAP
@pytest.fixture(scope="module")
def ros_messages():
    """One filled sample per demo channel with distinct stamps (topic -> list of messages)."""
    import msg_samples
    from rosgraph_msgs.msg import Clock

    def stamped(make, t):
        msg = make()
        stamp = msg.header.stamp if hasattr(msg, "header") else msg.clock
        stamp.sec, stamp.nanosec = int(t), int(round((t % 1.0) * 1e9))
        return msg

    def clock():
        return Clock()

    messages = {"/fpr/ground_truth": [stamped(msg_samples.fpr_state, 1.5), stamped(msg_samples.fpr_state, 0.25)],
                "/fpr/teleop": [stamped(msg_samples.teleop_command, 0.5)],
                "/fpr/info": [stamped(msg_samples.information_vector, 0.75)],
                "/clock": [stamped(clock, 0.004), stamped(clock, 0.008)]}
    for i in range(1, N + 1):
        ns = f"/fpr/uav{i}"
        messages[f"{ns}/status"] = [stamped(msg_samples.uav_status, 1.0 + i)]
        messages[f"{ns}/diagnostics"] = [stamped(msg_samples.controller_status, 2.0 + i)]
        messages[f"{ns}/local_state"] = [stamped(msg_samples.local_state, 3.0 + i)]
        messages[f"{ns}/setpoint"] = [stamped(msg_samples.attitude_thrust_setpoint, 4.0 + i)]
        messages[f"{ns}/wrench"] = [stamped(msg_samples.wrench_estimate, 5.0 + i)]
    return messages


def test_message_definition_is_complete_ros2msg():
    from mcap_log import DELIMITER, message_definition

    from fpr_msgs.msg import FprState

    text = message_definition(FprState)
    blocks = text.split(f"\n{DELIMITER}\n")
    assert blocks[0].startswith("#") and "geometry_msgs/Pose platform_pose" in blocks[0]
    names = [b.split("\n", 1)[0] for b in blocks[1:]]
    assert all(n.startswith("MSG: ") for n in names)
    names = [n[len("MSG: "):] for n in names]
    assert len(names) == len(set(names))  # each dependency once
    assert set(names) == {"std_msgs/Header", "builtin_interfaces/Time", "geometry_msgs/Pose", "geometry_msgs/Point",
                          "geometry_msgs/Quaternion", "geometry_msgs/Twist", "geometry_msgs/Vector3"}
    header = blocks[1 + names.index("std_msgs/Header")]
    assert "builtin_interfaces/Time stamp" in header and "string frame_id" in header


def test_mcap_round_trip(tmp_path, ros_messages):
    from mcap.reader import make_reader
    from mcap_log import DELIMITER, RosMcapWriter
    from rclpy.serialization import deserialize_message
    from swarm_recording import Snapshot, mcap_channels, write_mcap

    channels = mcap_channels(N)
    assert set(channels) == set(ros_messages)
    path = str(tmp_path / "flight.mcap")
    snapshot = Snapshot.__new__(Snapshot)  # the demo's snapshot, filled by hand instead of from live recorders
    snapshot.truth, snapshot.teleop = ros_messages["/fpr/ground_truth"], ros_messages["/fpr/teleop"]
    snapshot.info, snapshot.clock = ros_messages["/fpr/info"], ros_messages["/clock"]
    for kind, attribute in (("status", "status"), ("diagnostics", "diagnostics"), ("local_state", "local_state"),
                            ("setpoint", "setpoints"), ("wrench", "wrench")):
        setattr(snapshot, attribute, {i: ros_messages[f"/fpr/uav{i}/{kind}"] for i in range(1, N + 1)})
    with RosMcapWriter(path, metadata={"scenario": "synthetic"}) as writer:
        for topic, msg_type in channels.items():
            writer.add_channel(topic, msg_type)
        count = write_mcap(writer, snapshot)
    assert count == sum(len(v) for v in ros_messages.values())

    with open(path, "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert {c.topic for c in summary.channels.values()} == set(channels)
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            msg_type = channels[channel.topic]
            assert channel.message_encoding == "cdr"
            assert schema.encoding == "ros2msg"
            assert schema.name == f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"
            text = schema.data.decode("utf-8")
            assert f"{DELIMITER}\nMSG: builtin_interfaces/Time\n" in text
        assert summary.statistics.message_count == count
        assert [m.metadata["scenario"] for m in reader.iter_metadata()] == ["synthetic"]
        read: dict[str, list] = {}
        log_times = []
        for _, channel, message in reader.iter_messages(log_time_order=False):
            msg = deserialize_message(message.data, channels[channel.topic])
            stamp = msg.header.stamp if hasattr(msg, "header") else msg.clock
            assert message.log_time == message.publish_time == stamp.sec * 10 ** 9 + stamp.nanosec
            read.setdefault(channel.topic, []).append(msg)
            log_times.append(message.log_time)
    assert log_times == sorted(log_times)  # written in simulation-time order
    for topic, msgs in ros_messages.items():
        expected = sorted(msgs, key=lambda m: (m.header.stamp if hasattr(m, "header") else m.clock).sec * 10 ** 9
                          + (m.header.stamp if hasattr(m, "header") else m.clock).nanosec)
        assert read[topic] == expected, topic


def test_mcap_writer_refuses_a_wrong_type_on_a_channel(tmp_path, ros_messages):
    from mcap_log import RosMcapWriter

    with RosMcapWriter(str(tmp_path / "x.mcap")) as writer:
        writer.write("/fpr/teleop", ros_messages["/fpr/teleop"][0])
        with pytest.raises(TypeError):
            writer.write("/fpr/teleop", ros_messages["/fpr/info"][0])
        assert writer.counts == {"/fpr/teleop": 1}


def test_state_names_come_from_the_message_constants():
    from swarm_recording import state_names

    from fpr_msgs.msg import TeleopCommand, UavStatus

    names = state_names()
    assert names.bridge_state[UavStatus.STATE_OFFBOARD] == "OFFBOARD"
    assert names.teleop_mode[TeleopCommand.MODE_LAND] == "LAND"
    assert names.controller_mode[1] == "COMMUNICATING" and names.fly_mode == TeleopCommand.MODE_FLY
