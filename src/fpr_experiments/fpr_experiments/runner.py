"""Run an experiment (rclpy): for each variant, build the graph from the description, fly it in one process
(:class:`~fpr_experiments.inprocess.InProcessGraph`) or as processes grouped as on the robot
(:mod:`fpr_experiments.processes`), record, compute the metrics and write the variant's report folder; then
compare with the thesis and write the experiment's ``metrics.json`` (:mod:`fpr_experiments.report`).

Python API::

    from fpr_experiments import run_experiment
    result = run_experiment("table_3_3", seed=1, quick=False)
    result.metrics["fowo"]["force_z_rmse_n"], result.report_dir
    # another realism profile, and scenario values laid over the experiment's (a calibration):
    run_experiment("table_3_2", quick=True, realism="hardware", scenario_overrides={"link": {"loss": 0.05}})
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from fpr_model.numeric_dispatch import numeric_dispatch_in_effect
from fpr_model.opencv_dispatch import opencv_dispatch as dispatch_context

from fpr_experiments.catalog import Experiment, Variant, load_experiment
from fpr_experiments.graph import GraphOptions, describe_graph, write_graph_file
from fpr_experiments.resources import SCENARIOS, resolve_file_parameters

#: wall-clock budget per simulated second (a safety net against a stalled graph, not a performance target)
WALL_PER_SIM_SECOND = 40.0
#: [s] simulated between progress lines
PROGRESS_PERIOD = 2.0


def default_output_root() -> str:
    return os.environ.get("FPR_REPORTS", os.path.join(os.getcwd(), "reports"))


@dataclass
class CheckResult:
    metric: str
    value: float
    bounds: dict[str, float]

    @property
    def passed(self) -> bool:
        if not math.isfinite(self.value):
            return False
        return self.value >= self.bounds.get("min", -math.inf) and self.value <= self.bounds.get("max", math.inf)

    def text(self) -> str:
        limits = " and ".join(f"{'>=' if k == 'min' else '<='} {v:g}" for k, v in sorted(self.bounds.items()))
        return f"{self.metric} = {self.value:.3g} ({limits}): {'ok' if self.passed else 'FAILED'}"


@dataclass
class VariantResult:
    variant: str
    metrics: dict[str, float]
    checks: list[CheckResult]
    report_dir: str
    sim_time: float
    wall_time: float
    lockstep_timeouts: int
    completed: bool
    callback_errors: list[str] = field(default_factory=list)
    record: Any = None  #: the FlightRecord (kept in memory for the experiment's comparison plots)

    @property
    def passed(self) -> bool:
        return self.completed and not self.callback_errors and all(c.passed for c in self.checks)


@dataclass
class ExperimentResult:
    experiment: str
    variants: dict[str, VariantResult]
    report_dir: str
    summary: dict[str, Any] = field(default_factory=dict)

    @property
    def metrics(self) -> dict[str, dict[str, float]]:
        return {k: v.metrics for k, v in self.variants.items()}

    @property
    def passed(self) -> bool:
        return all(v.passed for v in self.variants.values())


def _say(text: str) -> None:
    print(text, flush=True)


def effective_scenario(name: str, seed: int | None, path: str, realism: str | None = None,
                       overrides: Mapping[str, Any] | None = None) -> str:
    """Write the scenario the run uses to ``path`` and return ``path``: the named one, ``overrides`` deep-merged
    over it (mappings key by key, anything else replaced: fpr_sim.scenario.deep_merge), ``seed`` and ``realism``
    (the profile name, whose overlay the simulator lays under the file) set when given. Validated here."""
    import yaml
    from fpr_sim.scenario import deep_merge, scenario_from_dict

    with open(SCENARIOS.resolve(name), encoding="utf-8") as stream:
        data = yaml.safe_load(stream) or {}
    if overrides:
        data = deep_merge(data, dict(overrides))
    if seed is not None:
        data["seed"] = int(seed)
    if realism:
        data["realism"] = realism
    scenario_from_dict(data)  # validate before the graph starts
    with open(path, "w", encoding="utf-8") as stream:
        yaml.safe_dump(data, stream, sort_keys=False)
    return path


def graph_options(experiment: Experiment, variant: Variant, scenario_file: str, cameras: str, n: int,
                  extra: dict[str, dict[str, Any]] | None = None, realism: str | None = None) -> GraphOptions:
    """The graph of one variant; ``realism`` None: the experiment's profile."""
    resolved = experiment.resolved(variant)
    parameters = resolve_file_parameters(resolved["parameters"])
    for executable, values in (extra or {}).items():
        parameters.setdefault(executable, {}).update(values)
    if experiment.link_outage:
        parameters.setdefault("info_link", {}).update(
            {"outage_start": float(experiment.link_outage[0]), "outage_end": float(experiment.link_outage[1])})
    return GraphOptions(n=n, mode=resolved["mode"], cameras=cameras, backend="sim", scenario=scenario_file,
                        operator=experiment.operator, script=resolved["script"],
                        realism=realism or experiment.realism, info_link=bool(experiment.link_outage),
                        detection_fallback=experiment.detection_fallback,
                        parameters=parameters,
                        uav_parameters=resolved["uav_parameters"])


