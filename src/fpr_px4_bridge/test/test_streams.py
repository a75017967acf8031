"""The telemetry rates asked of PX4 (fpr_px4_bridge.streams): parsing, and the one-at-a-time request sequence."""

import math

import pytest
from fpr_px4_bridge.px4_protocol import MAV_CMD_SET_MESSAGE_INTERVAL
from fpr_px4_bridge.streams import DEFAULT_MESSAGE_RATES, StreamConfigurator, parse_message_rates

ACCEPTED, DENIED, IN_PROGRESS = 0, 2, 5


def test_default_rates_parse_to_message_ids_and_intervals():
    requests = parse_message_rates(DEFAULT_MESSAGE_RATES)
    assert [(r.name, r.message_id, r.interval_us) for r in requests] == [
        ("ATTITUDE", 30, -1), ("ATTITUDE_QUATERNION", 31, 20000), ("HIGHRES_IMU", 105, 20000),
        ("LOCAL_POSITION_NED", 32, 20000)]
    command = requests[0].command()
    assert command.command == MAV_CMD_SET_MESSAGE_INTERVAL and command.params[:2] == (30.0, -1.0)


def test_names_are_case_insensitive_and_default_restores_px4s_rate():
    (request,) = parse_message_rates([" sys_status = default "])
    assert request.name == "SYS_STATUS" and math.isnan(request.rate) and request.interval_us == 0
    assert request.describe() == "SYS_STATUS at PX4's default rate"
    assert parse_message_rates(["ODOMETRY=30"])[0].interval_us == 33333


@pytest.mark.parametrize("entry, problem", [
    ("ATTITUDE", "expected 'NAME=rate'"), ("=5", "expected 'NAME=rate'"), ("ATTITUDE=", "expected 'NAME=rate'"),
    ("NOT_A_MESSAGE=5", "not a MAVLink common message"), ("HEARTBEAT=5", "HEARTBEAT"),
    ("ATTITUDE=fast", "must be a number"), ("ATTITUDE=-1", "[0, 1000]"), ("ATTITUDE=nan", "[0, 1000]"),
    ("ATTITUDE=inf", "[0, 1000]"), ("ATTITUDE=1e9", "[0, 1000]"),
    ("ATTITUDE_QUATERNION=0", "may not be stopped"), ("LOCAL_POSITION_NED=0", "may not be stopped"),
])
def test_bad_entries_are_refused_with_the_entry_named(entry, problem):
    with pytest.raises(ValueError) as error:
        parse_message_rates([entry])
    assert problem in str(error.value)


def test_a_message_named_twice_is_refused():
    with pytest.raises(ValueError, match="named twice"):
        parse_message_rates(["ATTITUDE=0", "attitude=10"])


def _ids(commands):
    return [int(c.params[0]) for c in commands]


def test_nothing_is_sent_before_px4_is_heard_then_one_request_at_a_time_each_after_the_previous_ack():
    streams = StreamConfigurator(parse_message_rates(DEFAULT_MESSAGE_RATES))
    assert streams.step(0.0, connected=False) == [] and streams.done
    assert _ids(streams.step(0.02, connected=True)) == [30]
    assert streams.step(0.04, connected=True) == []  # no second request while one is outstanding
    streams.on_command_ack(IN_PROGRESS, 0.05)  # not an answer yet
    assert streams.step(0.06, connected=True) == []
    streams.on_command_ack(ACCEPTED, 0.07)
    assert _ids(streams.step(0.08, connected=True)) == [31]
    for t, expected in ((0.10, [105]), (0.12, [32])):
        streams.on_command_ack(ACCEPTED, t - 0.01)
        assert _ids(streams.step(t, connected=True)) == expected
    assert streams.take_events() == []
    streams.on_command_ack(ACCEPTED, 0.13)
    assert streams.done and streams.step(0.14, connected=True) == []
    (event,) = streams.take_events()
    assert event.level == "info" and event.text == (
        "PX4 telemetry: ATTITUDE off, ATTITUDE_QUATERNION 50 Hz, HIGHRES_IMU 50 Hz, LOCAL_POSITION_NED 50 Hz")
    streams.on_command_ack(ACCEPTED, 0.15)  # a stray ACK after the end changes nothing
    assert streams.done and streams.take_events() == []


def test_unanswered_requests_are_repeated_then_dropped_with_a_warning_and_a_refusal_is_warned():
    streams = StreamConfigurator(parse_message_rates(["ATTITUDE=0", "ODOMETRY=30"]), retry_interval=0.5,
                                 max_attempts=3)
    sent = []
    for k in range(150):  # 3 s at 50 Hz
        t = round(0.02 * k, 2)
        commands = _ids(streams.step(t, connected=True))
        sent += [(t, i) for i in commands]
        if commands == [331]:
            streams.on_command_ack(DENIED, t + 0.01)  # PX4 refuses ODOMETRY; ATTITUDE is never answered
    assert streams.done
    # ATTITUDE: 3 attempts 0.5 s apart, dropped 0.5 s after the last; then ODOMETRY at once, refused
    assert sent == [(0.0, 30), (0.5, 30), (1.0, 30), (1.5, 331)]
    events = streams.take_events()
    assert [e.level for e in events] == ["warn", "warn"]
    assert "ATTITUDE off (no answer after 3 attempts)" in events[0].text
    assert "ODOMETRY 30 Hz (DENIED)" in events[1].text and "keeps its own rate" in events[1].text


def test_a_regained_link_sends_the_whole_list_again():
    streams = StreamConfigurator(parse_message_rates(["ATTITUDE=0"]))
    assert _ids(streams.step(0.0, connected=True)) == [30]
    streams.on_command_ack(ACCEPTED, 0.01)
    assert streams.step(0.02, connected=True) == [] and streams.done
    assert streams.step(0.5, connected=False) == []  # PX4 silent (e.g. rebooting): nothing to send to
    assert _ids(streams.step(3.0, connected=True)) == [30]
    assert streams.rounds == 2
    assert any("requesting the telemetry rates again" in e.text for e in streams.take_events())


def test_no_requests_means_no_commands():
    streams = StreamConfigurator(())
    assert streams.step(0.0, connected=True) == [] and streams.done and streams.rounds == 0


def test_configurator_refuses_a_non_positive_retry_interval_or_attempts():
    with pytest.raises(ValueError):
        StreamConfigurator((), retry_interval=0.0)
    with pytest.raises(ValueError):
        StreamConfigurator((), max_attempts=0)
