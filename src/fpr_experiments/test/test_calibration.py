"""The calibration driver (ROS-free parts): score, overrides, knobs file, coordinate search, report."""

import math

import pytest
from fpr_experiments.calibration import (
    CALIBRATION_SET,
    Evaluation,
    Knob,
    calibration_markdown,
    coordinate_search,
    geometric_rms_error,
    load_knobs,
    nested_overrides,
)


def test_geometric_rms_error():
    assert geometric_rms_error([1.0, 1.0]) == pytest.approx(1.0)
    assert geometric_rms_error([2.0, 0.5]) == pytest.approx(2.0)      # a factor 2 either way is a factor 2
    assert geometric_rms_error([4.0]) == pytest.approx(4.0)
    assert geometric_rms_error([]) == math.inf
    assert geometric_rms_error([1.0, 0.0]) == math.inf
    assert geometric_rms_error([1.0, math.nan]) == math.inf


def test_nested_overrides():
    assert nested_overrides({"actuation.thrust_noise": 0.02, "actuation.motor_spread": 0.03, "seed": 4}) == {
        "actuation": {"thrust_noise": 0.02, "motor_spread": 0.03}, "seed": 4}
    with pytest.raises(ValueError, match="collides"):
        nested_overrides({"a": 1, "a.b": 2})


def test_load_knobs(tmp_path):
    good = tmp_path / "k.yaml"
    good.write_text("knobs:\n  - {key: sensors.gyro_noise, values: [0.001, 0.003], note: datasheet}\n")
    assert load_knobs(str(good)) == [Knob("sensors.gyro_noise", [0.001, 0.003], "datasheet")]
    bad = tmp_path / "bad.yaml"
    bad.write_text("knobs:\n  - {key: sensors.gyro_noise}\n")
    with pytest.raises(ValueError, match="non-empty 'values'"):
        load_knobs(str(bad))
    with pytest.raises(ValueError, match="no knobs"):
        (tmp_path / "empty.yaml").write_text("{}\n")
        load_knobs(str(tmp_path / "empty.yaml"))


def _fake_evaluator(target: dict[str, float], flown: list[dict]):
    """Ratios = 1 + distance of each knob from its target: the optimum is the target."""

    def evaluate(assignment):
        flown.append(assignment)
        ratios = {f"x/y/{k}": 1.0 + abs(assignment[k] - v) for k, v in target.items()}
        return Evaluation(assignment, ratios=ratios, ours=dict(ratios), thesis={k: 1.0 for k in ratios})

    return evaluate


def test_coordinate_search_finds_the_separable_optimum_and_never_reflies():
    knobs = [Knob("a", [0.0, 1.0, 2.0]), Knob("b", [5.0, 3.0])]
    flown: list[dict] = []
    best, history = coordinate_search(knobs, _fake_evaluator({"a": 2.0, "b": 3.0}, flown), rounds=2)
    assert best.assignment == {"a": 2.0, "b": 3.0}
    assert best.score == pytest.approx(1.0)
    assert len({tuple(sorted(a.items())) for a in flown}) == len(flown) == len(history)


def test_a_failed_flight_never_wins():
    failed = Evaluation({"a": 1}, ratios={"x": 1.0}, failures=["table_3_2/impedance seed 0: flipped"])
    assert failed.score == math.inf


def test_markdown_names_the_calibration_set_and_every_evaluation():
    knobs = [Knob("a", [0.0, 1.0])]
    history = [Evaluation({"a": 0.0}, ratios={"table_3_2/impedance/roll_rmse_deg": 0.1},
                          ours={"table_3_2/impedance/roll_rmse_deg": 0.46},
                          thesis={"table_3_2/impedance/roll_rmse_deg": 4.6}),
               Evaluation({"a": 1.0}, ratios={"table_3_2/impedance/roll_rmse_deg": 0.9},
                          ours={"table_3_2/impedance/roll_rmse_deg": 4.1},
                          thesis={"table_3_2/impedance/roll_rmse_deg": 4.6})]
    text = calibration_markdown(knobs, history, history[1], [0], "ros2 run fpr_experiments calibrate", "abc1234")
    for experiment, variant in CALIBRATION_SET:
        assert f"`{experiment}` / `{variant}`" in text
    assert "×0.1" in text and "×0.9" in text and "**best**" in text
    assert "a: 1.0" in text   # the chosen values, as written to 90_calibrated.yaml


def test_only_safety_checks_disqualify():
    from fpr_experiments.calibration import safety_failures

    failed = ["roll_rmse_deg = 5.2 (<= 5): FAILED", "ground_contacts = 1 (<= 0): FAILED",
              "uav1.detection_rate_pct = 40 (>= 50): FAILED", "max_abs_roll_deg = 45 (<= 30): FAILED"]
    assert safety_failures(failed) == ["ground_contacts = 1 (<= 0): FAILED", "max_abs_roll_deg = 45 (<= 30): FAILED"]
