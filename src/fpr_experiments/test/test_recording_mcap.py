"""Recorded messages -> FlightRecord and -> flight.mcap (real rclpy serialization; no node is started)."""

from __future__ import annotations

import json
import math

import pytest
from fpr_experiments.mcap_log import DELIMITER, RosMcapWriter, message_definition
from fpr_experiments.recording import PILOT_EVENTS, Recording, flight_record, state_names, write_mcap
from geometry_msgs.msg import Pose, Vector3
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from fpr_msgs.msg import ControllerStatus, FprState, TeleopCommand, UavStatus

N = 3


def _stamp(msg, t: float):
    stamp = msg.header.stamp if hasattr(msg, "header") else msg.clock
    stamp.sec, stamp.nanosec = int(t), int(round((t % 1.0) * 1e9))
    return msg


def _truth(t: float, z: float) -> FprState:
    msg = _stamp(FprState(), t)
    msg.platform_pose.position.z = z
    msg.platform_pose.orientation.w = 1.0
    msg.leg_angles, msg.leg_rates = [1.0] * N, [0.0] * N
    msg.uav_poses = [Pose() for _ in range(N)]
    for pose in msg.uav_poses:
        pose.orientation.w = 1.0
        pose.position.z = z - 0.9
    msg.uav_velocities = [Vector3() for _ in range(N)]
    msg.uav_thrusts = [11.0] * N
    msg.external_wrench = [0.0, 0.0, -1.96] + [0.0] * (3 + N)
    msg.payload_mass = 0.2
    msg.battery_voltages = [12.1] * N
    return msg


def _recording() -> Recording:
    teleop = _stamp(TeleopCommand(), 0.5)
    teleop.mode = TeleopCommand.MODE_FLY
    teleop.leg_angles, teleop.leg_rates = [1.0] * N, [0.0] * N
    teleop.roll = 0.1
    diagnostics = _stamp(ControllerStatus(), 0.6)
    diagnostics.desired_position.z = 2.0
    diagnostics.desired_roll = 0.1
    diagnostics.desired_leg_angles = [1.0] * N
    status = _stamp(UavStatus(), 0.7)
    status.state = UavStatus.STATE_OFFBOARD
    messages = {"/fpr/ground_truth": [_truth(1.5, 2.0), _truth(0.25, 1.5)], "/fpr/teleop": [teleop],
                "/clock": [_stamp(Clock(), 0.004), _stamp(Clock(), 0.008)],
                PILOT_EVENTS: [String(data=json.dumps({"t": 1.25, "event": "task_end", "kind": "goto",
                                                       "success": True}))]}
    for i in range(1, N + 1):
        messages[f"/fpr/uav{i}/controller_status"] = [diagnostics]
        messages[f"/fpr/uav{i}/status"] = [status]
    return Recording(messages, {k: [serialize_message(m) for m in v] for k, v in messages.items()},
                     {k: type(v[0]) for k, v in messages.items()})


def test_flight_record_from_messages():
    record = flight_record(_recording(), N, experiment="x")
    assert record.truth.t.tolist() == [0.25, 1.5]  # sorted by stamp
    assert record.truth.position[:, 2].tolist() == [1.5, 2.0]
    assert record.truth.uav_positions.shape == (2, N, 3) and record.truth.uav_positions[0, 0, 2] == pytest.approx(0.6)
    assert record.truth.external_wrench[0, 2] == pytest.approx(-1.96) and record.truth.payload_mass[1] == 0.2
    assert record.command.mode.tolist() == [TeleopCommand.MODE_FLY] and record.command.roll[0] == pytest.approx(0.1)
    uav = record.uavs[1]
    assert uav.desired_position[0, 2] == 2.0 and uav.desired_legs.shape == (1, N)
    assert uav.bridge_state.tolist() == [UavStatus.STATE_OFFBOARD]
    assert record.events == [{"t": 1.25, "event": "task_end", "kind": "goto", "success": True}]
    assert math.isclose(record.uavs[0].desired_rpy[0, 0], 0.1)


def test_emergency_entries_name_each_uav_entering_the_emergency_and_why():
    recording = _recording()

    def status(t: float, state: int, own: bool = False, reason: str = "") -> UavStatus:
        msg = _stamp(UavStatus(), t)
        msg.state, msg.emergency_own, msg.emergency_reason = state, own, reason
        return msg

    offboard, emergency = UavStatus.STATE_OFFBOARD, UavStatus.STATE_EMERGENCY
    why = "platform tilt above max_platform_tilt 45° for 0.3 s (the structure is out of control)"
    recording.messages["/fpr/uav2/status"] = [status(2.0, emergency, True, why), status(1.0, offboard),
                                              status(2.1, emergency, True, why), status(3.0, offboard),
                                              status(4.0, emergency, True, "again")]
    recording.messages["/fpr/uav1/status"] = [status(1.0, offboard), status(2.05, emergency, False, "uav2 ...")]
    record = flight_record(recording, N)
    entries = [(round(e["t"], 6), e["uav"], e["own"], e["reason"]) for e in record.emergencies]
    assert entries == [(2.0, 2, True, why), (2.05, 1, False, "uav2 ..."),
                       (4.0, 2, True, "again")]  # a status repeated in EMERGENCY is no new entry
    assert flight_record(_recording(), N).emergencies == []


def test_mcap_round_trip(tmp_path):
    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message

    recording = _recording()
    path = str(tmp_path / "flight.mcap")
    writer = write_mcap(recording, path, metadata={"experiment": "synthetic"})
    assert sum(writer.counts.values()) == sum(len(v) for v in recording.messages.values())
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert {c.topic for c in summary.channels.values()} == set(recording.messages)
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert channel.message_encoding == "cdr" and schema.encoding == "ros2msg"
        assert [m.metadata["experiment"] for m in reader.iter_metadata()] == ["synthetic"]
        times, truth = [], []
        for _, channel, message in reader.iter_messages(log_time_order=False):
            times.append(message.log_time)
            if channel.topic == "/fpr/ground_truth":
                truth.append(deserialize_message(message.data, FprState).platform_pose.position.z)
            if channel.topic == PILOT_EVENTS:
                assert message.log_time == 1_250_000_000  # the event's own time
    assert times == sorted(times) and truth == [1.5, 2.0]


def test_message_definition_is_complete_ros2msg():
    text = message_definition(FprState)
    blocks = text.split(f"\n{DELIMITER}\n")
    names = [b.split("\n", 1)[0][len("MSG: "):] for b in blocks[1:]]
    assert len(names) == len(set(names))
    assert {"std_msgs/Header", "builtin_interfaces/Time", "geometry_msgs/Pose"} <= set(names)


def test_mcap_writer_refuses_a_wrong_type_on_a_channel(tmp_path):
    with RosMcapWriter(str(tmp_path / "x.mcap")) as writer:
        writer.write("/fpr/teleop", _stamp(TeleopCommand(), 0.1))
        with pytest.raises(TypeError):
            writer.write("/fpr/teleop", _stamp(Clock(), 0.2))


def test_state_names_come_from_the_message_constants():
    names = state_names()
    assert names.bridge_state[UavStatus.STATE_OFFBOARD] == "OFFBOARD"
    assert names.teleop_mode[TeleopCommand.MODE_LAND] == "LAND" and names.fly_mode == TeleopCommand.MODE_FLY
