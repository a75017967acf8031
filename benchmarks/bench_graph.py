"""The whole simulated graph's speed (fpr_experiments' in-process runner): real-time factor and CPU seconds per
simulated second, for n = 3 / 6 with emulated marker poses or rendered images + ArUco, and the levers as ratios in
one run: the deterministic single-thread runner vs the threaded one (background executor + the simulator's
lockstep), lean nodes (no parameter services, no default QoS event handlers), the /clock rate and the executor
that drains the deterministic runner (rclpy's SingleThreadedExecutor or fpr_experiments' SweepExecutor). Flight: the
takeoff_landing experiment's scenario and script for n = 3 (arm on the ground, fly, climb), steps_roll_legs for
n = 6, ``--seconds`` simulated from the start (default 12). Run on a quiet machine, through the isolation:

    bash scripts/isolated.sh python benchmarks/bench_graph.py [--seconds 12] [--cases n3_emulated,n3_images]

Prints one line per case (wall, CPU, RTF, CPU per simulated second and, for the deterministic one-process runner,
its split into the simulator's steps — physics, sensors, rendering, publishing — and the rest of the graph (thread
CPU time, ``InProcessGraph(measure_periods=True)``), the controllers' step in the graph: median and 95th percentile
of their 50 Hz timer callback, lockstep timeouts, the executor's entity count, the machine's load average before and
after) and the ratios of each lever against the baseline of its case; then :func:`summary`: the mean RTF of every
lever run more than once and, with levers 6 and 7 (e.g. ``--levers 6,7,6,7,6,7``), issue 11's figure, the hardware
profile's cost.

``--overlap`` compares issue 15's overlapped two-process layout (fpr_experiments.overlapped: the simulator in a
process of its own, one /clock period ahead of the graph) with what it could give at best: the default runner is
flown with the CPU of every /clock period split into the simulator's step and the graph's drains
(``InProcessGraph(measure_periods=True)``), and :func:`overlap_bound` replays those costs on two processes with no
communication cost at all, under the lockstep rule (the simulator passes a control boundary only with the
setpoints computed on it) and as the overlapped layout schedules them (every step waits for the drains of the
period before the last: one period of added latency); then the overlapped layout is flown, interleaved with the
one-process runner. The lever "overlapped layout" flies it among the others.

``--numeric-dispatch baseline`` starts the benchmark again with numpy, OpenBLAS and libm pinned as the experiments
fly them (fpr_model.numeric_dispatch; the default, ``native``, is what the figures before 2026-12-07's last session
used); the first line says which code ran.

The VMs these runs get differ by up to ×2.2 in speed from one session to the next, and one VM's speed drifts by
up to ×1.5 within minutes (docs/benchmarks.md, 2026-12-07). So every line also gives a speed probe of the machine
around that run: bench_control's n = 3 communicating controller step (Python and small numpy arrays, as most of the
graph), 1000 calls timed right before and right after the run (median of each). On the VM of docs/benchmarks.md's
2026-12-01 controller figures it was :data:`REFERENCE_STEP_US`. It tells whether a run's machine was slow; it does
not convert an RTF to another machine (on 2026-12-07 the probe and the RTF were not proportional from run to run).
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import time

from fpr_experiments.graph import GraphOptions, describe_graph
from fpr_experiments.inprocess import InProcessGraph
from fpr_experiments.overlapped import OverlappedGraph
from fpr_experiments.recording import recorded_topics
from fpr_model.opencv_dispatch import opencv_dispatch as dispatch_context

#: case -> (n, scenario, script, cameras)
CASES = {
    "n3_emulated": (3, "ground_start", "integration_flight", "emulated"),
    "n3_images": (3, "ground_start", "integration_flight", "images"),
    "n6_emulated": (6, "n6_unequal", "steps_roll_legs", "emulated"),
    "n6_images": (6, "n6_unequal", "steps_roll_legs", "images"),
}
#: lever -> (deterministic runner, lean nodes, /clock rate [Hz], realism profile, executor); the first is the
#: baseline (main before issue 15); the deterministic runner drains with rclpy's executor or the SweepExecutor
#: (fpr_experiments.sweep_executor; "sweep-copy": one conversion per subscription, as rclpy; "sweep-dds": every
#: message through DDS instead of fpr_experiments.intra_process's in-process delivery); "hardware" compares
#: the realism profiles on the default runner (issue 11: hardware <= 20 % cost); optionally node parameters
#: {executable: {name: value}} (None: none), OpenCV's dispatch (fpr_model.opencv_dispatch; default native), the
#: layout ("one process" or "overlapped") and InProcessGraph keyword options (None: none)
LEVERS = {"threaded, full nodes, /clock 250 Hz": (False, False, 250.0, "ideal", "rclpy"),
          "threaded, lean nodes": (False, True, 250.0, "ideal", "rclpy"),
          "threaded, /clock 100 Hz": (False, False, 100.0, "ideal", "rclpy"),
          "threaded, lean + /clock 100 Hz": (False, True, 100.0, "ideal", "rclpy"),
          "deterministic, full nodes, /clock 250 Hz, rclpy executor": (True, False, 250.0, "ideal", "rclpy"),
          "deterministic, lean + /clock 100 Hz, rclpy executor": (True, True, 100.0, "ideal", "rclpy"),
          "deterministic, lean + /clock 100 Hz, sweep executor (default)": (True, True, 100.0, "ideal", "sweep"),
          "default + hardware realism": (True, True, 100.0, "hardware", "sweep"),
          # appended (the indices above stay those of docs/benchmarks.md's commands): the sweep as it was before
          # it converted each message once for all subscribers
          "sweep, one conversion per subscription": (True, True, 100.0, "ideal", "sweep-copy"),
          # the sweep with every message through DDS (the default before fpr_experiments.intra_process)
          "sweep, every message through DDS": (True, True, 100.0, "ideal", "sweep-dds"),
          # the default with the ArUco detectors searching every frame whole (before their region of interest)
          "default, ArUco whole frames (roi_margin 0)": (True, True, 100.0, "ideal", "sweep",
                                                          {"aruco_detector": {"roi_margin": 0.0}}),
          # the default with PX4's own telemetry rates (before the bridges asked for theirs: ATTITUDE 100 Hz on)
          "default, PX4's telemetry rates (configure_streams false)": (True, True, 100.0, "ideal", "sweep",
                                                                       {"px4_bridge": {"configure_streams": False}}),
          # the default with OpenCV's baseline code, as fpr_experiments' runs fly it (fpr_model.opencv_dispatch;
          # every lever above lets OpenCV pick the CPU's SIMD code)
          "default, OpenCV baseline dispatch (the experiments')": (True, True, 100.0, "ideal", "sweep", None,
                                                                     "baseline"),
          # the default with the MessageInfo callbacks (the controllers' zeta) through DDS, as before the router
          # numbered them itself (fpr_experiments.intra_process)
          "default, MessageInfo topics through DDS": (True, True, 100.0, "ideal", "sweep-info-dds"),
          # the default with the simulator reading /clock too (use_sim_time, as before fpr_experiments.graph left it
          # out): its one DDS reader made every /clock message cross DDS
          "default, the simulator subscribed to /clock": (True, True, 100.0, "ideal", "sweep",
                                                          {"simulator": {"use_sim_time": True}}),
          # the overlapped two-process layout (fpr_experiments.overlapped): the simulator in a process of its own,
          # one /clock period ahead of the graph (its CPU is counted with the graph's)
          "overlapped layout (the simulator in a process of its own)": (True, True, 100.0, "ideal", "sweep", None,
                                                                        "native", "overlapped"),
          # the hardware profile with the ArUco detectors forgetting their region of interest at the first frame
          # without the marker (before roi_hold; compare with lever 7)
          "hardware realism, ArUco roi_hold 0": (True, True, 100.0, "hardware", "sweep",
                                                 {"aruco_detector": {"roi_hold": 0}}),
          # the default without keeping the graph's heap out of the garbage collector's full collections (as before
          # InProcessGraph's freeze_heap; the last element: InProcessGraph keyword options)
          "default, the garbage collector walking the whole heap": (True, True, 100.0, "ideal", "sweep", None,
                                                                     "native", "one process",
                                                                     {"freeze_heap": False})}


#: [µs] bench_control's n = 3 communicating step, median, on the VM of docs/benchmarks.md's 2026-12-01 figures
REFERENCE_STEP_US = 264.0


def reference_step_us(repeats: int = 1000) -> float:
    """Median [µs] of bench_control's n = 3 communicating (C) controller step on this machine now."""
    import bench_control  # this folder is the script's (sys.path[0])

    _, _, _, step = bench_control.setup(3, "communicating")
    step()
    return 1e6 * float(bench_control.timeit(step, repeats)[0])


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _entities(graph: InProcessGraph) -> int:
    """Entities the main executor waits on (subscriptions, timers, services, clients, QoS event handlers)."""
    total = 0
    for node in graph.nodes:
        if node is graph.simulator:
            continue
        total += len(list(node.subscriptions)) + len(list(node.timers)) + len(list(node.services))
        total += len(list(node.clients)) + sum(len(getattr(e, "event_handlers", [])) for e in
                                               [*node.publishers, *node.subscriptions])
    return total


