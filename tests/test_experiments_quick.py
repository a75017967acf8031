"""Every experiment of fpr_experiments runs by name with ``--quick`` (shortened flights): each flight completes with
no callback error and passes its checks — the experiment's own thresholds on its flight metrics plus the ones
every flight must keep (roll and pitch under 30 deg, no UAV touching the ground unless landing, no fly-away, no
NaN). The full durations run through ``ros2 run fpr_experiments run all`` (docs/results.md). The quick run flies
each experiment's ``quick_variants`` (every controller mode, observer and task kind is flown by at least one);
assertions on metrics only, never on wall time.
"""

from __future__ import annotations

import json
import math
import os
import subprocess

import pytest
from fpr_experiments.catalog import DEFAULT_REALISM, experiment_names, load_experiment
from fpr_experiments.runner import run_experiment

#: the graph-regression flights fly the ideal profile by name (issue 11: "ideal kept for unit-level tests"); the
#: experiments' default, hardware, is validated by docs/results.md and docs/seed_spread.md (some of its full
#: flights fail their checks there, on purpose: the simulator is as hard to fly as the robot), and here by the demo
REGRESSION_REALISM = "ideal"


@pytest.mark.parametrize("name", experiment_names())
def test_experiment_runs_quick_and_passes_its_checks(name, tmp_path):
    experiment = load_experiment(name)
    variants = experiment.quick_variants or None
    result = run_experiment(name, quick=True, variants=variants, output_root=str(tmp_path), plots=False,
                            realism=REGRESSION_REALISM)
    assert set(result.variants) == set(variants or [v.id for v in experiment.variants])
    for variant_id, variant in result.variants.items():
        failed = [c.text() for c in variant.checks if not c.passed]
        assert variant.completed, f"{name}/{variant_id} did not complete"
        assert not variant.callback_errors, variant.callback_errors[:3]
        assert not failed, f"{name}/{variant_id}: {failed}"
        assert os.path.getsize(os.path.join(variant.report_dir, "flight.mcap")) > 10_000
        assert_mcap_shows_the_robot_in_3d(os.path.join(variant.report_dir, "flight.mcap"))
        assert all(math.isfinite(variant.metrics[m]) for m in ("max_abs_roll_deg", "max_height_m"))
    assert os.path.exists(os.path.join(result.report_dir, "metrics.json"))


def test_the_demo_flies_the_default_hardware_profile_and_passes_its_checks(tmp_path):
    """The demo (scripts/run_demo.sh: takeoff_landing) flies the experiments' default profile, hardware: model
    mismatch, thrust noise, sensor noise and latency, a lossy link; quick, deterministic (in-process runner)."""
    assert DEFAULT_REALISM == "hardware" and load_experiment("takeoff_landing").realism == "hardware"
    result = run_experiment("takeoff_landing", quick=True, output_root=str(tmp_path), plots=False)
    for variant_id, variant in result.variants.items():
        failed = [c.text() for c in variant.checks if not c.passed]
        assert variant.completed and not variant.callback_errors and not failed, f"{variant_id}: {failed}"
        assert variant.metrics["tracking_time_s"] > 4.0  # it flew
        with open(os.path.join(variant.report_dir, "metrics.json"), encoding="utf-8") as stream:
            report = json.load(stream)
        assert report["realism"]["profile"] == "hardware", report["realism"]


def _walk_to_world(parents: dict[str, str], frame: str) -> bool:
    for _ in range(16):
        if frame == "world":
            return True
        if frame not in parents:
            return False
        frame = parents[frame]
    return False


