"""Launch-free integration (DESIGN.md §7): decentralized impedance (mode ``impedance``, on-board LocalState +
the peers' ζ, Table 4.5 gains) picks up a 300 g payload in hover, is flown up by the operator with it, and
releases it (thesis §4.4.2 Scenario I, Fig. 4.14; issue: "sinks to the ground with the payload, flies away after
the release").

One flight in ONE process (fpr_experiments' description and in-process runner: simulator in lockstep, emulated
cameras, 3 × bridge / pose estimator / controller, teleop, joy_script), ~14 s simulated: ARM + FLY at once from
the hover scenario (1.5 m, legs 45°); payload attached at P at 3 s; hands off until 5.5 s; stick up (+0.3 m/s)
5.5-7 s; hands off; payload released at 9 s; hands off to the end. Metrics from the ground truth and the
controllers' wrench estimates, never sleeps.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from fpr_experiments.graph import GraphOptions, describe_graph
from fpr_experiments.inprocess import InProcessGraph
from fpr_experiments.recording import flight_record, recorded_topics

MASS = 0.3              # [kg]
WEIGHT = MASS * 9.81    # [N]
ATTACH, RELEASE = 3.0, 9.0
CLIMB = (5.5, 7.0)      # left stick up: +0.3 m/s
CLIMB_RATE = 0.3        # [m/s]
END = 14.0              # [s] simulated
LEG = 45.0              # [deg] legs of the hover scenario

SCENARIO = f"""name: payload_pickup_release
seed: 3
initial_state: {{mode: hover, position: [0.0, 0.0, 1.5], leg_angles: 0.7854, armed: true}}
payloads: [{{mass: {MASS}, attach_time: {ATTACH}, release_time: {RELEASE}}}]
"""
JOY_SCRIPT = f"""axes_count: 8
buttons_count: 11
loop: false
keyframes:
  - {{t: 0.0, axes: {{2: 1.0, 5: 1.0}}, buttons: {{0: 1}}}}
  - {{t: 0.2, buttons: {{0: 0}}}}
  - {{t: 0.4, buttons: {{2: 1}}}}
  - {{t: 0.6, buttons: {{2: 0}}}}
  - {{t: {CLIMB[0]}, axes: {{1: 1.0}}}}
  - {{t: {CLIMB[1]}, axes: {{1: 0.0}}}}
