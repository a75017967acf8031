"""The whole simulated FPR swarm in ONE process (DESIGN.md §3, §7 "launch-free integration"): a reusable helper
for the integration tests (and later the demo).

:class:`SwarmGraph` builds, in its own rclpy context, the ``simulator`` node (fpr_sim), per UAV i a
``px4_bridge``, a ``pose_estimator`` (and, with real images, an ``aruco_detector``) and a ``controller`` in the
namespace ``/fpr/uav<i>``, the ground ``teleop`` and a ``joy_script`` playing a Joy timeline, plus a
:class:`SwarmRecorder` node that keeps what the metrics need. Every node runs with ``use_sim_time`` and the
parameters of its package's config YAML (``--params-file`` is per process, so the files are turned into
``parameter_overrides``, the same values a ``--params-file`` would give), then the per-instance values
(``uav_id``, ``mode``, ...) and the caller's overrides on top.

All nodes but the simulator spin in one SingleThreadedExecutor in a background thread; the simulation is
stepped by :meth:`SwarmGraph.run_until` in the caller's thread, one ``/clock`` period (4 ms) at a time, so
the caller can stop on a condition of the recorded data. With ``lockstep`` (default) the simulator waits at
every 20 ms boundary for each streaming UAV's setpoint computed for that period (the bridges put the setpoint's
stamp in SET_ATTITUDE_TARGET.time_boot_ms, so their repetitions of an older setpoint do not count, see
fpr_sim.simulation), which the controllers compute on the ``/clock`` just published: the controllers' inputs are
at most one control period old and results do not depend on the machine's speed (up to the ordering of
same-instant callbacks). No per-period wait in this helper (the multi-process run gets the same lockstep);
only a backpressure (``max_graph_lag``) keeps the simulation from running seconds ahead of the graph while
nothing streams.

Usage::

    with SwarmGraph(SwarmOptions(scenario="hover.yaml", joy_script="integration_flight.yaml")) as swarm:
        swarm.wait_for_discovery()
        swarm.run_until(lambda: swarm.sim_time >= 20.0, wall_timeout=180.0)
        truth = swarm.recorder.truth_arrays()
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import rclpy
from fpr_model.rotations import quat_to_euler_zyx
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy

from fpr_msgs.msg import AttitudeThrustSetpoint, ControllerStatus, FprState, LocalState, TeleopCommand, UavStatus

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

__all__ = ["SwarmGraph", "SwarmOptions", "SwarmRecorder", "UavNodes", "build_ground_nodes", "build_uav_nodes",
           "config_path", "node_parameters", "parameters_from_yaml"]


# ------------------------------------------------------------------------------------------------ parameters
def config_path(package: str, *parts: str) -> str:
    """``share/<package>/config/<parts>`` of the installed package, else the source tree's ``config/``."""
    try:
        from ament_index_python.packages import get_package_share_directory

        path = os.path.join(get_package_share_directory(package), "config", *parts)
        if os.path.exists(path):
            return path
    except Exception:  # noqa: BLE001 - no ament index (plain source tree)
        pass
    return os.path.join(ROOT, "src", package, "config", *parts)


def parameters_from_yaml(path: str, node_name: str) -> dict[str, Any]:
    """The parameters a ``--params-file path`` gives node ``node_name`` (the ``/**`` section first, then sections
    naming the node), as ``{dotted_name: value}``. (rclpy's ``parameter_dict_from_yaml_file`` turns ``.nan`` into
    the string 'nan', unlike the rcl parser behind ``--params-file``, hence this small reader.)"""
    import yaml

    with open(path, encoding="utf-8") as stream:
        document = yaml.safe_load(stream) or {}
    sections = [key for key in document if key == "/**"]
    sections += [key for key in document if key != "/**" and key.lstrip("/").split("/")[-1] == node_name]
    values: dict[str, Any] = {}

    def flatten(prefix: str, tree: dict) -> None:
        for key, value in tree.items():
            name = f"{prefix}{key}"
            if isinstance(value, dict):
                flatten(name + ".", value)
            else:
                values[name] = value

    for key in sections:
        flatten("", (document[key] or {}).get("ros__parameters", {}) or {})
    return values


def _overrides(values: dict[str, Any]) -> list[Parameter]:
    return [Parameter(name, value=value) for name, value in values.items()]


