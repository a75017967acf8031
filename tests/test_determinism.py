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
what it received: the run raises). Nor does the overlap benchmark's per-period CPU measurement, nor keeping the
graph's objects out of the garbage collector's full collections (``gc.freeze``, InProcessGraph's default). The
overlapped two-process layout (fpr_experiments.overlapped) is deterministic under load too, and one /clock period
of control latency away from the one-process flight.
"""

from __future__ import annotations

import gc
import multiprocessing
import time

import numpy as np
import pytest
from fpr_experiments.catalog import load_experiment
from fpr_experiments.graph import describe_graph
from fpr_experiments.inprocess import InProcessGraph
from fpr_experiments.overlapped import OverlappedGraph
from fpr_experiments.recording import flight_record, recorded_topics
from fpr_experiments.resources import SCENARIOS
from fpr_experiments.runner import graph_options

SECONDS = 10.0  # [s] simulated


def _burn(stop_at: float) -> None:
    x = 0
    while time.monotonic() < stop_at:
        x = (x * 1103515245 + 12345) % 2 ** 31


def _fly(executor: str | None = None, verify_delivery: bool = False, overlapped: bool = False,
         **runner_options) -> dict[str, np.ndarray]:
    experiment = load_experiment("takeoff_landing")
    variant = experiment.variants[0]
    specs = describe_graph(graph_options(experiment, variant, SCENARIOS.resolve(experiment.scenario), "emulated", 3))
    if overlapped:
        graph = OverlappedGraph(specs, recorded_topics(3), verify_delivery=verify_delivery, **runner_options)
    else:
        graph = InProcessGraph(specs, recorded_topics(3), deterministic=True, executor=executor,
                               verify_delivery=verify_delivery, **runner_options)
    with graph:
        graph.wait_for_discovery()
        assert graph.run_until(lambda: graph.sim_time >= SECONDS - 1e-9, wall_timeout=300.0)
        assert graph.wait_for_recorder()
        recording = graph.recorder.snapshot()
        assert graph.errors == []
        period_costs = np.array(graph.period_costs).reshape(-1, 3)
        frozen_in_flight = gc.get_freeze_count()
    frozen_after_close = gc.get_freeze_count()
    truth = flight_record(recording, 3).truth
    setpoints = np.array([[m.header.stamp.sec, m.header.stamp.nanosec, m.attitude.w, m.attitude.x, m.attitude.y,
                           m.attitude.z, m.thrust] for i in (1, 2, 3) for m in recording.get(f"/fpr/uav{i}/setpoint")])
    return {"t": truth.t, "position": truth.position, "quat": truth.quat, "legs": truth.legs,
            "thrusts": truth.thrusts, "uav_positions": truth.uav_positions, "setpoints": setpoints,
            "period_costs": period_costs, "frozen": np.array([frozen_in_flight, frozen_after_close])}


def _quiet_and_loaded(overlapped: bool = False) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The flight on whatever the machine is doing, then with a CPU burner per core (and the in-process delivery's
    check that no message changes after it was published)."""
    quiet = _fly(overlapped=overlapped)
    stop_at = time.monotonic() + 600.0
    burners = [multiprocessing.Process(target=_burn, args=(stop_at,), daemon=True)
               for _ in range(max(2, multiprocessing.cpu_count()))]
    for burner in burners:
        burner.start()
    try:
        start = time.monotonic()
        loaded = _fly(verify_delivery=True, overlapped=overlapped)
        print(f"\n[determinism] loaded flight{' (overlapped layout)' if overlapped else ''}: {SECONDS:.0f} s "
              f"simulated in {time.monotonic() - start:.1f} s wall with {len(burners)} CPU burners", flush=True)
    finally:
        for burner in burners:
            burner.terminate()
        for burner in burners:
            burner.join(timeout=5.0)
    return quiet, loaded


@pytest.fixture(scope="module")
def flights():
    return _quiet_and_loaded()


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


def test_period_measurement_changes_nothing(flights):
    """benchmarks/bench_graph.py --overlap: the per-period CPU measurement leaves the flight as it is; one (time,
    simulator CPU, graph CPU) per /clock period (100 Hz)."""
    quiet, _ = flights
    measured = _fly(measure_periods=True)
    _assert_same_flight(quiet, measured)
    costs = measured["period_costs"]
    assert len(quiet["period_costs"]) == 0
    assert len(costs) == round(100 * SECONDS)
    np.testing.assert_allclose(costs[:, 0], np.arange(1, len(costs) + 1) * 0.01, atol=1e-9)
    assert np.all(costs[:, 1:] >= 0.0) and costs[:, 1].sum() > 0.0 and costs[:, 2].sum() > 0.0


def test_keeping_the_heap_from_the_garbage_collector_changes_nothing(flights):
    """InProcessGraph freezes the collector's view of the graph's objects (and, each simulated second, of the
    growing recording) and gives them back at close; without it, the same flight."""
    quiet, _ = flights
    frozen_in_flight, frozen_after_close = quiet["frozen"]
    assert frozen_in_flight > 100_000 and frozen_after_close == 0
    unfrozen = _fly(freeze_heap=False)
    assert list(unfrozen["frozen"]) == [0, 0]
    _assert_same_flight(quiet, unfrozen)


# ---- the overlapped two-process layout (fpr_experiments.overlapped) ---------------------------------------------
@pytest.fixture(scope="module")
def overlapped_flights():
    return _quiet_and_loaded(overlapped=True)


def test_overlapped_layout_same_flight_under_load(overlapped_flights):
    """The simulator's process and the graph's run in parallel; what each reads of the other is fixed by the
    period messages and the datagram counts, not by their timing."""
    quiet, loaded = overlapped_flights
    assert len(quiet["t"]) == round(100 * SECONDS)
    _assert_same_flight(quiet, loaded)


def test_overlapped_layout_is_the_same_flight_with_one_period_of_latency(flights, overlapped_flights):
    """Not the one-process flight (the setpoints act one /clock period later), but the same take-off and climb: the
    same setpoint stamps (the controllers run on the same /clock), the platform within 5 cm and the legs within 1
    deg of the one-process flight at every sample."""
    one_process, _ = flights
    overlapped, _ = overlapped_flights
    assert one_process["t"].shape == overlapped["t"].shape
    assert not np.array_equal(one_process["position"], overlapped["position"])
    assert np.array_equal(one_process["setpoints"][:, :2], overlapped["setpoints"][:, :2])
    position_gap = np.abs(one_process["position"] - overlapped["position"]).max()
    legs_gap = np.degrees(np.abs(one_process["legs"] - overlapped["legs"]).max())
    print(f"\n[determinism] overlapped vs one process: platform {100 * position_gap:.2f} cm, legs {legs_gap:.3f} deg "
          "apart at most")
    assert position_gap < 0.05 and legs_gap < 1.0
