"""The graph as SEPARATE PROCESSES, grouped as on the robot (DESIGN.md §7): one ``node_group`` process per UAV
(its companion computer: bridge, detector, estimator, controller), one for the ground station (teleop +
operator), one for a fault-injecting link if any, and the simulator alone (``ros2 run fpr_sim simulator``), all
from the same graph description as the in-process runner. This process only records. The simulator runs its own
loop, paced at ``real_time_factor`` (the other processes must keep up on the machine's cores) with its lockstep
on, and stops at the run's duration.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

from fpr_experiments.graph import NodeSpec, groups, write_graph_file
from fpr_experiments.network import separate_hosts_environment
from fpr_experiments.recording import Topic

#: [s] wall: every group process must print READY within this
READY_TIMEOUT = 120.0
#: [s] wall: how long the other processes keep running after a fault killed the simulator
SIMULATOR_LINGER = 3.0
#: [s] wall: from a restarted process's discovery (its /clock subscription seen) to the simulation's resume: the
#: matching of its other endpoints
RESTART_SETTLE = 0.5
#: [s] wall: the simulation resumes anyway this long after a restart (a process that never comes up)
RESTART_HOLD_LIMIT = 60.0
_TIMEOUTS = re.compile(r"lockstep timeouts: (\d+)")
_TIMEOUT_WARNING = re.compile(r"lockstep: (\d+) control periods timed out")


def node_pid(pid: int) -> int:
    """The process that runs the node started as ``pid``: ``pid`` itself when the command exec'd the node (this
    project's ``ros2`` stand-in), its child when ``ros2 run`` started the node as a child process and waits for it
    (ros2cli's ``ros2 run``). Follows a chain of only children (Linux ``/proc/<pid>/task/<pid>/children``); a process
    with no child or several, or no /proc, is the node."""
    for _ in range(8):
        try:
            with open(f"/proc/{pid}/task/{pid}/children", encoding="ascii") as children_file:
                children = children_file.read().split()
        except OSError:
            return pid
        if len(children) != 1:
            return pid
        pid = int(children[0])
    return pid


class _Process:
    """One process of the graph, its output drained into ``<log_dir>/<name>.log``. Signals meant for the node
    (:meth:`crash`, :meth:`signal_node`, :meth:`stop`) reach the node's own process, also when ``ros2 run`` started
    it as a child (:func:`node_pid`): a SIGUSR1 to ros2cli's waiting wrapper would end the wrapper (Python's
    default action) and leave the node running, a SIGKILL would orphan the node."""

    def __init__(self, name: str, command: list[str], log_dir: str, log_name: str | None = None) -> None:
        self.name = name
        self.lines: list[str] = []
        self.ready = threading.Event()
        self.log = open(os.path.join(log_dir, f"{log_name or name}.log"), "w",  # noqa: SIM115 - closed
                        encoding="utf-8")
        self.process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                        bufsize=1)
        self._thread = threading.Thread(target=self._drain, name=f"drain-{name}", daemon=True)
        self._thread.start()

    def _drain(self) -> None:
        for line in self.process.stdout:
            line = line.rstrip()
            self.lines.append(line)
            self.log.write(line + "\n")
            if line.startswith("READY"):
                self.ready.set()

    def _kill_node(self, signum: int) -> None:
        """``signum`` to the node's process, then to the started process if that is another (a wrapper)."""
        if self.process.poll() is not None:
            return
        node = node_pid(self.process.pid)
        for pid in dict.fromkeys((node, self.process.pid)):
            try:
                os.kill(pid, signum)
            except ProcessLookupError:
                pass

    def crash(self) -> None:
        """SIGKILL the node (a crash: no clean shutdown), and its ``ros2 run`` wrapper if it has one."""
        self._kill_node(signal.SIGKILL)

    def signal_node(self, signum: int) -> None:
        """``signum`` to the node's process only (the wrapper, if any, keeps waiting for it)."""
        if self.process.poll() is None:
            try:
                os.kill(node_pid(self.process.pid), signum)
            except ProcessLookupError:
                pass  # it has just ended

    def stop(self) -> None:
        # rclpy shuts down on SIGTERM; a ros2 run wrapper would not pass it on, but ends when its node has ended
        self.signal_node(signal.SIGTERM)
        try:
            self.process.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            self._kill_node(signal.SIGKILL)
            self.process.wait()
        self._thread.join(timeout=5.0)
        self.log.close()


