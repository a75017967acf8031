"""Results never depend on the machine's load: the same experiment and seed, flown twice by the deterministic
in-process runner (fpr_experiments.inprocess, one thread, fixed order: simulate a /clock period, drain the graph,
the bridges read their MAVLink, drain again), once on whatever this machine is doing and once with two CPU
burners (one busy process per core of the 2-core CI machine, at the same priority), give the same ground truth,
bit for bit: positions, attitudes, leg angles and thrusts at every sample. The controllers' setpoints agree to
1e-12 (measured: equal, or 7e-15 apart in a few runs out of ten: numpy / OpenBLAS SIMD kernels round small
reductions differently with the arrays' memory alignment, which varies with the heap); the MAVLink setpoint is
float32, which absorbs such differences (a float32 rounding flip would take a 1e-15 error at a 1e-7 boundary, about
one in ten thousand 10 s flights). Flight: the takeoff_landing experiment, first 10 s (arm, fly, OFFBOARD,
lift-off, climb). The sweep executor's one conversion per message (subscribers share one Python message) changes
nothing either: the same flight with a conversion per subscription ("sweep-copy", as rclpy does) gives the same
ground truth. Nor does the in-process delivery (fpr_experiments.intra_process, the default): the same flight with
every message through DDS ("sweep-dds") gives the same ground truth, and the loaded flight runs with the delivery's
check that no message changes after it was published (a publisher reusing its message, a subscriber modifying
what it received: the run raises). Nor do the overlap benchmark's options (the simulator's messages through DDS,
the per-period CPU measurement).
"""

from __future__ import annotations

import multiprocessing
import time

import numpy as np
import pytest
from fpr_experiments.catalog import load_experiment
from fpr_experiments.graph import describe_graph
from fpr_experiments.inprocess import InProcessGraph
from fpr_experiments.recording import flight_record, recorded_topics
from fpr_experiments.resources import SCENARIOS
from fpr_experiments.runner import graph_options

SECONDS = 10.0  # [s] simulated


def _burn(stop_at: float) -> None:
    x = 0
    while time.monotonic() < stop_at:
        x = (x * 1103515245 + 12345) % 2 ** 31


def _fly(executor: str | None = None, verify_delivery: bool = False, **runner_options) -> dict[str, np.ndarray]:
    experiment = load_experiment("takeoff_landing")
    variant = experiment.variants[0]
    specs = describe_graph(graph_options(experiment, variant, SCENARIOS.resolve(experiment.scenario), "emulated", 3))
    with InProcessGraph(specs, recorded_topics(3), deterministic=True, executor=executor,
                        verify_delivery=verify_delivery, **runner_options) as graph:
        graph.wait_for_discovery()
        assert graph.run_until(lambda: graph.sim_time >= SECONDS - 1e-9, wall_timeout=300.0)
        assert graph.wait_for_recorder()
        recording = graph.recorder.snapshot()
        assert graph.errors == []
        period_costs = np.array(graph.period_costs).reshape(-1, 3)
    truth = flight_record(recording, 3).truth
    setpoints = np.array([[m.header.stamp.sec, m.header.stamp.nanosec, m.attitude.w, m.attitude.x, m.attitude.y,
                           m.attitude.z, m.thrust] for i in (1, 2, 3) for m in recording.get(f"/fpr/uav{i}/setpoint")])
    return {"t": truth.t, "position": truth.position, "quat": truth.quat, "legs": truth.legs,
            "thrusts": truth.thrusts, "uav_positions": truth.uav_positions, "setpoints": setpoints,
            "period_costs": period_costs}


@pytest.fixture(scope="module")
def flights():
    quiet = _fly()
    stop_at = time.monotonic() + 600.0
    burners = [multiprocessing.Process(target=_burn, args=(stop_at,), daemon=True)
               for _ in range(max(2, multiprocessing.cpu_count()))]
    for burner in burners:
        burner.start()
    try:
        start = time.monotonic()
        loaded = _fly(verify_delivery=True)
        print(f"\n[determinism] loaded flight: {SECONDS:.0f} s simulated in {time.monotonic() - start:.1f} s wall "
              f"with {len(burners)} CPU burners", flush=True)
    finally:
        for burner in burners:
            burner.terminate()
        for burner in burners:
            burner.join(timeout=5.0)
    return quiet, loaded


def test_both_recordings_are_complete(flights):
    for flight in flights:
        t = flight["t"]
        print(f"[determinism] {len(t)} ground-truth samples from {t[0]:.3f} to {t[-1]:.3f} s; missing: "
              f"{sorted(set(np.round(np.arange(0.01, SECONDS + 1e-9, 0.01), 3)) - set(np.round(t, 3)))[:10]}")
        assert len(t) == round(100 * SECONDS)  # 100 Hz ground truth, none lost by the recorder


@pytest.mark.parametrize("key", ["position", "quat", "legs", "thrusts", "uav_positions"])
def test_same_seed_same_ground_truth_bit_for_bit_under_load(flights, key):
    quiet, loaded = flights
    assert quiet[key].shape == loaded[key].shape
    assert np.array_equal(quiet[key], loaded[key]), f"{key}: max difference {np.abs(quiet[key] - loaded[key]).max()}"


def test_same_setpoints_under_load(flights):
    quiet, loaded = flights
    assert quiet["setpoints"].shape == loaded["setpoints"].shape and len(quiet["setpoints"]) > 1000
    assert np.array_equal(quiet["setpoints"][:, :2], loaded["setpoints"][:, :2])  # same stamps, same order
    np.testing.assert_allclose(quiet["setpoints"], loaded["setpoints"], rtol=0.0, atol=1e-12)


def _assert_same_flight(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    """The same ground truth bit for bit, the same setpoints to 1e-12 (see the module doc)."""
    for key in ("position", "quat", "legs", "thrusts", "uav_positions"):
        assert np.array_equal(a[key], b[key]), f"{key}: max difference {np.abs(a[key] - b[key]).max()}"
    np.testing.assert_allclose(a["setpoints"], b["setpoints"], rtol=0.0, atol=1e-12)


def test_the_flight_took_off(flights):
    quiet, _ = flights
    assert quiet["position"][:, 2].max() > quiet["position"][0, 2] + 0.5


def test_sharing_one_message_among_subscribers_changes_nothing(flights):
    quiet, _ = flights
    _assert_same_flight(quiet, _fly(executor="sweep-copy"))


def test_in_process_delivery_changes_nothing(flights):
    quiet, _ = flights
    _assert_same_flight(quiet, _fly(executor="sweep-dds"))


def test_simulator_messages_through_dds_and_period_measurement_change_nothing(flights):
    """benchmarks/bench_graph.py --overlap: the simulator's messages crossing DDS (as from a process of its own) and
    the per-period CPU measurement leave the flight as it is; one (time, simulator CPU, graph CPU) per /clock
    period (100 Hz)."""
    quiet, _ = flights
    measured = _fly(simulator_through_dds=True, measure_periods=True)
    _assert_same_flight(quiet, measured)
    costs = measured["period_costs"]
    assert len(quiet["period_costs"]) == 0
    assert len(costs) == round(100 * SECONDS)
    np.testing.assert_allclose(costs[:, 0], np.arange(1, len(costs) + 1) * 0.01, atol=1e-9)
    assert np.all(costs[:, 1:] >= 0.0) and costs[:, 1].sum() > 0.0 and costs[:, 2].sum() > 0.0
