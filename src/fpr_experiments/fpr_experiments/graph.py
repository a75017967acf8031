"""The ONE description of the FPR node graph (DESIGN.md §3), ROS-free.

:func:`describe_graph` returns the node list — package, executable, node name, namespace, parameter files and
overrides, remappings, and the process group each node runs in on the robot — for n UAVs, a controller mode,
cameras (rendered images + ``aruco_detector``, or the simulator's emulated marker poses) and a backend:

- ``sim``: the ``simulator`` node replaces the hardware; every other node runs on simulated time (``use_sim_time``;
  the simulator is the clock);
- ``real``: the robot. No simulator, no ``use_sim_time``; the camera images come from a camera driver on each
  companion computer (``/fpr/uav<i>/camera/image_raw`` + ``camera_info``), the PX4 links from each bridge's
  ``connection_url`` (a params file per vehicle), and ``/fpr/motion_capture`` (fpr_msgs/FprState; the centralized /
  ground-truth modes only, the controllers' ``motion_capture_topic``) from a motion-capture bridge. In simulation
  the simulator publishes it (fpr_sim ``motion_capture``: exact in the ideal profile, noisy and late in hardware).

Three consumers use it and nothing else: the in-process runner (:mod:`fpr_experiments.inprocess`, one executor),
the multi-process runner (:mod:`fpr_experiments.processes`, one process per group: ``simulator``, ``uav<i>``,
``ground``, as on the robot) and ``launch/fpr.launch.py`` (native Jazzy, one process per node). Parameters always
reach a node through rcl's own argument handling: ``--params-file`` for files, ``-p name:=value`` for overrides
(:meth:`NodeSpec.ros_args`), later values winning, exactly as ``ros2 run … --ros-args …`` would.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from fpr_experiments.resources import JOY_SCRIPTS, SCENARIOS, config_path

BACKENDS = ("sim", "real")
CAMERAS = ("emulated", "images")
OPERATORS = ("joy_script", "pilot", "joystick", "none")
MODES = ("centralized", "communicating", "non_communicating", "impedance", "pd", "pd_compensated")

#: executable -> (package, default parameter file in the package's config/ or None)
EXECUTABLES: dict[str, tuple[str, str | None]] = {
    "simulator": ("fpr_sim", "simulator.yaml"),
    "px4_bridge": ("fpr_px4_bridge", "px4_bridge.yaml"),
    "aruco_detector": ("fpr_estimation", "aruco_detector.yaml"),
    "pose_estimator": ("fpr_estimation", "pose_estimator.yaml"),
    "controller": ("fpr_control", "controller.yaml"),
    "teleop": ("fpr_control", None),
    "joy_script": ("fpr_control", None),
    "joystick": ("fpr_control", None),
    "pilot": ("fpr_experiments", None),
    "info_link": ("fpr_experiments", None),
    "detection_fallback": ("fpr_experiments", None),
}
#: executables that run once per UAV, in the namespace /fpr/uav<i>
PER_UAV = ("px4_bridge", "aruco_detector", "pose_estimator", "controller")
GROUND_NAMESPACE = "/fpr/ground"


def uav_namespace(uav_id: int) -> str:
    return f"/fpr/uav{uav_id}"


def parameter_value_text(value: Any) -> str:
    """``value`` as the YAML text rcl parses after ``-p name:=`` (JSON is valid YAML flow: strings stay strings,
    lists stay lists, ``true``/``false`` are booleans)."""
    if isinstance(value, float) and not math.isfinite(value):
        return ".nan" if math.isnan(value) else (".inf" if value > 0 else "-.inf")
    if isinstance(value, tuple):
        value = list(value)
    return json.dumps(value)


@dataclass
class NodeSpec:
    """One node of the graph, as ``ros2 run <package> <executable> --ros-args <ros_args()>`` would start it."""

    package: str
    executable: str
    name: str
    namespace: str
    group: str                                     #: process group on the robot: simulator | uav<i> | ground | …
    params_files: list[str] = field(default_factory=list)
    parameters: dict[str, Any] = field(default_factory=dict)  #: overrides, applied after the files
    remappings: list[tuple[str, str]] = field(default_factory=list)
    uav_id: int | None = None

    @property
    def fully_qualified_name(self) -> str:
        return f"{self.namespace.rstrip('/')}/{self.name}" if self.namespace else f"/{self.name}"

    def ros_args(self) -> list[str]:
        """The node's ``--ros-args …`` (namespace, name, files, ``-p`` overrides, remappings)."""
        args = ["--ros-args", "-r", f"__node:={self.name}"]
        if self.namespace:
            args += ["-r", f"__ns:={self.namespace}"]
        for path in self.params_files:
            args += ["--params-file", path]
        for name, value in self.parameters.items():
            args += ["-p", f"{name}:={parameter_value_text(value)}"]
        for source, target in self.remappings:
            args += ["-r", f"{source}:={target}"]
        return args

    def command(self, enclave: bool = False) -> list[str]:
        """``ros2 run`` command line of this node alone; ``enclave``: in its SROS2 enclave (its fully qualified
        name, the enclaves of fpr_experiments.security's policy)."""
        return ["ros2", "run", self.package, self.executable, *self.ros_args(),
                *(["--enclave", self.fully_qualified_name] if enclave else [])]

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["remappings"] = [list(r) for r in self.remappings]
        return out

    @staticmethod
    def from_dict(data: Mapping[str, Any]) -> NodeSpec:
        values = dict(data)
        values["remappings"] = [tuple(r) for r in values.get("remappings", [])]
        return NodeSpec(**values)