class Progress:
    """One line every :data:`PROGRESS_PERIOD` simulated seconds (height, attitude, legs, bridges, RTF)."""

    def __init__(self, label: str, graph, duration: float) -> None:
        from fpr_experiments.recording import state_names

        self.label, self.graph, self.duration = label, graph, duration
        self.names = state_names()
        self.start_wall = self.last_wall = time.monotonic()
        self.last_sim = graph.sim_time

    def __call__(self) -> None:
        import numpy as np
        from fpr_model.rotations import quat_to_euler_zyx

        graph, now = self.graph, time.monotonic()
        rtf = (graph.sim_time - self.last_sim) / max(now - self.last_wall, 1e-9)
        self.last_wall, self.last_sim = now, graph.sim_time
        recorder = graph.recorder
        truth = recorder.latest("/fpr/ground_truth")
        command = recorder.latest("/fpr/teleop")
        line = f"[{self.label}] t={graph.sim_time:5.1f}/{self.duration:.0f} s  wall {now - self.start_wall:5.1f} s  " \
               f"RTF {rtf:4.2f}  "
        if command is not None:
            line += f"{self.names.teleop_mode.get(command.mode, '?'):<5} "
        if truth is not None:
            q = truth.platform_pose.orientation
            roll, pitch, _ = np.degrees(quat_to_euler_zyx(np.array([q.w, q.x, q.y, q.z])))
            legs = " ".join(f"{math.degrees(a):4.1f}" for a in truth.leg_angles)
            line += (f"z {truth.platform_pose.position.z:5.2f} m  roll {roll:+5.1f} pitch {pitch:+5.1f} deg  "
                     f"legs {legs} deg  ")
        states = []
        for i in range(1, (len(truth.leg_angles) if truth is not None else 0) + 1):
            status = recorder.latest(f"/fpr/uav{i}/status")
            states.append(self.names.bridge_state.get(status.state, "-") if status is not None else "-")
        line += "bridges " + ",".join(states) + f"  timeouts {graph.lockstep_timeouts}"
        _say(line)


def _check(metrics: dict[str, float], experiment: Experiment) -> list[CheckResult]:
    return [CheckResult(metric, float(metrics.get(metric, math.nan)), bounds)
            for metric, bounds in experiment.all_checks().items()]