# ------------------------------------------------------------------------------------------------ options
@dataclass
class SwarmOptions:
    """What to build. Names of scenario / joy script files are looked up in the packages' config folders."""

    scenario: str = "hover.yaml"  #: fpr_sim config/scenarios/<name> or a path
    joy_script: str = "takeoff_hover_land.yaml"  #: fpr_control config/joy_scripts/<name> or a path
    controller_mode: str = "communicating"
    emulated_cameras: bool = True  #: noisy MarkerDetection poses; False: images + aruco_detector
    real_time_factor: float = 0.0  #: 0 = lockstep as fast as possible
    lockstep: bool = True
    lockstep_timeout: float = 0.5  #: [s] wall
    #: [s] simulated: the stepping thread never runs further than this ahead of the graph's clock (the recorder's
    #: /clock). The simulator's lockstep holds it only while setpoint streams are live; before arming and after
    #: landing the one executor would otherwise pile up a backlog that the lockstep must then wait off (timeouts).
    #: Not a per-period wait: with live streams the graph is within one control period anyway. inf: off.
    max_graph_lag: float = 0.1
    #: extra parameters per node kind: "simulator", "px4_bridge", "pose_estimator", "aruco_detector",
    #: "controller", "teleop", "joy_script" (applied last)
    overrides: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: per-UAV extra parameters: {(kind, uav_id): {...}}
    uav_overrides: dict[tuple[str, int], dict[str, Any]] = field(default_factory=dict)


def _resolve(name: str, package: str, folder: str) -> str:
    if os.path.exists(name):
        return os.path.abspath(name)
    for path in (config_path(package, folder, name), os.path.join(ROOT, "src", package, "config", folder, name)):
        if os.path.exists(path):
            return path
    raise FileNotFoundError(f"{name}: neither a path nor in {package}/config/{folder}")


# ------------------------------------------------------------------------------------------------ recorder
def _t(stamp) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


class SwarmRecorder(Node):
    """Keeps the ground truth and every UAV's status / diagnostics / local_state / setpoint, and the teleop
    command, each with its header stamp (simulation time)."""

    def __init__(self, n: int, **kwargs) -> None:
        super().__init__("swarm_recorder", **kwargs)
        self.n = n
        self.lock = threading.Lock()
        self.truth: list[FprState] = []
        self.teleop: list[TeleopCommand] = []
        self.status: dict[int, list[UavStatus]] = {i: [] for i in range(1, n + 1)}
        self.diagnostics: dict[int, list[ControllerStatus]] = {i: [] for i in range(1, n + 1)}
        self.local_state: dict[int, list[LocalState]] = {i: [] for i in range(1, n + 1)}
        self.setpoints: dict[int, list[AttitudeThrustSetpoint]] = {i: [] for i in range(1, n + 1)}
        reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        best_effort = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.create_subscription(FprState, "/fpr/ground_truth", self._keep(self.truth), reliable)
        self.create_subscription(TeleopCommand, "/fpr/teleop", self._keep(self.teleop), reliable)
        for i in range(1, n + 1):
            ns = f"/fpr/uav{i}"
            self.create_subscription(UavStatus, f"{ns}/status", self._keep(self.status[i]), reliable)
            self.create_subscription(ControllerStatus, f"{ns}/diagnostics", self._keep(self.diagnostics[i]),
                                     reliable)
            self.create_subscription(LocalState, f"{ns}/local_state", self._keep(self.local_state[i]), reliable)
            self.create_subscription(AttitudeThrustSetpoint, f"{ns}/setpoint", self._keep(self.setpoints[i]),
                                     best_effort)

    def _keep(self, store: list) -> Callable:
        def callback(msg) -> None:
            with self.lock:
                store.append(msg)
        return callback

    # ---- views for metrics ------------------------------------------------------------------------
    def latest_status(self) -> dict[int, UavStatus | None]:
        with self.lock:
            return {i: (s[-1] if s else None) for i, s in self.status.items()}

    def truth_arrays(self) -> dict[str, np.ndarray]:
        """Ground truth as arrays: t, platform position (N,3), roll/pitch/yaw (N,3) [rad], legs (N,n) [rad],
        uav thrusts (N,n) [N], and a finiteness flag of each message."""
        with self.lock:
            msgs = list(self.truth)
        t = np.array([_t(m.header.stamp) for m in msgs])
        pos = np.array([[m.platform_pose.position.x, m.platform_pose.position.y, m.platform_pose.position.z]
                        for m in msgs]).reshape(-1, 3)
        rpy = np.array([quat_to_euler_zyx(np.array([m.platform_pose.orientation.w, m.platform_pose.orientation.x,
                                                    m.platform_pose.orientation.y, m.platform_pose.orientation.z]))
                        for m in msgs]).reshape(-1, 3)
        legs = np.array([list(m.leg_angles) for m in msgs]).reshape(-1, self.n)
        thrusts = np.array([list(m.uav_thrusts) for m in msgs]).reshape(-1, self.n)
        velocity = np.array([[m.platform_twist.linear.x, m.platform_twist.linear.y, m.platform_twist.linear.z]
                             for m in msgs]).reshape(-1, 3)
        finite = np.array([_finite_fpr_state(m) for m in msgs], dtype=bool)
        return {"t": t, "position": pos, "rpy": rpy, "legs": legs, "thrusts": thrusts, "velocity": velocity,
                "finite": finite}

    def local_state_ages(self) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Per UAV: the control instants t_d (diagnostics stamps) [s] and, at each, the age [s] of the newest
        local_state stamped at or before t_d, i.e. how old the controller's estimate is at best (NaN: none yet)."""
        with self.lock:
            diagnostics = {i: np.array([_t(m.header.stamp) for m in d]) for i, d in self.diagnostics.items()}
            local = {i: np.array(sorted(_t(m.header.stamp) for m in s)) for i, s in self.local_state.items()}
        ages = {}
        for i, t_d in diagnostics.items():
            stamps = local[i]
            if not len(stamps):
                ages[i] = (t_d, np.full(len(t_d), np.nan))
                continue
            k = np.searchsorted(stamps, t_d + 1e-9) - 1
            ages[i] = (t_d, np.where(k >= 0, t_d - stamps[np.maximum(k, 0)], np.nan))
        return ages

    def teleop_arrays(self) -> dict[str, np.ndarray]:
        """Commanded χ_d: t, mode, velocity (N,3), roll, pitch, legs (N,n)."""
        with self.lock:
            msgs = list(self.teleop)
        return {"t": np.array([_t(m.header.stamp) for m in msgs]),
                "mode": np.array([m.mode for m in msgs], dtype=int),
                "velocity": np.array([[m.platform_velocity.x, m.platform_velocity.y, m.platform_velocity.z]
                                      for m in msgs]).reshape(-1, 3),
                "roll": np.array([m.roll for m in msgs]), "pitch": np.array([m.pitch for m in msgs]),
                "legs": np.array([list(m.leg_angles) for m in msgs]).reshape(-1, self.n)}


