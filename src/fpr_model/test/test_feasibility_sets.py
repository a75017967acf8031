"""ATS and AWS of thesis Ch. 5 (spec §4.2, tests A1-A9)."""

import math

import numpy as np
import pytest
from fpr_model.kinematics import jacobian
from fpr_model.parameters import default_parameters
from fpr_model.polytope import convex_hull
from scipy.optimize import linprog
from scipy.spatial import Delaunay

from fpr_model import feasibility as fz

PARAMS = default_parameters()


@pytest.fixture(scope="module")
def ats17():
    return fz.available_thrust_set(25.0, math.radians(35.0), 12, 38)


@pytest.fixture(scope="module")
def ats38():
    return fz.available_thrust_set(25.0, math.radians(35.0), 24, 165)


def _wrench_matrix(roll, pitch, theta):
    q = fz.equal_leg_configuration(PARAMS, fz.platform_orientation_quat(roll, pitch), theta)
    return jacobian(PARAMS, q).T


# A1 -------------------------------------------------------------------------------------------------------
def test_a1_vertex_counts_and_canonical_points(ats17, ats38):
    assert ats17.vertices.shape == (17, 3)
    assert ats38.vertices.shape == (38, 3)
    cap = ats17.vertices[13:]
    assert cap.shape == (4, 3)
    polar = np.degrees(np.arccos(cap[:, 2] / np.linalg.norm(cap, axis=1)))
    np.testing.assert_allclose(polar, 18.0, atol=1e-9)  # one ring at ϑ = 18° (Deserno, N = 38)
    np.testing.assert_allclose(cap[:, 2], 23.7764, atol=1e-4)
    np.testing.assert_allclose(ats17.vertices[1:13, 2], 20.4788, atol=1e-4)
    np.testing.assert_allclose(np.hypot(*ats17.vertices[1:13, :2].T), 14.3394, atol=1e-4)
    cap38 = ats38.vertices[25:]
    polar38 = np.sort(np.degrees(np.arccos(cap38[:, 2] / 25.0)))
    np.testing.assert_allclose(polar38[:3], 8.18, atol=0.01)
    np.testing.assert_allclose(polar38[3:], 24.55, atol=0.01)


def test_a1_deserno_radius_independent():
    # E3: on the unit sphere; the count must be near N (with r = f_max the text's version collapses to 0 rings).
    polar, _ = fz.deserno_sphere_points(1000)
    assert abs(polar.size - 1000) < 30


# A2, A3, A4 -----------------------------------------------------------------------------------------------
def test_a2_theoretical_volume():
    assert fz.ats_theoretical_volume(25.0, math.radians(35.0)) == pytest.approx(5918.24, abs=0.01)


def test_a3_precision(ats17, ats38):
    assert ats17.precision == pytest.approx(0.903, abs=0.005)
    assert ats38.precision == pytest.approx(0.964, abs=0.005)
    assert ats17.polytope.volume == pytest.approx(5352.76, abs=0.01)  # [RECON] regression


def test_a4_facet_counts_informational(ats17, ats38):
    # Table 5.1 reports 30 half-spaces = the triangulated count; merged coplanar facets: 25 [RECON].
    assert ats17.polytope.n_triangulated_facets == 30
    assert ats17.polytope.n_facets == 25
    assert ats38.polytope.n_facets == 72


# A5, A6 ---------------------------------------------------------------------------------------------------
def test_a5_hrep_matches_vrep(ats17):
    rng = np.random.default_rng(5)
    points = rng.uniform([-16, -16, -1], [16, 16, 26], size=(4000, 3))
    by_h = points @ ats17.normals.T - ats17.offsets  # signed slack per facet
    margin = np.max(by_h, axis=1)
    clear = np.abs(margin) > 1e-9
    inside_h = margin <= 0
    inside_v = Delaunay(ats17.vertices).find_simplex(points) >= 0
    assert clear.sum() > 3900
    assert 500 < inside_h[clear].sum() < 3500  # both classes are represented
    np.testing.assert_array_equal(inside_h[clear], inside_v[clear])


@pytest.mark.parametrize("n_cone, n_sphere", [(12, 38), (24, 165)])
def test_a6_discrete_ats_inside_continuous(n_cone, n_sphere):
    ats = fz.available_thrust_set(25.0, math.radians(35.0), n_cone, n_sphere)
    v = ats.vertices
    norms = np.linalg.norm(v, axis=1)
    assert np.all(norms <= 25.0 + 1e-9)
    assert np.all(norms * math.cos(math.radians(35.0)) <= v[:, 2] + 1e-9)  # (5.7) cone


