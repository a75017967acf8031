"""Launch-free integration (DESIGN.md §7): the same experiment and seed flown by fpr_experiments' two runners —
the whole graph in ONE process, and as SEPARATE PROCESSES grouped as on the robot (one ``node_group`` per UAV and
one for the ground station, the simulator alone through ``ros2 run``) — agree on their flight metrics.

Experiment ``takeoff_landing`` with ``--quick`` (12 s: arm, fly, take off, climb 4 s at 0.3 m/s, hold). The two
runs are not identical (the simulator of the multi-process run paces itself at real-time factor 0.5 and its
processes do not share one executor's callback order), so the metrics must agree to within stated tolerances:
the climb height within 5 cm, the roll / pitch RMSEs within 0.5 deg and the leg RMSE within 0.3 deg, the
vertical-speed RMSE within 0.02 m/s, the tracking window within 0.5 s. Measured 2026-12-04, the one-process run
(deterministic) gives roll 0.52, pitch 0.53, legs 0.44 deg; five multi-process runs gave roll 0.41-0.74, pitch
0.52-0.86 (0.86 in CI, beside the other test session), legs 0.43-0.51 deg, height within 1 cm: the processes'
real latencies make the attitude errors a little larger and vary by +-0.2 deg from run to run, so the former 0.3 deg
on roll and pitch failed now and then; a broken runner (lost or late messages) costs degrees. The simulator of
the multi-process run starts once every node's /clock subscription is matched (its wait_for_clock_subscribers),
so no process misses the start. Assertions on metrics, never on wall time.
"""

from __future__ import annotations

import json
import math
import os

import pytest

from fpr_experiments import run_experiment

EXPERIMENT = "takeoff_landing"
SEED = 7
#: the runners are under test here, not the realism: flown on the ideal profile by name (the experiments' default is
#: hardware; with it this comparison failed on a fresh clone at stop 19, its tolerances being set on ideal flights)
REALISM = "ideal"
TOLERANCE = {"max_height_m": 0.05, "roll_rmse_deg": 0.5, "pitch_rmse_deg": 0.5, "legs_rmse_deg": 0.3,
             "vertical_speed_rmse": 0.02, "tracking_time_s": 0.5}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = str(tmp_path_factory.mktemp("reports"))
    one = run_experiment(EXPERIMENT, seed=SEED, quick=True, output_root=os.path.join(root, "one"), plots=False,
                         realism=REALISM)
    many = run_experiment(EXPERIMENT, seed=SEED, quick=True, processes=True, real_time_factor=0.5,
                          output_root=os.path.join(root, "many"), plots=False, realism=REALISM)
    return one.variants["communicating"], many.variants["communicating"]


def test_both_runs_complete_and_pass_their_checks(runs):
    for result in runs:
        assert result.completed and not result.callback_errors, result.callback_errors
        assert result.passed, [c.text() for c in result.checks if not c.passed]
        assert result.metrics["tracking_time_s"] > 4.0  # it flew


def test_the_processes_run_was_grouped_as_on_the_robot(runs):
    _, many = runs
    with open(os.path.join(many.report_dir, "graph.json"), encoding="utf-8") as stream:
        groups = sorted({node["group"] for node in json.load(stream)["nodes"]})
    assert groups == ["ground", "simulator", "uav1", "uav2", "uav3"]
    logs = os.path.join(many.report_dir, "logs")
    assert sorted(os.listdir(logs)) == ["ground.log", "simulator.log", "uav1.log", "uav2.log", "uav3.log"]
    for i in (1, 2, 3):
        with open(os.path.join(logs, f"uav{i}.log"), encoding="utf-8") as stream:
            log = stream.read()
        assert f"READY uav{i} 3 nodes" in log and "-> OFFBOARD" in log and "DISARM" not in log


@pytest.mark.parametrize("metric", sorted(TOLERANCE))
def test_in_process_and_multi_process_metrics_agree(runs, metric):
    one, many = runs
    a, b = one.metrics[metric], many.metrics[metric]
    print(f"[runners] {metric}: one process {a:.4f}, processes {b:.4f} (tolerance {TOLERANCE[metric]})")
    assert math.isfinite(a) and math.isfinite(b)
    assert abs(a - b) <= TOLERANCE[metric]
