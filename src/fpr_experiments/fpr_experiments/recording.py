"""Recording a run (rclpy): one :class:`Recorder` node keeps every topic the experiment reports on, serialized
(raw subscriptions: nothing is deserialized while the simulation runs; in the deterministic runner's in-process
delivery, the published message objects themselves, serialized at the end), in its own executor thread. At the end
:meth:`Recorder.snapshot` deserializes them once into :class:`Recording` (message lists per topic), which
:func:`flight_record` turns into the numpy :class:`~fpr_experiments.records.FlightRecord` of the metrics and
:func:`write_mcap` into ``flight.mcap`` (Foxglove, ``ros2 bag``). Camera images are not recorded (tens of MB per
simulated second); the marker detections made from them are.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import BatteryState, Imu, Joy
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from fpr_experiments.graph import CHECKED_MARKER_TOPIC
from fpr_experiments.mcap_log import RosMcapWriter, stamp_ns
from fpr_experiments.records import (
    CommandSeries,
    FlightRecord,
    StateNames,
    TruthSeries,
    UavSeries,
)
from fpr_msgs.msg import (
    AttitudeThrustSetpoint,
    ControllerStatus,
    FprState,
    InformationVector,
    LocalState,
    MarkerDetection,
    TeleopCommand,
    UavStatus,
    WrenchEstimate,
)

#: topic name of the scripted operator's task events (JSON in std_msgs/String)
PILOT_EVENTS = "/fpr/pilot/events"


@dataclass(frozen=True)
class Topic:
    name: str
    msg_type: type
    reliable: bool  #: the publisher is reliable (subscribe reliable: no drops); else best effort
    latched: bool = False  #: transient local (/tf_static, /robot_description): the last message, whenever joined


def recorded_topics(n: int, pilot: bool = False, target: bool = False,
                    detection_fallback: bool = False) -> list[Topic]:
    """Every topic a run records (see the module doc); ``detection_fallback``: also each UAV's supervised detections
    (fpr_experiments.detection_fallback_node)."""
    topics = [Topic("/clock", Clock, False), Topic("/fpr/ground_truth", FprState, True),
              Topic("/fpr/motion_capture", FprState, True),
              Topic("/fpr/teleop", TeleopCommand, True), Topic("/fpr/info", InformationVector, False),
              Topic("/fpr/ground/joy", Joy, True), Topic("/tf", TFMessage, True),
              Topic("/tf_static", TFMessage, True, latched=True),
              Topic("/robot_description", String, True, latched=True), Topic("/diagnostics", DiagnosticArray, True)]
    if pilot:
        topics.append(Topic(PILOT_EVENTS, String, True))
    if target:
        topics.append(Topic("/fpr/target", PoseStamped, False))
    for i in range(1, n + 1):
        ns = f"/fpr/uav{i}"
        topics += [Topic(f"{ns}/status", UavStatus, True), Topic(f"{ns}/controller_status", ControllerStatus, True),
                   Topic(f"{ns}/local_state", LocalState, True), Topic(f"{ns}/setpoint", AttitudeThrustSetpoint, False),
                   Topic(f"{ns}/wrench", WrenchEstimate, False), Topic(f"{ns}/marker", MarkerDetection, False),
                   Topic(f"{ns}/imu", Imu, False), Topic(f"{ns}/velocity_body", TwistStamped, False),
                   Topic(f"{ns}/battery", BatteryState, True)]
        if detection_fallback:
            topics.append(Topic(f"{ns}/{CHECKED_MARKER_TOPIC}", MarkerDetection, False))
    return topics


class Recorder(Node):
    """Raw subscriptions to ``topics``, spun by its own executor in a background thread unless ``spin`` is False
    (see the module doc)."""

    def __init__(self, context, topics: Iterable[Topic], use_sim_time: bool = True, live_view=None,
                 spin: bool = True) -> None:
        """``live_view``: a :class:`fpr_experiments.live_view.LiveView` every received message is forwarded to
        (the same bytes, stamped with the recorder's clock), or None. ``spin`` False: no executor thread of its
        own; the caller's executor serves the subscriptions (the deterministic in-process runner)."""
        from rclpy.parameter import Parameter

        # swept by the caller (spin False): no default QoS event handlers, as the lean nodes it records (set before
        # Node.__init__, which creates the node's own publishers through create_publisher)
        self._without_event_handlers = not spin
        # swept, it is as lean as the nodes: no type-description service either (node_factory.LEAN_ROS_ARGS)
        lean = [Parameter("start_type_description_service", value=False)] if not spin else []
        super().__init__("experiment_recorder", context=context, use_global_arguments=False,
                         start_parameter_services=False,
                         parameter_overrides=[Parameter("use_sim_time", value=use_sim_time), *lean])
        self.topics = {t.name: t for t in topics}
        self.live_view = live_view
        self.lock = threading.Lock()
        self._data: dict[str, list[bytes]] = {name: [] for name in self.topics}
        for topic in self.topics.values():
            qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE if topic.reliable
                             else ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if topic.latched
                             else DurabilityPolicy.VOLATILE)
            self.create_subscription(topic.msg_type, topic.name, self._keep(self._data[topic.name], topic.name), qos,
                                     raw=True)
        self._running = True
        self._executor: SingleThreadedExecutor | None = None
        self._thread: threading.Thread | None = None
        if spin:
            self._executor = SingleThreadedExecutor(context=context)
            self._executor.add_node(self)
            self._thread = threading.Thread(target=self._spin, name="experiment_recorder", daemon=True)
            self._thread.start()

    def create_publisher(self, *args, event_callbacks=None, **kwargs):
        if event_callbacks is None and self._without_event_handlers:
            from rclpy.event_handler import PublisherEventCallbacks

            event_callbacks = PublisherEventCallbacks(use_default_callbacks=False)
        return super().create_publisher(*args, event_callbacks=event_callbacks, **kwargs)

    def create_subscription(self, *args, event_callbacks=None, **kwargs):
        if event_callbacks is None and self._without_event_handlers:
            from rclpy.event_handler import SubscriptionEventCallbacks

            event_callbacks = SubscriptionEventCallbacks(use_default_callbacks=False)
        return super().create_subscription(*args, event_callbacks=event_callbacks, **kwargs)

    def _keep(self, store: list, topic: str):
        def callback(data) -> None:
            with self.lock:
                store.append(data)
            if self.live_view is not None:
                if not isinstance(data, bytes):
                    data = serialize_message(data)
                self.live_view.log(topic, data, self.get_clock().now().nanoseconds)
        # the in-process delivery (fpr_experiments.intra_process) may hand over the published message object
        # instead of its CDR bytes: kept as it is, serialized at the end (snapshot)
        callback.accepts_messages = True
        return callback

    def _spin(self) -> None:
        while self._running and self.context.ok():
            try:
                self._executor.spin_once(timeout_sec=0.05)
            except Exception:  # noqa: BLE001 - the context shut down under us at exit
                if not self._running or not self.context.ok():
                    return
                raise

    # ---- during the run -------------------------------------------------------------------------------
    def count(self, topic: str) -> int:
        with self.lock:
            return len(self._data[topic])

    def latest(self, topic: str):
        """The newest message of ``topic`` (a copy of its own: the caller may change it), or None."""
        with self.lock:
            data = self._data[topic][-1] if self._data[topic] else None
        if data is None:
            return None
        if not isinstance(data, bytes):
            data = serialize_message(data)
        return deserialize_message(data, self.topics[topic].msg_type)

    def latest_time(self, topic: str) -> float | None:
        with self.lock:
            data = self._data[topic][-1] if self._data[topic] else None
        if data is None:
            return None
        msg = deserialize_message(data, self.topics[topic].msg_type) if isinstance(data, bytes) else data
        return log_time_ns(msg) * 1e-9

    def wait_for_publishers(self, expected: dict[str, int], timeout: float = 20.0) -> None:
        """Until each topic has its number of publishers (discovery), else ``TimeoutError``."""
        deadline = time.monotonic() + timeout
        while missing := [t for t, count in expected.items() if self.count_publishers(t) < count]:
            if time.monotonic() > deadline:
                raise TimeoutError(f"recorder: no publisher yet on {missing}")
            time.sleep(0.05)

    def wait_for(self, topic: str, sim_time: float, timeout: float = 30.0) -> bool:
        """Until the newest ``topic`` message is stamped at or after ``sim_time`` [s] (the graph may lag)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            t = self.latest_time(topic)
            if t is not None and t >= sim_time - 1e-6:
                return True
            time.sleep(0.01)
        return False

    # ---- at the end ---------------------------------------------------------------------------------
    def snapshot(self) -> Recording:
        with self.lock:
            data = {name: list(items) for name, items in self._data.items()}
        messages = {name: [deserialize_message(d, self.topics[name].msg_type) if isinstance(d, bytes) else d
                           for d in items] for name, items in data.items()}
        serialized = {name: [d if isinstance(d, bytes) else serialize_message(d) for d in items]
                      for name, items in data.items()}
        return Recording(messages, serialized, {n: t.msg_type for n, t in self.topics.items()})

    def stop(self) -> None:
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._executor is not None:
            self._executor.shutdown(timeout_sec=1.0)
        self.destroy_node()


@dataclass
class Recording:
    """Deserialized messages per topic (``messages``), their CDR bytes (``serialized``) and types."""

    messages: dict[str, list]
    serialized: dict[str, list[bytes]]
    types: dict[str, type]

    def get(self, topic: str) -> list:
        return self.messages.get(topic, [])


def log_time_ns(msg) -> int:
    """Simulation time [ns] of a recorded message: its header stamp (rosgraph_msgs/Clock: its clock); the
    pilot's JSON events (std_msgs/String) carry theirs as "t" [s]."""
    if hasattr(msg, "header") or hasattr(msg, "clock"):
        return stamp_ns(msg)
    if hasattr(msg, "transforms"):  # tf2_msgs/TFMessage: its first transform's stamp
        return stamp_ns(msg.transforms[0]) if msg.transforms else 0
    import json

    try:
        return int(round(float(json.loads(msg.data)["t"]) * 1e9))
    except (ValueError, KeyError, TypeError, AttributeError):
        return 0