def test_ats_bad_input():
    with pytest.raises(ValueError):
        fz.thrust_set_vertices(max_thrust=float("nan"))
    with pytest.raises(ValueError):
        fz.thrust_set_vertices(max_tilt=math.radians(95.0))
    with pytest.raises(ValueError):
        fz.thrust_set_vertices(n_cone=2)
    with pytest.raises(ValueError):
        fz.deserno_sphere_points(0)


# A7, A8 ---------------------------------------------------------------------------------------------------
def test_a7_force_set_pose_independent(ats17):
    rng = np.random.default_rng(7)
    three_ats = convex_hull(3.0 * ats17.vertices)
    for _ in range(3):
        roll, pitch = rng.uniform(-0.6, 0.6, size=2)
        theta = rng.uniform(0.3, 1.3)
        sets = fz.decomposed_wrench_sets(ats17, _wrench_matrix(roll, pitch, theta))
        assert sets.force.n_vertices == 17
        assert sets.force.volume == pytest.approx(three_ats.volume, rel=1e-9)
        np.testing.assert_allclose(
            np.sort(sets.force.vertices, axis=0), np.sort(three_ats.vertices, axis=0), atol=1e-9
        )


def test_a8_decomposed_aws_at_case_pose(ats17):
    sets = fz.decomposed_wrench_sets(ats17, _wrench_matrix(0.0, 0.0, 0.785))  # pose (5.25)
    assert sets.force.n_vertices == 17
    assert sets.platform_moment.n_vertices == 170
    assert sets.platform_moment.n_facets == 150
    assert sets.leg_moment.n_vertices == 8
    assert sets.leg_moment.n_facets == 6
    np.testing.assert_allclose(sets.leg_moment_bounds[:, 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(sets.leg_moment_bounds[:, 0], -25.68, atol=0.01)
    lo = sets.force.vertices.min(axis=0)
    hi = sets.force.vertices.max(axis=0)
    np.testing.assert_allclose([lo[2], hi[2]], [0.0, 71.33], atol=0.01)
    # [RECON] extents of M_p (the spec rounds to 0.01).
    m_lo = sets.platform_moment.vertices.min(axis=0)
    m_hi = sets.platform_moment.vertices.max(axis=0)
    np.testing.assert_allclose(m_hi, [36.48, 38.86, 37.19], atol=0.02)
    np.testing.assert_allclose(m_lo, [-36.48, -31.73, -37.19], atol=0.02)


# A9 -------------------------------------------------------------------------------------------------------
def _in_vrep(vertices, w):
    """w ∈ conv(vertices) by an LP feasibility problem (λ >= 0, Σλ = 1, Vᵀλ = w)."""
    m = vertices.shape[0]
    A_eq = np.vstack([vertices.T, np.ones((1, m))])
    b_eq = np.append(w, 1.0)
    result = linprog(np.zeros(m), A_eq=A_eq, b_eq=b_eq, bounds=(0, None), method="highs")
    return result.status == 0


def test_a9_hrep_aws_equals_vrep_aws(ats17):
    W = _wrench_matrix(math.radians(10), math.radians(25), math.radians(45))
    halfspaces = fz.wrench_halfspaces(ats17, W)
    vertices = fz.aws_vertices(ats17, W)
    assert vertices.shape == (17**3, 9)
    rng = np.random.default_rng(9)
    # Random thrust triples, half inside and half slightly outside the ATS, mapped to wrenches.
    checked = {True: 0, False: 0}
    for _ in range(24):
        thrusts = np.stack([ats17.vertices[rng.integers(17, size=4)].T @ rng.dirichlet(np.ones(4)) for _ in range(3)])
        thrusts *= rng.uniform(0.9, 1.1)
        w = W @ thrusts.reshape(-1)
        slack = np.max(w @ halfspaces.normals.T - halfspaces.offsets)
        if abs(slack) < 1e-6:
            continue
        by_h = bool(slack <= 0)
        assert by_h == _in_vrep(vertices, w)
        # and the per-quadrotor statement of (5.21): J^{-T} w = thrusts
        assert by_h == bool(np.all([ats17.polytope.contains(t) for t in thrusts]))
        checked[by_h] += 1
    assert checked[True] >= 3 and checked[False] >= 3


def test_hrep_rejects_non_square_and_singular(ats17):
    with pytest.raises(ValueError):
        fz.wrench_halfspaces(ats17, np.eye(9)[:, :8])
    with pytest.raises(ValueError):
        fz.wrench_halfspaces(ats17, _wrench_matrix(0.0, 0.0, 0.0))  # θ = 0: J singular