@dataclass
class GraphOptions:
    """What graph to build (see the module doc). Parameter overrides are per executable (``parameters``), per
    (executable, uav_id) (``uav_parameters``, applied after), and extra parameter files per executable
    (``params_files``, after the package's own file)."""

    n: int = 3
    mode: str = "communicating"
    cameras: str = "emulated"
    backend: str = "sim"
    scenario: str = "ground_start"          #: sim: a scenario name or path (fpr_experiments / fpr_sim config)
    operator: str = "joy_script"            #: joy_script | pilot | joystick | none (an external /joy publisher)
    script: str = "takeoff_hover_land"      #: joy_script / pilot: a script name or path
    #: sim: realism profile (fpr_sim.scenario.realism_profiles: ideal | hardware) of the simulator and the info
    #: link; "": the scenario's own ``realism`` key (default ideal)
    realism: str = ""
    #: route /fpr/info through an info_link node (a scheduled outage); sim only. The node is also there whenever
    #: the realism profile enables the Wi-Fi link model (scenario.link)
    info_link: bool = False
    #: sim: the thesis's motion-capture supervision of the detections (§4.4.2, a ``detection_fallback`` node between
    #: each UAV's camera pipeline and its pose estimator, which then reads :data:`CHECKED_MARKER_TOPIC`)
    detection_fallback: bool = False
    #: MAVLink 2 signing key file for every px4_bridge and (sim) every emulated PX4; "": unsigned
    signing_key_file: str = ""
    parameters: dict[str, dict[str, Any]] = field(default_factory=dict)
    uav_parameters: dict[tuple[str, int], dict[str, Any]] = field(default_factory=dict)
    params_files: dict[str, list[str]] = field(default_factory=dict)

    def validate(self) -> None:
        def one_of(name: str, value: str, valid: Sequence[str]) -> None:
            if value not in valid:
                raise ValueError(f"{name} '{value}' is not one of {', '.join(valid)}")

        one_of("backend", self.backend, BACKENDS)
        one_of("cameras", self.cameras, CAMERAS)
        one_of("operator", self.operator, OPERATORS)
        one_of("mode", self.mode, MODES)
        if isinstance(self.n, bool) or not isinstance(self.n, int) or self.n < 3:
            raise ValueError(f"n must be an integer >= 3, got {self.n!r}")
        if self.backend == "real" and self.cameras == "emulated":
            raise ValueError("cameras 'emulated' needs the simulator (backend sim); the robot uses images")
        if self.backend == "real" and (self.realism or self.info_link):
            raise ValueError("realism and info_link need the simulator (backend sim): the robot has its own")
        if self.backend == "real" and self.detection_fallback:
            raise ValueError("detection_fallback is an experiment set-up on the simulator's motion capture (backend "
                             "sim); on the robot run the detection_fallback node by hand beside a MOCAP bridge")
        if self.realism:
            from fpr_sim.scenario import realism_profiles

            one_of("realism", self.realism, realism_profiles())
        unknown = sorted(set(self.parameters) - set(EXECUTABLES))
        unknown += sorted({kind for kind, _ in self.uav_parameters} - set(EXECUTABLES))
        unknown += sorted(set(self.params_files) - set(EXECUTABLES))
        if unknown:
            raise ValueError(f"parameters for unknown executable(s) {unknown}; valid: {', '.join(EXECUTABLES)}")


