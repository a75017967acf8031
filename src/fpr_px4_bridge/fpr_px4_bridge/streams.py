"""The PX4 telemetry rates a bridge asks for (ROS-free, explicit time, no I/O).

PX4 streams its own defaults on an onboard MAVLink link (mavlink_main.cpp, ``MAVLINK_MODE_ONBOARD``: ATTITUDE
100 Hz, ATTITUDE_QUATERNION 50 Hz, HIGHRES_IMU 50 Hz, LOCAL_POSITION_NED 30 Hz, ...). The bridge reads
ATTITUDE_QUATERNION (attitude and body rates: ``imu``), HIGHRES_IMU (specific force), LOCAL_POSITION_NED
(velocity, the flight envelope) and the battery messages, and needs the first three at the controllers' 50 Hz;
it never reads ATTITUDE (the same attitude as Euler angles, 100 of the ~260 frames PX4 sends per second). So by
default (:data:`DEFAULT_MESSAGE_RATES`, node parameter ``message_rates``) it asks PX4 for LOCAL_POSITION_NED at
50 Hz instead of 30, and for no ATTITUDE: less load on the link (a serial line on the vehicle) and less to
decode; on the simulated swarm ~4 % of the CPU at n = 6.

Protocol: once PX4 is heard, one ``MAV_CMD_SET_MESSAGE_INTERVAL`` (511; param1 message id, param2 interval
[µs], −1 = stop the stream) per entry, in order, one at a time. The next goes out after PX4's COMMAND_ACK for
511: ACCEPTED, or a refusal (warned: PX4 keeps its own rate for that message). Without an ACK the request is
repeated every ``retry_interval`` and dropped after ``max_attempts`` (warned). After the link was lost and
regained (PX4 may have rebooted and forgotten the rates) the whole list is sent again. One info line when done.

Limits: COMMAND_ACK does not say which message a 511 was for; with one request outstanding at a time, a late ACK
of a repeated request can be taken for the next request's. The worst case is a stream left at PX4's default rate
(the bridge reads what arrives at any rate; the flight envelope's 0.5 s staleness rule still holds at 2 Hz).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from fpr_px4_bridge.offboard import CommandRequest, LogEvent
from fpr_px4_bridge.px4_protocol import MAV_CMD_SET_MESSAGE_INTERVAL, MAV_RESULT_ACCEPTED, MAV_RESULT_NAMES

__all__ = ["DEFAULT_MESSAGE_RATES", "READ_MESSAGES", "StreamConfigurator", "StreamRequest", "parse_message_rates"]

#: node parameter ``message_rates``'s default: "NAME=rate [Hz]", 0 stops the stream, "NAME=default" restores PX4's
DEFAULT_MESSAGE_RATES = ("ATTITUDE=0", "ATTITUDE_QUATERNION=50", "HIGHRES_IMU=50", "LOCAL_POSITION_NED=50")
#: what the bridge reads (fpr_px4_bridge.telemetry): these may not be stopped
READ_MESSAGES = frozenset({"ATTITUDE_QUATERNION", "HIGHRES_IMU", "SCALED_IMU", "ODOMETRY", "LOCAL_POSITION_NED",
                           "SYS_STATUS", "BATTERY_STATUS"})
#: [Hz] highest rate that may be asked for (PX4's fastest onboard streams run at a few hundred Hz)
MAX_RATE = 1000.0
_MAV_RESULT_IN_PROGRESS = 5


@dataclass(frozen=True)
class StreamRequest:
    """One stream: MAVLink message ``name`` (id ``message_id``) at ``rate`` [Hz]; 0: stopped; NaN: PX4's
    default."""

    name: str
    message_id: int
    rate: float

    @property
    def interval_us(self) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL's param2: −1 stops, 0 restores the default, else the period [µs]."""
        if math.isnan(self.rate):
            return 0
        return -1 if self.rate == 0.0 else int(round(1e6 / self.rate))

    def describe(self) -> str:
        if math.isnan(self.rate):
            return f"{self.name} at PX4's default rate"
        return f"{self.name} off" if self.rate == 0.0 else f"{self.name} {self.rate:g} Hz"

    def command(self) -> CommandRequest:
        return CommandRequest(MAV_CMD_SET_MESSAGE_INTERVAL,
                              (float(self.message_id), float(self.interval_us), 0.0, 0.0, 0.0, 0.0, 0.0),
                              f"SET_MESSAGE_INTERVAL {self.describe()}")


