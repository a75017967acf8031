"""The simulated FPR swarm demo: fly a scripted mission with the whole node graph, report it.

Builds the simulator, per UAV a px4_bridge, pose_estimator (+ aruco_detector with images) and controller, the
teleop and a joy_script in one process (tests/swarm_graph.py), flies the joy script in lockstep, prints a
progress line every few simulated seconds and, at the end, a summary table of flight metrics; writes
``metrics.json``, PNG plots and ``flight.mcap`` (Foxglove / ``ros2 bag``) to the output folder.

Run it through ``bash scripts/run_demo.sh [args]`` (network isolation, workspace sourced), e.g.::

    bash scripts/run_demo.sh --quick
    bash scripts/run_demo.sh --mode non_communicating --output-dir reports/demo_nc
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
# tests/swarm_graph.py is the project's launch-free graph runner (the whole node graph in one process, stepped
# in lockstep); the demo uses its public API only.
sys.path.insert(0, os.path.join(ROOT, "tests"))

from flight_report import compute_metrics, format_summary, write_metrics_json, write_plots  # noqa: E402
from mcap_log import RosMcapWriter  # noqa: E402
from swarm_graph import SwarmGraph, SwarmOptions, config_path  # noqa: E402
from swarm_recording import Snapshot, TopicLogger, flight_record, mcap_channels, state_names, write_mcap  # noqa: E402

MODES = ("communicating", "non_communicating", "impedance", "centralized", "pd", "pd_compensated")
QUICK_DURATION = 12.0   #: [s] --quick flies the first seconds of the mission (default script: arm, climb, hold)
SETTLE = 5.0            #: [s] simulated after the script's last keyframe (landing, disarm)
PROGRESS_PERIOD = 2.0   #: [s] simulated between progress lines


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="ground_start.yaml",
                        help="fpr_sim config/scenarios/<name> or a path (default: %(default)s)")
    parser.add_argument("--script", default="integration_flight.yaml",
                        help="fpr_control config/joy_scripts/<name> or a path (default: %(default)s)")
    parser.add_argument("--mode", default="communicating", choices=MODES,
                        help="controller mode (default: %(default)s)")
    parser.add_argument("--cameras", default="emulated", choices=("emulated", "images"),
                        help="emulated: noisy marker poses (real-time factor ~0.8 here); images: rendered camera "
                             "images + aruco_detector (~0.15 here: the default mission takes 3-4 min)")
    parser.add_argument("--duration", type=float, default=None,
                        help="simulated seconds (default: the script's last keyframe + 5 s; 30 s if it loops)")
    parser.add_argument("--real-time-factor", type=float, default=0.0,
                        help="pace the simulation (0: as fast as the lockstep allows)")
    parser.add_argument("--output-dir", default=os.path.join(ROOT, "reports", "demo"),
                        help="where metrics.json, the PNG plots and flight.mcap go (default: reports/demo)")
    parser.add_argument("--quick", action="store_true",
                        help=f"fly only the first {QUICK_DURATION:.0f} s, lighter plots")
    return parser.parse_args(argv)


def script_duration(script: str) -> float:
    """Last keyframe of a joy script + :data:`SETTLE` s (30 s for a looping script)."""
    path = script if os.path.exists(script) else config_path("fpr_control", "joy_scripts", script)
    with open(path, encoding="utf-8") as stream:
        document = yaml.safe_load(stream) or {}
    if document.get("loop"):
        return 30.0
    return max((float(k.get("t", 0.0)) for k in document.get("keyframes", [])), default=0.0) + SETTLE


class Progress:
    """Prints one line every :data:`PROGRESS_PERIOD` simulated seconds."""

    def __init__(self, swarm: SwarmGraph) -> None:
        self.swarm = swarm
        self.names = state_names()
        self.start_wall = self.last_wall = time.monotonic()
        self.start_sim = self.last_sim = swarm.sim_time

    def __call__(self) -> None:
        swarm, recorder, now = self.swarm, self.swarm.recorder, time.monotonic()
        if swarm.sim_time < 0.5 * PROGRESS_PERIOD:  # run_until also calls at the first step: nothing to say yet
            return
        rtf = (swarm.sim_time - self.last_sim) / max(now - self.last_wall, 1e-9)
        self.last_wall, self.last_sim = now, swarm.sim_time
        with recorder.lock:
            truth = recorder.truth[-1] if recorder.truth else None
            command = recorder.teleop[-1] if recorder.teleop else None
            states = [s[-1].state if s else -1 for s in recorder.status.values()]
        line = f"[demo] t={swarm.sim_time:5.1f} s  wall {now - self.start_wall:5.1f} s  RTF {rtf:4.2f}  "
        if command is not None:
            line += f"{self._phase(command):<14} "
        if truth is not None:
            from fpr_model.rotations import quat_to_euler_zyx

            q = truth.platform_pose.orientation
            roll, pitch, _ = np.degrees(quat_to_euler_zyx(np.array([q.w, q.x, q.y, q.z])))
            legs = " ".join(f"{math.degrees(a):4.1f}" for a in truth.leg_angles)
            line += (f"z {truth.platform_pose.position.z:5.2f} m  roll {roll:+5.1f} pitch {pitch:+5.1f} deg  "
                     f"legs {legs} deg  ")
        line += "bridges " + ",".join(self.names.bridge_state.get(s, "-") for s in states)
        line += f"  timeouts {swarm.lockstep_timeouts}"
        print(line, flush=True)

    def _phase(self, command) -> str:
        mode = self.names.teleop_mode.get(command.mode, "?")
        if command.mode != self.names.fly_mode:
            return mode
        if abs(command.roll_rate) > 0.01 or abs(command.pitch_rate) > 0.01:
            return f"{mode}/tilt"
        vz = command.platform_velocity.z
        return f"{mode}/" + ("climb" if vz > 0.05 else "descend" if vz < -0.05 else "hold")


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    duration = args.duration if args.duration is not None else script_duration(args.script)
    if args.quick:
        duration = min(duration, QUICK_DURATION)
    os.makedirs(args.output_dir, exist_ok=True)
    options = SwarmOptions(scenario=args.scenario, joy_script=args.script, controller_mode=args.mode,
                           emulated_cameras=args.cameras == "emulated", real_time_factor=args.real_time_factor)
    print(f"[demo] scenario {args.scenario}, script {args.script}, controller {args.mode}, {args.cameras} "
          f"cameras, {duration:.1f} s simulated -> {args.output_dir}", flush=True)
    wall_start = time.monotonic()
    completed, interrupted = False, False
    with SwarmGraph(options) as swarm:
        logger = TopicLogger(swarm.context, swarm.n)
        mcap = RosMcapWriter(os.path.join(args.output_dir, "flight.mcap"), metadata={
            "scenario": args.scenario, "script": args.script, "controller_mode": args.mode,
            "cameras": args.cameras})
        try:
            for topic, msg_type in mcap_channels(swarm.n).items():
                mcap.add_channel(topic, msg_type)
            swarm.wait_for_discovery()
            logger.wait_for_publishers()
            print(f"[demo] {len(swarm.nodes)} nodes built and discovered in {time.monotonic() - wall_start:.1f} s",
                  flush=True)
            progress = Progress(swarm)
            flight_start = time.monotonic()
            try:
                completed = swarm.run_until(lambda: swarm.sim_time >= duration - 1e-9,
                                            wall_timeout=120.0 + 30.0 * duration, progress=progress,
                                            progress_period=PROGRESS_PERIOD)
            except KeyboardInterrupt:
                interrupted = True
                print("\n[demo] interrupted: reporting what was recorded", flush=True)
            flight_wall = time.monotonic() - flight_start
            if not completed and not interrupted:
                print(f"[demo] wall-clock timeout at t = {swarm.sim_time:.1f} s", flush=True)
            # the ROS graph's executors may lag the simulation by a few periods: let the recorders catch up
            wait_for_recorder = getattr(swarm, "wait_for_recorder", None)  # newer SwarmGraph versions
            caught_up = logger.wait_for_clock(swarm.sim_time, timeout=10.0)
            if wait_for_recorder is not None:
                caught_up = wait_for_recorder(wall_timeout=10.0) and caught_up
            if not caught_up:
                print("[demo] the recorders did not catch up with the simulation: the log ends early", flush=True)
            snapshot = Snapshot(swarm.recorder, logger)
            record = flight_record(
                snapshot, swarm.n, scenario=os.path.basename(args.scenario), script=os.path.basename(args.script),
                controller_mode=args.mode, cameras=args.cameras, sim_time=swarm.sim_time,
                wall_time=flight_wall, lockstep_timeouts=swarm.lockstep_timeouts,
                callback_errors=list(swarm.errors), completed=completed)
            count = write_mcap(mcap, snapshot)
        finally:
            mcap.close()
            logger.stop()
    metrics = compute_metrics(record)
    write_metrics_json(metrics, os.path.join(args.output_dir, "metrics.json"))
    plots = write_plots(record, args.output_dir, dpi=80 if args.quick else 110)
    print("\n" + format_summary(metrics), flush=True)
    for error in record.callback_errors[:5]:
        print(f"[demo] callback error: {error}", flush=True)
    print(f"\n[demo] wrote {os.path.join(args.output_dir, 'metrics.json')}, {mcap.path} ({count} messages, "
          f"{sum(1 for c in mcap.counts.values() if c)} topics) and {len(plots)} plots: "
          f"{', '.join(os.path.basename(p) for p in plots)}", flush=True)
    print(f"[demo] total wall time {time.monotonic() - wall_start:.1f} s", flush=True)
    return 0 if completed and not record.callback_errors else 1


if __name__ == "__main__":
    sys.exit(main())
