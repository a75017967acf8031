"""Fault injection in the multi-process graph (issue 12): kill one node of one UAV mid-hover, optionally restart
it, and measure what the robot did — from the ground truth and from every SET_ATTITUDE_TARGET and mode change
of the emulated PX4s (the simulator's ``px4_log_file``, :mod:`fpr_sim.px4_log`).

The flight: the ``hover`` scenario (armed in OFFBOARD at 1.5 m, legs 45°), the ``integration_hover`` joy script
(ARM + FLY, climb 2 s at 0.3 m/s to ~2.1 m, hold), mode C, emulated cameras, the graph as on the robot (one
process per UAV, ground, simulator) except that the victim node runs in a process of its own, so that it can
die alone (SIGKILL: no clean shutdown, as a crash). Lockstep with ``lockstep_on_timeout: continue`` and a 0.3 s
watchdog: a dead stream is waited for once, then the simulation flies on without it (PX4's failsafes play out in
simulation time). A restart holds the world (the simulator paused) while the new process starts: the node is back
``restart_after`` s of simulation time after the kill, however long its start-up takes on the machine
(fpr_experiments.processes.ProcessFault).

Metrics (:func:`fault_metrics`), all after the fault instant t_f (the kill, simulation time):

- ``max_tilt_deg``: the platform's largest tilt (angle between its z axis and the vertical) [°];
- ``max_climb_m``: the largest height any UAV reached above its own height at t_f [m];
- ``all_disarmed_s``: from t_f until every emulated PX4 is disarmed for good [s] (NaN: some never disarmed);
- ``touchdown_speed_mps``: the fastest descent of any UAV within 5 cm above its touchdown height [m/s];
- ``end_height_m``: the platform centre's height at the end [m]; ``hover_held``: at the end every PX4 is armed
  in OFFBOARD, the platform within 8° of level and within 0.4 m of its height at t_f (the recovery case);
- ``max_thrust_received``: the largest raw normalized thrust any PX4 received after t_f (1 = full throttle).

Killing the ``simulator`` (every emulated PX4 with it) measures instead how fast each bridge says so:
``link_lost_s`` the largest, over the UAVs, wall time from the kill to the bridge's "PX4 lost" line
(:func:`link_loss_delays`; the bridges' wall-clock watchdog, since /clock stops with the simulator), and
``link_lost_silence_uav<i>_s`` the silence that line reports: wall time since the last frame the bridge's receive
thread read. On a loaded machine the two differ: a bridge process held off the CPU reads the datagrams the
simulator sent before dying up to a second late (seen on a 2-core VM, 2026-12-07: 1.53 s from the kill, 0.5 s of
silence).

``ros2 run fpr_experiments faults`` runs a matrix of cases (nodes × restart × seeds) and writes a Markdown table
(``docs/safety.md``); tests/test_fault_response.py asserts the issue's acceptance on a few of them.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["FAULT_NODES", "FAULT_TARGETS", "FaultCase", "FaultResult", "fault_metrics", "link_loss_delays",
           "run_fault"]

#: the nodes of a UAV that can be killed: its controller, its PX4 bridge, its pose estimator
FAULT_NODES = ("controller", "px4_bridge", "pose_estimator")
#: ... and the simulator (all PX4s at once; no restart)
FAULT_TARGETS = (*FAULT_NODES, "simulator")
SCENARIO = "hover"
SCRIPT = "integration_hover"
#: [s] simulated: the climb of the script ends at 5.1 s; the robot is settled at 8 s
DEFAULT_FAULT_TIME = 8.0


@dataclass(frozen=True)
class FaultCase:
    node: str = "controller"              #: one of FAULT_NODES
    uav: int = 2                          #: the UAV whose node dies (1-based)
    at: float = DEFAULT_FAULT_TIME        #: [s] simulation time of the kill
    restart_after: float | None = None    #: [s] simulation time from the kill to the restart; None: stays dead
    seed: int | None = None               #: scenario seed (None: the scenario's own)
    after: float = 16.0                   #: [s] simulated after the kill
    mode: str = "communicating"
    realism: str = ""                     #: "" : the scenario's own (ideal)

    def __post_init__(self) -> None:
        if self.node not in FAULT_TARGETS:
            raise ValueError(f"fault node '{self.node}' is not one of {', '.join(FAULT_TARGETS)}")
        if self.node == "simulator" and self.restart_after is not None:
            raise ValueError("the simulator cannot be restarted")
        if self.restart_after is not None and not self.restart_after > 0.0:
            raise ValueError(f"restart_after must be > 0 s, got {self.restart_after}")

    @property
    def label(self) -> str:
        restart = f"restart {self.restart_after:g} s" if self.restart_after is not None else "no restart"
        if self.node == "simulator":
            return f"simulator killed at {self.at:g} s, seed {self.seed}"
        return f"uav{self.uav} {self.node} killed at {self.at:g} s, {restart}, seed {self.seed}"

    @property
    def group(self) -> str:
        """The victim's own process group."""
        return "simulator" if self.node == "simulator" else f"uav{self.uav}_{self.node}"


