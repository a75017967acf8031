"""``simulator`` node: replaces the FPR hardware (plant, PX4 autopilots over MAVLink, cameras). Thin wrapper
around :class:`fpr_sim.simulation.Simulation` (DESIGN.md §3, §5).

Publishes ``/clock`` (rosgraph_msgs/Clock, ``clock_rate`` ≤ 250 Hz), ``/fpr/ground_truth`` (fpr_msgs/FprState),
and per UAV ``/fpr/uav<i>/camera/image_raw`` + ``camera/camera_info`` (20 Hz), or ``/fpr/uav<i>/marker``
(fpr_msgs/MarkerDetection) when ``cameras.emulated`` is set in the scenario or ``emulated_cameras`` is true, each
stamped at its exposure instant and published ``cameras.latency`` later (the first /clock tick at or after),
``/fpr/motion_capture`` (fpr_msgs/FprState, the centralized modes' motion capture: fpr_sim.sensors.MotionCapture,
an exact copy of the ground truth published with it unless ``motion_capture.enabled``), and,
when the scenario enables ``target``, ``/fpr/target`` (geometry_msgs/PoseStamped, frame ``flat_platform``, at
``target.rate``): the noisy relative pose of the target of fpr_sim.target (thesis §4.4.2, (4.39)). Camera and
target topics are published reliable (REP-2003: any subscriber can connect; readers pick the sensor-data QoS).

For RViz and Foxglove: ``/tf`` (tf2_msgs/TFMessage, ``tf_rate``, default 50 Hz, 0 = off: world -> platform ->
leg<i> -> uav<i>/base_link from the ground truth, fpr_sim.tf_tree; built only while /tf has a subscriber: ~1 ms per
message for n = 6), ``/tf_static`` (each UAV's true camera mounting,
uav<i>/base_link -> uav<i>/camera_optical, the images' frame) and ``/robot_description`` (std_msgs/String, the URDF
of the TRUE robot, fpr_model.robot_description), both latched (transient local), as robot_state_publisher does.
"""

from __future__ import annotations

import time

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from fpr_model.node_parameters import NodeParameters, settle_heap
from fpr_model.opencv_dispatch import ENVIRONMENT_VARIABLE, apply_opencv_dispatch
from fpr_model.robot_description import robot_description
from fpr_px4_bridge.link import load_signing_key
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, TransformStamped, Vector3
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from fpr_msgs.msg import FprState, MarkerDetection
from fpr_sim._kernels import kernel_summary
from fpr_sim.cameras import CameraRig
from fpr_sim.plant import GroundTruth
from fpr_sim.px4_log import Px4Log
from fpr_sim.quadrotor import plain_floats
from fpr_sim.scenario import load_scenario, realism_profiles
from fpr_sim.sensors import DelayLine, MotionCapture
from fpr_sim.simulation import Simulation, SimulationOptions
from fpr_sim.target import TARGET_FRAME, TargetEmulator
from fpr_sim.tf_tree import FrameTransform, camera_transforms, robot_transforms


def _stamp(t: float) -> Time:
    sec = int(t)
    return Time(sec=sec, nanosec=int(round((t - sec) * 1e9)) % 1_000_000_000)


#: REP-2003: sensor data is published with the system default profile (reliable, volatile), so that any subscriber
#: can connect; subscribers that prefer dropping to retransmitting (estimators, detectors) use the sensor-data profile
SENSOR_PUBLISHER_QOS = 10


def _pose(position, quat_wxyz) -> Pose:
    """A Pose of a position (3,) [m] and a quaternion [w, x, y, z] (array-likes)."""
    return _pose_of_floats(plain_floats(position), plain_floats(quat_wxyz))


def _pose_of_floats(position: list[float], quat_wxyz: list[float]) -> Pose:
    """:func:`_pose` of plain Python floats (no conversion: the ground truth converts its arrays once)."""
    w, x, y, z = quat_wxyz
    return Pose(position=Point(x=position[0], y=position[1], z=position[2]), orientation=Quaternion(x=x, y=y, z=z,
                                                                                                       w=w))


