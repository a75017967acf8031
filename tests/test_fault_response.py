"""Issue 12 acceptance in the default suite, on six flights of the fault matrix (multi-process graph, as on the
robot; asserting on the ground truth and on every SET_ATTITUDE_TARGET the emulated PX4s received):

- UAV 2's controller, px4_bridge or pose_estimator SIGKILLed mid-hover, not restarted: the swarm guard brings the
  robot down together — tilt < 30°, nobody climbs > 0.5 m, every PX4 disarmed within 15 s, touchdown < 1 m/s,
  never more than full thrust;
- the controller or the px4_bridge restarted 2 s later: it rejoins, and the robot holds hover;
- the simulator SIGKILLed (every PX4 gone at once, /clock stops): every bridge says "PX4 lost" after at most 0.6 s
  of silence on its link (its steady-clock watchdog; its /clock-driven checks stop with the clock).

The whole matrix (controller / px4_bridge / pose_estimator × dead / restarted after 2 s × 5 seeds, and the
simulator) is ``bash scripts/run_faults.sh --results docs/safety.md``: ~40 min, too long for this suite.
"""

from __future__ import annotations

import pytest
from fpr_experiments.faults import FaultCase, run_fault

#: (node, seed) of the flights: one seed each (the matrix flies five), different seeds across the cases
KILLED = [("controller", 0), ("px4_bridge", 1), ("pose_estimator", 2)]
RESTARTED = [("controller", 1), ("px4_bridge", 0)]


@pytest.fixture(scope="module", params=KILLED, ids=[node for node, _ in KILLED])
def node_killed(request, tmp_path_factory):
    node, seed = request.param
    return run_fault(FaultCase(node=node, uav=2, seed=seed), str(tmp_path_factory.mktemp(f"{node}_killed")),
                     log=False)


@pytest.fixture(scope="module", params=RESTARTED, ids=[node for node, _ in RESTARTED])
def node_restarted(request, tmp_path_factory):
    node, seed = request.param
    return run_fault(FaultCase(node=node, uav=2, restart_after=2.0, seed=seed),
                     str(tmp_path_factory.mktemp(f"{node}_restarted")), log=False)


@pytest.fixture(scope="module")
def simulator_killed(tmp_path_factory):
    return run_fault(FaultCase(node="simulator", at=3.0, after=2.0, seed=0),
                     str(tmp_path_factory.mktemp("simulator_killed")), log=False)


def test_a_dead_node_brings_the_robot_down_together(node_killed):
    result = node_killed
    m = result.metrics
    print(f"\n[faults] {result.case.label}: {m}")
    assert [e[0] for e in result.events] == [f"killed uav2_{result.case.node}"]
    assert result.errors == []
    assert m["max_tilt_deg"] < 30.0
    assert m["max_climb_m"] < 0.5
    # disarmed by PX4's land detector (landed), for good; NaN (some PX4 never disarmed) fails too
    assert m["all_disarmed_s"] <= 15.0
    assert m["touchdown_speed_mps"] < 1.0  # NaN (some UAV never came down to its landing gear) fails too
    assert m["hover_held"] == 0.0
    assert m["max_thrust_received"] <= 1.0  # normalized: 1 = f_max


def test_a_node_restarted_within_2_s_rejoins_and_the_robot_holds_hover(node_restarted):
    result = node_restarted
    m = result.metrics
    print(f"\n[faults] {result.case.label}: {m}")
    node = result.case.node
    assert [e[0] for e in result.events] == [f"killed uav2_{node}", f"restarted uav2_{node}"]
    assert result.errors == []
    assert m["max_tilt_deg"] < 30.0 and m["max_climb_m"] < 0.5
    assert m["hover_held"] == 1.0  # every PX4 armed in OFFBOARD again, level within 8°, height within 0.4 m
    assert m["max_thrust_received"] <= 1.0


def test_every_bridge_says_the_simulator_died_once_its_link_is_silent(simulator_killed):
    """Each bridge's wall watchdog (wall_silence_timeout 0.5 s, checked at 20 Hz) says "PX4 lost" once the last frame
    it read is 0.5 s old, and every bridge says it within 1 s of the kill on an unloaded machine (measured 0.51-0.55 s).
    A bridge process held off the CPU reads the frames the simulator sent before dying late, and its silence starts
    from there: on this project's 2-core CI VM two bridges said it 1.53 s after the kill, each after 0.5 s of
    silence (2026-12-07). The wall bound from the kill allows such a stall (2.5 s); the silence the bridges report is
    the watchdog's own timing and has no allowance."""
    m = simulator_killed.metrics
    print(f"\n[faults] {simulator_killed.case.label}: {m}")
    assert [e[0] for e in simulator_killed.events] == ["killed simulator"]
    for uav in (1, 2, 3):
        assert m[f"link_lost_silence_uav{uav}_s"] <= 0.6, uav  # 0.5 s + the 20 Hz check, printed to 0.1 s
        assert m[f"link_lost_uav{uav}_s"] < 2.5, uav