def assert_mcap_shows_the_robot_in_3d(path: str) -> None:
    """Issue 14: what Foxglove / RViz need from a report's MCAP. Every /tf message of the simulator's tree (a recorded
    instant) resolves world -> every uav<i>/base_link on its own, with no gap longer than 0.1 s between instants;
    /tf_static hangs each camera below its UAV; the estimators' frames hang below their UAV's body; the
    /robot_description URDF parses with ROS's URDF parser (urdf_parser_py) and has n legs and n UAVs."""
    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import String
    from tf2_msgs.msg import TFMessage
    from urdf_parser_py.urdf import URDF

    description, statics, instants, others = None, {}, [], {}
    with open(path, "rb") as stream:
        for _schema, channel, message in make_reader(stream).iter_messages(
                topics=["/tf", "/tf_static", "/robot_description"]):
            if channel.topic == "/robot_description":
                description = deserialize_message(message.data, String).data
                continue
            transforms = deserialize_message(message.data, TFMessage).transforms
            parents = {t.child_frame_id: t.header.frame_id for t in transforms}
            if channel.topic == "/tf_static":
                statics.update(parents)
            elif any(t.header.frame_id == "world" for t in transforms):
                stamp = transforms[0].header.stamp
                instants.append((stamp.sec + 1e-9 * stamp.nanosec, parents))
            else:
                others.update(parents)
    assert description is not None, "no /robot_description"
    robot = URDF.from_xml_string(description)
    links = {link.name for link in robot.links}
    n = sum(1 for name in links if name.startswith("leg") and name[3:].isdigit())
    assert n >= 3 and {f"uav{i}/base_link" for i in range(1, n + 1)} <= links, sorted(links)
    assert {f"leg{i}" for i in range(1, n + 1)} <= links and "platform" in links
    assert len(instants) > 10, f"only {len(instants)} /tf instants"
    times = [t for t, _ in instants]
    assert max(b - a for a, b in zip(times, times[1:], strict=False)) <= 0.1 + 1e-9
    for t, parents in instants:
        unresolved = [i for i in range(1, n + 1) if not _walk_to_world(parents, f"uav{i}/base_link")]
        assert not unresolved, f"t = {t:.3f} s: /tf does not resolve world -> uav{unresolved}"
    for i in range(1, n + 1):
        assert statics.get(f"uav{i}/camera_optical") == f"uav{i}/base_link", statics
    for child, parent in others.items():  # the estimators' platform_estimate frames
        assert child.endswith("/platform_estimate") and parent == child.split("/")[0] + "/base_link", (child, parent)


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ros2", "run", "fpr_experiments", *args], capture_output=True, text=True, timeout=120)


def test_list_shows_every_experiment():
    done = _cli("list")
    assert done.returncode == 0, done.stderr
    for name in experiment_names():
        assert name in done.stdout


def _experiment_file(tmp_path, **changes) -> str:
    import yaml

    data = {"id": "bad", "title": "a bad experiment", "scenario": "ground_start", "script": "integration_flight",
            "duration": 2.0, "quick_duration": 1.0, "variants": [{"id": "a"}], "metrics": [{"metric": "roll_rmse_deg"}],
            **changes}
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


@pytest.mark.parametrize("case, message", [
    ("unknown name", "error: unknown experiment 'table_9_9'; valid: "),
    ("unknown variant", "error: experiment 'table_3_2' has no variant 'lqr'; valid: "),
    ("missing file", "error: unknown experiment '/no/such/experiment.yaml'; valid: "),
    ("unknown scenario", "error: unknown scenario 'nowhere'; valid: "),
    ("bad mode", "error: mode 'bogus' is not one of centralized, "),
    ("bad node parameter", "error: node parameter max_thrust = -1.0 refused: Parameter max_thrust out of range"),
    ("unknown realism flag", "error: --realism: unknown realism profile 'rough'; profiles: ideal, hardware"),
    ("unknown realism key", "error: "),
])
def test_a_wrong_name_file_or_parameter_is_one_clear_line_and_a_non_zero_exit(case, message, tmp_path):
    args = {"unknown name": lambda: ("run", "table_9_9"),
            "unknown variant": lambda: ("run", "table_3_2", "--variant", "lqr"),
            "missing file": lambda: ("run", "/no/such/experiment.yaml"),
            "unknown scenario": lambda: ("run", _experiment_file(tmp_path, scenario="nowhere")),
            "bad mode": lambda: ("run", _experiment_file(tmp_path, mode="bogus"), "--output-dir", str(tmp_path)),
            "bad node parameter": lambda: ("run", _experiment_file(tmp_path, parameters={
                "controller": {"max_thrust": -1.0}}), "--output-dir", str(tmp_path)),
            "unknown realism flag": lambda: ("run", "table_3_2", "--realism", "rough"),
            "unknown realism key": lambda: ("run", _experiment_file(tmp_path, realism="rough"))}[case]()
    done = _cli(*args)
    assert done.returncode == 2, done.stdout[-2000:] + done.stderr[-2000:]
    lines = [line for line in done.stderr.strip().splitlines() if line and not line.startswith("[")]
    assert len(lines) == 1 and lines[0].startswith(message), done.stderr[-3000:]
    assert "Traceback" not in done.stderr + done.stdout
    if case.startswith("unknown realism"):
        assert lines[0].endswith("unknown realism profile 'rough'; profiles: ideal, hardware")


def test_a_bad_option_value_is_refused_by_the_parser():
    done = _cli("run", "table_3_2", "--cameras", "infrared")
    assert done.returncode == 2 and "invalid choice: 'infrared'" in done.stderr