@dataclass(frozen=True)
class ProcessFault:
    """Fault injection (issue 12): SIGKILL the process of ``group`` (a crash: no clean shutdown) once the
    simulation reaches ``at`` [s]; with ``restart_after`` [s of simulation time after the kill], start the same
    command again (a supervisor restarting the node, e.g. systemd's ``Restart=on-failure``) and hold the simulation
    (SIGUSR1 / SIGUSR2, fpr_sim's ``SimulatorNode.hold_paused``) until the new process said READY, the graph shows a
    ``/clock`` subscription that was not there before (the new participant discovered: every node of a group runs on
    simulated time) and ``RESTART_SETTLE`` wall seconds more passed for its other endpoints' matching:
    ``restart_after`` is when the node is back, and its start-up costs no simulation time. Without the hold, a
    start-up of 2-4 wall s on a loaded 2-core machine (python imports, rclpy, discovery) cost 1-2 s of simulation at
    real_time_factor 0.5, and whether the restarted node rejoined before its bridge's 5 s Hold ran out depended on
    the machine (a CI run, 2026-12-07). ``group``
    "simulator" kills the simulator (no restart: the run ends ``SIMULATOR_LINGER`` wall seconds later, the other
    processes still running, so that their reaction to the lost PX4s can be read from their logs)."""

    group: str
    at: float
    restart_after: float | None = None


@dataclass
class _Restarting:
    """A restarted process the simulation is held for (_FaultInjector)."""

    process: _Process
    clock_subscriptions: set[bytes]  #: the /clock subscriptions' GIDs in the graph before it started
    spawned: float  #: [s] monotonic wall time of the spawn
    up: float | None = None  #: [s] monotonic wall time it was seen up (discovered, dead, or the hold's limit)


