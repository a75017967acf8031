"""Teleoperation leg-angle limits, the orientation grid (F8), general n, and the report command."""

import math

import numpy as np
import pytest
from fpr_model.kinematics import jacobian
from fpr_model.parameters import default_parameters

from fpr_model import feasibility as fz
from fpr_model import feasibility_cli

PARAMS = default_parameters()


@pytest.fixture(scope="module")
def ats():
    return fz.available_thrust_set()


@pytest.fixture(autouse=True)
def fresh_cache():
    fz.clear_leg_angle_range_cache()
    yield
    fz.clear_leg_angle_range_cache()


# feasible_leg_angle_range ------------------------------------------------------------------------------------
@pytest.mark.parametrize("roll_deg, pitch_deg", [(0.0, 0.0), (10.0, 25.0)])
def test_range_endpoints_bracket_the_thresholds(ats, roll_deg, pitch_deg):
    roll, pitch = math.radians(roll_deg), math.radians(pitch_deg)
    min_force, min_moment = 6.0, 5.0
    lo, hi = fz.feasible_leg_angle_range(PARAMS, roll, pitch, min_force, min_moment)
    assert math.radians(10) < lo < hi < math.radians(80)
    quat = fz.platform_orientation_quat(roll, pitch)
    inside = fz.margin_curve(PARAMS, ats, quat, np.linspace(lo + 1e-3, hi - 1e-3, 25))
    assert np.all(inside.force >= min_force - 0.02) and np.all(inside.moment >= min_moment - 0.02)
    outside = fz.margin_curve(PARAMS, ats, quat, np.array([lo - math.radians(1.0), hi + math.radians(1.0)]))
    assert np.all(np.minimum(outside.force - min_force, outside.moment - min_moment) < 0)


def test_range_zero_thresholds_is_the_feasible_region():
    lo, hi = fz.feasible_leg_angle_range(PARAMS, 0.0, 0.0, 0.0, 0.0)
    assert math.radians(7.0) <= lo <= math.radians(8.0)  # F7: infeasible below 8°
    assert hi == pytest.approx(math.radians(89.0))


def test_range_none_when_nothing_qualifies():
    assert fz.feasible_leg_angle_range(PARAMS, 0.0, 0.0, 9.0, 0.0) is None  # best force margin is 8.53 N
    assert fz.feasible_leg_angle_range(PARAMS, 0.0, 0.0, 0.0, 7.0) is None  # best moment margin is 6.80 N·m


def test_range_is_cached_per_orientation_cell():
    first = fz.feasible_leg_angle_range(PARAMS, 0.1, 0.2, 5.0, 4.0)
    cached = dict(fz._CURVE_CACHE)
    again = fz.feasible_leg_angle_range(PARAMS, 0.1 + 1e-4, 0.2, 5.0, 4.0)  # same 1° cell
    assert again == first and dict(fz._CURVE_CACHE).keys() == cached.keys()
    other_thresholds = fz.feasible_leg_angle_range(PARAMS, 0.1, 0.2, 7.0, 4.0)  # thresholds: no recomputation
    assert len(fz._CURVE_CACHE) == 1 and other_thresholds[1] - other_thresholds[0] < first[1] - first[0]
    fz.feasible_leg_angle_range(PARAMS, 0.3, 0.2, 5.0, 4.0)
    assert len(fz._CURVE_CACHE) == 2


def test_range_bad_input():
    for bad in (float("nan"), float("inf")):
        with pytest.raises(ValueError):
            fz.feasible_leg_angle_range(PARAMS, bad, 0.0, 1.0, 1.0)
        with pytest.raises(ValueError):
            fz.feasible_leg_angle_range(PARAMS, 0.0, 0.0, bad, 1.0)
    with pytest.raises(ValueError):
        fz.feasible_leg_angle_range(PARAMS, 0.0, 0.0, 1.0, 1.0, leg_angle_step=0.0)
    with pytest.raises(ValueError, match="n = 3"):
        fz.feasible_leg_angle_range(default_parameters(4), 0.0, 0.0, 1.0, 1.0)


