"""Static feasibility margins and optimal leg angles of thesis Ch. 5 (spec §4.3, tests F1-F9)."""

import math

import numpy as np
import pytest
from fpr_model.dynamics import gravity
from fpr_model.kinematics import jacobian
from fpr_model.parameters import default_parameters
from fpr_model.polytope import convex_hull
from scipy.spatial import HalfspaceIntersection

from fpr_model import feasibility as fz
from fpr_model import geometry

PARAMS = default_parameters()
FLAT = (0.0, 0.0)
INCLINED = (math.radians(10.0), math.radians(25.0))

# Thesis Table 5.4 [DOC]: leg angle -> (flat F, flat M, inclined F, inclined M).
TABLE_5_4 = {15: (4.10, 2.42, 3.02, 1.78), 45: (8.22, 6.90, 7.07, 6.03), 75: (5.01, 4.99, 2.96, 3.04)}


@pytest.fixture(scope="module")
def ats():
    return fz.available_thrust_set()


def _margins(ats, orientation, theta_deg, params=PARAMS):
    return fz.feasibility_margins(params, ats, fz.platform_orientation_quat(*orientation), math.radians(theta_deg))


def _halfspaces_and_gravity(ats, orientation, theta):
    q = fz.equal_leg_configuration(PARAMS, fz.platform_orientation_quat(*orientation), theta)
    return fz.wrench_halfspaces(ats, jacobian(PARAMS, q).T), gravity(PARAMS, q)


# M6 prerequisite: the gravity wrench the margins use (spec §2.2.4) -------------------------------------------
def test_gravity_wrench_at_flat_45(ats):
    q = fz.equal_leg_configuration(PARAMS, fz.platform_orientation_quat(*FLAT), math.radians(45.0))
    w_g = gravity(PARAMS, q)
    np.testing.assert_allclose(
        w_g, [0, 0, 34.3448, 0.0734, 0.1357, 0, -7.5599, -7.7118, -7.6395], atol=1e-3
    )
    f_g = np.linalg.solve(jacobian(PARAMS, q).T, w_g)
    np.testing.assert_allclose(
        f_g, [-1.0931, 0, 11.3436, 0.5466, -0.9467, 11.5496, 0.5466, 0.9467, 11.4515], atol=1e-3
    )


# F1 -------------------------------------------------------------------------------------------------------
def _qp_margin(A, b, x_g):
    """Thesis Table 5.3 / (5.35): per facet j, min ‖x − x_g‖² s.t. a_jᵀx = b_j, solved from its KKT system."""
    best = np.inf
    for a, beta in zip(A, b, strict=True):
        kkt = np.block([[2.0 * np.eye(3), a[:, None]], [a[None, :], np.zeros((1, 1))]])
        x = np.linalg.solve(kkt, np.append(2.0 * x_g, beta))[:3]
        best = min(best, float((x - x_g) @ (x - x_g)))
    return math.sqrt(best)


def _hull_margin(A, b, x_g):
    """Independent: vertices of the slice by half-space intersection, their irredundant hull, min distance."""
    vertices = HalfspaceIntersection(np.column_stack([A, -b]), x_g).intersections
    hull = convex_hull(vertices)
    return float(np.min(hull.offsets - hull.normals @ x_g))


def test_f1_closed_form_equals_qp_and_hull_distance(ats):
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(12):
        orientation = tuple(rng.uniform(-0.5, 0.5, size=2))
        theta = rng.uniform(math.radians(15), math.radians(85))
        halfspaces, w_g = _halfspaces_and_gravity(ats, orientation, theta)
        margins = fz.static_margins(halfspaces, w_g)
        if not margins.feasible or min(margins.force, margins.moment) < 1e-3:
            continue
        for sl, expected in ((fz.force_slice(halfspaces, w_g), margins.force),
                             (fz.moment_slice(halfspaces, w_g), margins.moment)):
            assert sl.feasible
            assert _qp_margin(sl.normals, sl.offsets, sl.point) == pytest.approx(expected, rel=1e-9, abs=1e-9)
            assert _hull_margin(sl.normals, sl.offsets, sl.point) == pytest.approx(expected, rel=1e-7, abs=1e-7)
            # the ball of radius margin around the equilibrium is inside the slice; a bigger one is not
            directions = rng.normal(size=(200, 3))
            directions /= np.linalg.norm(directions, axis=1, keepdims=True)
            inner = sl.point + 0.999 * expected * directions
            assert np.all(inner @ sl.normals.T <= sl.offsets + 1e-9)
        checked += 1
    assert checked >= 6


# F2, F3, F4 ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("theta_deg", [45, 75])
def test_f2_table_5_4_at_45_and_75(ats, theta_deg):
    flat = _margins(ats, FLAT, theta_deg)
    inclined = _margins(ats, INCLINED, theta_deg)
    got = (flat.force, flat.moment, inclined.force, inclined.moment)
    np.testing.assert_allclose(got, TABLE_5_4[theta_deg], rtol=0.05)


def test_f3_table_5_4_at_15(ats):
    flat = _margins(ats, FLAT, 15)
    inclined = _margins(ats, INCLINED, 15)
    got = (flat.force, flat.moment, inclined.force, inclined.moment)
    np.testing.assert_allclose(got, TABLE_5_4[15], rtol=0.20)
    np.testing.assert_allclose(got, (3.45, 2.06, 2.65, 1.57), atol=0.01)  # [RECON] pinned regression