def write_mcap(recording: Recording, path: str, metadata: dict[str, str] | None = None) -> RosMcapWriter:
    """Every recorded message into ``path`` in log-time (simulation time = header stamp) order."""
    writer = RosMcapWriter(path, metadata=metadata)
    try:
        entries = []
        for topic, msgs in recording.messages.items():
            writer.add_channel(topic, recording.types[topic])
            for msg, data in zip(msgs, recording.serialized[topic], strict=True):
                entries.append((log_time_ns(msg), topic, data))
        entries.sort(key=lambda entry: entry[0])
        for time_ns, topic, data in entries:
            writer.write_serialized(topic, data, time_ns)
    finally:
        writer.close()
    return writer


# ------------------------------------------------------------------------------------------------ conversion
def constant_names(msg_type: type, prefix: str) -> dict[int, str]:
    """``{value: name}`` of a message's ``PREFIX_NAME=value`` constants, e.g. UavStatus.STATE_OFFBOARD."""
    return {int(getattr(msg_type, name)): name[len(prefix):]
            for name in dir(msg_type) if name.startswith(prefix) and name.isupper()}


def state_names() -> StateNames:
    return StateNames(teleop_mode=constant_names(TeleopCommand, "MODE_"),
                      bridge_state=constant_names(UavStatus, "STATE_"),
                      controller_mode=constant_names(ControllerStatus, "MODE_"),
                      fly_mode=TeleopCommand.MODE_FLY, land_mode=TeleopCommand.MODE_LAND,
                      offboard_state=UavStatus.STATE_OFFBOARD, emergency_state=UavStatus.STATE_EMERGENCY)