@dataclass
class FaultResult:
    case: FaultCase
    metrics: dict[str, float]
    events: list[tuple[str, float, float]]
    output_dir: str
    completed: bool
    errors: list[str] = field(default_factory=list)


def fault_graph(case: FaultCase, scenario_file: str, px4_log_file: str,
                parameters: Mapping[str, Mapping[str, Any]] | None = None) -> list:
    """The node specs of ``case``'s flight (module doc), the victim in its own group."""
    from fpr_experiments.graph import GraphOptions, describe_graph

    options = GraphOptions(n=3, mode=case.mode, cameras="emulated", scenario=scenario_file, operator="joy_script",
                           script=SCRIPT, realism=case.realism,
                           parameters={k: dict(v) for k, v in (parameters or {}).items()})
    options.parameters.setdefault("simulator", {}).update(
        {"lockstep_on_timeout": "continue", "lockstep_timeout": 0.3, "px4_log_file": px4_log_file})
    specs = describe_graph(options)
    if case.node == "simulator":
        return specs
    victims = [s for s in specs if s.executable == case.node and s.uav_id == case.uav]
    if len(victims) != 1:
        raise ValueError(f"no node {case.node} of uav {case.uav} in the graph")
    victims[0].group = case.group
    return specs


#: the emergency-response combinations compared (README of fpr_px4_bridge, "Emergency response"): node parameter
#: overrides per executable and scenario overrides (the emulated PX4s' failsafe, fpr_sim Px4Config)
ALTERNATIVES: dict[str, dict[str, Any]] = {
    "guard": {"description": "swarm guard (default): every UAV Hold on a fault, AUTO.LAND after 5 s unless it "
                             "clears (rejoin); the lost UAV's PX4: COM_OF_LOSS_T 0.5 s, Hold COM_FAIL_ACT_T 5 s, Land; "
                             "MPC_XY_P 2.0, MPC_XY_VEL_P_ACC 4.0, MPC_XY_VEL_I_ACC 2.0",
              "parameters": {"px4_bridge": {"swarm_guard": True}}, "scenario": {}},
    "no_guard": {"description": "no swarm response (before issue 12): only the lost UAV's PX4 failsafe acts; the "
                                "others fall back to NC (4.32) and fly on",
                 "parameters": {"px4_bridge": {"swarm_guard": False}}, "scenario": {}},
    "soft_hold": {"description": "swarm guard, PX4's horizontal position hold softer than fpr_sim's defaults "
                                 "(MPC_XY_P 1.8, MPC_XY_VEL_P_ACC 3.0, MPC_XY_VEL_I_ACC 0.4: the defaults before "
                                 "2026-12-03; the legs' horizontal load is taken up more slowly in Hold)",
                  "parameters": {"px4_bridge": {"swarm_guard": True}},
                  "scenario": {"px4": {"position_control": {"xy_p": 1.8, "xy_vel_p": 3.0, "xy_vel_i": 0.4}}}},
    "land_now": {"description": "swarm guard, AUTO.LAND at once (emergency_hold_time 0, COM_FAIL_ACT_T 0): no "
                                "chance to rejoin",
                 "parameters": {"px4_bridge": {"swarm_guard": True, "emergency_hold_time": 0.0}},
                 "scenario": {"px4": {"failsafe_hold_time": 0.0}}},
}