def _spec(options: GraphOptions, executable: str, namespace: str, group: str, instance: dict[str, Any],
          uav_id: int | None = None, remappings: list[tuple[str, str]] | None = None) -> NodeSpec:
    package, default_file = EXECUTABLES[executable]
    files = [config_path(package, default_file)] if default_file else []
    files += [str(f) for f in options.params_files.get(executable, [])]
    parameters: dict[str, Any] = {}
    if options.backend == "sim" and executable != "simulator":
        # the simulator IS the clock: it stamps with its own simulated time, and a /clock subscription of its own
        # would only read back what it publishes (in the in-process runner it also made every /clock message go
        # through DDS for that one reader: ~1 % of the CPU in a profile, not measurable as a lever,
        # docs/benchmarks.md; the multi-process runner's count of /clock readers did not include it either)
        parameters["use_sim_time"] = True
    parameters.update(instance)
    parameters.update(options.parameters.get(executable, {}))
    if uav_id is not None:
        parameters.update(options.uav_parameters.get((executable, uav_id), {}))
    return NodeSpec(package=package, executable=executable, name=executable, namespace=namespace, group=group,
                    params_files=files, parameters=parameters, remappings=list(remappings or []), uav_id=uav_id)


#: sim with an info_link node: UAV j's controller reads the peers' ζ here (the node's ``output_topic``)
INFO_LINK_TOPIC = "/fpr/uav{uav}/info_link"
#: with ``detection_fallback``: the supervised detections each pose estimator reads (relative to /fpr/uav<i>)
CHECKED_MARKER_TOPIC = "marker_checked"


def describe_graph(options: GraphOptions) -> list[NodeSpec]:
    """The node list of the FPR graph for ``options`` (see the module doc), in start order: simulator, then per
    UAV its on-board nodes, then the ground station (and, sim, the info link when an outage or the realism
    profile's link model needs it: every controller then reads its own topic :data:`INFO_LINK_TOPIC`)."""
    options.validate()
    n = options.n
    specs: list[NodeSpec] = []
    info_link: dict[str, Any] | None = None
    if options.backend == "sim":
        from fpr_sim.scenario import load_scenario

        scenario_file = SCENARIOS.resolve(options.scenario)
        scenario = load_scenario(scenario_file, realism=options.realism or None)
        if scenario.n != n:
            raise ValueError(f"scenario '{options.scenario}' has n = {scenario.n}, the graph n = {n}")
        simulator = {"scenario_file": scenario_file, "realism": scenario.realism,
                     "emulated_cameras": options.cameras == "emulated"}
        if options.signing_key_file:
            simulator["signing_key_file"] = options.signing_key_file
        specs.append(_spec(options, "simulator", "", "simulator", simulator))
        if options.info_link or scenario.link.enabled:
            info_link = {"n": n, "output_topic": INFO_LINK_TOPIC, "scenario_file": scenario_file,
                         "realism": scenario.realism}
    for i in range(1, n + 1):
        ns, group = uav_namespace(i), f"uav{i}"
        bridge = {"uav_id": i, "n": n}
        if info_link is not None:  # the swarm guard hears the peers' zeta as this UAV's controller does
            bridge["info_topic"] = INFO_LINK_TOPIC.format(uav=i)
        if options.backend == "sim":  # the emulated PX4 boots at simulation time 0: exact setpoint stamps
            bridge["px4_boot_clock"] = "ros_time"
        if options.signing_key_file:
            bridge["signing_key_file"] = options.signing_key_file
        specs.append(_spec(options, "px4_bridge", ns, group, bridge, i))
        if options.cameras == "images":
            specs.append(_spec(options, "aruco_detector", ns, group, {}, i))
        fallback_remap = [("marker", CHECKED_MARKER_TOPIC)] if options.detection_fallback else None
        specs.append(_spec(options, "pose_estimator", ns, group, {"uav_id": i, "n": n}, i, fallback_remap))
        controller = {"uav_id": i, "n": n, "mode": options.mode}
        if info_link is not None:
            controller["info_input_topic"] = INFO_LINK_TOPIC.format(uav=i)
        specs.append(_spec(options, "controller", ns, group, controller, i))
    specs.append(_spec(options, "teleop", GROUND_NAMESPACE, "ground", {
        "n": n, "mapping_file": config_path("fpr_control", "teleop.yaml")}))
    if options.operator in ("joy_script", "pilot"):
        specs.append(_spec(options, options.operator, GROUND_NAMESPACE, "ground", {
            "script": JOY_SCRIPTS.resolve(options.script)}))
    elif options.operator == "joystick":
        specs.append(_spec(options, "joystick", GROUND_NAMESPACE, "ground", {}))
    if info_link is not None:
        specs.append(_spec(options, "info_link", "/fpr", "link", info_link))
    if options.detection_fallback:
        specs.append(_spec(options, "detection_fallback", "/fpr", "ground", {
            "n": n, "output_topic": CHECKED_MARKER_TOPIC, "seed": int(scenario.seed)}))
    return specs