@pytest.mark.parametrize("orientation", [FLAT, INCLINED])
def test_f4_45_is_best_of_the_three(ats, orientation):
    m15, m45, m75 = (_margins(ats, orientation, t) for t in (15, 45, 75))
    assert m45.force > max(m15.force, m75.force)
    assert m45.moment > max(m15.moment, m75.moment)


def test_reference_curve_flat(ats):
    """Spec §2.9 reference curve (flat), 5°..85°, pinned to ±0.02."""
    angles = np.radians(np.arange(5, 90, 5))
    curve = fz.margin_curve(PARAMS, ats, fz.platform_orientation_quat(*FLAT), angles)
    force = [0, 1.00, 3.45, 6.08, 8.38, 8.52, 8.49, 8.33, 8.06, 7.71, 7.29, 6.80, 6.25, 5.63, 4.93, 4.13, 3.19]
    moment = [0, 0.58, 2.06, 3.76, 5.33, 6.08, 6.46, 6.68, 6.79, 6.79, 6.67, 6.45, 6.10, 5.60, 4.92, 4.03, 2.95]
    np.testing.assert_allclose(curve.force, force, atol=0.02)
    np.testing.assert_allclose(curve.moment, moment, atol=0.02)


def test_curve_matches_single_evaluations(ats):
    quat = fz.platform_orientation_quat(*INCLINED)
    curve = fz.margin_curve(PARAMS, ats, quat, np.radians([3.0, 20.0, 41.0, 88.0]))
    for theta, f, m in zip(curve.leg_angles, curve.force, curve.moment, strict=True):
        single = fz.feasibility_margins(PARAMS, ats, quat, theta)
        assert single.force == pytest.approx(f, abs=1e-12)
        assert single.moment == pytest.approx(m, abs=1e-12)


# F5, F6 ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "orientation, force_deg, force_margin, moment_deg, moment_margin",
    [(FLAT, 32, 8.66, 48, 6.92), (INCLINED, 32, 8.23, 41, 6.13)],
)
def test_f5_f6_optimal_leg_angles(ats, orientation, force_deg, force_margin, moment_deg, moment_margin):
    best = fz.optimal_leg_angles(PARAMS, ats, fz.platform_orientation_quat(*orientation))
    assert abs(math.degrees(best.force_angle) - force_deg) <= 2.0 + 1e-9
    assert abs(math.degrees(best.moment_angle) - moment_deg) <= 2.0 + 1e-9
    assert best.force_margin == pytest.approx(force_margin, rel=0.04)
    assert best.moment_margin == pytest.approx(moment_margin, rel=0.04)


# F7 -------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("orientation", [FLAT, INCLINED])
def test_f7_infeasible_below_8_degrees(ats, orientation):
    curve = fz.margin_curve(PARAMS, ats, fz.platform_orientation_quat(*orientation), np.radians(np.arange(1, 9)))
    assert not curve.feasible[:7].any()
    np.testing.assert_array_equal(curve.force[:7], 0.0)
    np.testing.assert_array_equal(curve.moment[:7], 0.0)
    assert curve.feasible[7] and curve.force[7] > 0 and curve.moment[7] > 0


def test_singular_leg_angle_gives_zero_not_nan(ats):
    curve = fz.margin_curve(PARAMS, ats, fz.platform_orientation_quat(*FLAT), np.array([0.0, 0.5]))
    assert curve.force[0] == 0.0 and curve.moment[0] == 0.0 and not curve.feasible[0]
    assert curve.feasible[1]
    assert fz.feasibility_margins(PARAMS, ats, fz.platform_orientation_quat(*FLAT), 0.0).force == 0.0


# F9 -------------------------------------------------------------------------------------------------------
def test_f9_wrong_anchor_angles_do_not_reproduce(ats, monkeypatch):
    """Negative control: the printed (2.7) layout 0/60/120° (E1) must NOT give Table 5.4."""
    monkeypatch.setattr(geometry, "leg_anchor_angles", lambda n: np.radians([0.0, 60.0, 120.0]))
    wrong = default_parameters()  # fresh object: its cached model constants use the patched layout
    got = []
    for theta in (15, 45, 75):
        for orientation in (FLAT, INCLINED):
            m = _margins(ats, orientation, theta, params=wrong)
            got += [m.force, m.moment]
    assert max(got) <= 0.95 + 0.01
    right = _margins(ats, FLAT, 45)
    assert right.force > 8.0  # the control really differs from the correct layout


# Bad input --------------------------------------------------------------------------------------------------
def test_n_not_3_is_refused(ats):
    params4 = default_parameters(4)
    with pytest.raises(ValueError, match="n = 3"):
        fz.margin_curve(params4, ats, fz.platform_orientation_quat(0.0, 0.0))
    with pytest.raises(ValueError, match="n = 3"):
        fz.feasibility_margins(params4, ats, fz.platform_orientation_quat(0.0, 0.0), 0.7)


def test_nan_leg_angles_are_refused(ats):
    with pytest.raises(ValueError):
        fz.margin_curve(PARAMS, ats, fz.platform_orientation_quat(0.0, 0.0), [0.5, float("nan")])