def run_variant(experiment: Experiment, variant: Variant, output_dir: str, *, seed: int | None = None,
                quick: bool = False, cameras: str | None = None, processes: bool = False,
                real_time_factor: float = 0.5, plots: bool = True, log: bool = True, realism: str | None = None,
                scenario_overrides: Mapping[str, Any] | None = None,
                live_view_port: int | None = None,
                parameter_overrides: Mapping[str, Mapping[str, Any]] | None = None,
                opencv_dispatch: str = "baseline", overlapped: bool = False) -> VariantResult:
    """Fly one variant and write its report folder (see the module doc); ``realism`` None: the experiment's
    profile; ``scenario_overrides`` deep-merged over the variant's scenario (:func:`effective_scenario`);
    ``parameter_overrides`` ``{executable: {parameter: value}}`` laid over the experiment's and the variant's node
    parameters (every node of that executable; graph.json keeps what each node got); ``opencv_dispatch``
    (fpr_model.opencv_dispatch) ``baseline``: the rendered images and the detections do not depend on the CPU
    (the flight is the same on every x86_64 machine), ``native``: OpenCV's own SIMD choice, as on the robot.
    ``overlapped``: the simulator in a process of its own beside the graph (fpr_experiments.overlapped: one
    /clock period of added control latency; not with ``processes``)."""
    from fpr_experiments import report
    from fpr_experiments.metrics import compute_metrics
    from fpr_experiments.recording import flight_record, recorded_topics, write_mcap

    if processes and overlapped:
        raise ValueError("choose one layout: processes (one per UAV group) or overlapped (the simulator beside the "
                         "graph)")
    variant = with_parameter_overrides(variant, parameter_overrides)
    resolved = experiment.resolved(variant)
    duration = resolved["quick_duration"] if quick else resolved["duration"]
    cameras = cameras or experiment.cameras
    os.makedirs(output_dir, exist_ok=True)
    realism = realism or experiment.realism
    scenario_file = effective_scenario(resolved["scenario"], seed, os.path.join(output_dir, "scenario.yaml"),
                                       realism, scenario_overrides)
    from fpr_sim.scenario import load_scenario

    scenario = load_scenario(scenario_file)
    n = scenario.n
    options = graph_options(experiment, variant, scenario_file, cameras, n, realism=realism)
    specs = describe_graph(options)
    write_graph_file(specs, os.path.join(output_dir, "graph.json"))
    topics = recorded_topics(n, pilot=experiment.operator == "pilot", target=scenario_has_target(scenario),
                             detection_fallback=experiment.detection_fallback)
    label = f"{experiment.id}/{variant.id}"
    if log:
        _say(f"[{label}] scenario {os.path.basename(resolved['scenario'])}, script {resolved['script']}, "
             f"mode {resolved['mode']}, {cameras} cameras, realism {scenario.realism}"
             f"{' + overrides' if scenario_overrides else ''}"
             f"{' + node parameters ' + _parameters_text(parameter_overrides) if parameter_overrides else ''}, "
             f"seed {scenario.seed}, {duration:.0f} s simulated"
             f"{' (quick)' if quick else ''}{', OpenCV ' + opencv_dispatch if cameras == 'images' else ''}, "
             f"numeric code {numeric_dispatch_in_effect()}, {layout_name(processes, overlapped)} -> {output_dir}")
    wall_start = time.monotonic()
    live_view = None
    if live_view_port is not None:
        from fpr_experiments.live_view import LiveView

        live_view = LiveView(topics, port=live_view_port)
        _say(f"[{label}] live view: Foxglove WebSocket on {live_view.url()} ({len(live_view.channels)} topics, the "
             f"report MCAP's; layout config/viz/fpr_foxglove_layout.json)")
    try:
        with dispatch_context(opencv_dispatch):  # this process and the ones it starts
            if processes:
                from fpr_experiments.processes import run_processes

                outcome = run_processes(specs, topics, duration, output_dir=output_dir,
                                        real_time_factor=real_time_factor, label=label, log=log, live_view=live_view)
            else:
                outcome = _run_in_process(specs, topics, duration, label, log, live_view, overlapped)
    finally:
        if live_view is not None:
            live_view.stop()
    recording, completed, lockstep_timeouts, errors, flight_wall = outcome
    record = flight_record(recording, n, experiment=experiment.id, variant=variant.id,
                           scenario=os.path.basename(resolved["scenario"]), script=resolved["script"],
                           controller_mode=resolved["mode"], cameras=cameras, sim_time=duration if completed else
                           _last_time(recording), wall_time=flight_wall, lockstep_timeouts=lockstep_timeouts,
                           callback_errors=errors, completed=completed, camera_rate=scenario.cameras.rate,
                           landing_gear_height=scenario.quadrotor.landing_gear_height,
                           target_position=list(scenario.target.position) if scenario_has_target(scenario) else None)
    window = None
    if experiment.window:
        from fpr_experiments.metrics import tracking_mask

        start, end = experiment.window
        window = tracking_mask(record) & (record.truth.t >= start) & (record.truth.t <= end)
    metrics = compute_metrics(record, window)
    if experiment.link_outage:
        from fpr_experiments.metrics import recovery_time

        metrics["recovery_time_s"] = recovery_time(record, float(experiment.link_outage[1]))
    checks = _check(metrics, experiment)
    mcap = write_mcap(recording, os.path.join(output_dir, "flight.mcap"), metadata={
        "experiment": experiment.id, "variant": variant.id, "scenario": resolved["scenario"],
        "script": resolved["script"], "mode": resolved["mode"], "cameras": cameras, "seed": str(scenario.seed),
        "realism": scenario.realism, "opencv_dispatch": opencv_dispatch,
        "numeric_dispatch": numeric_dispatch_in_effect()})
    result = VariantResult(variant.id, metrics, checks, output_dir, record.sim_time, flight_wall, lockstep_timeouts,
                           completed, errors, record if plots else None)
    report.write_variant_json(result, record, os.path.join(output_dir, "metrics.json"), scenario)
    if plots:
        report.write_variant_plots(record, experiment, output_dir, dpi=80 if quick else 110)
        if not quick:  # the 3D animation where people look first (~10-15 s of rendering per flight)
            from fpr_experiments.animation import write_animation

            write_animation(record, os.path.join(output_dir, "flight.gif"))
    if log:
        failed = [c.text() for c in checks if not c.passed]
        _say(f"[{label}] {record.sim_time:.1f} s simulated in {flight_wall:.1f} s wall (RTF "
             f"{record.sim_time / max(flight_wall, 1e-9):.2f}), {lockstep_timeouts} lockstep timeouts, "
             f"{sum(mcap.counts.values())} messages logged, total {time.monotonic() - wall_start:.0f} s; checks "
             + ("ok" if not failed else "FAILED: " + "; ".join(failed)))
        for error in errors[:3]:
            _say(f"[{label}] callback error: {error}")
        for entry in [e for e in record.emergencies if e["own"]][:3]:  # the root causes; the peers follow them
            _say(f"[{label}] swarm emergency at {entry['t']:.2f} s: uav{entry['uav']}: {entry['reason']}")
    return result