def _t(msg) -> float:
    return log_time_ns(msg) * 1e-9


def _xyz(v) -> list[float]:
    return [v.x, v.y, v.z]


def _wxyz(q) -> list[float]:
    return [q.w, q.x, q.y, q.z]


def _series(msgs: list, width: int | None, extract) -> tuple[np.ndarray, np.ndarray]:
    """(t sorted, values sorted) of ``extract(msg)`` over ``msgs``; (0,) / (0, width) arrays when empty."""
    t = np.array([_t(m) for m in msgs], dtype=float)
    order = np.argsort(t, kind="stable")
    if not msgs:
        return t, np.zeros((0,) if width is None else (0, width))
    values = np.array([extract(m) for m in msgs], dtype=float)
    return t[order], values[order]


def _relative_from_marker(msg, calibration) -> list[float]:
    """p_T_bi (4.2) of one marker detection as [x, y, z, qw, qx, qy, qz]."""
    from fpr_estimation.estimator import relative_pose_from_detection
    from fpr_model.rotations import quat_to_rotmat, rotmat_to_quat

    T = np.eye(4)
    T[:3, :3] = quat_to_rotmat(np.asarray(_wxyz(msg.pose.orientation)) / max(
        np.linalg.norm(_wxyz(msg.pose.orientation)), 1e-12))
    T[:3, 3] = _xyz(msg.pose.position)
    relative = relative_pose_from_detection(T, calibration)
    return [*relative[:3, 3], *rotmat_to_quat(relative[:3, :3])]


