"""The fault injector's restart (fpr_experiments.processes._FaultInjector), with stand-in processes: the killed
group is SIGKILLed at its instant; at the restart the simulator is paused (SIGUSR1) and resumed (SIGUSR2) only once
the new process said READY, a /clock subscription that was not in the graph before shows up, and RESTART_SETTLE
passed."""

from __future__ import annotations

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
