"""ROS side of the demo: a small logger node for the topics the swarm's recorder does not keep, the message
-> numpy conversion into :class:`flight_report.FlightRecord`, and the MCAP log of everything recorded."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from flight_report import CommandSeries, FlightRecord, StateNames, TruthSeries, UavSeries
from mcap_log import RosMcapWriter, stamp_ns
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from fpr_msgs.msg import (
    AttitudeThrustSetpoint,
    ControllerStatus,
    FprState,
    InformationVector,
    LocalState,
    TeleopCommand,
    UavStatus,
    WrenchEstimate,
)


def _stamp(msg: Any) -> float:
    return stamp_ns(msg) * 1e-9


def constant_names(msg_type: type, prefix: str) -> dict[int, str]:
    """``{value: name}`` of a message's ``PREFIX_NAME=value`` constants, e.g. UavStatus.STATE_OFFBOARD."""
    return {int(getattr(msg_type, name)): name[len(prefix):]
            for name in dir(msg_type) if name.startswith(prefix) and name.isupper()}


def state_names() -> StateNames:
    return StateNames(teleop_mode=constant_names(TeleopCommand, "MODE_"),
                      bridge_state=constant_names(UavStatus, "STATE_"),
                      controller_mode=constant_names(ControllerStatus, "MODE_"),
                      fly_mode=TeleopCommand.MODE_FLY, offboard_state=UavStatus.STATE_OFFBOARD)


