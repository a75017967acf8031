"""The fault injector's restart (fpr_experiments.processes._FaultInjector), with stand-in processes: the killed
group is SIGKILLed at its instant; at the restart the simulator is paused (SIGUSR1) and resumed (SIGUSR2) only once
the new process said READY, a /clock subscription that was not in the graph before shows up, and RESTART_SETTLE
passed."""

from __future__ import annotations

import os
import signal
import threading
import time
from types import SimpleNamespace

import pytest
from fpr_experiments.processes import ProcessFault, _FaultInjector

from fpr_experiments import processes


class _FakePopen:
    def __init__(self) -> None:
        self.signals: list[int] = []
        self.killed = False

    def kill(self) -> None:
        self.killed = True

    def poll(self):
        return -9 if self.killed else None

    def send_signal(self, signum: int) -> None:
        self.signals.append(signum)


class _FakeProcess:
    def __init__(self, name: str, command=None, log_dir=None, log_name=None) -> None:
        self.name, self.log_name = name, log_name
        self.process = _FakePopen()
        self.ready = threading.Event()
        self.stopped = False

    def stop(self) -> None:
        self.stopped = True

    def crash(self) -> None:
        self.process.kill()

    def signal_node(self, signum: int) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signum)


class _FakeGraph:
    def __init__(self) -> None:
        self.gids = [b"old-controller", b"simulator-recorder"]

    def get_subscriptions_info_by_topic(self, topic: str):
        assert topic == "/clock"
        return [SimpleNamespace(endpoint_gid=list(gid)) for gid in self.gids]


@pytest.fixture
def injector(monkeypatch):
    monkeypatch.setattr(processes, "_Process", _FakeProcess)
    monkeypatch.setattr(processes, "RESTART_SETTLE", 0.05)
    procs = {"uav2_controller": _FakeProcess("uav2_controller"), "simulator": _FakeProcess("simulator")}
    graph = _FakeGraph()
    inj = _FaultInjector([ProcessFault("uav2_controller", 8.0, 2.0)], procs, {"uav2_controller": ["x"]}, "/tmp",
                         graph_node=graph)
    return inj, procs, graph


def test_the_simulation_holds_until_the_restarted_node_is_discovered(injector):
    inj, procs, graph = injector
    victim, simulator = procs["uav2_controller"], procs["simulator"].process
    inj(7.99)
    assert not victim.process.killed
    inj(8.0)
    assert victim.process.killed and simulator.signals == []
    inj(9.99)
    assert "uav2_controller" in procs and procs["uav2_controller"] is victim  # still the dead one
    inj(10.0)
    restarted = procs["uav2_controller"]
    assert restarted is not victim and victim.stopped and restarted.log_name == "uav2_controller.restarted"
    assert simulator.signals == [signal.SIGUSR1]
    assert [e[0] for e in inj.events] == ["killed uav2_controller", "restarted uav2_controller"]
    time.sleep(0.1)
    inj(10.0)
    assert simulator.signals == [signal.SIGUSR1]  # not READY yet
    restarted.ready.set()
    time.sleep(0.1)
    inj(10.0)
    assert simulator.signals == [signal.SIGUSR1]  # READY, but nobody has discovered it yet (same /clock GIDs)
    graph.gids.append(b"new-controller")
    inj(10.0)
    assert simulator.signals == [signal.SIGUSR1]  # discovered just now: RESTART_SETTLE for its other endpoints
    time.sleep(0.1)
    inj(10.0)
    assert simulator.signals == [signal.SIGUSR1, signal.SIGUSR2]
    inj(12.0)
    assert simulator.signals == [signal.SIGUSR1, signal.SIGUSR2]  # once


def test_a_restarted_process_that_dies_at_start_up_does_not_hold_the_world(injector):
    inj, procs, _graph = injector
    simulator = procs["simulator"].process
    inj(8.0)
    inj(10.0)
    procs["uav2_controller"].process.kill()  # crashed before READY
    inj(10.0)
    time.sleep(0.1)
    inj(10.0)
    assert simulator.signals == [signal.SIGUSR1, signal.SIGUSR2]


def test_a_restarted_process_never_discovered_is_let_go_at_the_limit_and_said_so(injector, monkeypatch):
    inj, procs, _graph = injector
    monkeypatch.setattr(processes, "RESTART_HOLD_LIMIT", 0.05)
    simulator = procs["simulator"].process
    inj(8.0)
    inj(10.0)
    procs["uav2_controller"].ready.set()  # READY, but its /clock subscription never shows up
    time.sleep(0.1)
    inj(10.0)
    assert simulator.signals == [signal.SIGUSR1]  # RESTART_SETTLE after the limit
    time.sleep(0.1)
    inj(10.0)
    assert simulator.signals == [signal.SIGUSR1, signal.SIGUSR2]
    assert inj.events[-1][0] == "hold released: uav2_controller not up after 0.05 s wall"


#: a node that reports the signals it gets (as the simulator does SIGUSR1 / SIGUSR2) and ends on SIGTERM
_NODE = """
import signal, sys, time
def on_signal(signum, frame):
    print(signal.Signals(signum).name, flush=True)
    if signum == signal.SIGTERM:
        sys.exit(0)
for s in (signal.SIGUSR1, signal.SIGUSR2, signal.SIGTERM):
    signal.signal(s, on_signal)
print("READY", flush=True)
while True:
    time.sleep(0.01)
"""
#: what ros2cli's ``ros2 run`` does: start the node as a child process and wait for it (Python's default actions
#: for SIGUSR1 / SIGTERM: the wrapper would end and leave the node running)
_WRAPPER = "import subprocess, sys; sys.exit(subprocess.call([sys.executable, '-c', sys.argv[1]]))"


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"  # a zombie has ended
    except OSError:
        return False


def _wait_for(predicate, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


@pytest.mark.parametrize("wrapped", [False, True], ids=["exec", "ros2cli-wrapper"])
def test_signals_reach_the_node_also_behind_a_ros2_run_wrapper(tmp_path, wrapped):
    """The fault injector's SIGUSR1 / SIGUSR2 reach the node, not a wrapper that would die of them; its crash
    kills the node and the wrapper (no orphan); a stop ends both through the node's SIGTERM."""
    import sys

    command = [sys.executable, "-c", _WRAPPER, _NODE] if wrapped else [sys.executable, "-c", _NODE]
    for ending in ("crash", "stop"):
        proc = processes._Process(f"node_{ending}", command, str(tmp_path))
        node = None
        try:
            assert proc.ready.wait(20.0)
            node = processes.node_pid(proc.process.pid)
            assert (node != proc.process.pid) == wrapped
            for signum in (signal.SIGUSR1, signal.SIGUSR2):  # one at a time: each handler prints a line
                proc.signal_node(signum)
                assert _wait_for(lambda p=proc, s=signum: p.lines[-1] == signal.Signals(s).name), proc.lines
            assert proc.process.poll() is None and _alive(node)  # the wrapper still waits for its node
            if ending == "crash":
                proc.crash()
                assert proc.process.wait(10.0) == -signal.SIGKILL
            else:
                proc.stop()
                assert proc.process.returncode == 0 and proc.lines[-1] == "SIGTERM"
            assert _wait_for(lambda n=node: not _alive(n)), "the node outlived its wrapper"
        finally:  # no process left behind, also when an assertion failed
            proc.crash()
            proc.process.wait(10.0)
            if node is not None and _alive(node):
                os.kill(node, signal.SIGKILL)
            if not proc.log.closed:
                proc.stop()