#: [s] wall: while the lockstep waits, /clock is re-published this often (SimulatorNode._on_lockstep_wait)
CLOCK_REPEAT_S = 0.25
#: [s of wall time] pacing debt the simulator still catches up on; beyond it (a stall: the machine's load, a
#: lockstep wait) the pacing restarts from now instead of racing ahead at full speed until the debt is paid: a
#: catch-up burst ran a CI flight at 1.6x real time, faster than the MAVLink clients' own clocks expect
PACING_MAX_DEBT_S = 0.2


class SimulatorNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("simulator", **kwargs)
        p = NodeParameters(self)
        p("scenario_file", "", (
            "scenario YAML: a path, or a bundled scenario's name (config/scenarios: hover, ground_start, ...); empty: "
            "default scenario"))
        p("realism", "", (
            "realism profile: ideal | hardware (config/realism/); empty: the scenario's own 'realism' key (default "
            "ideal). The scenario's explicit values always win over the profile's"), choices=("", *realism_profiles()))
        p("real_time_factor", 1.0, "pacing: simulated s per wall s; 0 = as fast as lockstep allows", high=1000.0)
        p("lockstep", True, (
            "wait at each control period for every streaming UAV's setpoint computed for that period"))
        p("lockstep_timeout", 30.0, (
            "[s] wall: watchdog of a live setpoint stream that neither delivers nor ends (a dead or hung node)"),
          low=0.1, high=3600.0)
        p("lockstep_on_timeout", "stop", (
            "stop: stop the simulation with one error naming the UAVs; continue: count it and fly on (fault runs)"),
          choices=("stop", "continue"))
        p("control_rate", 50.0, "controllers' rate used by the lockstep [Hz]", low=1.0, high=1000.0)
        p("physics_rate", 1000.0, "fixed physics step rate [Hz]", low=10.0, high=100000.0)
        p("clock_rate", 250.0, "/clock publishing rate [Hz], at most 250", low=1.0, high=250.0)
        p("ground_truth_rate", 100.0, "/fpr/ground_truth rate [Hz]", low=0.1, high=1000.0)
        p("tf_rate", 50.0, "/tf rate [Hz] (the true robot's frames for RViz / Foxglove); 0 = no /tf, /tf_static nor "
          "/robot_description", high=1000.0)
        p("local_base_port", 14580, (
            "UAV i's PX4 emulator binds 127.0.0.1:local_base_port+i-1, as PX4 SITL instance i-1 (0: ephemeral)"),
          high=65535)
        p("remote_base_port", 14540, (
            "UAV i's PX4 emulator sends HEARTBEAT/telemetry to 127.0.0.1:remote_base_port+i-1 (where px4_bridge "
            "listens), then replies to whoever talks to it; 0: silent until contacted"), high=65535)
        p("emulated_cameras", False, "publish noisy marker poses instead of images")
        p("signing_key_file", "", (
            "MAVLink 2 signing key of every emulated PX4 (64 hex digits or 32 bytes, as px4_bridge's): frames signed, "
            "unsigned input refused; empty: no signing (PX4's default)"))
        p("px4_log_file", "", (
            "CSV of every SET_ATTITUDE_TARGET the emulated PX4s receive (raw thrust, quaternion) and every arming / "
            "mode change, simulation time (fpr_sim.px4_log: fault-injection evidence); empty: off"))
        p("duration", 0.0, "stop after this simulated time [s]; 0 = run until shutdown", high=1e7)
        p("wait_for_clock_subscribers", 0, (
            "run(): before the first step, wait until /clock has this many subscriptions (every simulated-time node "
            "of a multi-process graph), so that no process misses the start; 0 = start at once"), high=1000)
        p("wait_for_clock_subscribers_timeout", 60.0, (
            "[s] wall: give up waiting for the /clock subscribers and start anyway (with a warning)"), high=3600.0)
        get = self.get_parameter
        self.scenario = load_scenario(get("scenario_file").value, realism=str(get("realism").value) or None)
        options = SimulationOptions(physics_rate=float(get("physics_rate").value),
                                    control_rate=float(get("control_rate").value),
                                    lockstep=bool(get("lockstep").value),
                                    lockstep_timeout=float(get("lockstep_timeout").value),
                                    lockstep_on_timeout=str(get("lockstep_on_timeout").value),
                                    local_base_port=int(get("local_base_port").value),
                                    remote_base_port=int(get("remote_base_port").value),
                                    signing_key=load_signing_key(str(get("signing_key_file").value))
                                    if get("signing_key_file").value else None)
        self.sim = Simulation(self.scenario, options)
        log_file = str(get("px4_log_file").value)
        self.px4_log = Px4Log(log_file, self.sim.emulators) if log_file else None
        self.sim.on_notice = self.get_logger().warning
        self.sim.on_lockstep_wait = self._on_lockstep_wait
        self._clock_republished_at = 0.0
        self.real_time_factor = max(0.0, float(get("real_time_factor").value))
        self.clock_period = 1.0 / min(250.0, max(1.0, float(get("clock_rate").value)))
        self.truth_period = 1.0 / max(1.0, float(get("ground_truth_rate").value))
        self.camera_period = 1.0 / self.scenario.cameras.rate
        self.duration = float(get("duration").value)
        self.emulated = bool(get("emulated_cameras").value) or self.scenario.cameras.emulated
        self.cameras = CameraRig(self.scenario.cameras, self.sim.n, self.scenario.seed) \
            if self.scenario.cameras.enabled else None
        self.clock_pub = self.create_publisher(Clock, "/clock", 10)
        self.truth_pub = self.create_publisher(FprState, "/fpr/ground_truth", 10)
        self.mocap = MotionCapture(self.scenario.motion_capture, self.scenario.seed)
        self.mocap_pub = self.create_publisher(FprState, "/fpr/motion_capture", 10)
        self.mocap_period = 1.0 / self.scenario.motion_capture.rate
        self._next_mocap = 0.0
        #: latent messages (camera frames, detections, motion-capture frames): (publisher, message) by due time
        self.pending = DelayLine()
        self.image_pubs, self.info_pubs, self.marker_pubs = [], [], []
        for i in range(1, self.sim.n + 1):
            if self.emulated:
                self.marker_pubs.append(self.create_publisher(MarkerDetection, f"/fpr/uav{i}/marker",
                                                              SENSOR_PUBLISHER_QOS))
            else:
                self.image_pubs.append(self.create_publisher(Image, f"/fpr/uav{i}/camera/image_raw",
                                                             SENSOR_PUBLISHER_QOS))
                self.info_pubs.append(self.create_publisher(CameraInfo, f"/fpr/uav{i}/camera/camera_info",
                                                            SENSOR_PUBLISHER_QOS))
        self.target = (TargetEmulator(self.scenario.target, self.scenario.seed) if self.scenario.target.enabled
                       else None)
        self.target_pub = (self.create_publisher(PoseStamped, "/fpr/target", SENSOR_PUBLISHER_QOS)
                           if self.target is not None else None)
        self.target_period = 1.0 / self.scenario.target.rate
        self._next_target = 0.0
        self._setup_tf(float(get("tf_rate").value))
        self._next_truth = 0.0
        self.last_truth_time: float | None = None
        self._next_camera = 0.0
        self._last_timeouts = 0
        self._payload_changes_logged = 0
        self._wall_start: float | None = None
        self._sim_start = 0.0
        self.pacing_debt_dropped = 0.0  #: [s of wall time] pacing debt not caught up (PACING_MAX_DEBT_S)
        #: set by SIGUSR1, cleared by SIGUSR2 (main()): run() holds the world between two steps (hold_paused)
        self.pause_requested = False
        self.get_logger().info(
            f"scenario '{self.scenario.name}', n = {self.sim.n}, PX4 emulators bound to UDP ports {self.sim.ports}, "
            f"sending to {self.sim.remote_ports}, "
            f"real_time_factor {self.real_time_factor}, lockstep {options.lockstep} (watchdog "
            f"{options.lockstep_timeout:g} s: {options.lockstep_on_timeout})")
        self.get_logger().info(f"plant kernel: {kernel_summary(self.sim.plant.kernel)}")
        if apply_opencv_dispatch() != "native":  # rendered images: the same on every CPU
            self.get_logger().info(f"OpenCV dispatch: baseline ({ENVIRONMENT_VARIABLE}): rendered images do not "
                                   "depend on the CPU's SIMD features")

    # ------------------------------------------------------------------------------------------------
    def run(self) -> None:
        """Step until shutdown or ``duration``, serving this node's own callbacks (parameter services) once per
        control period: one executor, built once (``rclpy.spin_once`` would build a wait set per call, ~0.2 ms)."""
        executor = SingleThreadedExecutor(context=self.context)
        executor.add_node(self)
        self._wait_for_clock_subscribers(executor)
        steps_per_spin = max(1, round(1.0 / (self.clock_period * float(self.get_parameter("control_rate").value))))
        try:
            steps = 0
            while rclpy.ok(context=self.context) and not self.sim.stop_requested and self.step():
                steps += 1
                if steps % steps_per_spin == 0:
                    executor.spin_once(timeout_sec=0.0)
                if self.pause_requested:
                    self.hold_paused(executor)
        finally:
            executor.remove_node(self)
            executor.shutdown(timeout_sec=0.0)
        if self.sim.stop_requested:
            self.get_logger().info(f"stopped by a signal at t = {self.sim.time:.3f} s")

    def _wait_for_clock_subscribers(self, executor) -> None:
        expected = int(self.get_parameter("wait_for_clock_subscribers").value)
        if expected <= 0:
            return
        deadline = time.monotonic() + float(self.get_parameter("wait_for_clock_subscribers_timeout").value)
        while rclpy.ok(context=self.context) and not self.sim.stop_requested and \
                self.clock_pub.get_subscription_count() < expected:
            if time.monotonic() > deadline:
                self.get_logger().warning(f"/clock has {self.clock_pub.get_subscription_count()} of the {expected} "
                                          "expected subscriptions: starting anyway")
                return
            executor.spin_once(timeout_sec=0.05)
        self.get_logger().info(f"/clock has its {expected} subscriptions: starting the simulation")

    def hold_paused(self, executor) -> None:
        """Paused (SIGUSR1 until SIGUSR2; the fault injector's restart, fpr_experiments.processes): the world holds
        between two steps — no physics, no new /clock time, no sensor data —, while every emulated PX4 keeps
        sending HEARTBEATs and /clock is repeated (``_on_lockstep_wait``, as in a lockstep wait), so that nobody
        takes the held simulator for a dead one. The pacing restarts at the resume (no catch-up burst)."""
        t, start = self.sim.time, time.monotonic()
        self.get_logger().info(f"paused at t = {t:.3f} s (SIGUSR1): the world holds until SIGUSR2")
        while self.pause_requested and not self.sim.stop_requested and rclpy.ok(context=self.context):
            self._on_lockstep_wait(time.monotonic() - start)
            executor.spin_once(timeout_sec=0.05)
        self._wall_start = None  # step() restarts the pacing from the resume
        self.get_logger().info(f"resumed at t = {t:.3f} s after {time.monotonic() - start:.2f} s of wall time")

    def _on_lockstep_wait(self, waited: float) -> None:
        """While the lockstep waits at a boundary: /clock again (same time) every CLOCK_REPEAT_S of wall time. Every
        node's /clock subscription is best effort (rclpy's TimeSource), so a lost last /clock would leave the
        controllers' timers stopped and the lockstep waiting for their setpoints until its watchdog; a repeated
        time changes nothing for a node that had it. Each emulated PX4 sends a HEARTBEAT with it
        (Px4Emulator.keep_alive): a waiting simulator is alive, and the bridges' wall watchdog must not say
        'PX4 lost' (a false peer loss for the swarm guard, seen at a multi-process start)."""
        if waited < self._clock_republished_at + CLOCK_REPEAT_S:
            if waited < self._clock_republished_at:
                self._clock_republished_at = 0.0  # a new wait
            return
        self._clock_republished_at = waited
        for emulator in self.sim.emulators:
            emulator.keep_alive()
        if rclpy.ok(context=self.context):
            self.clock_pub.publish(Clock(clock=_stamp(self.sim.time)))

    def step(self) -> bool:
        """Advance one ``/clock`` period (lockstep included), publish what is due, pace to
        ``real_time_factor``; False once ``duration`` is reached. For hosts that spin this node in their own
        executor and drive the simulation from another thread (fpr_experiments.inprocess)."""
        if self._wall_start is None:
            self._wall_start, self._sim_start = time.monotonic(), self.sim.time
        self.sim.advance(self.clock_period)
        if not rclpy.ok(context=self.context):
            return False  # shut down (SIGINT/SIGTERM) while stepping: publishing now would raise
        t = self.sim.time
        if self.px4_log is not None:
            self.px4_log.sample(t)
        self.clock_pub.publish(Clock(clock=_stamp(t)))
        if t + 1e-9 >= self._next_truth:
            self._next_truth += self.truth_period
            truth_msg = self._truth_message()
            self.truth_pub.publish(truth_msg)
            if not self.mocap.config.enabled:
                self.mocap_pub.publish(truth_msg)  # ideal motion capture: the exact truth, undelayed
            self.last_truth_time = t  #: [s] stamp of the latest /fpr/ground_truth published
        if self.tf_pub is not None and t + 1e-9 >= self._next_tf:
            self._next_tf += self.tf_period
            if self.tf_pub.get_subscription_count() > 0:  # lazy: built only for a listener (issue 15)
                self._publish_tf()
        if self.mocap.config.enabled and t + 1e-9 >= self._next_mocap:
            self._next_mocap += self.mocap_period
            frame = self.mocap.measure(self.sim.ground_truth())
            if frame is not None:
                self._publish_later(t + self.mocap.latency, self.mocap_pub, self._state_message(frame))
        if self.cameras is not None and t + 1e-9 >= self._next_camera:
            self._next_camera += self.camera_period
            self._publish_cameras(t)
        for publisher, message in self.pending.pop_due(t):
            publisher.publish(message)
        if self.target is not None and t + 1e-9 >= self._next_target:
            self._next_target += self.target_period
            self.target_pub.publish(self._target_message(t))
        changes = self.sim.plant.environment.payload_changes
        if len(changes) > self._payload_changes_logged:
            self._log_payload_changes(changes[self._payload_changes_logged:])
            self._payload_changes_logged = len(changes)
        if self.sim.lockstep_timeouts != self._last_timeouts:
            self._last_timeouts = self.sim.lockstep_timeouts
            self.get_logger().warning(f"lockstep: {self._last_timeouts} control periods timed out waiting "
                                      f"for setpoints (latest {self.sim.last_timeout})", throttle_duration_sec=5.0)
        if self.real_time_factor > 0.0:
            self._pace(t)
        if self.duration > 0.0 and t >= self.duration:
            self.get_logger().info(f"duration {self.duration} s reached: stopping "
                                   f"(lockstep timeouts: {self.sim.lockstep_timeouts}, oldest setpoint on "
                                   f"arrival: {1000.0 * self.sim.setpoint_latency_max():.0f} ms)")
            return False
        return True

    def _pace(self, t: float) -> None:
        """Sleep until wall time catches up with ``t`` / real_time_factor; a debt beyond PACING_MAX_DEBT_S is
        dropped (the pacing restarts from now), counted and said at most every 10 s."""
        now = time.monotonic()
        ahead = (t - self._sim_start) / self.real_time_factor - (now - self._wall_start)
        if ahead > 0.0:
            time.sleep(ahead)
        elif ahead < -PACING_MAX_DEBT_S:
            self._wall_start, self._sim_start = now, t
            self.pacing_debt_dropped += -ahead
            self.get_logger().info(
                f"slower than real_time_factor {self.real_time_factor:g} (machine load or a lockstep wait): "
                f"{self.pacing_debt_dropped:.1f} s of wall time not caught up so far; the pacing restarts from "
                f"t = {t:.3f} s instead of running ahead", throttle_duration_sec=10.0)

    def _log_payload_changes(self, changes) -> None:
        """One INFO line per payload attached (picked up) or released (fpr_sim.environment.PayloadChange)."""
        for change in changes:
            what = f"payload {change.index} ({change.mass:.3f} kg)"
            if change.attached and change.pickup:
                self.get_logger().info(f"{what} picked up at t = {change.time:.3f} s (P {change.distance:.3f} m "
                                       "from its pickup_position)")
            else:
                self.get_logger().info(f"{what} {'attached' if change.attached else 'released'} at "
                                       f"t = {change.time:.3f} s")

    def _setup_tf(self, rate: float) -> None:
        """/tf publisher at ``rate`` [Hz] (0: none), and the latched /tf_static and /robot_description."""
        self.tf_pub = None
        self._next_tf = 0.0
        if not rate > 0.0:
            return
        self.tf_period = 1.0 / rate
        self.tf_pub = self.create_publisher(TFMessage, "/tf", 100)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.description_pub = self.create_publisher(String, "/robot_description", latched)
        self.description_pub.publish(String(data=robot_description(self.sim.plant.params)))
        mounts = ([camera.body_T_camera for camera in self.cameras.true_cameras] if self.cameras is not None else [])
        self.tf_static_pub = self.create_publisher(TFMessage, "/tf_static", latched)
        self.tf_static_pub.publish(self._tf_message(camera_transforms(mounts), self.sim.time))

    def _publish_tf(self) -> None:
        truth = self.sim.ground_truth()
        s = truth.state
        transforms = robot_transforms(self.sim.plant.params, s.position, s.quat, s.leg_angles, truth.uav_positions,
                                      truth.uav_quats)
        self.tf_pub.publish(self._tf_message(transforms, truth.time))

    @staticmethod
    def _tf_message(transforms: list[FrameTransform], t: float) -> TFMessage:
        msg = TFMessage()
        for transform in transforms:
            stamped = TransformStamped()
            stamped.header.stamp = _stamp(t)
            stamped.header.frame_id = transform.parent
            stamped.child_frame_id = transform.child
            x, y, z = (float(v) for v in transform.translation)
            stamped.transform.translation = Vector3(x=x, y=y, z=z)
            w, qx, qy, qz = (float(v) for v in transform.quat)
            stamped.transform.rotation = Quaternion(x=qx, y=qy, z=qz, w=w)
            msg.transforms.append(stamped)
        return msg

    def _publish_later(self, due: float, publisher, message) -> None:
        """Publish ``message`` at ``due`` [s] simulation time (now if due already; else at the first /clock tick at or
        after it)."""
        if due <= self.sim.time + 1e-9:
            publisher.publish(message)
        else:
            self.pending.push(due, (publisher, message))

    def _truth_message(self) -> FprState:
        return self._state_message(self.sim.ground_truth())

    @staticmethod
    def _state_message(truth: GroundTruth) -> FprState:
        """fpr_msgs/FprState of a ground truth (or a motion-capture frame of it), stamped at its instant."""
        s = truth.state
        msg = FprState()
        msg.header.stamp = _stamp(truth.time)
        msg.header.frame_id = "world"
        msg.platform_pose = _pose(s.position, s.quat)
        vx, vy, vz = plain_floats(s.velocity)
        msg.platform_twist.linear = Vector3(x=vx, y=vy, z=vz)
        wx, wy, wz = plain_floats(s.rate)
        msg.platform_twist.angular = Vector3(x=wx, y=wy, z=wz)
        msg.leg_angles = plain_floats(s.leg_angles)
        msg.leg_rates = plain_floats(s.leg_rates)
        msg.uav_poses = [_pose_of_floats(p, q) for p, q in zip(plain_floats(truth.uav_positions),
                                                               plain_floats(truth.uav_quats), strict=True)]
        msg.uav_velocities = [Vector3(x=v[0], y=v[1], z=v[2]) for v in plain_floats(truth.uav_velocities)]
        msg.uav_thrusts = plain_floats(truth.uav_thrusts)
        msg.external_wrench = plain_floats(truth.external_wrench)
        msg.contact_force = float(truth.contact_force)
        msg.payload_mass = float(truth.payload_mass)
        msg.battery_voltages = plain_floats(truth.battery_voltages)
        return msg

    def _target_message(self, t: float) -> PoseStamped:
        """The emulated relative target pose now (fpr_sim.target) as a PoseStamped in F_Fp."""
        state = self.sim.plant.state
        pose = self.target.measure(state.position, state.quat)
        msg = PoseStamped()
        msg.header.stamp = _stamp(t)
        msg.header.frame_id = TARGET_FRAME
        msg.pose = _pose(pose.position, pose.quat)
        return msg

    def _publish_cameras(self, t: float) -> None:
        truth = self.sim.ground_truth()
        stamp = _stamp(t)
        due = t + self.scenario.cameras.latency
        if self.emulated:
            for i, detection in enumerate(self.cameras.emulate(truth)):
                if detection is None:
                    continue  # a missed detection (cameras.detection_probability)
                T = detection.camera_T_marker
                from fpr_model.rotations import rotmat_to_quat

                msg = MarkerDetection()
                msg.header.stamp = stamp
                msg.header.frame_id = f"uav{i + 1}/camera_optical"
                msg.marker_id = 0
                msg.pose = _pose(T[:3, 3], rotmat_to_quat(T[:3, :3]))
                msg.reprojection_error = 0.0
                msg.ambiguity_ratio = float("inf")
                msg.corners = [float("nan")] * 8
                msg.marker_size = float(self.cameras.calibration.marker_size)
                self._publish_later(due, self.marker_pubs[i], msg)
            return
        camera = self.cameras.calibration.camera
        for i, frame in enumerate(self.cameras.render(truth)):
            image = Image()
            image.header.stamp = stamp
            image.header.frame_id = f"uav{i + 1}/camera_optical"
            image.height, image.width = frame.image.shape
            image.encoding = "mono8"
            image.step = image.width
            image.data = frame.image.tobytes()
            self._publish_later(due, self.image_pubs[i], image)
            info = CameraInfo()  # the NOMINAL calibration (what the estimator is configured with)
            info.header = image.header
            info.height, info.width = camera.height, camera.width
            info.distortion_model = "plumb_bob"
            info.d = [float(v) for v in camera.dist_coeffs]
            info.k = [float(v) for v in np.asarray(camera.camera_matrix).reshape(-1)]
            info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
            info.p = [camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
            self._publish_later(due, self.info_pubs[i], info)

    def destroy_node(self) -> None:
        if self.px4_log is not None:
            self.px4_log.close()
        self.sim.close()
        super().destroy_node()


def main(args=None) -> None:
    """``ros2 run fpr_sim simulator``. SIGINT / SIGTERM stop the loop between two steps (a flag), then the node is
    destroyed and the context shut down: rclpy's own handler would shut the context down asynchronously while the
    loop publishes, which could crash the process (seen once as SIGSEGV in CI) or raise RCLError. SIGUSR1 pauses
    the simulation between two steps, SIGUSR2 resumes it (:meth:`SimulatorNode.hold_paused`)."""
    import signal
    import sys

    from rclpy.signals import SignalHandlerOptions

    from fpr_sim.simulation import LockstepStalled

    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    status = 0

    def request_stop(signum, _frame) -> None:
        if node is None or node.sim.stop_requested:
            raise KeyboardInterrupt  # before the loop runs, or a second signal: stop at once
        node.sim.stop_requested = True  # nothing else here: the handler may interrupt any Python code

    def request_pause(signum, _frame) -> None:
        if node is not None:
            node.pause_requested = signum == signal.SIGUSR1  # a flag only, as request_stop

    previous = {sig: signal.signal(sig, request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    previous.update({sig: signal.signal(sig, request_pause) for sig in (signal.SIGUSR1, signal.SIGUSR2)})
    try:
        try:
            node = SimulatorNode()
        except (FileNotFoundError, ValueError) as error:  # a scenario or parameter error: one line, no traceback
            print(f"[simulator] error: {error}", file=sys.stderr)
            status = 2
            return
        settle_heap()  # no garbage-collector pause walks the start-up's objects (fpr_model.node_parameters)
        node.run()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except LockstepStalled as error:
        node.get_logger().error(str(error))
        status = 1
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
        if status:
            sys.exit(status)


if __name__ == "__main__":
    main()