def _finite_fpr_state(m: FprState) -> bool:
    p, q = m.platform_pose.position, m.platform_pose.orientation
    values = [p.x, p.y, p.z, q.w, q.x, q.y, q.z, *m.leg_angles, *m.leg_rates, *m.uav_thrusts, *m.external_wrench]
    return all(math.isfinite(v) for v in values)


# ------------------------------------------------------------------------------------------------ node builders
def node_parameters(options: SwarmOptions, kind: str, package: str, config_file: str | None, node_name: str,
                    instance: dict[str, Any], uav_id: int | None = None) -> list[Parameter]:
    """Parameter overrides of one node: its package's config YAML, then ``instance`` values, then the
    caller's overrides (``options.overrides[kind]``, ``options.uav_overrides[(kind, uav_id)]``); use_sim_time."""
    values: dict[str, Any] = {}
    if config_file is not None:
        values.update(parameters_from_yaml(config_path(package, config_file), node_name))
    values.update(instance)
    values.update(options.overrides.get(kind, {}))
    if uav_id is not None:
        values.update(options.uav_overrides.get((kind, uav_id), {}))
    values["use_sim_time"] = True
    return _overrides(values)


@dataclass
class UavNodes:
    """The on-board nodes of one UAV (namespace /fpr/uav<i>)."""

    bridge: Node
    estimator: Node
    controller: Node
    detector: Node | None = None

    @property
    def nodes(self) -> list[Node]:
        return [n for n in (self.bridge, self.detector, self.estimator, self.controller) if n is not None]


def build_uav_nodes(context, options: SwarmOptions, uav_id: int, n: int) -> UavNodes:
    """px4_bridge, (aruco_detector,) pose_estimator and controller of UAV ``uav_id`` in ``context``."""
    from fpr_control.controller_node import ControllerNode
    from fpr_estimation.pose_estimator import PoseEstimatorNode
    from fpr_px4_bridge.px4_bridge_node import Px4BridgeNode

    ns, i, o = f"/fpr/uav{uav_id}", uav_id, options
    bridge = Px4BridgeNode(context=context, namespace=ns, parameter_overrides=node_parameters(
        o, "px4_bridge", "fpr_px4_bridge", "px4_bridge.yaml", "px4_bridge", {"uav_id": i}, i))
    detector = None
    if not o.emulated_cameras:
        from fpr_estimation.aruco_detector import ArucoDetectorNode

        detector = ArucoDetectorNode(context=context, namespace=ns, parameter_overrides=node_parameters(
            o, "aruco_detector", "fpr_estimation", "aruco_detector.yaml", "aruco_detector", {}, i))
    estimator = PoseEstimatorNode(context=context, namespace=ns, parameter_overrides=node_parameters(
        o, "pose_estimator", "fpr_estimation", "pose_estimator.yaml", "pose_estimator", {"uav_id": i, "n": n}, i))
    controller = ControllerNode(context=context, namespace=ns, parameter_overrides=node_parameters(
        o, "controller", "fpr_control", "controller.yaml", "controller",
        {"uav_id": i, "n": n, "mode": o.controller_mode}, i))
    return UavNodes(bridge, estimator, controller, detector)


