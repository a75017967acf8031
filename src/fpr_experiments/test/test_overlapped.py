"""fpr_experiments.overlapped's failures: every one stops the run with one error naming the side that failed, and
leaves no simulator process behind. (Its flights, deterministic under load and one /clock period of latency away
from the one-process flight: tests/test_determinism.py.)"""

from __future__ import annotations

import os
import signal
from dataclasses import replace

import pytest
from fpr_experiments.graph import GraphOptions, describe_graph
from fpr_experiments.overlapped import OverlappedGraph, simulator_domain


def _specs(**simulator_parameters):
    specs = describe_graph(GraphOptions(n=3, mode="communicating", cameras="emulated", scenario="ground_start",
                                        script="integration_flight"))
    return [replace(s, parameters={**s.parameters, **simulator_parameters}) if s.executable == "simulator" else s
            for s in specs]


def test_the_simulator_process_is_in_another_ros_domain():
    for domain in (0, 1, 42, 100, 101, 232):
        assert simulator_domain(domain) != domain and 1 <= simulator_domain(domain) <= 101


def test_a_graph_without_exactly_one_simulator_is_refused():
    specs = _specs()
    with pytest.raises(ValueError, match="exactly one simulator"):
        OverlappedGraph([s for s in specs if s.executable != "simulator"])


def test_a_simulator_that_cannot_start_is_one_error_naming_its_cause():
    with pytest.raises(RuntimeError, match="simulator process failed: .*no parameter named no_such_parameter"):
        OverlappedGraph(_specs(no_such_parameter=1))


def test_a_dead_simulator_process_stops_the_run_with_its_exit_code():
    with OverlappedGraph(_specs(), watchdog=5.0) as graph:
        graph.wait_for_discovery()
        assert graph.run_until(lambda: graph.sim_time >= 0.5 - 1e-9, wall_timeout=60.0)
        process = graph.simulator.process
        os.kill(process.pid, signal.SIGKILL)
        process.wait(timeout=10.0)
        with pytest.raises(RuntimeError, match=r"simulator process (ended|is gone) \(exit code -9\)"):
            graph.run_until(lambda: graph.sim_time >= 5.0, wall_timeout=60.0)
    assert process.poll() is not None


def test_closing_the_graph_ends_the_simulator_process():
    with OverlappedGraph(_specs()) as graph:
        graph.wait_for_discovery()
        assert graph.run_until(lambda: graph.sim_time >= 0.2 - 1e-9, wall_timeout=60.0)
        process = graph.simulator.process
    assert process.wait(timeout=1.0) == 0