def _time_controller_ticks(graph) -> list[float]:
    """Wall time [s] of every controller's 50 Hz step in the graph (the node's timer callback: ζ book-keeping,
    state reconstruction, model, observer, law, thrust distribution, the setpoint message; in-process delivery
    only queues it), appended to the returned list as the flight runs."""
    ticks: list[float] = []
    for spec, node in zip(graph.specs, graph.nodes, strict=True):
        if spec.executable != "controller":
            continue
        for timer in node.timers:
            if timer.callback == node._on_tick:
                timer.callback = _timed(timer.callback, ticks)
    return ticks


def _timed(callback, times: list[float]):
    def timed(*args):
        start = time.perf_counter()
        try:
            return callback(*args)
        finally:
            times.append(time.perf_counter() - start)
    return timed


def overlap_bound(period_costs: list[tuple[float, float, float]], control_rate: float = 50.0,
                  lag: int = 0) -> float:
    """Speed-up bound of running the simulator and the graph in two processes: ``period_costs`` = (simulation
    time T_k [s], simulator CPU s_k [s] of the step ending at T_k, graph CPU g_k [s] of the drains on T_k), one per
    /clock period, as :class:`InProcessGraph` measures them. Schedule: the graph's g_k starts when step k is done
    and g_(k-1) is; the simulator's step k+1 starts when step k is done and:

    - ``lag`` 0, the lockstep rule: if T_k is a control boundary (a multiple of 1 / ``control_rate``), when the
      graph has computed that boundary's setpoints (g_k);
    - ``lag`` 1, the overlapped layout as fpr_experiments.overlapped builds it: at every period, when g_(k-1) is
      done (the setpoints computed on /clock T_(k-1) act from T_k: one period of added latency).

    Returns Σ(s_k + g_k) / the schedule's makespan (communication free: an upper bound). (Until 2026-12-07 ``lag``
    1 waited only at the boundaries, for g_(k-1): the setpoints of g_k, where the controllers' work is, then
    waited for nobody, a schedule no implementation can have; it gave x1.4-1.6.)"""
    if lag not in (0, 1):
        raise ValueError(f"lag must be 0 or 1, got {lag}")
    sim_done = 0.0
    graph_done = [0.0, 0.0]  # g_(k-1), g_(k-2) finished at
    previous_time = None
    for time_k, sim_cost, graph_cost in period_costs:
        start = sim_done
        if lag == 1 or (previous_time is not None
                        and abs(previous_time * control_rate - round(previous_time * control_rate)) < 1e-6):
            start = max(start, graph_done[lag])
        sim_done = start + sim_cost
        graph_done = [max(graph_done[0], sim_done) + graph_cost, graph_done[0]]
        previous_time = time_k
    serial = sum(s + g for _, s, g in period_costs)
    return serial / graph_done[0] if graph_done[0] > 0.0 else 1.0