def build_ground_nodes(context, options: SwarmOptions, n: int) -> tuple[Node, Node]:
    """The ground station: teleop (mapping config/teleop.yaml) and joy_script, namespace /fpr/ground."""
    from fpr_control.joy_script_node import JoyScriptNode
    from fpr_control.teleop_node import TeleopNode

    teleop = TeleopNode(context=context, namespace="/fpr/ground", parameter_overrides=node_parameters(
        options, "teleop", "fpr_control", None, "teleop",
        {"n": n, "mapping_file": config_path("fpr_control", "teleop.yaml")}))
    joy_script = JoyScriptNode(context=context, namespace="/fpr/ground", parameter_overrides=node_parameters(
        options, "joy_script", "fpr_control", None, "joy_script",
        {"script": _resolve(options.joy_script, "fpr_control", "joy_scripts")}))
    return teleop, joy_script


# ------------------------------------------------------------------------------------------------ the graph
class SwarmGraph:
    """See the module doc. A context manager: ``close()`` destroys every node and shuts the context down."""

    def __init__(self, options: SwarmOptions | None = None) -> None:
        self.options = options = options or SwarmOptions()
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.nodes: list[Node] = []
        self.errors: list[str] = []  #: exceptions raised in callbacks (the graph keeps running)
        self._running = True
        self._executor: SingleThreadedExecutor | None = None
        self._spinner: threading.Thread | None = None
        try:
            self._build()
        except BaseException:
            self.close()
            raise

    # ---- construction -----------------------------------------------------------------------------
    def _add(self, node: Node) -> Node:
        self.nodes.append(node)
        return node

    def _build(self) -> None:
        from fpr_sim.simulator import SimulatorNode

        o, ctx = self.options, self.context
        self.simulator = self._add(SimulatorNode(context=ctx, parameter_overrides=node_parameters(
            o, "simulator", "fpr_sim", "simulator.yaml", "simulator",
            {"scenario_file": _resolve(o.scenario, "fpr_sim", "scenarios"),
             "real_time_factor": float(o.real_time_factor), "lockstep": o.lockstep,
             "lockstep_timeout": float(o.lockstep_timeout), "emulated_cameras": o.emulated_cameras,
             "duration": 0.0})))
        self.n = n = self.simulator.sim.n
        self.bridges, self.estimators, self.detectors, self.controllers = [], [], [], []
        for i in range(1, n + 1):
            uav = build_uav_nodes(ctx, o, i, n)
            for node in uav.nodes:
                self._add(node)
            self.bridges.append(uav.bridge)
            self.estimators.append(uav.estimator)
            self.controllers.append(uav.controller)
            if uav.detector is not None:
                self.detectors.append(uav.detector)
        self.teleop, self.joy_script = (self._add(node) for node in build_ground_nodes(ctx, o, n))
        self.recorder = self._add(SwarmRecorder(n, context=ctx, parameter_overrides=[
            Parameter("use_sim_time", value=True)]))
        self._executor = SingleThreadedExecutor(context=ctx)
        for node in self.nodes:
            if node is not self.simulator:
                self._executor.add_node(node)
        self._spinner = threading.Thread(target=self._spin, name="swarm_executor", daemon=True)
        self._spinner.start()

    def _spin(self) -> None:
        executor = self._executor
        while self._running and self.context.ok():
            try:
                executor.spin_once(timeout_sec=0.05)
            except Exception as error:  # noqa: BLE001 - report, keep the graph alive, the test fails on metrics
                if not self._running or not self.context.ok():
                    return
                self.errors.append(repr(error))

    # ---- discovery ----------------------------------------------------------------------------------
    def discovery_pending(self) -> list[str]:
        """Connections not matched yet (publisher -> expected subscriber count)."""
        n, pending = self.n, []

        def need(what: str, publisher, count: int) -> None:
            if publisher.get_subscription_count() < count:
                pending.append(f"{what} ({publisher.get_subscription_count()}/{count})")

        sim_time_nodes = len(self.nodes) - 1  # every node but the simulator listens to /clock
        need("/clock", self.simulator.clock_pub, sim_time_nodes)
        need("/fpr/ground_truth", self.simulator.truth_pub, 1)
        need("joy", self.joy_script.pub, 1)
        need("/fpr/teleop", self.teleop.pub, 2 * n + 1)
        for k in range(n):
            i = k + 1
            if self.options.emulated_cameras:
                need(f"uav{i} marker", self.simulator.marker_pubs[k], 1)
            else:
                need(f"uav{i} image", self.simulator.image_pubs[k], 1)
            need(f"uav{i} imu", self.bridges[k].imu_pub, 2)
            need(f"uav{i} velocity_body", self.bridges[k].velocity_pub, 1)
            need(f"uav{i} local_state", self.estimators[k]._pub, 2)
            need(f"uav{i} setpoint", self.controllers[k].setpoint_pub, 2)
            need(f"uav{i} /fpr/info", self.controllers[k].info_pub, n)
            need(f"uav{i} diagnostics", self.controllers[k].status_pub, 1)
            need(f"uav{i} status", self.bridges[k].status_pub, 1)
        return pending

    def wait_for_discovery(self, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while pending := self.discovery_pending():
            if time.monotonic() > deadline:
                raise TimeoutError(f"discovery incomplete after {timeout} s: {pending}")
            time.sleep(0.05)

    # ---- running ------------------------------------------------------------------------------------
    @property
    def sim_time(self) -> float:
        return self.simulator.sim.time

    @property
    def lockstep_timeouts(self) -> int:
        return self.simulator.sim.lockstep_timeouts

    def setpoint_latency_max(self, start: float = 0.0, end: float = math.inf) -> float:
        """[s] the oldest controller setpoint on arrival at its emulated PX4 (simulation time − its stamp) among
        those that arrived between ``start`` and ``end`` [s, simulation time]."""
        return self.simulator.sim.setpoint_latency_max(start, end)

    def _hold_for_graph(self, wall_deadline: float) -> None:
        """Backpressure (``max_graph_lag``): wait while the recorder's clock is too far behind the simulation."""
        limit = self.options.max_graph_lag
        clock = self.recorder.get_clock()
        while self.sim_time - clock.now().nanoseconds * 1e-9 > limit and time.monotonic() < wall_deadline:
            time.sleep(0.0005)

    def run_until(self, condition: Callable[[], bool], wall_timeout: float, sim_timeout: float = math.inf,
                  progress: Callable[[], None] | None = None, progress_period: float = 2.0) -> bool:
        """Step the simulation until ``condition()`` (checked every /clock period); False on a timeout
        (wall [s] or simulated [s]). ``progress`` is called every ``progress_period`` simulated seconds."""
        wall_deadline = time.monotonic() + wall_timeout
        sim_deadline = self.sim_time + sim_timeout
        next_progress = self.sim_time
        while not condition():
            if time.monotonic() > wall_deadline or self.sim_time >= sim_deadline:
                return False
            self.simulator.step()
            self._hold_for_graph(wall_deadline)
            if progress is not None and self.sim_time >= next_progress:
                next_progress += progress_period
                progress()
        return True

    def wait_for_recorder(self, wall_timeout: float = 30.0) -> bool:
        """Wait until the recorder holds the last published ground truth: the lockstep holds the simulation only
        while setpoint streams are live, so after the landing (or before arming) the one executor of the ROS
        graph may lag behind the simulation. False on the (wall) timeout."""
        last = self.simulator._next_truth - self.simulator.truth_period
        deadline = time.monotonic() + wall_timeout
        while time.monotonic() < deadline:
            with self.recorder.lock:
                if self.recorder.truth and _t(self.recorder.truth[-1].header.stamp) >= last - 1e-6:
                    return True
            time.sleep(0.01)
        return False

    # ---- teardown -----------------------------------------------------------------------------------
    def close(self) -> None:
        self._running = False
        if self._spinner is not None:
            self._spinner.join(timeout=5.0)
        if self._executor is not None:
            self._executor.shutdown(timeout_sec=1.0)
        for node in reversed(self.nodes):
            try:
                node.destroy_node()
            except Exception:  # noqa: BLE001 - best effort at teardown
                pass
        self.nodes.clear()
        self.context.try_shutdown()

    def __enter__(self) -> SwarmGraph:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
