"""``ros2 run fpr_experiments run <name>|all [options]`` and ``ros2 run fpr_experiments list``.

``run`` flies an experiment's variants (progress line every 2 simulated seconds, a table at the end), writes
``reports/<experiment>/`` (``metrics.json``, each variant's plots, ``flight.mcap``, ``graph.json``,
``scenario.yaml``) and exits 0 when every variant completed and passed its flight checks, 1 otherwise, 2 on a
usage error (an unknown name, a missing file, a bad parameter: one line saying what and what is valid).
``run all`` runs every experiment and writes ``docs/results.md``; ``run all --report-only`` rebuilds it from the
``metrics.json`` already in ``reports/``.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time

from rclpy.exceptions import InvalidParameterValueException

from fpr_experiments.resources import UnknownNameError


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ros2 run fpr_experiments run", description=__doc__.split("\n\n")[0])
    parser.add_argument("name", help="experiment name (see `ros2 run fpr_experiments list`) or 'all'")
    parser.add_argument("--quick", action="store_true", help="shortened flights (the test suite's setting)")
    parser.add_argument("--seed", type=int, default=None, help="override every scenario's seed")
    parser.add_argument("--cameras", choices=("images", "emulated"), default=None,
                        help="rendered images + aruco_detector, or emulated marker poses (default: the experiment's)")
    parser.add_argument("--realism", default=None, metavar="PROFILE",
                        help="realism profile of the simulator and the inter-UAV link: ideal | hardware (default: "
                             "each experiment's, catalog key 'realism')")
    parser.add_argument("--set", action="append", default=None, metavar="KEY=VALUE", dest="overrides",
                        help="override one scenario value in every variant (repeatable; dotted key, YAML value), "
                             "laid over the realism profile, e.g. --set actuation.thrust_noise=0.02 (ablations: "
                             "the run's scenario.yaml keeps the merged values)")
    parser.add_argument("--param", action="append", default=None, metavar="EXECUTABLE.NAME=VALUE",
                        dest="parameters",
                        help="override one node parameter of every node of an executable in every variant "
                             "(repeatable; YAML value), laid over the experiment's, e.g. --param "
                             "pose_estimator.filter=mekf (ablations of the onboard software; graph.json keeps what "
                             "each node got; a name the node does not declare stops the run)")
    parser.add_argument("--processes", action="store_true",
                        help="one process per UAV / ground station / simulator, as on the robot (default: one)")
    parser.add_argument("--overlapped", action="store_true",
                        help="the simulator in a process of its own, stepping the next /clock period while the graph "
                             "works on the last (fpr_experiments.overlapped): deterministic, one /clock period of "
                             "added control latency; default: everything in one process")
    parser.add_argument("--real-time-factor", type=float, default=0.5,
                        help="pace of the simulator with --processes (default %(default)s; 2 cores here)")
    parser.add_argument("--variant", action="append", default=None,
                        help="run only this variant (repeatable; default: all)")
    parser.add_argument("--output-dir", default=None,
                        help="reports root (default: $FPR_REPORTS or ./reports)")
    parser.add_argument("--results", default=None,
                        help="with 'all': where results.md goes (default: <repo>/docs/results.md)")
    parser.add_argument("--report-only", action="store_true",
                        help="with 'all': rebuild results.md from the reports' metrics.json, fly nothing")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--live-view", type=int, nargs="?", const=8765, default=None, metavar="PORT",
                        help="serve each flight live to the Foxglove app over WebSocket on 127.0.0.1:PORT (default "
                             "8765; 0: any free port), the report MCAP's topics (fpr_experiments.live_view)")
    parser.add_argument("--cpu-dispatch", "--opencv-dispatch", choices=("baseline", "native"), default="baseline",
                        dest="cpu_dispatch",
                        help="the CPU-dependent code of OpenCV, numpy, OpenBLAS and libm (fpr_model.opencv_dispatch, "
                             "fpr_model.numeric_dispatch): 'baseline' (default) pins the code every x86-64 CPU has, "
                             "so a flight is the same flight on every machine (the run starts itself again with "
                             "the numeric libraries pinned, once); 'native' lets each library pick the CPU's "
                             "fastest code, as on the robot. --opencv-dispatch is the former name")
    parser.add_argument("--jobs", type=int, default=1,
                        help="with 'all': experiments flown in parallel, each in its own isolated process (its own "
                             "network namespace and ROS domain; 2 cores: 2); default 1")
    return parser


def _results_path(args) -> str:
    if args.results:
        return args.results
    return os.path.join(os.environ.get("FPR_ROOT") or os.getcwd(), "docs", "results.md")


def _command_line(args) -> str:
    parts = ["ros2 run fpr_experiments run all", *(shlex.quote(token) for token in _experiment_flags(args))]
    if args.jobs > 1:
        parts.append(f"--jobs {args.jobs}")
    return " ".join(parts)


def _experiment_flags(args) -> list[str]:
    """The options of ``run all`` that each experiment's run takes too (results.md's command line, --jobs), as
    argument tokens."""
    tokens = []
    if args.quick:
        tokens.append("--quick")
    if args.seed is not None:
        tokens += ["--seed", str(args.seed)]
    if args.cameras:
        tokens += ["--cameras", args.cameras]
    if args.realism:
        tokens += ["--realism", args.realism]
    for override in args.overrides or []:
        tokens += ["--set", override]
    for parameter in args.parameters or []:
        tokens += ["--param", parameter]
    if args.processes:
        tokens.append("--processes")
    if args.overlapped:
        tokens.append("--overlapped")
    if args.cpu_dispatch != "baseline":
        tokens += ["--cpu-dispatch", args.cpu_dispatch]
    return tokens


def scenario_overrides(settings: list[str] | None) -> dict | None:
    """``["actuation.thrust_noise=0.02", ...]`` -> the nested scenario overlay (values parsed as YAML: numbers,
    booleans, lists); None without settings. A malformed setting is a ValueError naming it."""
    import yaml

    from fpr_experiments.calibration import nested_overrides

    if not settings:
        return None
    assignment = {}
    for setting in settings:
        key, separator, text = setting.partition("=")
        if not separator or not key.strip() or any(not part for part in key.strip().split(".")):
            raise ValueError(f"--set {setting!r}: expected KEY=VALUE with a dotted scenario key, e.g. "
                             "actuation.thrust_noise=0.02")
        try:
            assignment[key.strip()] = yaml.safe_load(text)
        except yaml.YAMLError as error:
            raise ValueError(f"--set {setting!r}: the value is not YAML ({error})") from None
    return nested_overrides(assignment)


def parameter_overrides(settings: list[str] | None) -> dict | None:
    """``["pose_estimator.filter=mekf", ...]`` -> ``{"pose_estimator": {"filter": "mekf"}}`` (values parsed as YAML);
    None without settings. A malformed setting or an executable the graph does not have is a ValueError naming it."""
    import yaml

    from fpr_experiments.graph import EXECUTABLES

    if not settings:
        return None
    overrides: dict[str, dict] = {}
    for setting in settings:
        key, separator, text = setting.partition("=")
        executable, dot, name = key.strip().partition(".")
        if not separator or not dot or not executable or not name:
            raise ValueError(f"--param {setting!r}: expected EXECUTABLE.NAME=VALUE, e.g. pose_estimator.filter=mekf")
        if executable not in EXECUTABLES:
            raise ValueError(f"--param {setting!r}: no executable '{executable}' in the graph; valid: "
                             f"{', '.join(EXECUTABLES)}")
        try:
            overrides.setdefault(executable, {})[name] = yaml.safe_load(text)
        except yaml.YAMLError as error:
            raise ValueError(f"--param {setting!r}: the value is not YAML ({error})") from None
    return overrides


def _write_results(names: list[str], output_root: str, path: str, command: str) -> str:
    from fpr_experiments import report
    from fpr_experiments.catalog import load_experiment

    summaries, experiments = [], {}
    for name in names:
        metrics = os.path.join(output_root, name, "metrics.json")
        if not os.path.exists(metrics):
            print(f"[results] no {metrics}: {name} left out", flush=True)
            continue
        with open(metrics, encoding="utf-8") as stream:
            summary = json.load(stream)
        # the realism settings and the cameras of the run (each variant's metrics.json keeps its scenario's)
        for variant in summary.get("variants", {}).values():
            variant_json = os.path.join(output_root, name, variant.get("report_dir", ""), "metrics.json")
            missing = [key for key in ("realism", "cameras") if not summary.get(key)]
            if missing and os.path.exists(variant_json):
                with open(variant_json, encoding="utf-8") as stream:
                    variant_summary = json.load(stream)
                for key in missing:
                    summary[key] = variant_summary.get(key)
        summaries.append(summary)
        experiments[name] = load_experiment(name)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w", encoding="utf-8") as stream:
        stream.write(report.results_markdown(summaries, experiments, command))
    return path


def _flight_seconds(experiment) -> float:
    """Simulated seconds an experiment flies (all its variants): the order of the parallel queue, longest first."""
    return sum(v.duration or experiment.duration for v in experiment.variants)


def _run_parallel(experiments: list, args, output_root: str) -> list[str]:
    """``run all --jobs N``: each experiment in its own ``scripts/isolated.sh ros2 run fpr_experiments run <name>``
    (its own network namespace: no shared port or DDS domain), N at a time, longest first; one line per start and
    end; returns the experiments whose checks failed. The reports land where a sequential run puts them."""
    import subprocess

    root = os.environ.get("FPR_ROOT") or os.getcwd()
    isolated = os.path.join(root, "scripts", "isolated.sh")
    flags = _experiment_flags(args) + (["--no-plots"] if args.no_plots else []) \
        + (["--real-time-factor", str(args.real_time_factor)] if args.processes else [])
    queue = sorted(experiments, key=_flight_seconds, reverse=True)
    running: dict[str, tuple[subprocess.Popen, object]] = {}
    failed, started, done = [], time.monotonic(), 0
    log_dir = os.path.join(output_root, "_logs")
    os.makedirs(log_dir, exist_ok=True)
    while queue or running:
        while queue and len(running) < args.jobs:
            experiment = queue.pop(0)
            log = open(os.path.join(log_dir, f"{experiment.id}.log"), "w", encoding="utf-8")  # noqa: SIM115
            env = dict(os.environ, FPR_IN_NETNS="0", ROS_DOMAIN_ID=str(1 + (len(running) + done) % 100))
            command = ["bash", isolated, "ros2", "run", "fpr_experiments", "run", experiment.id, "--output-dir",
                       output_root, *flags]
            running[experiment.id] = (subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, env=env), log)
            print(f"[all] start {experiment.id} ({_flight_seconds(experiment):.0f} s simulated; log {log.name})",
                  flush=True)
        time.sleep(1.0)
        for name, (process, log) in list(running.items()):
            if process.poll() is None:
                continue
            log.close()
            del running[name]
            done += 1
            if process.returncode != 0:
                failed.append(name)
            verdict = {0: "checks passed", 1: "checks FAILED"}.get(process.returncode, f"exit {process.returncode}")
            print(f"[all] {done}/{len(experiments)} {name}: {verdict} ({time.monotonic() - started:.0f} s)",
                  flush=True)
    return failed


def run_main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from fpr_experiments.catalog import experiment_names
    from fpr_experiments.runner import default_output_root, run_experiment

    output_root = args.output_dir or default_output_root()
    try:
        names = experiment_names() if args.name == "all" else [args.name]
        if args.report_only:
            if args.name != "all":
                raise ValueError("--report-only works with 'all'")
            print(f"wrote {_write_results(names, output_root, _results_path(args), _command_line(args))}")
            return 0
        from fpr_experiments.catalog import check_realism, load_experiment
        from fpr_experiments.network import say_isolation

        pin_numeric_code(args.cpu_dispatch, entry_point=argv is None)

        say_isolation()  # where the flights' DDS traffic can go (a warning outside scripts/isolated.sh's namespace)

        if args.realism is not None:
            check_realism(args.realism, "--realism")
        if args.processes and args.overlapped:
            raise ValueError("--processes and --overlapped are two layouts: choose one")
        overrides = scenario_overrides(args.overrides)
        parameters = parameter_overrides(args.parameters)
        experiments = [load_experiment(name) for name in names]  # every name and file checked before anything flies
        start, status, failed = time.monotonic(), 0, []
        if args.live_view is not None and args.name == "all" and args.jobs > 1:
            raise ValueError("--live-view serves one flight at a time: not with --jobs > 1")
        if args.name == "all" and args.jobs > 1:
            failed = _run_parallel(experiments, args, output_root)
            status = 1 if failed else 0
            names = []
        for k, name in enumerate(names):
            if len(names) > 1:
                print(f"\n===== [{k + 1}/{len(names)}] {name} ({time.monotonic() - start:.0f} s so far) =====",
                      flush=True)
            result = run_experiment(name, seed=args.seed, quick=args.quick, cameras=args.cameras,
                                    processes=args.processes, variants=args.variant, output_root=output_root,
                                    real_time_factor=args.real_time_factor, plots=not args.no_plots,
                                    realism=args.realism, live_view_port=args.live_view,
                                    scenario_overrides=overrides, parameter_overrides=parameters,
                                    opencv_dispatch=args.cpu_dispatch, overlapped=args.overlapped)
            if not result.passed:
                status = 1
                failed.append(name)
        if args.name == "all":
            names = [e.id for e in experiments]
            path = _write_results(names, output_root, _results_path(args), _command_line(args))
            print(f"\nwrote {path}; {len(names)} experiments in {time.monotonic() - start:.0f} s"
                  + (f"; checks failed in: {', '.join(failed)}" if failed else "; every check passed"), flush=True)
        return status
    except InvalidParameterValueException as error:
        print(f"error: {_refused_parameter_line(error)}", file=sys.stderr, flush=True)
        return 2
    except (UnknownNameError, FileNotFoundError, ValueError, TimeoutError, RuntimeError) as error:
        print(f"error: {error}", file=sys.stderr, flush=True)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


def pin_numeric_code(dispatch: str, entry_point: bool) -> None:
    """``baseline``: make this process run numpy's, OpenBLAS's and libm's pinned code (fpr_model.numeric_dispatch).
    They are chosen when they load, so the program starts itself again in the pinned environment, once, when it is
    the program (``ros2 run``, ``python -m``, ``python -c "... run_main()"``); called in a process of somebody else's
    (a test's ``run_main([...])``) it only says which code the flights run."""
    from fpr_model.numeric_dispatch import numeric_dispatch_in_effect, reexec_pinned

    if dispatch != "baseline" or numeric_dispatch_in_effect() == "baseline":
        return
    if entry_point:
        reexec_pinned()  # returns only on a CPU the pin does not cover, having said so
        return
    print("[fpr] numeric code: native in this process (run_main called in-process), so these flights may differ "
          "in their last digits on another CPU; `ros2 run fpr_experiments run` pins it", flush=True)


def _refused_parameter_line(error: Exception) -> str:
    """One line for a node parameter rclpy refused at declaration (its descriptor range or our validator).

    rclpy formats it "Invalid parameter value (V) for parameter. Reason: R: NAME" (rclpy/exceptions.py,
    ParameterException); R already names the range."""
    text = str(error)
    value = text.split("(", 1)[1].split(")", 1)[0] if "(" in text else "?"
    reason, _, name = text.split("Reason: ", 1)[-1].rpartition(": ")
    return f"node parameter {name or '?'} = {value} refused: {reason or text}"


def list_main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ros2 run fpr_experiments list",
                                     description="List the experiments (name, thesis reference, variants).")
    parser.add_argument("--verbose", "-v", action="store_true", help="also scenario, script, durations")
    args = parser.parse_args(argv)
    from fpr_experiments.catalog import load_all

    try:
        experiments = load_all()
    except (UnknownNameError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    width = max(len(e.id) for e in experiments)
    for e in experiments:
        print(f"{e.id:<{width}}  {e.title}")
        print(f"{'':<{width}}  {e.thesis}; variants: {', '.join(v.id for v in e.variants)}")
        if args.verbose:
            print(f"{'':<{width}}  scenario {e.scenario}, script {e.script}, operator {e.operator}, cameras "
                  f"{e.cameras}, mode {e.mode}, {e.duration:.0f} s ({e.quick_duration:.0f} s quick)")
    return 0


if __name__ == "__main__":
    sys.exit(run_main())