class _FaultInjector:
    """Applies :class:`ProcessFault` s from the runner's polling loop; ``events`` lists (what, sim time, wall),
    wall as ``time.time()`` (the epoch seconds of the ROS log lines' stamps)."""

    def __init__(self, faults: Sequence[ProcessFault], processes: dict, commands: dict, log_dir: str,
                 graph_node=None) -> None:
        unknown = sorted({f.group for f in faults} - set(commands) - {"simulator"})
        if unknown:
            raise ValueError(f"fault for unknown process group(s) {unknown}; groups: {', '.join(commands)}, "
                             "simulator")
        if any(f.group == "simulator" and f.restart_after is not None for f in faults):
            raise ValueError("the simulator cannot be restarted (its state is the world's)")
        self.pending = sorted(faults, key=lambda f: f.at)
        self.restarts: list[tuple[float, ProcessFault]] = []
        self.processes, self.commands, self.log_dir = processes, commands, log_dir
        self.events: list[tuple[str, float, float]] = []
        #: restarted processes the simulation is held for (class doc)
        self.starting: list[_Restarting] = []
        self.graph_node = graph_node  #: a node of the runner's, for the graph (the /clock subscriptions)

    def __call__(self, sim_time: float) -> None:
        while self.pending and sim_time >= self.pending[0].at:
            fault = self.pending.pop(0)
            self.processes[fault.group].crash()
            self.events.append((f"killed {fault.group}", sim_time, time.time()))
            if fault.restart_after is not None:
                self.restarts.append((sim_time + fault.restart_after, fault))
        for due, fault in list(self.restarts):
            if sim_time >= due:
                self.restarts.remove((due, fault))
                self._signal_simulator(signal.SIGUSR1)  # hold the world while the node starts (class doc)
                old = self.processes.pop(fault.group)
                old.stop()
                before = self._clock_subscriptions()
                self.processes[fault.group] = restarted = _Process(
                    fault.group, self.commands[fault.group], self.log_dir, log_name=f"{fault.group}.restarted")
                self.starting.append(_Restarting(restarted, before, time.monotonic()))
                self.events.append((f"restarted {fault.group}", sim_time, time.time()))
        if self.starting:
            now = time.monotonic()
            for entry in self.starting:
                if entry.up is not None:
                    continue
                if entry.process.process.poll() is not None or (entry.process.ready.is_set() and (
                        self.graph_node is None or self._clock_subscriptions() - entry.clock_subscriptions)):
                    entry.up = now  # discovered, or dead at start-up (its log says why)
                elif now - entry.spawned > RESTART_HOLD_LIMIT:
                    entry.up = now
                    self.events.append((f"hold released: {entry.process.name} not up after {RESTART_HOLD_LIMIT:g} s "
                                        "wall", sim_time, time.time()))
            if all(e.up is not None and now - e.up >= RESTART_SETTLE for e in self.starting):
                self.starting.clear()
                self._signal_simulator(signal.SIGUSR2)

    def _clock_subscriptions(self) -> set[bytes]:
        """The endpoint GIDs of every /clock subscription in the graph (a killed process's linger until its
        participant's lease runs out, so counting them would not tell a new one); empty without a graph node."""
        if self.graph_node is None:
            return set()
        return {bytes(info.endpoint_gid) for info in self.graph_node.get_subscriptions_info_by_topic("/clock")}

    def _signal_simulator(self, signum: int) -> None:
        simulator = self.processes.get("simulator")
        if simulator is not None:
            simulator.signal_node(signum)

    @property
    def simulator_killed(self) -> bool:
        return any(what == "killed simulator" for what, _, _ in self.events)


class _Clock:
    """What the progress line needs, read from the recorder and the simulator's log."""

    def __init__(self, recorder, simulator: _Process) -> None:
        self.recorder, self.simulator = recorder, simulator

    @property
    def sim_time(self) -> float:
        return self.recorder.latest_time("/clock") or 0.0

    @property
    def lockstep_timeouts(self) -> int:
        counts = [int(m.group(1)) for line in self.simulator.lines for m in [_TIMEOUT_WARNING.search(line)] if m]
        return counts[-1] if counts else 0