class TopicLogger(Node):
    """Keeps ``/fpr/info``, every ``/fpr/uav<i>/wrench`` and ``/clock`` (the swarm recorder keeps the rest),
    spun by its own executor thread in the swarm's context. Best-effort subscriptions match both the
    best-effort and the reliable publishers."""

    def __init__(self, context, n: int) -> None:
        super().__init__("demo_topic_logger", context=context)
        self.n = n
        self.lock = threading.Lock()
        self.info: list[InformationVector] = []
        self.clock: list[Clock] = []
        self.wrench: dict[int, list[WrenchEstimate]] = {i: [] for i in range(1, n + 1)}
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.create_subscription(InformationVector, "/fpr/info", self._keep(self.info), qos)
        self.create_subscription(Clock, "/clock", self._keep(self.clock), qos)
        for i in range(1, n + 1):
            self.create_subscription(WrenchEstimate, f"/fpr/uav{i}/wrench", self._keep(self.wrench[i]), qos)
        self._executor = SingleThreadedExecutor(context=context)
        self._executor.add_node(self)
        self._running = True
        self._thread = threading.Thread(target=self._spin, name="demo_topic_logger", daemon=True)
        self._thread.start()

    def _keep(self, store: list):
        def callback(msg) -> None:
            with self.lock:
                store.append(msg)
        return callback

    def _spin(self) -> None:
        while self._running and self.context.ok():
            try:
                self._executor.spin_once(timeout_sec=0.05)
            except Exception:  # noqa: BLE001 - context shut down under us at exit
                if not self._running or not self.context.ok():
                    return
                raise

    def wait_for_publishers(self, timeout: float = 20.0) -> None:
        """Until every logged topic has its publishers (discovery), or ``TimeoutError``."""
        expected = {"/fpr/info": self.n, "/clock": 1, **{f"/fpr/uav{i}/wrench": 1 for i in range(1, self.n + 1)}}
        deadline = time.monotonic() + timeout
        while missing := [t for t, count in expected.items() if self.count_publishers(t) < count]:
            if time.monotonic() > deadline:
                raise TimeoutError(f"demo logger: no publisher yet on {missing}")
            time.sleep(0.05)

    def wait_for_clock(self, sim_time: float, timeout: float = 30.0) -> bool:
        """Until the newest ``/clock`` kept is at ``sim_time`` [s] (the executor may lag the simulation)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                if self.clock and stamp_ns(self.clock[-1]) * 1e-9 >= sim_time - 1e-6:
                    return True
            time.sleep(0.01)
        return False

    def stop(self) -> None:
        self._running = False
        self._thread.join(timeout=5.0)
        self._executor.shutdown(timeout_sec=1.0)
        self.destroy_node()


# ------------------------------------------------------------------------------------------------ snapshot
class Snapshot:
    """Copies of every recorded message list (taken under the recorders' locks at the end of the flight)."""

    def __init__(self, recorder, logger: TopicLogger) -> None:
        with recorder.lock:
            self.truth: list[FprState] = list(recorder.truth)
            self.teleop: list[TeleopCommand] = list(recorder.teleop)
            self.status = {i: list(v) for i, v in recorder.status.items()}
            self.diagnostics = {i: list(v) for i, v in recorder.diagnostics.items()}
            self.local_state = {i: list(v) for i, v in recorder.local_state.items()}
            self.setpoints = {i: list(v) for i, v in recorder.setpoints.items()}
        with logger.lock:
            self.info = list(logger.info)
            self.clock = list(logger.clock)
            self.wrench = {i: list(v) for i, v in logger.wrench.items()}
        self.truth_arrays = recorder.truth_arrays()
        self.teleop_arrays = recorder.teleop_arrays()

    def topics(self) -> Iterator[tuple[str, list]]:
        """(topic, messages) of every logged topic."""
        yield "/fpr/ground_truth", self.truth
        yield "/fpr/teleop", self.teleop
        yield "/fpr/info", self.info
        yield "/clock", self.clock
        for i in sorted(self.status):
            ns = f"/fpr/uav{i}"
            yield f"{ns}/status", self.status[i]
            yield f"{ns}/diagnostics", self.diagnostics[i]
            yield f"{ns}/local_state", self.local_state[i]
            yield f"{ns}/setpoint", self.setpoints[i]
            yield f"{ns}/wrench", self.wrench.get(i, [])


def mcap_channels(n: int) -> dict[str, type]:
    """Topic -> message type of every channel of the demo's MCAP log."""
    channels: dict[str, type] = {"/fpr/ground_truth": FprState, "/fpr/teleop": TeleopCommand,
                                 "/fpr/info": InformationVector, "/clock": Clock}
    for i in range(1, n + 1):
        ns = f"/fpr/uav{i}"
        channels.update({f"{ns}/status": UavStatus, f"{ns}/diagnostics": ControllerStatus,
                         f"{ns}/local_state": LocalState, f"{ns}/setpoint": AttitudeThrustSetpoint,
                         f"{ns}/wrench": WrenchEstimate})
    return channels


def write_mcap(writer: RosMcapWriter, snapshot: Snapshot) -> int:
    """All recorded messages into ``writer`` in log-time (simulation time) order; returns the count."""
    entries = [(stamp_ns(msg), topic, msg) for topic, msgs in snapshot.topics() for msg in msgs]
    entries.sort(key=lambda entry: entry[0])
    for time_ns, topic, msg in entries:
        writer.write(topic, msg, log_time_ns=time_ns)
    return len(entries)


# ------------------------------------------------------------------------------------------------ record
def _sorted_series(msgs: list, *fields) -> tuple[np.ndarray, ...]:
    t = np.array([_stamp(m) for m in msgs], dtype=float)
    order = np.argsort(t, kind="stable")
    columns = [np.array([f(m) for m in msgs])[order] if msgs else np.zeros(0) for f in fields]
    return (t[order], *columns)


def flight_record(snapshot: Snapshot, n: int, **run_info) -> FlightRecord:
    """Message lists -> the numpy :class:`FlightRecord` the report works on."""
    truth, teleop = snapshot.truth_arrays, snapshot.teleop_arrays
    uavs = []
    for i in range(1, n + 1):
        status_t, state = _sorted_series(snapshot.status[i], lambda m: m.state)
        diagnostics_t, active, fallback = _sorted_series(snapshot.diagnostics[i], lambda m: m.active_mode,
                                                         lambda m: m.fallback_active)
        setpoint_t, thrust = _sorted_series(snapshot.setpoints[i], lambda m: m.thrust)
        uavs.append(UavSeries(uav_id=i, status_t=status_t, bridge_state=state.astype(int),
                              diagnostics_t=diagnostics_t, active_mode=active.astype(int),
                              fallback=fallback.astype(bool), setpoint_t=setpoint_t,
                              setpoint_thrust=thrust.astype(float)))
    return FlightRecord(
        n=n,
        truth=TruthSeries(t=truth["t"], position=truth["position"], velocity=truth["velocity"], rpy=truth["rpy"],
                          legs=truth["legs"], thrusts=truth["thrusts"]),
        command=CommandSeries(t=teleop["t"], mode=teleop["mode"], velocity=teleop["velocity"], roll=teleop["roll"],
                              pitch=teleop["pitch"], legs=teleop["legs"]),
        uavs=uavs, names=state_names(), **run_info)