def run_case(case: str, deterministic: bool, lean: bool, clock_rate: float, seconds: float,
             realism: str = "ideal", executor: str = "sweep",
             measure_periods: bool = False, node_parameters: dict | None = None,
             opencv_dispatch: str = "native", layout: str = "one process",
             graph_options: dict | None = None) -> dict:
    n, scenario, script, cameras = CASES[case]
    model = {}
    if n != 3:
        from fpr_experiments.resources import MODELS

        model = {"controller": {"model_file": MODELS.resolve(f"fpr_n{n}_unequal")}}
    options = GraphOptions(n=n, mode="communicating", cameras=cameras, scenario=scenario, script=script,
                           parameters={"simulator": {"clock_rate": clock_rate}, **model, **(node_parameters or {})},
                           realism=realism)
    load_before = os.getloadavg()[0]
    with dispatch_context(opencv_dispatch), \
            (OverlappedGraph(describe_graph(options), recorded_topics(n)) if layout == "overlapped" else
             InProcessGraph(describe_graph(options), recorded_topics(n), lean=lean, deterministic=deterministic,
                            executor=executor if deterministic else None,
                            measure_periods=measure_periods, **(graph_options or {}))) as graph:
        graph.wait_for_discovery()
        ticks = _time_controller_ticks(graph)
        entities = _entities(graph)
        wall, cpu = time.monotonic(), _cpu()
        graph.run_until(lambda: graph.sim_time >= seconds - 1e-9, wall_timeout=60.0 + 60.0 * seconds)
        wall, cpu = time.monotonic() - wall, _cpu() - cpu
        if layout == "overlapped":
            cpu += graph.simulator_cpu  # the simulator process's, from its first period on
        simulated = graph.sim_time
        timeouts = graph.lockstep_timeouts
        period_costs = list(graph.period_costs)
        # how far the platform climbed: the flight was flown, not only the ground phase (after the timing)
        heights = [m.platform_pose.position.z for m in graph.recorder.snapshot().get("/fpr/ground_truth")]
    ticks_us = sorted(1e6 * t for t in ticks)
    return {"period_costs": period_costs,
            "tick_median_us": ticks_us[len(ticks_us) // 2] if ticks_us else math.nan,
            "tick_p95_us": ticks_us[int(0.95 * (len(ticks_us) - 1))] if ticks_us else math.nan,
            "case": case, "lean": lean, "clock_rate": clock_rate, "simulated": simulated, "wall": wall, "cpu": cpu,
            "rtf": simulated / wall, "cpu_per_sim_s": cpu / simulated, "timeouts": timeouts, "entities": entities,
            "load": (load_before, os.getloadavg()[0]),
            "climbed": max(heights) - heights[0] if heights else math.nan}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=12.0, help="simulated seconds per run")
    parser.add_argument("--cases", default=",".join(CASES), help="comma-separated: " + ", ".join(CASES))
    parser.add_argument("--levers", default="all", help="'all' or comma-separated lever numbers (0 = baseline): "
                        + "; ".join(f"{k} {name}" for k, name in enumerate(LEVERS)))
    parser.add_argument("--overlap", action="store_true", help="price the overlapped two-process layout (module "
                        "doc) instead of the levers")
    parser.add_argument("--numeric-dispatch", choices=("native", "baseline"), default="native",
                        help="numpy's, OpenBLAS's and libm's code (fpr_model.numeric_dispatch): 'native' (default, "
                             "the figures before 2026-12-07's last session) or 'baseline', the pinned code the "
                             "experiments fly (the benchmark starts itself again in it)")
    args = parser.parse_args()
    if args.numeric_dispatch == "baseline":
        from fpr_model.numeric_dispatch import reexec_pinned

        reexec_pinned()
    if args.overlap:
        overlap(args.cases.split(","), args.seconds)
        return
    levers = list(LEVERS.items())
    if args.levers != "all":
        levers = [levers[int(k)] for k in args.levers.split(",")]
    from fpr_model.numeric_dispatch import numeric_dispatch_in_effect, openblas_core

    print(f"# bench_graph: {args.seconds:.0f} s simulated per run, {os.cpu_count()} cores, load average "
          f"{os.getloadavg()[0]:.2f}, numeric code {numeric_dispatch_in_effect()} (OpenBLAS {openblas_core()})",
          flush=True)
    print(f"# probe: bench_control's n = 3 C step before / after each run, median of 1000 calls "
          f"({REFERENCE_STEP_US:.0f} us on the reference VM)", flush=True)
    runs: list[tuple[str, str, float]] = []  # (case, lever, RTF) of every run, for the summary
    for case in args.cases.split(","):
        baseline = None
        for name, (deterministic, lean, clock_rate, realism, executor, *extra) in levers:
            step_before = reference_step_us()
            layout = extra[2] if len(extra) > 2 else "one process"
            r = run_case(case, deterministic, lean, clock_rate, args.seconds, realism, executor,
                         measure_periods=deterministic and layout == "one process",
                         node_parameters=extra[0] if extra else None,
                         opencv_dispatch=extra[1] if len(extra) > 1 else "native", layout=layout,
                         graph_options=extra[3] if len(extra) > 3 else None)
            step_after = reference_step_us()
            baseline = baseline or r
            split = ""
            if r["period_costs"]:  # the simulator's step (physics, sensors, rendering, publishing) and the rest
                split = (f" (simulator {sum(c[1] for c in r['period_costs']) / r['simulated']:4.2f}, graph "
                         f"{sum(c[2] for c in r['period_costs']) / r['simulated']:4.2f})")
            print(f"{case:12s} {name:56s} wall {r['wall']:6.1f} s  CPU {r['cpu']:6.1f} s  RTF {r['rtf']:5.2f}  "
                  f"probe {step_before:3.0f}/{step_after:3.0f} us  CPU/sim-s {r['cpu_per_sim_s']:5.2f}{split}  "
                  f"x{r['rtf'] / baseline['rtf']:4.2f} vs baseline  "
                  f"controller step {r['tick_median_us']:4.0f} us (p95 {r['tick_p95_us']:4.0f})  "
                  f"entities {r['entities']:4d}  timeouts {r['timeouts']}  "
                  f"load {r['load'][0]:.2f}->{r['load'][1]:.2f}  climbed {r['climbed']:4.2f} m",
                  flush=True)
            runs.append((case, name, r["rtf"]))
    for line in summary(runs):
        print(line, flush=True)