def run_processes(specs: Sequence[NodeSpec], topics: Sequence[Topic], duration: float, *, output_dir: str,
                  real_time_factor: float = 0.5, label: str = "run", log: bool = True, live_view=None,
                  faults: Sequence[ProcessFault] = (), fault_events: list | None = None):
    """Fly ``duration`` simulated seconds; returns (recording, completed, lockstep timeouts, errors, wall).
    ``faults``: processes to kill (and restart) on the way; what happened when is appended to ``fault_events``
    ((what, simulation time, wall time) tuples). A killed process's exit is not an error. The middleware:
    :func:`separate_hosts_environment` (one log line says which)."""
    middleware = separate_hosts_environment()
    saved = {name: os.environ.get(name) for name in middleware}
    os.environ.update(middleware)  # this process's recorder and every process it starts (restored at the end)
    if log:
        print(f"[{label}] processes: " + ("UDP only, no shared memory (loopback-only network namespace: "
                                          + " ".join(f"{k}={v}" for k, v in middleware.items()) + ")"
                                          if middleware else "Fast DDS defaults (LOCALHOST discovery)"), flush=True)
    try:
        return _run_processes(specs, topics, duration, output_dir=output_dir, real_time_factor=real_time_factor,
                              label=label, log=log, live_view=live_view, faults=faults, fault_events=fault_events)
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _run_processes(specs, topics, duration, *, output_dir, real_time_factor, label, log, live_view, faults,
                   fault_events):
    import rclpy

    from fpr_experiments.recording import Recorder
    from fpr_experiments.runner import PROGRESS_PERIOD, WALL_PER_SIM_SECOND, Progress

    log_dir = os.path.join(output_dir, "logs")
    os.makedirs(log_dir, exist_ok=True)
    graph_file = os.path.join(output_dir, "graph.json")
    write_graph_file(specs, graph_file)
    by_group = groups(specs)
    n = sum(1 for s in specs if s.executable == "controller")
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    recorder = Recorder(context, topics, use_sim_time=True, live_view=live_view)
    processes: dict[str, _Process] = {}
    errors: list[str] = []
    commands = {group: ["ros2", "run", "fpr_experiments", "node_group", "--graph", graph_file, "--group", group,
                        "--lean"] for group in by_group if group != "simulator"}
    injector = _FaultInjector(faults, processes, commands, log_dir, graph_node=recorder) if faults else None
    try:
        for group, command in commands.items():
            processes[group] = _Process(group, command, log_dir)
        deadline = time.monotonic() + READY_TIMEOUT
        for name, process in processes.items():
            if not process.ready.wait(max(0.0, deadline - time.monotonic())):
                raise RuntimeError(f"{name} not ready after {READY_TIMEOUT:.0f} s: {process.lines[-15:]}")
        expected = {"/fpr/teleop": 1, "/fpr/info": n, **{f"/fpr/uav{i}/controller_status": 1 for i in range(1, n + 1)}}
        recorder.wait_for_publishers(expected, timeout=30.0)
        simulator_spec = next(s for s in specs if s.executable == "simulator")
        # every other node runs on simulated time (one /clock subscription each), and so does the recorder; the
        # info link has a second one (it releases the zeta in flight on /clock)
        clock_subscribers = len(specs) - 1 + 1 + sum(s.executable == "info_link" for s in specs)
        simulator_spec = replace(simulator_spec, parameters={
            **simulator_spec.parameters, "duration": float(duration), "real_time_factor": float(real_time_factor),
            "wait_for_clock_subscribers": clock_subscribers})
        start = time.monotonic()
        processes["simulator"] = simulator = _Process("simulator", simulator_spec.command(), log_dir)
        clock = _Clock(recorder, simulator)
        progress = Progress(label, clock, duration) if log else None
        next_progress = PROGRESS_PERIOD
        wall_deadline = start + 60.0 + WALL_PER_SIM_SECOND * duration
        while simulator.process.poll() is None and time.monotonic() < wall_deadline:
            time.sleep(0.05 if injector is not None else 0.2)
            if injector is not None:
                injector(clock.sim_time)
            if progress is not None and clock.sim_time >= next_progress:
                next_progress += PROGRESS_PERIOD
                progress()
        simulator_killed = injector is not None and injector.simulator_killed
        if simulator_killed:
            time.sleep(SIMULATOR_LINGER)  # the others, on without it: what they say is in their logs
        completed = simulator.process.poll() == 0
        wall = time.monotonic() - start
        if simulator.process.poll() is None:
            errors.append(f"simulator did not reach {duration} s within the wall-clock budget")
        elif simulator.process.returncode != 0 and not simulator_killed:
            errors.append(f"simulator exited with {simulator.process.returncode}: {simulator.lines[-5:]}")
        if not simulator_killed:
            recorder.wait_for("/fpr/ground_truth", duration - 0.02, timeout=10.0)
        time.sleep(0.3)  # messages in flight from the other processes
        recording = recorder.snapshot()
        timeouts = [int(m.group(1)) for line in simulator.lines for m in [_TIMEOUTS.search(line)] if m]
        for name, process in processes.items():
            errors += [f"{name}: {line}" for line in process.lines if line.startswith(("CALLBACK_ERROR", "Traceback"))]
        if injector is not None and fault_events is not None:
            fault_events.extend(injector.events)
        return recording, completed, timeouts[-1] if timeouts else clock.lockstep_timeouts, errors, wall
    finally:
        for process in processes.values():
            process.stop()
        recorder.stop()
        context.try_shutdown()