def flight_record(recording: Recording, n: int, **run_info) -> FlightRecord:
    """Message lists -> the numpy :class:`FlightRecord` (SI units, simulation time [s])."""
    from fpr_model.calibration import load_vision_calibration
    from fpr_model.rotations import quat_to_euler_zyx

    truth_msgs = recording.get("/fpr/ground_truth")
    t, state = _series(truth_msgs, None, lambda m: [
        *_xyz(m.platform_pose.position), *_wxyz(m.platform_pose.orientation), *m.leg_angles, *m.leg_rates,
        *_xyz(m.platform_twist.linear), *_xyz(m.platform_twist.angular), *m.uav_thrusts,
        *[c for p in m.uav_poses for c in (*_xyz(p.position), *_wxyz(p.orientation))],
        *m.external_wrench, m.contact_force, m.payload_mass, *m.battery_voltages]) if truth_msgs else (
        np.zeros(0), np.zeros((0, 0)))
    k = 0

    def take(width: int) -> np.ndarray:
        nonlocal k
        block = state[:, k:k + width] if len(t) else np.zeros((0, width))
        k += width
        return block

    position, quat, legs, leg_rates = take(3), take(4), take(n), take(n)
    velocity, rate, thrusts = take(3), take(3), take(n)
    poses = take(7 * n).reshape(-1, n, 7)
    wrench, contact, payload, battery = take(6 + n), take(1)[:, 0], take(1)[:, 0], take(n)
    rpy = np.array([quat_to_euler_zyx(q / np.linalg.norm(q)) for q in quat]).reshape(-1, 3)
    truth = TruthSeries(t=t, position=position, quat=quat, rpy=rpy, legs=legs, leg_rates=leg_rates,
                        velocity=velocity, rate=rate, thrusts=thrusts, uav_positions=poses[:, :, :3],
                        uav_quats=poses[:, :, 3:], external_wrench=wrench, contact_force=contact,
                        payload_mass=payload, battery=battery)
    teleop = recording.get("/fpr/teleop")
    ct, cv = _series(teleop, 9 + n, lambda m: [
        m.mode, *_xyz(m.platform_velocity), m.yaw_rate, m.roll, m.pitch, m.contact_force, m.roll_rate, *m.leg_angles])
    command = CommandSeries(t=ct, mode=cv[:, 0].astype(int), velocity=cv[:, 1:4], yaw_rate=cv[:, 4],
                            roll=cv[:, 5], pitch=cv[:, 6], contact_force=cv[:, 7], legs=cv[:, 9:])
    calibration = load_vision_calibration(None)
    uavs = []
    for i in range(1, n + 1):
        ns = f"/fpr/uav{i}"
        st, sv = _series(recording.get(f"{ns}/status"), 1, lambda m: [m.state])
        dt, dv = _series(recording.get(f"{ns}/controller_status"), 9 + n, lambda m: [
            m.active_mode, m.fallback_active, *_xyz(m.desired_position), m.desired_roll, m.desired_pitch,
            m.desired_yaw, m.desired_contact_force, *(list(m.desired_leg_angles) or [np.nan] * n)])
        pt, pv = _series(recording.get(f"{ns}/setpoint"), 1, lambda m: [m.thrust])
        wt, wv = _series(recording.get(f"{ns}/wrench"), 7 + n, lambda m: [
            *_xyz(m.platform_force), *_xyz(m.platform_moment), m.contact_force, *m.leg_moments])
        lt, lv = _series(recording.get(f"{ns}/local_state"), 11, lambda m: [
            *_xyz(m.relative_pose.position), *_wxyz(m.relative_pose.orientation), m.leg_angle, m.platform_roll,
            m.platform_pitch, m.valid])
        mt, mv = _series(recording.get(f"{ns}/marker"), 7, lambda m: _relative_from_marker(m, calibration))
        # an emulated (motion-capture) detection has no image: NaN reprojection error (detection_fallback_node)
        kt, kv = _series(recording.get(f"{ns}/{CHECKED_MARKER_TOPIC}"), 1,
                         lambda m: [float(math.isnan(m.reprojection_error))])
        uavs.append(UavSeries(
            uav_id=i, status_t=st, bridge_state=sv[:, 0].astype(int), diagnostics_t=dt,
            active_mode=dv[:, 0].astype(int), fallback=dv[:, 1].astype(bool), desired_position=dv[:, 2:5],
            desired_rpy=dv[:, 5:8], desired_contact_force=dv[:, 8], desired_legs=dv[:, 9:],
            setpoint_t=pt, setpoint_thrust=pv[:, 0], wrench_t=wt, wrench_force=wv[:, 0:3],
            wrench_moment=wv[:, 3:6], wrench_contact=wv[:, 6], wrench_legs=wv[:, 7:], local_t=lt,
            local_position=lv[:, 0:3], local_quat=lv[:, 3:7], local_leg_angle=lv[:, 7], local_roll=lv[:, 8],
            local_pitch=lv[:, 9], local_valid=lv[:, 10].astype(bool), marker_t=mt, marker_position=mv[:, 0:3],
            marker_quat=mv[:, 3:7], checked_t=kt, checked_emulated=kv[:, 0].astype(bool)))
    events = []
    if PILOT_EVENTS in recording.messages:
        import json

        events = [json.loads(m.data) for m in recording.get(PILOT_EVENTS)]
    return FlightRecord(n=n, truth=truth, command=command, uavs=uavs, names=state_names(), events=events,
                        emergencies=emergency_entries(recording, n), **run_info)


def emergency_entries(recording: Recording, n: int) -> list[dict]:
    """Every entry of a UAV's bridge into the swarm's emergency response (UavStatus.STATE_EMERGENCY), with the
    reason its status gave, in time order (:attr:`FlightRecord.emergencies`)."""
    entries = []
    for i in range(1, n + 1):
        previous = None
        for msg in sorted(recording.get(f"/fpr/uav{i}/status"), key=_t):
            if msg.state == UavStatus.STATE_EMERGENCY and previous != UavStatus.STATE_EMERGENCY:
                entries.append({"t": _t(msg), "uav": i, "own": bool(msg.emergency_own),
                                "reason": str(msg.emergency_reason)})
            previous = msg.state
    return sorted(entries, key=lambda e: (e["t"], e["uav"]))