def parse_message_rates(entries: Sequence[str]) -> tuple[StreamRequest, ...]:
    """``["NAME=rate", ...]`` -> requests; rate in Hz (0: stop; ``default``: PX4's own rate). Raises ValueError with
    the offending entry: unknown message, HEARTBEAT (the link's proof of life and PX4's mode), a message the bridge
    reads set to 0, a rate outside [0, 1000] Hz, a message named twice."""
    requests: list[StreamRequest] = []
    for entry in entries:
        name, sep, value = str(entry).partition("=")
        name, value = name.strip().upper(), value.strip().lower()
        if not sep or not name or not value:
            raise ValueError(f"message_rates entry {entry!r}: expected 'NAME=rate' (e.g. 'ATTITUDE=0')")
        message_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}", None)
        if not isinstance(message_id, int):
            raise ValueError(f"message_rates entry {entry!r}: {name} is not a MAVLink common message")
        if name == "HEARTBEAT":
            raise ValueError("message_rates: HEARTBEAT is PX4's proof of life and mode report; leave it at PX4's "
                             "rate")
        if value == "default":
            rate = math.nan
        else:
            try:
                rate = float(value)
            except ValueError:
                raise ValueError(f"message_rates entry {entry!r}: the rate must be a number [Hz] or 'default'") \
                    from None
            if not 0.0 <= rate <= MAX_RATE:
                raise ValueError(f"message_rates entry {entry!r}: the rate must be in [0, {MAX_RATE:g}] Hz")
            if rate == 0.0 and name in READ_MESSAGES:
                raise ValueError(f"message_rates entry {entry!r}: the bridge reads {name}, it may not be stopped")
        if any(r.name == name for r in requests):
            raise ValueError(f"message_rates: {name} is named twice")
        requests.append(StreamRequest(name, message_id, rate))
    return tuple(requests)


class StreamConfigurator:
    """Sends the requests of :func:`parse_message_rates` to PX4, one at a time (module doc). Times [s]."""

    def __init__(self, requests: Sequence[StreamRequest], retry_interval: float = 0.5, max_attempts: int = 6) -> None:
        if retry_interval <= 0.0 or max_attempts < 1:
            raise ValueError("retry_interval must be > 0 and max_attempts >= 1")
        self.requests = tuple(requests)
        self.retry_interval = float(retry_interval)
        self.max_attempts = int(max_attempts)
        self._index = len(self.requests)  # nothing to do before PX4 is heard
        self._attempts = 0
        self._last_sent = -math.inf
        self._was_connected = False
        self._outcomes: list[str] = []  # per request of this round: "" confirmed, else why not
        self._events: list[LogEvent] = []
        self.rounds = 0  #: rounds started (the first connection and every regained link)

    @property
    def done(self) -> bool:
        """No request outstanding (all answered or dropped; also before PX4 was heard)."""
        return self._index >= len(self.requests)

    def take_events(self) -> list[LogEvent]:
        events, self._events = self._events, []
        return events

    def step(self, now: float, connected: bool) -> list[CommandRequest]:
        """The command to send now (at most one), given whether PX4 is heard at ``now``."""
        if connected and not self._was_connected and self.requests:
            self._index, self._attempts, self._last_sent, self._outcomes = 0, 0, -math.inf, []
            self.rounds += 1
            if self.rounds > 1:
                self._events.append(LogEvent("info", "streams.again", "PX4 link regained: requesting the "
                                                                      "telemetry rates again"))
        self._was_connected = connected
        if not connected or self.done or now - self._last_sent < self.retry_interval:
            return []
        if self._attempts >= self.max_attempts:
            self._finish_one(f"no answer after {self.max_attempts} attempts")
            if self.done:
                return []
        self._attempts += 1
        self._last_sent = now
        return [self.requests[self._index].command()]

    def on_command_ack(self, result: int, now: float) -> None:
        """PX4's COMMAND_ACK for MAV_CMD_SET_MESSAGE_INTERVAL (the outstanding request's)."""
        if self.done or self._attempts == 0 or result == _MAV_RESULT_IN_PROGRESS:
            return
        self._finish_one("" if result == MAV_RESULT_ACCEPTED else MAV_RESULT_NAMES.get(result, f"result {result}"))

    def _finish_one(self, problem: str) -> None:
        request = self.requests[self._index]
        if problem:
            self._events.append(LogEvent("warn", f"streams.{request.name}",
                                         f"PX4 did not take {request.describe()} ({problem}): it keeps its own rate"))
        self._outcomes.append(problem)
        self._index += 1
        self._attempts, self._last_sent = 0, -math.inf
        if self.done:
            taken = [r.describe() for r, p in zip(self.requests, self._outcomes, strict=True) if not p]
            if taken:
                self._events.append(LogEvent("info", "streams.done", "PX4 telemetry: " + ", ".join(taken)))