def run_fault(case: FaultCase, output_dir: str, *, parameters: Mapping[str, Mapping[str, Any]] | None = None,
              scenario_overrides: Mapping[str, Any] | None = None, real_time_factor: float = 0.5,
              log: bool = True) -> FaultResult:
    """Fly ``case`` in the multi-process graph; metrics, events and the flight's files in ``output_dir``."""
    from fpr_sim.px4_log import read_px4_log
    from fpr_sim.scenario import load_scenario

    from fpr_experiments.processes import ProcessFault, run_processes
    from fpr_experiments.recording import flight_record, recorded_topics, write_mcap
    from fpr_experiments.runner import effective_scenario

    os.makedirs(output_dir, exist_ok=True)
    scenario_file = effective_scenario(SCENARIO, case.seed, os.path.join(output_dir, "scenario.yaml"),
                                       case.realism or None, scenario_overrides)
    scenario = load_scenario(scenario_file)
    px4_log_file = os.path.join(output_dir, "px4_log.csv")
    specs = fault_graph(case, scenario_file, px4_log_file, parameters)
    events: list[tuple[str, float, float]] = []
    duration = case.at + case.after
    recording, completed, _timeouts, errors, _wall = run_processes(
        specs, recorded_topics(3), duration, output_dir=output_dir, real_time_factor=real_time_factor,
        label=case.label, log=log, faults=[ProcessFault(case.group, case.at, case.restart_after)],
        fault_events=events)
    record = flight_record(recording, 3, experiment="fault", variant=case.node, scenario=SCENARIO, script=SCRIPT,
                           controller_mode=case.mode, cameras="emulated", sim_time=duration, wall_time=_wall,
                           lockstep_timeouts=_timeouts, callback_errors=errors, completed=completed,
                           camera_rate=scenario.cameras.rate,
                           landing_gear_height=scenario.quadrotor.landing_gear_height)
    write_mcap(recording, os.path.join(output_dir, "flight.mcap"), metadata={"fault": case.label})
    killed = [e for e in events if e[0].startswith("killed")]
    fault_time = killed[0][1] if killed else case.at
    if case.node == "simulator":
        if not killed:
            raise RuntimeError(f"{case.label}: the simulator ended before the kill")
        delays = link_loss_delays(os.path.join(output_dir, "logs"), killed[0][2], 3)
        silences = link_loss_silences(os.path.join(output_dir, "logs"), killed[0][2], 3)
        metrics = {"fault_time_s": float(fault_time), **{f"link_lost_uav{i}_s": d for i, d in delays.items()},
                   "link_lost_s": max(delays.values()),
                   **{f"link_lost_silence_uav{i}_s": v for i, v in silences.items()}}
        result = FaultResult(case, metrics, events, output_dir, completed, errors)
        _write_result(result)
        return result
    metrics = fault_metrics(record, read_px4_log(px4_log_file), fault_time,
                            scenario.quadrotor.landing_gear_height)
    result = FaultResult(case, metrics, events, output_dir, completed, errors)
    _write_result(result)
    return result


RESULT_FILE = "result.json"


def _write_result(result: FaultResult) -> None:
    import json
    from dataclasses import asdict

    with open(os.path.join(result.output_dir, RESULT_FILE), "w", encoding="utf-8") as stream:
        json.dump({"case": asdict(result.case), "metrics": result.metrics, "events": result.events,
                   "completed": result.completed, "errors": result.errors[:20]}, stream, indent=1)