"""


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    folder = tmp_path_factory.mktemp("payload")
    scenario, script = folder / "payload_pickup_release.yaml", folder / "payload_hands_off_climb.yaml"
    scenario.write_text(SCENARIO)
    script.write_text(JOY_SCRIPT)
    specs = describe_graph(GraphOptions(mode="impedance", cameras="emulated", scenario=str(scenario),
                                        script=str(script)))
    wall_start = time.monotonic()
    with InProcessGraph(specs, recorded_topics(3)) as swarm:
        swarm.wait_for_discovery()

        def progress() -> None:
            truth = swarm.recorder.latest("/fpr/ground_truth")
            if truth is not None:
                print(f"[payload] t={swarm.sim_time:5.1f} s  wall={time.monotonic() - wall_start:5.1f} s  "
                      f"z={truth.platform_pose.position.z:.3f} m", flush=True)

        assert swarm.run_until(lambda: swarm.sim_time >= END, wall_timeout=180.0, progress=progress)
        assert swarm.wait_for_recorder()
        recording = swarm.recorder.snapshot()
        errors = list(swarm.errors)
    record = flight_record(recording, 3)
    truth = record.truth
    print(f"[payload] flight done in {time.monotonic() - wall_start:.1f} s wall", flush=True)
    yield {"truth": {"t": truth.t, "position": truth.position, "velocity": truth.velocity, "rpy": truth.rpy,
                     "legs": truth.legs, "finite": np.all(np.isfinite(truth.position), axis=1)},
           "wrench": {u.uav_id: {"t": u.wrench_t, "force": u.wrench_force} for u in record.uavs},
           "diagnostics": {i: recording.get(f"/fpr/uav{i}/controller_status") for i in (1, 2, 3)},
           "errors": errors, "n": 3}


def _window(truth, start, end):
    mask = (truth["t"] >= start) & (truth["t"] <= end)
    assert mask.sum() >= 10, f"too few samples in [{start}, {end}] s"
    return mask


def _z_at(truth, t):
    return float(np.interp(t, truth["t"], truth["position"][:, 2]))


def test_no_errors_and_impedance_without_fallback(flight):
    assert flight["errors"] == []
    for i, diagnostics in flight["diagnostics"].items():
        flying = [d for d in diagnostics if 1.0 <= d.header.stamp.sec + 1e-9 * d.header.stamp.nanosec <= END]
        assert len(flying) > 40 * (END - 1.0), f"uav {i}: diagnostics missing"
        assert {d.active_mode for d in flying} == {3} and not any(d.fallback_active for d in flying), \
            f"uav {i}: left the impedance mode"


def test_attitude_and_legs_stay_in_the_envelope(flight):
    """Roll and pitch well under 30° (here < 10°), legs within 12° of their 45° over the whole flight."""
    truth = flight["truth"]
    assert truth["finite"].all()
    rpy = np.degrees(np.abs(truth["rpy"][:, :2])).max()
    legs = np.abs(np.degrees(truth["legs"]) - LEG).max()
    print(f"[payload] worst |roll|,|pitch| {rpy:.1f} deg, worst leg deviation {legs:.1f} deg")
    assert rpy < 10.0
    assert legs < 12.0


def test_height_held_with_the_load_hands_off(flight):
    """The observer compensates the load (before: a steady sink −m g / B^d = −0.29 m/s onto the quadrotors): a
    bounded dip while the estimate converges, then the height holds."""
    truth = flight["truth"]
    z_attach = _z_at(truth, ATTACH)
    dip = z_attach - truth["position"][_window(truth, ATTACH, CLIMB[0]), 2].min()
    hold = truth["velocity"][_window(truth, CLIMB[0] - 1.0, CLIMB[0]), 2]
    print(f"[payload] dip {dip:.3f} m after the attachment; v_z {hold.mean():+.3f} m/s before the climb")
    assert dip < 0.6
    assert abs(hold.mean()) < 0.05


def test_operator_climb_tracked_with_the_load(flight):
    truth = flight["truth"]
    climbing = truth["velocity"][_window(truth, CLIMB[0] + 0.7, CLIMB[1]), 2]
    holding = truth["velocity"][_window(truth, RELEASE - 1.0, RELEASE), 2]
    print(f"[payload] climb v_z {climbing.mean():+.3f} m/s (command {CLIMB_RATE}), then {holding.mean():+.3f} m/s")
    assert climbing.mean() == pytest.approx(CLIMB_RATE, abs=0.08)
    assert abs(holding.mean()) < 0.05


def test_estimates_converge_to_the_load_on_every_uav(flight):
    """Fig. 4.14: f̂_pz,e → −m g on every UAV, with little difference between them."""
    estimates = []
    for i, w in flight["wrench"].items():
        mask = (w["t"] >= RELEASE - 1.0) & (w["t"] <= RELEASE)
        assert mask.sum() > 20, f"uav {i}: wrench estimates missing"
        estimates.append(w["force"][mask, 2].mean())
    print(f"[payload] f_hat_z with the load: {np.round(estimates, 2).tolist()} N (truth {-WEIGHT:.2f} N)")
    assert np.allclose(estimates, -WEIGHT, atol=0.4)
    assert np.ptp(estimates) < 0.3


def test_no_fly_away_after_the_release(flight):
    truth = flight["truth"]
    z_release = _z_at(truth, RELEASE)
    after = _window(truth, RELEASE, END)
    rise = truth["position"][after, 2].max() - z_release
    settled = truth["velocity"][_window(truth, END - 2.0, END), 2]
    print(f"[payload] rise {rise:.3f} m after the release; v_z {settled.mean():+.3f} m/s at the end")
    assert rise < 0.7
    assert abs(settled.mean()) < 0.05
    assert np.abs(truth["position"][after, :2] - truth["position"][after][0, :2]).max() < 0.5
