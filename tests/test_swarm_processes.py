"""Launch-free integration (DESIGN.md §7), the swarm as SEPARATE PROCESSES: one per UAV (px4_bridge +
pose_estimator + controller in one executor, tests/swarm_processes.py), one ground station (teleop + joy_script),
one simulator (``ros2 run fpr_sim simulator``, paced at real_time_factor 0.5, emulated cameras). The test process
only records (SwarmRecorder). Short flight from the hover scenario (config/joy_scripts/integration_hover.yaml):
arm + fly, climb 2 s at 0.3 m/s, hold. Assertions on flight metrics from the ground truth, never on sleeps.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from swarm_graph import SwarmRecorder  # noqa: E402
from swarm_processes import simulator_command  # noqa: E402

N = 3
SCENARIO = "hover.yaml"
JOY_SCRIPT = os.path.join(os.path.dirname(HERE), "src", "fpr_control", "config", "joy_scripts",
                          "integration_hover.yaml")
REAL_TIME_FACTOR = 0.5  # the simulator runs its own loop: paced so the 5 processes keep up on 2 cores
DURATION = 9.0          # [s] simulated
CLIMB = (3.0, 5.0)      # left stick up: +0.3 m/s
HOLD = (6.5, 9.0)
CLIMB_RATE = 0.3
CONTROL_PERIOD = 0.02   # [s] controllers at 50 Hz


def _start(command: list[str]) -> subprocess.Popen:
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1)


def _drain(process: subprocess.Popen, lines: list[str], ready: threading.Event) -> None:
    for line in process.stdout:
        lines.append(line.rstrip())
        if line.startswith("READY"):
            ready.set()


def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


@pytest.fixture(scope="module")
def flight():
    wall_start = time.monotonic()
    python = [sys.executable, os.path.join(HERE, "swarm_processes.py")]
    commands = {f"uav{i}": python + ["uav", str(i), "--n", str(N)] for i in range(1, N + 1)}
    commands["ground"] = python + ["ground", "--n", str(N), "--script", JOY_SCRIPT]
    processes: dict[str, subprocess.Popen] = {}
    logs: dict[str, list[str]] = {}
    context = rclpy.Context()
    rclpy.init(context=context)
    recorder = SwarmRecorder(N, context=context, parameter_overrides=[Parameter("use_sim_time", value=True)])
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(recorder)
    running = True

    def spin() -> None:
        while running and context.ok():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    try:
        events = {}
        for name, command in commands.items():
            processes[name], logs[name], events[name] = _start(command), [], threading.Event()
            threading.Thread(target=_drain, args=(processes[name], logs[name], events[name]), daemon=True).start()
        for name, event in events.items():
            assert event.wait(90.0), f"{name} not ready: {logs[name][-20:]}"
        print(f"\n[processes] 3 UAV + ground processes ready in {time.monotonic() - wall_start:.1f} s", flush=True)
        sim_start = time.monotonic()
        processes["simulator"], logs["simulator"] = _start(simulator_command(SCENARIO, REAL_TIME_FACTOR,
                                                                                DURATION)), []
        threading.Thread(target=_drain, args=(processes["simulator"], logs["simulator"], threading.Event()),
                         daemon=True).start()
        try:
            processes["simulator"].wait(timeout=120.0)
        except subprocess.TimeoutExpired:
            pytest.fail(f"simulator did not finish {DURATION} s: {logs['simulator'][-20:]}")
        wall = time.monotonic() - sim_start
        time.sleep(0.5)  # let the recorder take the last messages in flight (not an assertion on timing)
        print(f"[processes] {DURATION} s simulated in {wall:.1f} s wall (incl. simulator start-up): "
              f"real-time factor {DURATION / wall:.2f}", flush=True)
        record = {"truth": recorder.truth_arrays(), "teleop": recorder.teleop_arrays(),
                  "status": {i: list(s) for i, s in recorder.status.items()},
                  "diagnostics": {i: list(d) for i, d in recorder.diagnostics.items()},
                  "setpoints": {i: list(s) for i, s in recorder.setpoints.items()},
                  "logs": logs, "returncode": processes["simulator"].returncode}
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.terminate()
        for process in processes.values():
            try:
                process.wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        running = False
        spinner.join(timeout=5.0)
        executor.shutdown(timeout_sec=1.0)
        recorder.destroy_node()
        context.try_shutdown()
    yield record


def test_simulator_ran_to_its_duration_with_few_lockstep_timeouts(flight):
    assert flight["returncode"] == 0, flight["logs"]["simulator"][-20:]
    text = "\n".join(flight["logs"]["simulator"])
    match = re.search(r"duration [\d.]+ s reached: stopping \(lockstep timeouts: (\d+), oldest setpoint on "
                      r"arrival: (\S+) ms\)", text)
    assert match, flight["logs"]["simulator"][-20:]
    timeouts, latency_ms = int(match.group(1)), float(match.group(2))
    print(f"[processes] simulator lockstep timeouts: {timeouts}; oldest controller setpoint on arrival at PX4: "
          f"{latency_ms:.0f} ms (simulation time)")
    assert timeouts <= 10  # the first periods wait for the bridges to start streaming (cross-process discovery)
    # the lockstep waits for each period's own setpoint (not the bridges' repetitions): the simulation never
    # runs ahead of the controller processes by more than one control period
    # (a setpoint can look up to one period "early": the bridges stamp it through a boot-time offset estimated
    # from telemetry received behind their /clock, biased early when the executors lag on a loaded machine)
    assert -1000.0 * CONTROL_PERIOD <= latency_ms <= 1000.0 * CONTROL_PERIOD


def test_bridges_never_disarm_on_their_own(flight):
    """hover.yaml starts armed in OFFBOARD while the bridges start IDLE: no DISARM until the operator's commands
    (here ARM then FLY at once; the report of an armed PX4 while IDLE is unit-tested in fpr_px4_bridge)."""
    for i in range(1, N + 1):
        log = "\n".join(flight["logs"][f"uav{i}"])
        assert "-> WARMUP" in log and "-> OFFBOARD" in log, f"uav {i}: log incomplete"
        assert "DISARM" not in log, f"uav {i}: the bridge sent a disarm"
    assert flight["truth"]["t"][-1] >= DURATION - 0.1


def test_bridges_offboard_and_controllers_in_mode_c(flight):
    offboard = []
    for i, statuses in flight["status"].items():
        reached = [_stamp(s) for s in statuses if s.state == 4]
        assert reached, f"uav {i}: bridge never OFFBOARD"
        offboard.append(reached[0])
    start = max(offboard) + 0.5
    print(f"[processes] all bridges OFFBOARD at t = {max(offboard):.2f} s")
    assert start < CLIMB[0]
    for i in range(1, N + 1):
        flying = [s for s in flight["status"][i] if _stamp(s) >= start]
        assert flying and all(s.state == 4 for s in flying), f"uav {i} left OFFBOARD"
        diagnostics = [d for d in flight["diagnostics"][i] if _stamp(d) >= start]
        assert len(diagnostics) > 30 * (DURATION - start), f"uav {i}: diagnostics missing"
        modes = {d.active_mode for d in diagnostics}
        fallbacks = sum(d.fallback_active for d in diagnostics)
        print(f"[processes] uav {i}: active modes {modes}, fallback periods {fallbacks}")
        assert modes == {1} and fallbacks == 0
        for sp in flight["setpoints"][i]:
            values = [sp.attitude.w, sp.attitude.x, sp.attitude.y, sp.attitude.z, sp.thrust]
            assert all(math.isfinite(v) for v in values)


def test_climb_and_hold(flight):
    truth, teleop = flight["truth"], flight["teleop"]
    t, z = truth["t"], truth["position"][:, 2]
    assert truth["finite"].all()
    gain = float(z[t <= HOLD[0]][-1] - z[t <= CLIMB[0]][-1])
    hold = (t >= HOLD[0]) & (t <= HOLD[1])
    roll_err = truth["rpy"][hold, 0] - np.interp(t[hold], teleop["t"], teleop["roll"])
    pitch_err = truth["rpy"][hold, 1] - np.interp(t[hold], teleop["t"], teleop["pitch"])
    leg_err = truth["legs"][hold] - np.column_stack([np.interp(t[hold], teleop["t"], teleop["legs"][:, k])
                                                     for k in range(N)])
    deg = np.degrees
    print(f"[processes] climb gained {gain:.3f} m (ideal {CLIMB_RATE * (CLIMB[1] - CLIMB[0]):.2f}); hold: roll "
          f"max error {deg(np.abs(roll_err).max()):.2f} deg, pitch {deg(np.abs(pitch_err).max()):.2f} deg, legs "
          f"{deg(np.abs(leg_err).max()):.2f} deg")
    assert gain == pytest.approx(CLIMB_RATE * (CLIMB[1] - CLIMB[0]), abs=0.2)
    assert hold.sum() > 100
    assert np.abs(roll_err).max() < math.radians(3.0)
    assert np.abs(pitch_err).max() < math.radians(3.0)
    assert np.abs(leg_err).max() < math.radians(5.0)