def scenario_has_target(scenario) -> bool:
    target = getattr(scenario, "target", None)
    return bool(target is not None and getattr(target, "enabled", False))


def _last_time(recording) -> float:
    clock = recording.get("/clock")
    return clock[-1].clock.sec + 1e-9 * clock[-1].clock.nanosec if clock else 0.0


def layout_name(processes: bool, overlapped: bool) -> str:
    """The runner's layout as the log and the reports say it."""
    return "processes" if processes else "overlapped (two processes)" if overlapped else "one process"


def _run_in_process(specs, topics, duration: float, label: str, log: bool, live_view=None, overlapped: bool = False):
    if overlapped:
        from fpr_experiments.overlapped import OverlappedGraph as Graph
    else:
        from fpr_experiments.inprocess import InProcessGraph as Graph

    with Graph(specs, topics, live_view=live_view) as graph:
        took = graph.wait_for_discovery()
        if log:
            _say(f"[{label}] {len(graph.nodes)} nodes built and discovered in {took:.1f} s")
        progress = Progress(label, graph, duration) if log else None
        start = time.monotonic()
        completed = graph.run_until(lambda: graph.sim_time >= duration - 1e-9,
                                    wall_timeout=60.0 + WALL_PER_SIM_SECOND * duration, progress=progress,
                                    progress_period=PROGRESS_PERIOD)
        wall = time.monotonic() - start
        if not completed and log:
            _say(f"[{label}] wall-clock timeout at t = {graph.sim_time:.1f} s")
        if not graph.wait_for_recorder(wall_timeout=15.0) and log:
            _say(f"[{label}] the recorder did not catch up with the simulation: the log ends early")
        recording = graph.recorder.snapshot()
        return recording, completed, graph.lockstep_timeouts, list(graph.errors), wall