def truth_from_mcap(path: str):
    """The ground-truth series :func:`fault_metrics` needs (t, position, quat, uav_positions; n), read back from a
    flight's MCAP (``/fpr/ground_truth``)."""
    from types import SimpleNamespace

    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message

    from fpr_msgs.msg import FprState

    t, position, quat, uavs = [], [], [], []
    with open(path, "rb") as stream:
        for _schema, _channel, message in make_reader(stream).iter_messages(topics=["/fpr/ground_truth"]):
            m = deserialize_message(message.data, FprState)
            p, q = m.platform_pose.position, m.platform_pose.orientation
            t.append(m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec)
            position.append([p.x, p.y, p.z])
            quat.append([q.w, q.x, q.y, q.z])
            uavs.append([[u.position.x, u.position.y, u.position.z] for u in m.uav_poses])
    truth = SimpleNamespace(t=np.array(t), position=np.array(position), quat=np.array(quat),
                            uav_positions=np.array(uavs))
    return SimpleNamespace(truth=truth, n=truth.uav_positions.shape[1])


def result_from_folder(folder: str) -> FaultResult:
    """A fault flight's result from its folder: ``result.json`` if the run wrote one, else recomputed from its
    flight.mcap, px4_log.csv and scenario.yaml (the case from the folder's name, ``<node>_<dead|restartS>_s<seed>``,
    the fault instant its nominal time)."""
    import json

    from fpr_sim.px4_log import read_px4_log
    from fpr_sim.scenario import load_scenario

    path = os.path.join(folder, RESULT_FILE)
    if os.path.exists(path):
        with open(path, encoding="utf-8") as stream:
            data = json.load(stream)
        return FaultResult(FaultCase(**data["case"]), data["metrics"], [tuple(e) for e in data["events"]], folder,
                           data["completed"], data["errors"])
    match = re.fullmatch(r"(.+)_(dead|restart([0-9.]+))_s(\d+)", os.path.basename(folder.rstrip("/")))
    if match and match.group(1) == "simulator":
        raise ValueError(f"a simulator kill needs the {RESULT_FILE} its run wrote (its delays are in wall time)")
    if not match:
        raise ValueError(f"{folder}: no {RESULT_FILE} and not a fault folder name")
    case = FaultCase(node=match.group(1), restart_after=float(match.group(3)) if match.group(3) else None,
                     seed=int(match.group(4)))
    scenario = load_scenario(os.path.join(folder, "scenario.yaml"))
    metrics = fault_metrics(truth_from_mcap(os.path.join(folder, "flight.mcap")),
                            read_px4_log(os.path.join(folder, "px4_log.csv")), case.at,
                            scenario.quadrotor.landing_gear_height)
    return FaultResult(case, metrics, [], folder, True)


#: a bridge's wall-watchdog line: ``[WARN] [<epoch s>] [<logger>…px4_bridge]: PX4 lost: …`` (rcutils' default
#: console format; its stamp is the system clock, whatever the node's ROS clock)
_LINK_LOST = re.compile(r"^\[WARN\] \[(\d+\.\d+)\] \[[^\]]*uav(\d+)\.px4_bridge\]: PX4 lost: no MAVLink "
                        r"frame for (\d+(?:\.\d+)?) s")


def link_loss_delays(log_dir: str, kill_wall: float, n: int) -> dict[int, float]:
    """Per UAV: wall seconds from ``kill_wall`` (epoch, ``time.time()``) to its bridge's first "PX4 lost" line
    at or after it in the processes' logs (``log_dir``/*.log); inf where none came."""
    return {uav: delay for uav, (delay, _) in _link_loss_lines(log_dir, kill_wall, n).items()}