def groups(specs: Sequence[NodeSpec]) -> dict[str, list[NodeSpec]]:
    """Node specs by process group, in order of first appearance."""
    out: dict[str, list[NodeSpec]] = {}
    for spec in specs:
        out.setdefault(spec.group, []).append(spec)
    return out


def write_graph_file(specs: Sequence[NodeSpec], path: str) -> None:
    """The node list as JSON (what the multi-process runner's ``node_group`` processes read; a record of the run)."""
    with open(path, "w", encoding="utf-8") as stream:
        json.dump({"nodes": [s.to_dict() for s in specs]}, stream, indent=1)
        stream.write("\n")


def read_graph_file(path: str) -> list[NodeSpec]:
    with open(path, encoding="utf-8") as stream:
        return [NodeSpec.from_dict(d) for d in json.load(stream)["nodes"]]


#: the launch file's arguments: name -> (default, description). "" defaults are filled by launch_options.
LAUNCH_ARGUMENTS: dict[str, tuple[str, str]] = {
    "backend": ("sim", "sim (the simulator replaces the hardware) | real (the robot)"),
    "n": ("3", "number of UAVs (sim: must match the scenario)"),
    "mode": ("communicating", "controller mode: " + " | ".join(MODES)),
    "cameras": ("", "emulated | images (default: emulated in sim, images on the robot)"),
    "scenario": ("ground_start", "sim: scenario name or path (fpr_experiments / fpr_sim config/scenarios)"),
    "operator": ("", "joy_script | joystick | none (default: joy_script in sim, joystick on the robot)"),
    "script": ("takeoff_hover_land", "joy_script: script name or path (config/joy_scripts)"),
    "realism": ("", "sim: realism profile of the simulator and the inter-UAV link, ideal | hardware (empty: the "
                    "scenario's own, default ideal)"),
    "signing_key_file": ("", "MAVLink 2 signing key (64 hex digits) for every px4_bridge (and, sim, every emulated "
                             "PX4); empty: unsigned"),
    "enclaves": ("false", "SROS2: true starts every node with --enclave <its fully qualified name> (set "
                          "ROS_SECURITY_KEYSTORE / ENABLE / STRATEGY; fpr_experiments README, 'Securing the ROS "
                          "graph')"),
}


def launch_enclaves(values: Mapping[str, str]) -> bool:
    """The launch argument ``enclaves`` as a boolean; ValueError for anything but true/false."""
    text = str(values.get("enclaves", LAUNCH_ARGUMENTS["enclaves"][0])).strip().lower()
    if text not in ("true", "false"):
        raise ValueError(f"enclaves must be true or false, got '{text}'")
    return text == "true"


def launch_options(values: Mapping[str, str]) -> GraphOptions:
    """:class:`GraphOptions` from the launch file's string arguments (the defaults of
    :data:`LAUNCH_ARGUMENTS` for the missing ones); ValueError says what is wrong."""
    unknown = sorted(set(values) - set(LAUNCH_ARGUMENTS))
    if unknown:
        raise ValueError(f"unknown launch argument(s) {unknown}; valid: {', '.join(LAUNCH_ARGUMENTS)}")
    merged = {name: str(values.get(name, default)) for name, (default, _) in LAUNCH_ARGUMENTS.items()}
    backend = merged["backend"]
    try:
        n = int(merged["n"])
    except ValueError:
        raise ValueError(f"n must be an integer, got '{merged['n']}'") from None
    cameras = merged["cameras"] or ("emulated" if backend == "sim" else "images")
    operator = merged["operator"] or ("joy_script" if backend == "sim" else "joystick")
    options = GraphOptions(n=n, mode=merged["mode"], cameras=cameras, backend=backend, scenario=merged["scenario"],
                           operator=operator, script=merged["script"], signing_key_file=merged["signing_key_file"],
                           realism=merged["realism"])
    options.validate()
    return options