def run_experiment(name: str, *, seed: int | None = None, quick: bool = False, cameras: str | None = None,
                   processes: bool = False, variants: list[str] | None = None, output_root: str | None = None,
                   real_time_factor: float = 0.5, plots: bool = True, log: bool = True, realism: str | None = None,
                   scenario_overrides: Mapping[str, Any] | None = None,
                   live_view_port: int | None = None,
                   parameter_overrides: Mapping[str, Mapping[str, Any]] | None = None,
                   opencv_dispatch: str = "baseline", overlapped: bool = False) -> ExperimentResult:
    """Run experiment ``name`` (all its variants, or ``variants``) and write ``<output_root>/<name>/``.

    ``realism``: a realism profile (fpr_sim.scenario.realism_profiles) instead of the experiment's (catalog key
    ``realism``, default :data:`fpr_experiments.catalog.DEFAULT_REALISM`). ``scenario_overrides``: a mapping
    deep-merged over every variant's scenario, e.g. ``{"actuation": {"thrust_noise": 0.02}}``; the merged
    scenario is each variant's ``scenario.yaml``, the file the simulator and the info link read. ``live_view_port``:
    serve each flight to the Foxglove app on ws://127.0.0.1:<port> while it runs (fpr_experiments.live_view; 0: an
    ephemeral port, printed). ``parameter_overrides``: node parameters of every variant, ``{executable: {name:
    value}}`` (ablations of the onboard software; a name no node of the executable declares stops the run).
    ``opencv_dispatch``: see :func:`run_variant` (default ``baseline``: the same flight on every CPU).
    ``overlapped``: the simulator beside the graph in a process of its own (:func:`run_variant`)."""
    from fpr_experiments import report
    from fpr_experiments.catalog import check_realism

    experiment = load_experiment(name)
    if realism is not None:
        check_realism(realism)
    chosen = [experiment.variant(v) for v in variants] if variants else experiment.variants
    root = os.path.join(output_root or default_output_root(), experiment.id)
    os.makedirs(root, exist_ok=True)
    results: dict[str, VariantResult] = {}
    for variant in chosen:
        results[variant.id] = run_variant(
            experiment, variant, os.path.join(root, variant.id), seed=seed, quick=quick, cameras=cameras,
            processes=processes, real_time_factor=real_time_factor, plots=plots, log=log, realism=realism,
            scenario_overrides=scenario_overrides, live_view_port=live_view_port,
            parameter_overrides=parameter_overrides, opencv_dispatch=opencv_dispatch, overlapped=overlapped)
    result = ExperimentResult(experiment.id, results, root)
    result.summary = report.write_experiment_report(experiment, result, root, quick=quick, seed=seed,
                                                    processes=processes, plots=plots, overlapped=overlapped)
    if log:
        _say("\n" + report.format_experiment_table(experiment, result.summary))
    return result


def with_parameter_overrides(variant: Variant, overrides: Mapping[str, Mapping[str, Any]] | None) -> Variant:
    """``variant`` with ``overrides`` (``{executable: {name: value}}``) laid over its node parameters, which
    :meth:`Experiment.resolved` lays over the experiment's: an override wins over both. None: ``variant`` itself."""
    if not overrides:
        return variant
    merged = {executable: dict(values) for executable, values in variant.parameters.items()}
    for executable, values in overrides.items():
        merged.setdefault(executable, {}).update(values)
    return replace(variant, parameters=merged)


def _parameters_text(overrides: Mapping[str, Mapping[str, Any]]) -> str:
    """``controller.observer=sowo, pose_estimator.filter=mekf`` (the run's log line)."""
    return ", ".join(f"{executable}.{name}={value}" for executable, values in overrides.items()
                     for name, value in values.items())


def main_exit_code(result: ExperimentResult) -> int:
    return 0 if result.passed else 1


if __name__ == "__main__":  # pragma: no cover - use `ros2 run fpr_experiments run`
    sys.exit(main_exit_code(run_experiment(sys.argv[1])))