def link_loss_silences(log_dir: str, kill_wall: float, n: int) -> dict[int, float]:
    """Per UAV: the silence [s] its bridge's first "PX4 lost" line after ``kill_wall`` reports (inf: none)."""
    return {uav: silence for uav, (_, silence) in _link_loss_lines(log_dir, kill_wall, n).items()}


def _link_loss_lines(log_dir: str, kill_wall: float, n: int) -> dict[int, tuple[float, float]]:
    lines = {i: (math.inf, math.inf) for i in range(1, n + 1)}
    for name in sorted(os.listdir(log_dir)):
        if not name.endswith(".log"):
            continue
        with open(os.path.join(log_dir, name), encoding="utf-8", errors="replace") as stream:
            for line in stream:
                match = _LINK_LOST.match(line)
                if match and float(match.group(1)) >= kill_wall and int(match.group(2)) in lines:
                    uav, delay = int(match.group(2)), float(match.group(1)) - kill_wall
                    if delay < lines[uav][0]:
                        lines[uav] = (delay, float(match.group(3)))
    return lines


def fault_metrics(record, px4_log, fault_time: float, landing_gear_height: float) -> dict[str, float]:
    """The module doc's metrics of one flight (``record``: fpr_experiments FlightRecord; ``px4_log``:
    fpr_sim.px4_log.Px4LogData)."""
    from fpr_model.rotations import quat_tilt

    truth = record.truth
    after = truth.t >= fault_time
    if after.sum() < 2:
        raise ValueError(f"no ground truth after the fault at {fault_time:.2f} s")
    t = truth.t[after]
    uav_z = truth.uav_positions[after, :, 2]
    metrics: dict[str, float] = {"fault_time_s": float(fault_time)}
    metrics["max_tilt_deg"] = float(np.degrees(quat_tilt(truth.quat[after]).max()))
    metrics["max_climb_m"] = float((uav_z - uav_z[0]).max())
    uav_ids = range(1, record.n + 1)
    disarms = [px4_log.disarm_time(i, fault_time) for i in uav_ids]
    metrics["all_disarmed_s"] = (max(disarms) - fault_time) if all(math.isfinite(d) for d in disarms) else math.nan
    speeds = []
    for k in range(record.n):
        z = uav_z[:, k]
        vz = np.gradient(z, t)
        ground = z.min()
        near = z <= ground + 0.05
        if ground <= landing_gear_height + 0.05 and near.any():
            speeds.append(float(-vz[near].min()))
    metrics["touchdown_speed_mps"] = max(speeds) if speeds else math.nan
    metrics["end_height_m"] = float(truth.position[-1, 2])
    end_tilt = math.degrees(quat_tilt(truth.quat[-1]))
    offboard_at_end = all(px4_log.armed_at(i, t[-1]) and px4_log.modes.get(i, ["?"])[-1].startswith("OFFBOARD")
                          for i in uav_ids)
    metrics["hover_held"] = float(offboard_at_end and end_tilt < 8.0
                                  and abs(truth.position[-1, 2] - truth.position[after][0, 2]) < 0.4)
    received = [px4_log.setpoint_thrust[i][px4_log.setpoint_t[i] >= fault_time] for i in uav_ids
                if i in px4_log.setpoint_t]
    metrics["max_thrust_received"] = float(max((r.max() for r in received if len(r)), default=math.nan))
    return metrics


