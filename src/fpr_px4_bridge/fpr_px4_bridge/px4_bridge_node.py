"""ROS 2 node ``px4_bridge``: one UAV's MAVLink 2 link to PX4 (thin wrapper around :mod:`fpr_px4_bridge.bridge`).

Run in the UAV's namespace: ``ros2 run fpr_px4_bridge px4_bridge --ros-args -r __ns:=/fpr/uav1 -p uav_id:=1``.
Subscribes ``setpoint`` (fpr_msgs/AttitudeThrustSetpoint) and ``/fpr/teleop`` (fpr_msgs/TeleopCommand);
publishes ``imu`` (sensor_msgs/Imu), ``velocity_body`` (geometry_msgs/TwistStamped), ``battery``
(sensor_msgs/BatteryState) and ``status`` (fpr_msgs/UavStatus). All times come from the node clock
(``use_sim_time`` honoured). Each SET_ATTITUDE_TARGET carries the setpoint's header stamp on PX4's boot clock
in ``time_boot_ms`` (ignored by real PX4; used by the simulator's lockstep), see :mod:`fpr_px4_bridge.bridge`.
Thrust normalization: ``battery_compensation`` (default true: f_max (C.2) at the reported voltage) or, false, at
the fixed ``nominal_voltage`` (12.4 V); the choice is logged once at start.
"""

from __future__ import annotations

import math
import select
import threading
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from fpr_model.battery import thrust_coefficients
from fpr_model.diagnostics import ERROR, OK, WARN, StatusReport, to_diagnostic_array
from fpr_model.node_parameters import NodeParameters, Param, node_seconds, settle_heap
from geometry_msgs.msg import TwistStamped
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sensor_msgs.msg import BatteryState, Imu

from fpr_msgs.msg import AttitudeThrustSetpoint, ControllerStatus, InformationVector, TeleopCommand, UavStatus
from fpr_px4_bridge.bridge import BridgeConfig, Px4Bridge
from fpr_px4_bridge.link import MavlinkLink, load_signing_key
from fpr_px4_bridge.offboard import LogEvent, OffboardConfig
from fpr_px4_bridge.streams import DEFAULT_MESSAGE_RATES, parse_message_rates
from fpr_px4_bridge.swarm_guard import SwarmGuardConfig
from fpr_px4_bridge.telemetry import BatterySample, BodyVelocitySample, ImuSample