def test_qualifying_range_takes_the_largest_run():
    angles = np.radians(np.arange(1.0, 11.0))
    force = np.array([0, 5, 5, 0, 5, 5, 5, 5, 0, 0], dtype=float)
    curve = fz.MarginCurve(angles, force, np.full(10, 9.0), np.ones(10, dtype=bool))
    lo, hi = fz.qualifying_range(curve, 2.5, 1.0)
    # run 5°..8°, ends interpolated half-way to the failing neighbours (excess +2.5 -> -2.5)
    assert math.degrees(lo) == pytest.approx(4.5) and math.degrees(hi) == pytest.approx(8.5)


# F8 -------------------------------------------------------------------------------------------------------
def test_f8_orientation_grid(ats):
    angles = np.radians(np.arange(0.0, 90.0 + 1e-9, 5.0))
    grid = fz.orientation_grid(PARAMS, ats, angles, angles)
    assert np.unravel_index(np.argmax(grid.force_margin), grid.force_margin.shape) == (0, 0)
    assert np.unravel_index(np.argmax(grid.moment_margin), grid.moment_margin.shape) == (0, 0)
    force_deg, moment_deg = np.degrees(grid.force_angle), np.degrees(grid.moment_angle)
    assert force_deg.min() >= 28 - 3 - 1e-9 and force_deg.max() <= 45 + 3 + 1e-9
    assert moment_deg.min() >= 35 - 3 - 1e-9 and moment_deg.max() <= 55 + 3 + 1e-9
    assert grid.force_margin.min() >= 7.0 and grid.moment_margin.min() >= 5.0
    # [RECON] regression: extremes of the grid
    assert (force_deg.min(), force_deg.max(), moment_deg.min(), moment_deg.max()) == pytest.approx((28, 47, 36, 55))
    assert grid.force_margin.min() == pytest.approx(7.64, abs=0.01)
    assert grid.moment_margin.min() == pytest.approx(5.53, abs=0.01)


# General n --------------------------------------------------------------------------------------------------
def test_decomposed_sets_for_four_legs(ats):
    params4 = default_parameters(4)
    q = fz.equal_leg_configuration(params4, fz.platform_orientation_quat(0.0, 0.0), math.radians(45))
    W = jacobian(params4, q).T
    assert W.shape == (10, 12)
    sets = fz.decomposed_wrench_sets(ats, W)
    assert sets.force.volume == pytest.approx(64.0 * ats.polytope.volume, rel=1e-9)  # 4·ATS, volume × 4³
    assert sets.leg_moment is None and sets.leg_moment_bounds.shape == (4, 2)
    assert sets.platform_moment.n_vertices > 0
    with pytest.raises(ValueError, match="square"):
        fz.wrench_halfspaces(ats, W)


# Command --------------------------------------------------------------------------------------------------
def test_cli_quick_writes_tables_and_plots(tmp_path, capsys):
    assert feasibility_cli.main(["--output-dir", str(tmp_path), "--quick"]) == 0
    out = capsys.readouterr().out
    assert "Table 5.1" in out and "Table 5.2" in out and "Table 5.4" in out
    assert "170" in out and "8.06 (8.22)" in out
    for name in ("summary.json", "margin_vs_leg_angle.png", "optimal_leg_angles_grid.png"):
        assert (tmp_path / name).stat().st_size > 1000
    import json

    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["table_5_2"]["M_p"] == {"vertices": 170, "facets": 150}
    assert summary["optima"]["flat"]["moment_angle_deg"] == pytest.approx(48.0)


def test_cli_rejects_bad_arguments(tmp_path, capsys):
    assert feasibility_cli.main(["--output-dir", str(tmp_path), "--grid-step", "0"]) == 2
    assert feasibility_cli.main(["--output-dir", str(tmp_path), "--parameters", str(tmp_path / "missing.yaml")]) == 2
    assert not (tmp_path / "summary.json").exists()