def format_table(results: Sequence[FaultResult]) -> str:
    """Markdown tables of fault results (one row per case; simulator kills in a table of their own)."""
    killed_simulator = [r for r in results if r.case.node == "simulator"]
    results = [r for r in results if r.case.node != "simulator"]
    simulator_table = ""
    if killed_simulator:
        rows = ["| simulator killed at [s] | seed | " + " | ".join(f"uav{i} says PX4 lost after [s wall] (silence [s])"
                                                                   for i in range(1, 4)) + " |",
                "|---|---|---|---|---|"]
        for result in killed_simulator:
            m = result.metrics
            rows.append(f"| {m['fault_time_s']:.2f} | {result.case.seed} | "
                        + " | ".join(f"{m.get(f'link_lost_uav{i}_s', math.inf):.2f} "
                                     f"({m.get(f'link_lost_silence_uav{i}_s', math.inf):.2f})" for i in range(1, 4))
                        + " |")
        simulator_table = "\n".join(rows)
        if not results:
            return simulator_table
    columns = [("max_tilt_deg", "max tilt [°]", "{:.1f}"), ("max_climb_m", "max climb [m]", "{:.2f}"),
               ("all_disarmed_s", "all disarmed [s]", "{:.1f}"), ("touchdown_speed_mps", "touchdown [m/s]", "{:.2f}"),
               ("end_height_m", "end height [m]", "{:.2f}"), ("hover_held", "hover held", "{:.0f}"),
               ("max_thrust_received", "max thrust [0-1]", "{:.2f}")]
    lines = ["| node | restart | seed | " + " | ".join(c[1] for c in columns) + " |",
             "|---|---|---|" + "---|" * len(columns)]
    for result in results:
        case = result.case
        cells = [("—" if not math.isfinite(result.metrics.get(key, math.nan)) else fmt.format(result.metrics[key]))
                 for key, _, fmt in columns]
        restart = f"{case.restart_after:g} s" if case.restart_after is not None else "none"
        lines.append(f"| {case.node} | {restart} | {case.seed} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + ("\n\n" + simulator_table if simulator_table else "")


def _parse_parameter(text: str) -> tuple[str, str, Any]:
    """``executable.name=value`` (value parsed as YAML) -> (executable, name, value)."""
    import yaml

    target, sep, value = text.partition("=")
    executable, dot, name = target.partition(".")
    if not (sep and dot and executable and name):
        raise ValueError(f"--parameter expects executable.name=value, got {text!r}")
    return executable, name, yaml.safe_load(value)


def main(argv: list[str] | None = None) -> int:
    """``ros2 run fpr_experiments faults``: the fault matrix (module doc) -> a Markdown report."""
    import argparse
    import sys
    import time

    parser = argparse.ArgumentParser(prog="ros2 run fpr_experiments faults", description=__doc__.split("\n\n")[0])
    parser.add_argument("--nodes", nargs="+", default=list(FAULT_TARGETS), choices=FAULT_TARGETS,
                        help="what to kill (default: each UAV node, then the simulator)")
    parser.add_argument("--restart", nargs="+", default=["none", "2"],
                        help="restart delays [s of simulation time after the kill]; 'none': stays dead")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    parser.add_argument("--uav", type=int, default=2)
    parser.add_argument("--alternatives", nargs="+", default=["guard"], choices=sorted(ALTERNATIVES))
    parser.add_argument("--parameter", action="append", default=[], metavar="EXECUTABLE.NAME=VALUE",
                        help="extra node parameter for every case, e.g. px4_bridge.emergency_hold_time=3")
    parser.add_argument("--output-dir", default=os.path.join("reports", "faults"))
    parser.add_argument("--results", default="", help="write the Markdown report here (e.g. docs/safety.md)")
    parser.add_argument("--real-time-factor", type=float, default=0.5)
    parser.add_argument("--report-only", action="store_true",
                        help="fly nothing: the report from the flights already in --output-dir (their result.json, "
                             "or recomputed from their MCAP and PX4 log)")
    args = parser.parse_args(argv)
    try:
        extra: dict[str, dict[str, Any]] = {}
        for text in args.parameter:
            executable, name, value = _parse_parameter(text)
            extra.setdefault(executable, {})[name] = value
        restarts = [None if r == "none" else float(r) for r in args.restart]
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    start = time.monotonic()
    sections = []
    if args.report_only:
        for alternative in args.alternatives:
            root = os.path.join(args.output_dir, alternative)
            folders = sorted(os.path.join(root, d) for d in os.listdir(root)) if os.path.isdir(root) else []
            folders = [f for f in folders if os.path.basename(f).startswith(tuple(f"{n}_" for n in args.nodes))]
            results = []
            for folder in folders:
                try:
                    results.append(result_from_folder(folder))
                except (ValueError, OSError) as error:  # e.g. an older simulator kill without its result.json
                    print(f"[faults] {folder} left out of the report: {error}", file=sys.stderr)
            results = [r for r in results if r.case.node in args.nodes and r.case.seed in args.seeds]
            sections.append((alternative, ALTERNATIVES[alternative]["description"], results))
        alternatives = []
    else:
        from fpr_experiments.network import say_isolation

        say_isolation()  # where the flights' DDS traffic can go (a warning outside scripts/isolated.sh's namespace)
        alternatives = args.alternatives
    for alternative in alternatives:
        spec = ALTERNATIVES[alternative]
        parameters = {k: dict(v) for k, v in spec["parameters"].items()}
        for executable, values in extra.items():
            parameters.setdefault(executable, {}).update(values)
        results = []
        for node in args.nodes:
            for restart in ([None] if node == "simulator" else restarts):
                for seed in args.seeds:
                    case = FaultCase(node=node, uav=args.uav, restart_after=restart, seed=seed)
                    folder = os.path.join(args.output_dir, alternative,
                                          f"{node}_{'dead' if restart is None else f'restart{restart:g}'}_s{seed}")
                    try:
                        result = run_fault(case, folder, parameters=parameters, scenario_overrides=spec["scenario"],
                                           real_time_factor=args.real_time_factor)
                    except (RuntimeError, ValueError, TimeoutError) as error:
                        print(f"[faults] {case.label}: {error}", flush=True)
                        continue
                    results.append(result)
                    m = result.metrics
                    if node == "simulator":
                        print(f"[faults] {alternative}: {case.label}: every bridge said 'PX4 lost' within "
                              f"{m['link_lost_s']:.2f} s wall ({time.monotonic() - start:.0f} s)", flush=True)
                        continue
                    print(f"[faults] {alternative}: {case.label}: tilt {m['max_tilt_deg']:.1f} deg, climb "
                          f"{m['max_climb_m']:.2f} m, disarmed after {m['all_disarmed_s']:.1f} s, touchdown "
                          f"{m['touchdown_speed_mps']:.2f} m/s, hover held {m['hover_held']:.0f} "
                          f"({time.monotonic() - start:.0f} s)", flush=True)
        sections.append((alternative, spec["description"], results))
    report = _report(sections, " ".join(["ros2 run fpr_experiments faults", *(argv if argv is not None
                                                                             else sys.argv[1:])]))
    if args.results:
        with open(args.results, "w", encoding="utf-8") as stream:
            stream.write(report)
        print(f"wrote {args.results} ({time.monotonic() - start:.0f} s)")
    else:
        print(report)
    return 0


def _report(sections, command: str) -> str:
    lines = ["# Fault injection: one node of one UAV killed mid-hover (issue 12)", "",
             f"Generated by `{command}` (wrapper: `bash scripts/run_faults.sh`); do not edit by hand.", "",
             __doc__.split("\n\n", 1)[1].split("``ros2 run")[0].strip(), "",
             "Acceptance (issue 12): platform tilt < 30°, no UAV climbs > 0.5 m above its height at the fault, "
             "every PX4 disarmed within 15 s touching down at < 1 m/s; restarted within 2 s: hover held; simulator "
             "killed: every bridge says the link is lost after at most 0.6 s of silence (its 0.5 s watchdog, checked "
             "at 20 Hz), within 1 s of the kill on an unloaded machine (the test allows 2.5 s for a bridge held off "
             "the CPU).", ""]
    for alternative, description, results in sections:
        lines += [f"## {alternative}", "", description, "", format_table(results), ""]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    import sys

    sys.exit(main())