_PARAMETERS = {
    "uav_id": Param(1, "UAV index i (1-based): MAVLink target system by default, default UDP port 14540 + i - 1",
                    low=1, high=64),
    "connection_url": ("", "udp://HOST:PORT (listen), udpout://HOST:PORT, serial:///dev/X or /dev/X; "
                           "empty: udp://127.0.0.1:(14540 + uav_id - 1)"),
    "baud": (921600, "serial baud rate (serial connections only)"),
    "system_id": Param(0, "our MAVLink system id; 0: the same as target_system (companion-computer convention)",
                       high=255),
    "component_id": Param(191, "our MAVLink component id (191 = MAV_COMP_ID_ONBOARD_COMPUTER)", low=1, high=255),
    "target_system": Param(0, "PX4 system id; 0: uav_id", high=255),
    "target_component": Param(1, "PX4 autopilot component id", low=1, high=255),
    "stream_rate": Param(50.0, "[Hz] SET_ATTITUDE_TARGET repetition rate of the latest setpoint (>= 50)", low=50.0,
                         high=1000.0),
    "setpoint_timeout": Param(0.25, "[s] setpoints older than this are not streamed (PX4's failsafe takes over)",
                              low=0.02, high=5.0),
    "thrust_min": Param(0.05, "lower clamp of the normalized thrust (C.1), in [0, 1)", high=0.99),
    "a_f": Param(math.nan, "[N/V] max-thrust slope (C.2); NaN: thesis Table C.1 value of uav_id", low=0.0,
                 high=100.0, allow_nan=True),
    "b_f": Param(math.nan, "[N] max-thrust offset (C.2); NaN: thesis Table C.1 value of uav_id", low=-1000.0,
                 high=1000.0, allow_nan=True),
    "fallback_voltage": Param(12.0, "[V] battery voltage used while PX4 reports none", low=1.0, high=60.0),
    "battery_compensation": (True, "true: f_max (C.2) at the reported battery voltage (Appendix C thrust "
                                   "regulation); false: at nominal_voltage, the thrust falls as the battery sags "
                                   "(the first Exp. I flights, thesis §3.5.1)"),
    "nominal_voltage": Param(12.4, "[V] f_max voltage when battery_compensation is false (charged 3S)", low=1.0,
                             high=60.0),
    "quaternion_tolerance": (1e-3, "setpoints with | |q| - 1 | above this are refused"),
    "thrust_refusal_ratio": Param(1.1, "in [1, 2]: a setpoint thrust above this x f_max (C.2) at the present voltage "
                                  "is "
                                  "refused (the last valid setpoint streams until setpoint_timeout); one in "
                                  "(f_max, ratio x f_max] is flown at normalized 1.0, announced; 1.0: refuse all "
                                  "above f_max", low=1.0, high=2.0),
    "heartbeat_timeout": (0.45, "[s] no frame at all from PX4 (telemetry, HEARTBEAT, ACK) for this long: 'PX4 "
                                "silent', DISCONNECTED (logged at the next stream tick: < 0.5 s at 50 Hz)"),
    "offboard_warmup": Param(1.2, "[s] continuous setpoint stream before requesting OFFBOARD (>= 1)", low=1.0,
                             high=60.0),
    "command_retry_interval": (0.5, "[s] between retries of unconfirmed ARM / OFFBOARD / LAND / KILL commands"),
    "command_max_attempts": Param(6, "attempts of ARM / OFFBOARD / LAND before giving up (KILL retries forever)",
                                  low=1, high=1000),
    "kill_flight_termination": (False, "KILL also sends DO_FLIGHTTERMINATION (PX4 then needs a reboot)"),
    "message_rates": (list(DEFAULT_MESSAGE_RATES), "telemetry rates asked of PX4 once it is heard "
                      "(MAV_CMD_SET_MESSAGE_INTERVAL), 'NAME=Hz'; 0 stops a stream, 'default' restores PX4's rate. "
                      "Default: no ATTITUDE (unused), LOCAL_POSITION_NED at 50 Hz (PX4: 30)"),
    "configure_streams": (True, "ask PX4 for message_rates; false: leave PX4's streams as they are"),
    "signing_key_file": ("", "MAVLink 2 signing secret (64 hex digits or 32 bytes); empty: signing off"),
    "signing_link_id": Param(0, "MAVLink 2 signing link id", high=255),
    "status_rate": Param(10.0, "[Hz] status publication rate", low=0.1, high=1000.0),
    "body_frame_id": ("", "frame_id of imu and velocity_body; empty: uav<i>/base_link"),
    "teleop_topic": ("/fpr/teleop", "TeleopCommand topic (mode: idle / arm / fly / land / kill)"),
    "px4_boot_clock": Param("auto", "estimate: map PX4's time_boot_ms onto the ROS clock from the telemetry (a real "
                               "vehicle); ros_time: PX4's boot clock is the ROS clock (PX4 SITL in lockstep, "
                               "fpr_sim's emulator); auto: ros_time with use_sim_time, else estimate",
                            choices=("auto", "estimate", "ros_time")),
    "receive_thread": (True, "read MAVLink in a thread of its own (true: on a robot, ros2 run); false: the owner "
                             "calls receive_pending() (fpr_experiments' deterministic in-process runner)"),
    "n": Param(3, "number of UAVs of the robot: the swarm guard watches the peers' status uav<j>/status, j != uav_id",
               low=1, high=64),
    "swarm_guard": (True, "the swarm's emergency response (README 'Emergency response'): on a fault of this UAV or "
                          "a peer, PX4 Hold, then AUTO.LAND after emergency_hold_time, or rejoin once clear; false: "
                          "stale setpoints only stop the stream (PX4's offboard-loss failsafe acts alone)"),
    "emergency_hold_time": Param(5.0, "[s] the emergency's Hold before AUTO.LAND: set PX4's COM_FAIL_ACT_T to the "
                                 "same value (a UAV whose bridge died lands with the others)", high=600.0),
    "rejoin_delay": Param(0.5, "[s] an emergency's cause must stay clear this long before the UAV rejoins", high=60.0),
    "rejoin_window": Param(10.0, "[s] an emergency within this long of the last rejoin: no more rejoins, AUTO.LAND "
                                 "now, as this UAV's own (a flapping cause lands the swarm)", high=3600.0),
    "info_topic": ("/fpr/info", "InformationVector topic the controllers read (proof of life of each peer's "
                                "controller for the swarm guard)"),
    "peer_status_topic": ("/fpr/uav{uav}/status", "UavStatus topic of UAV {uav} (the peers' bridges)"),
    "estimate_deadline": Param(0.15, "[s] own controller_status without a valid local state this long: emergency "
                               "(pose estimator, or a ground-truth mode's motion capture, dead or blind)", low=0.02,
                               high=60.0),
    "peer_status_deadline": Param(0.5, "[s] a peer's status this old while its zeta arrives: its bridge died: "
                                  "emergency", low=0.05, high=60.0),
    "peer_silence_deadline": Param(5.0, "[s] neither status nor zeta from a peer this long: emergency (longer than "
                                   "the link outages the NC fallback (4.32) rides out)", low=0.1, high=600.0),
    "max_height": Param(10.0, "[m] flight envelope: height above the take-off point (PX4 local position)",
                        low=0.1, high=10000.0),
    "max_distance": Param(20.0, "[m] flight envelope: horizontal distance from the take-off point (PX4 local "
                          "position; a geofence like PX4's GF_MAX_HOR_DIST: set it to the flight area)", low=0.1,
                          high=100000.0),
    "max_climb_rate": Param(2.0, "[m/s] flight envelope: climb rate, for envelope_time", low=0.1, high=100.0),
    "max_tilt_deg": Param(60.0, "[deg] flight envelope: UAV tilt, for envelope_time (PX4 FD_FAIL_R / FD_FAIL_P)",
                          low=1.0, high=179.0),
    "max_platform_tilt_deg": Param(45.0, "[deg] flight envelope: the platform's tilt in the own controller's state "
                                   "(ControllerStatus.platform_tilt), for envelope_time (1.5x the controller's "
                                   "command_max_tilt_deg 30)", low=1.0, high=179.0),
    "envelope_time": Param(0.3, "[s] an envelope excess must last this long (PX4 FD_FAIL_R_TTRI)", low=0.01,
                           high=60.0),
    "wall_silence_timeout": (0.5, "[s] of WALL time without any MAVLink frame, on simulation time only: PX4 (the "
                                  "simulator) is reported lost even though /clock stopped with it; 0: off. Runs "
                                  "with the receive thread (the deterministic runner owns the timing)"),
}