#: the levers whose RTFs give issue 11's figure: the hardware profile's cost against the default
IDEAL_LEVER, HARDWARE_LEVER = ("deterministic, lean + /clock 100 Hz, sweep executor (default)",
                               "default + hardware realism")


def summary(runs: list[tuple[str, str, float]]) -> list[str]:
    """Lines after the runs: the mean RTF of every (case, lever) run more than once, and per case with runs of both
    the default and the hardware profile, issue 11's figure: the cost ``1 − mean hardware RTF / mean ideal RTF``,
    with its range over the pairs in run order (the i-th ideal run with the i-th hardware run)."""
    lines = []
    by_lever: dict[tuple[str, str], list[float]] = {}
    for case, lever, rtf in runs:
        by_lever.setdefault((case, lever), []).append(rtf)
    for (case, lever), rtfs in by_lever.items():
        if len(rtfs) > 1:
            lines.append(f"# mean RTF {case} {lever}: {sum(rtfs) / len(rtfs):.2f} over {len(rtfs)} runs "
                         f"({min(rtfs):.2f}-{max(rtfs):.2f})")
    for case in dict.fromkeys(case for case, _, _ in runs):
        ideal, hardware = by_lever.get((case, IDEAL_LEVER)), by_lever.get((case, HARDWARE_LEVER))
        if not ideal or not hardware:
            continue
        cost = 1.0 - (sum(hardware) / len(hardware)) / (sum(ideal) / len(ideal))
        pairs = [1.0 - h / i for i, h in zip(ideal, hardware, strict=False)]
        lines.append(f"# hardware profile's cost (issue 11: at most 20 %) {case}: {100 * cost:.0f} % "
                     f"(mean RTF {sum(ideal) / len(ideal):.2f} ideal over {len(ideal)} runs, "
                     f"{sum(hardware) / len(hardware):.2f} hardware over {len(hardware)}; pairs "
                     f"{100 * min(pairs):.0f}-{100 * max(pairs):.0f} %)")
    return lines