class _EventLog:
    """Rate-limits log lines per event key (at most one per ``interval`` s, counting the suppressed ones)."""

    def __init__(self, logger, interval: float = 1.0) -> None:
        self._logger = logger
        self._interval = interval
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def emit(self, events: list[LogEvent]) -> None:
        now = time.monotonic()
        for event in events:
            last = self._last.get(event.key)
            if last is not None and now - last < self._interval and not event.key.startswith("state."):
                self._suppressed[event.key] = self._suppressed.get(event.key, 0) + 1
                continue
            self._last[event.key] = now
            skipped = self._suppressed.pop(event.key, 0)
            text = event.text + (f" ({skipped} similar suppressed)" if skipped else "")
            # one call site per severity: rclpy refuses a severity change at a call site
            if event.level == "error":
                self._logger.error(text)
            elif event.level == "warn":
                self._logger.warning(text)
            else:
                self._logger.info(text)


class Px4BridgeNode(Node):
    def __init__(self, **kwargs) -> None:
        """``kwargs`` go to ``rclpy.node.Node`` (e.g. ``context``, ``parameter_overrides`` in tests)."""
        super().__init__("px4_bridge", **kwargs)
        self.parameters = NodeParameters(self)
        self.parameters.declare_all(_PARAMETERS)
        p = {name: self.get_parameter(name).value for name in _PARAMETERS}
        uav_id = int(p["uav_id"])
        defaults = thrust_coefficients(uav_id)
        a_f = defaults.a_f if math.isnan(float(p["a_f"])) else float(p["a_f"])
        b_f = defaults.b_f if math.isnan(float(p["b_f"])) else float(p["b_f"])
        target_system = int(p["target_system"]) or uav_id
        self.config = BridgeConfig(
            uav_id=uav_id, target_system=target_system, target_component=int(p["target_component"]),
            stream_rate=float(p["stream_rate"]), setpoint_timeout=float(p["setpoint_timeout"]),
            thrust_min=float(p["thrust_min"]), a_f=a_f, b_f=b_f, fallback_voltage=float(p["fallback_voltage"]),
            battery_compensation=bool(p["battery_compensation"]), nominal_voltage=float(p["nominal_voltage"]),
            quaternion_tolerance=float(p["quaternion_tolerance"]),
            thrust_refusal_ratio=float(p["thrust_refusal_ratio"]),
            px4_boot_clock=self._boot_clock(str(p["px4_boot_clock"])),
            offboard=OffboardConfig(
                heartbeat_timeout=float(p["heartbeat_timeout"]), offboard_warmup=float(p["offboard_warmup"]),
                command_retry_interval=float(p["command_retry_interval"]),
                command_max_attempts=int(p["command_max_attempts"]),
                kill_flight_termination=bool(p["kill_flight_termination"]),
                emergency_hold_time=float(p["emergency_hold_time"]), rejoin_delay=float(p["rejoin_delay"]),
                rejoin_window=float(p["rejoin_window"])),
            guard=SwarmGuardConfig(
                enabled=bool(p["swarm_guard"]), uav_id=uav_id, estimate_deadline=float(p["estimate_deadline"]),
                peer_status_deadline=float(p["peer_status_deadline"]),
                peer_silence_deadline=float(p["peer_silence_deadline"]), max_height=float(p["max_height"]),
                max_distance=float(p["max_distance"]),
                max_climb_rate=float(p["max_climb_rate"]), max_tilt_deg=float(p["max_tilt_deg"]),
                max_platform_tilt_deg=float(p["max_platform_tilt_deg"]), envelope_time=float(p["envelope_time"])),
            message_rates=parse_message_rates(p["message_rates"]) if p["configure_streams"] else ())
        url = p["connection_url"] or f"udp://127.0.0.1:{14540 + uav_id - 1}"
        key = load_signing_key(p["signing_key_file"]) if p["signing_key_file"] else None
        self.link = MavlinkLink(url, system_id=int(p["system_id"]) or target_system,
                                component_id=int(p["component_id"]), target_system=target_system,
                                baud=int(p["baud"]), signing_key=key, signing_link_id=int(p["signing_link_id"]))
        self.bridge = Px4Bridge(self.config, self.link, boot_time=self._now())
        self.frame_id = p["body_frame_id"] or f"uav{uav_id}/base_link"
        self._lock = threading.Lock()
        self._log = _EventLog(self.get_logger())

        best_effort = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
        # best effort (REP-2003: any controller's publisher connects, reliable or not); a lost setpoint is a
        # missed control period, and in the simulator's lockstep a wait for the next one (its watchdog names it)
        self.create_subscription(AttitudeThrustSetpoint, "setpoint", self._on_setpoint, best_effort)
        self.create_subscription(TeleopCommand, p["teleop_topic"], self._on_teleop, best_effort)
        if self.config.guard.enabled:
            self.create_subscription(InformationVector, p["info_topic"], self._on_info, best_effort)
            self.create_subscription(ControllerStatus, "controller_status", self._on_controller_status, best_effort)
            for j in range(1, int(p["n"]) + 1):
                if j != uav_id:
                    self.create_subscription(UavStatus, str(p["peer_status_topic"]).format(uav=j),
                                             self._on_peer_status, best_effort)
        # REP-2003: sensor publishers reliable (the system default), so that any subscriber can connect; the
        # subscribers (pose_estimator, controller) use the sensor-data profile
        self.imu_pub = self.create_publisher(Imu, "imu", 10)
        self.velocity_pub = self.create_publisher(TwistStamped, "velocity_body", 10)
        self.battery_pub = self.create_publisher(BatteryState, "battery", 10)
        self.status_pub = self.create_publisher(UavStatus, "status", 10)
        #: REP-107 health once a second on /diagnostics (fpr_model.diagnostics)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._next_diagnostics = -math.inf
        self._rejected_reported = 0
        self._state_names = {getattr(UavStatus, name): name[len("STATE_"):] for name in dir(UavStatus)
                             if name.startswith("STATE_")}
        self.create_timer(1.0 / self.config.stream_rate, self._on_tick)
        self.create_timer(1.0 / float(p["status_rate"]), self._on_status)

        self._running = True
        self._last_rx_wall = time.monotonic()  # when the receive thread last read a frame (the wall watchdog's)
        self._rx_frames_read = 0
        self._rx_thread: threading.Thread | None = None
        if bool(p["receive_thread"]):
            self._rx_thread = threading.Thread(target=self._receive_loop, name="px4_bridge_rx", daemon=True)
            self._rx_thread.start()
        # Under use_sim_time every timer above runs on /clock, which stops when the simulator dies: the bridge's
        # own silence check (heartbeat_timeout) would never fire. A steady-clock watchdog watches the frames.
        self.wall_silence_timeout = float(p["wall_silence_timeout"])
        self._last_frame_wall = self._last_rx_wall
        self._rx_frames_seen = 0
        self._wall_silent_since: float | None = None
        self._pre_clock_silence_said = False
        self._pre_link_silence_said = False
        if bool(p["receive_thread"]) and self.wall_silence_timeout > 0.0 and \
                bool(self.get_parameter("use_sim_time").value):
            self.create_timer(0.05, self._on_wall_watchdog, clock=Clock(clock_type=ClockType.STEADY_TIME))
        address = self.link.local_address or self.link.spec.device
        self.get_logger().info(
            f"px4_bridge uav {uav_id}: {url} (bound {address}), PX4 system {target_system}, "
            f"stream {self.config.stream_rate:.0f} Hz, signing {'on' if key else 'off'}, "
            f"a_f={a_f} N/V b_f={b_f} N")
        self.get_logger().info(f"thrust normalization: {self.config.thrust_normalization()}")

    def _boot_clock(self, value: str) -> str:
        """The ``px4_boot_clock`` parameter resolved: ``auto`` is ``ros_time`` on simulation time (the simulated PX4
        boots at simulation time 0), ``estimate`` otherwise."""
        if value != "auto":
            return value  # BridgeConfig refuses anything but estimate / ros_time, naming the parameter
        return "ros_time" if bool(self.get_parameter("use_sim_time").value) else "estimate"

    def _now(self) -> float:
        return node_seconds(self)

    # ---- callbacks -----------------------------------------------------------------------------------------
    def _on_setpoint(self, msg: AttitudeThrustSetpoint) -> None:
        q = msg.attitude
        with self._lock:
            self.bridge.submit_setpoint((q.w, q.x, q.y, q.z), msg.thrust, msg.uav_id, self._now(),
                                        stamp=msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
            events = self.bridge.take_events()
        self._log.emit(events)

    def _on_teleop(self, msg: TeleopCommand) -> None:
        with self._lock:
            self.bridge.on_teleop(msg.mode, self._now())
            events = self.bridge.take_events()
        self._log.emit(events)

    def _on_info(self, msg: InformationVector) -> None:
        with self._lock:
            self.bridge.guard.on_info(msg.uav_id, self._now())

    def _on_controller_status(self, msg: ControllerStatus) -> None:
        if msg.uav_id == self.config.uav_id:
            with self._lock:
                self.bridge.guard.on_own_controller_status(bool(msg.local_state_valid), self._now(),
                                                           float(msg.platform_tilt))

    def _on_peer_status(self, msg: UavStatus) -> None:
        with self._lock:
            self.bridge.guard.on_peer_status(msg.uav_id, msg.state, msg.emergency_own, msg.emergency_reason,
                                             self._now(), msg.mode_name, msg.ready, msg.emergency_landing)

    def _on_tick(self) -> None:
        with self._lock:
            events = self.bridge.tick(self._now())
        self._log.emit(events)

    def _on_status(self) -> None:
        now = self.get_clock().now()
        with self._lock:
            s = self.bridge.status(now.nanoseconds * 1e-9)
        msg = UavStatus()
        msg.header.stamp = now.to_msg()
        msg.uav_id = s.uav_id
        msg.state = s.state
        msg.connected = s.connected
        msg.armed = s.armed
        msg.offboard = s.offboard
        msg.failsafe = s.failsafe
        msg.px4_custom_mode = s.px4_custom_mode
        msg.mode_name = s.mode_name
        msg.battery_voltage = float(s.battery_voltage)
        msg.battery_remaining = float(s.battery_remaining)
        msg.link_age = float(s.link_age)
        msg.setpoint_rate = float(s.setpoint_rate)
        msg.rx_garbage = min(s.rx_garbage, 0xFFFFFFFF)
        msg.rejected_setpoints = min(s.rejected_setpoints, 0xFFFFFFFF)
        msg.emergency, msg.emergency_own, msg.emergency_reason = s.emergency, s.emergency_own, s.emergency_reason
        msg.ready, msg.emergency_landing = s.ready, s.emergency_landing
        self.status_pub.publish(msg)
        self._publish_diagnostics(msg)

    def _publish_diagnostics(self, status: UavStatus) -> None:
        """REP-107 health on /diagnostics once a second: ERROR when PX4 is not heard, in FAILSAFE or killed; WARN
        while arming / warming up / landing or with refused setpoints; OK when idle or in OFFBOARD."""
        now = status.header.stamp.sec + 1e-9 * status.header.stamp.nanosec
        if now < self._next_diagnostics:
            return
        self._next_diagnostics = now + 1.0
        state = self._state_names.get(status.state, str(status.state))
        if not status.connected or status.state in (UavStatus.STATE_FAILSAFE, UavStatus.STATE_KILLED,
                                                    UavStatus.STATE_EMERGENCY):
            level = ERROR
            message = "PX4 not heard" if not status.connected else f"{state} (PX4 {status.mode_name})"
            if status.emergency:
                message += f": {status.emergency_reason}"
        elif status.state in (UavStatus.STATE_ARMING, UavStatus.STATE_WARMUP, UavStatus.STATE_LANDING) \
                or status.rejected_setpoints > self._rejected_reported:
            level, message = WARN, f"{state} (PX4 {status.mode_name})"
            if status.rejected_setpoints > self._rejected_reported:
                message += f", {status.rejected_setpoints - self._rejected_reported} setpoints refused"
        else:
            level, message = OK, f"{state} (PX4 {status.mode_name})"
        self._rejected_reported = status.rejected_setpoints
        report = StatusReport(self.get_fully_qualified_name(), level, message, f"uav{status.uav_id}", {
            "state": state, "PX4 mode": status.mode_name, "armed": status.armed, "link age [s]": status.link_age,
            "setpoint rate [Hz]": status.setpoint_rate, "battery [V]": status.battery_voltage,
            "garbage frames": status.rx_garbage, "refused setpoints": status.rejected_setpoints})
        self.diagnostics_pub.publish(to_diagnostic_array([report], status.header.stamp))

    def _on_wall_watchdog(self) -> None:
        """Steady clock, 20 Hz (use_sim_time only): no MAVLink frame for ``wall_silence_timeout`` wall seconds ->
        one warning and a status with ``connected`` false (the /clock-driven status timer may have stopped); one
        line again when frames come back."""
        now = time.monotonic()
        with self._lock:
            frames = self.link.counters.rx_frames
        if frames != self._rx_frames_seen:
            # when the receive thread read them (not this tick's time: up to a period later)
            self._rx_frames_seen, self._last_frame_wall = frames, min(now, self._last_rx_wall)
            if self._wall_silent_since is not None:
                self.get_logger().info(f"MAVLink frames again after {now - self._wall_silent_since:.1f} s of wall "
                                       "time without any")
                self._wall_silent_since = None
            return
        silence = now - self._last_frame_wall
        if frames == 0 or silence < self.wall_silence_timeout:  # never heard (start-up): the link is simply down
            return
        if self._now() <= 0.0:
            # heard, then silent before the first /clock: the simulator is waiting for its subscribers (a
            # multi-process start), nominal; once the clock runs a silence is a lost PX4 again
            if not self._pre_clock_silence_said:
                self._pre_clock_silence_said = True
                self.get_logger().info(f"no MAVLink frame for {silence:.1f} s of wall time before the simulation "
                                       "clock started (the simulator is waiting for the graph)")
            return
        if not self.bridge.machine.link_was_up:
            # heard, then silent before the link was up: PX4 / the simulator still starting (a loaded multi-process
            # start: a few frames, then the simulator's process busy starting for 0.7 s), nominal
            if not self._pre_link_silence_said:
                self._pre_link_silence_said = True
                self.get_logger().info(f"no MAVLink frame for {silence:.1f} s of wall time before the PX4 link "
                                       "came up (PX4 or the simulator still starting)")
            return
        if self._wall_silent_since is None:
            self._wall_silent_since = self._last_frame_wall
            self.get_logger().warning(
                f"PX4 lost: no MAVLink frame for {silence:.1f} s of wall time (wall_silence_timeout "
                f"{self.wall_silence_timeout:g} s) and simulation time at {self._now():.3f} s: the simulator (or PX4) "
                "is dead or hung")
        msg = UavStatus()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.uav_id = self.config.uav_id
        msg.state = UavStatus.STATE_DISCONNECTED
        msg.connected = False
        msg.link_age = float(silence)
        msg.mode_name = "unknown"
        self.status_pub.publish(msg)
        self._next_diagnostics = -math.inf  # say it now, whatever the /clock-driven schedule
        self._publish_diagnostics(msg)

    # ---- reception thread ------------------------------------------------------------------------------
    def _receive_loop(self) -> None:
        fileno = self.link.fileno()
        while self._running:
            try:
                ready, _, _ = select.select([fileno], [], [], 0.1)
            except (OSError, ValueError):
                return  # socket closed at shutdown
            if not ready or not self._running:
                continue
            self.receive_pending()
            frames = self.link.counters.rx_frames
            if frames != self._rx_frames_read:  # the wall watchdog's reference: when frames last came in
                self._rx_frames_read, self._last_rx_wall = frames, time.monotonic()

    def receive_pending(self) -> None:
        """Read and handle every MAVLink message waiting on the link now (non-blocking): what the receive thread
        does on each wake-up; with ``receive_thread`` false the owner calls it (at deterministic instants)."""
        now = self._now()
        if now <= 0.0:
            # use_sim_time before the first /clock: no time to judge or stamp with. Drop the input, or its
            # zero receive time would skew the time_boot_ms mapping (and link age) once the clock runs.
            with self._lock:
                dropped = len(self.link.receive())
            if dropped:
                self.get_logger().info(f"no /clock yet (use_sim_time): dropped {dropped} MAVLink messages",
                                       throttle_duration_sec=5.0)
            return
        with self._lock:
            samples = self.bridge.poll(now)
            events = self.bridge.take_events()
        self._log.emit(events)
        for sample in samples:
            self._publish(sample)

    def _stamp(self, seconds: float):
        return Time(nanoseconds=max(0, int(seconds * 1e9)), clock_type=self.get_clock().clock_type).to_msg()

    def _publish(self, sample) -> None:
        if isinstance(sample, ImuSample):
            msg = Imu()
            msg.header.stamp = self._stamp(sample.stamp)
            msg.header.frame_id = self.frame_id
            q = sample.orientation
            msg.orientation.w, msg.orientation.x, msg.orientation.y, msg.orientation.z = (float(c) for c in q)
            w = sample.angular_velocity
            msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = (float(c) for c in w)
            if sample.linear_acceleration is None:
                msg.linear_acceleration_covariance[0] = -1.0  # REP-145: not provided
            else:
                a = sample.linear_acceleration
                msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = (
                    float(c) for c in a)
            self.imu_pub.publish(msg)
        elif isinstance(sample, BodyVelocitySample):
            msg = TwistStamped()
            msg.header.stamp = self._stamp(sample.stamp)
            msg.header.frame_id = self.frame_id
            msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = (float(c) for c in sample.linear)
            msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z = (float(c) for c in sample.angular)
            self.velocity_pub.publish(msg)
        elif isinstance(sample, BatterySample):
            msg = BatteryState()
            msg.header.stamp = self._stamp(sample.stamp)
            msg.header.frame_id = self.frame_id
            msg.voltage = float(sample.voltage)
            msg.current = -float(sample.current)  # ROS: negative while discharging
            msg.percentage = float(sample.remaining)
            msg.charge = msg.capacity = msg.design_capacity = math.nan
            msg.temperature = math.nan
            msg.present = True
            msg.power_supply_status = BatteryState.POWER_SUPPLY_STATUS_DISCHARGING
            msg.power_supply_technology = BatteryState.POWER_SUPPLY_TECHNOLOGY_LIPO
            self.battery_pub.publish(msg)

    def destroy_node(self) -> None:
        self._running = False
        if self._rx_thread is not None and self._rx_thread.is_alive():
            self._rx_thread.join(timeout=1.0)
        self.link.close()
        super().destroy_node()


def main(args=None) -> None:
    rclpy.init(args=args)
    node = None
    try:
        node = Px4BridgeNode()
        settle_heap()  # no garbage-collector pause walks the start-up's objects (fpr_model.node_parameters)
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok():
            raise
        # a callback racing the shutdown (SIGINT/SIGTERM) found its context gone: nothing to report
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