def overlap(cases: list[str], seconds: float) -> None:
    """``--overlap``: per case, the default runner with its per-period costs and the bounds they give the two-process
    layouts (:func:`overlap_bound`), then the overlapped layout itself (fpr_experiments.overlapped), twice,
    interleaved with a second one-process run (module doc)."""
    print(f"# bench_graph --overlap: {seconds:.0f} s simulated per run, {os.cpu_count()} cores, load average "
          f"{os.getloadavg()[0]:.2f}", flush=True)
    for case in cases:
        r = run_case(case, True, True, 100.0, seconds, measure_periods=True)
        costs = r["period_costs"]
        sim_cpu = sum(s for _, s, _ in costs) / r["simulated"]
        graph_cpu = sum(g for _, _, g in costs) / r["simulated"]
        strict, pipelined = overlap_bound(costs, lag=0), overlap_bound(costs, lag=1)
        runs = [run_case(case, True, True, 100.0, seconds, layout=layout)
                for layout in ("overlapped", "one process", "overlapped")]
        one = (r["rtf"] + runs[1]["rtf"]) / 2.0
        overlapped = (runs[0]["rtf"] + runs[2]["rtf"]) / 2.0
        print(f"{case:12s} one process: RTF {r['rtf']:5.2f}, {runs[1]['rtf']:5.2f}  CPU/sim-s: simulator "
              f"{sim_cpu:5.3f} graph {graph_cpu:5.3f}  bound of two processes, free communication: x{strict:4.2f} "
              f"lockstep rule, x{pipelined:4.2f} overlapped  overlapped layout: RTF {runs[0]['rtf']:5.2f}, "
              f"{runs[2]['rtf']:5.2f} (x{overlapped / one:4.2f} measured), CPU/sim-s {runs[0]['cpu_per_sim_s']:5.3f}  "
              f"load {r['load'][0]:.2f}->{runs[2]['load'][1]:.2f}", flush=True)


if __name__ == "__main__":
    main()
