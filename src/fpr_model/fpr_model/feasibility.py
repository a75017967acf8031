"""Wrench feasibility analysis of the FPR (thesis Ch. 5, spec §2): ATS, AWS, static margins, optimal legs.

Pieces (thesis equation numbers; errata of spec §0.2 applied):

- **ATS** (Available Thrust Set) of one quadrotor (5.7)-(5.11): ball ``‖f‖ <= f_max`` ∩ tilt cone
  ``‖f‖·cos γ <= z^T f``, discretised by the apex, ``n_cone`` points on the cone rim (5.9) and Deserno's
  regular sphere points (5.10) run on the **unit** sphere (E3) and kept when their polar angle from +z is
  ``<= γ`` (E4). Canonical sets: ``n_cone = 12, n_sphere = 38`` -> 17 vertices; ``24, 165`` -> 38 vertices.
  Thrusts in F0 (world, z up), N. The ATS is closed (λ >= 0, E5).
- **AWS** (Available Wrench Set) (5.12)-(5.22): ``W = J^T`` maps the stacked thrusts ``f = [f_1; ...; f_n]``
  (F0, N) to ``w = [f_p (F0, N); m_p (Fp, N·m); m_l (joint axes, N·m)]`` (5.4).
  V-rep: ``W · (T × ... × T)``; for n = 3, ``W`` is square and invertible on θ ∈ (0, 90°], so **every one of
  the n_v^3 combinations is a vertex** (an invertible linear image of a product of polytopes).
  H-rep (5.19)-(5.22): ``A_w = A_aug · J^{-T}``, ``b_w = b_aug``.
  Decomposed sets (5.26): F_p (force, F0), M_p (platform moment, Fp), M_l (leg moments, a box).
- **Static feasibility** (5.27)-(5.28): ``w_g = g(q)`` (the gravity wrench of :func:`fpr_model.dynamics.gravity`,
  erratum E2 applied there) must lie in the AWS.
- **Margins** (5.29)-(5.35), closed form (E6): distance from f_p,g (resp. m_p,g) to the nearest facet of the
  static force slice F^s_p (5.33) (resp. moment slice M^s_p (5.34)); 0 when statically infeasible.
- **Optimal leg angles** (§5.5): equal leg angles θ = 1°..89° per platform orientation; orientation grid.
- **Teleoperation limits**: :func:`feasible_leg_angle_range` (cached, fit for a 50 Hz loop).

General n: the ATS, the V-rep and the decomposed sets work for any n >= 3. The H-rep AWS and the margins
need a square, invertible ``J`` (6 + n = 3n, i.e. n = 3). For n > 3, ``J^T`` is (6+n)×3n, the pseudo-inverse
does not preserve the inequalities, and the thesis points to an inequality-constrained optimisation
(Orsolino 2020) which is not implemented here: those functions raise ``ValueError`` for n != 3.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from fpr_model.dynamics import gravity
from fpr_model.geometry import make_configuration
from fpr_model.kinematics import jacobian
from fpr_model.parameters import FprParameters
from fpr_model.polytope import Polytope, convex_hull, minkowski_sum_points
from fpr_model.rotations import euler_zyx_to_quat

__all__ = [
    "CASE_MAX_THRUST",
    "CASE_MAX_TILT",
    "AvailableThrustSet",
    "DecomposedWrenchSets",
    "FeasibilityMargins",
    "MarginCurve",
    "OptimalLegAngles",
    "OrientationGrid",
    "StaticSlice",
    "WrenchHalfspaces",
    "available_thrust_set",
    "ats_theoretical_volume",
    "aws_vertices",
    "clear_leg_angle_range_cache",
    "decomposed_wrench_sets",
    "deserno_sphere_points",
    "equal_leg_configuration",
    "feasibility_margins",
    "feasible_leg_angle_range",
    "force_slice",
    "margin_curve",
    "moment_slice",
    "optimal_leg_angles",
    "orientation_grid",
    "platform_orientation_quat",
    "qualifying_range",
    "static_margins",
    "thrust_set_vertices",
    "wrench_halfspaces",
]

#: Case-study actuation limits (5.23): maximum total thrust of one quadrotor [N] and maximum tilt [rad].
CASE_MAX_THRUST = 25.0
CASE_MAX_TILT = math.radians(35.0)

#: Slack below which a wrench is outside the AWS (static infeasibility), in the units of b_w [N].
INFEASIBILITY_TOLERANCE = 1e-9

#: Default sweep of equal leg angles for the optimal search (§5.5): 1°..89° in 1° steps [rad].
DEFAULT_LEG_ANGLES = np.radians(np.arange(1.0, 90.0, 1.0))


# ----------------------------------------------------------------------------------------------------------
# Available Thrust Set (§5.3.2)
# ----------------------------------------------------------------------------------------------------------
def deserno_sphere_points(n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Deserno's regular placement of about ``n_points`` points on the **unit** sphere (E3), §5.3.2.

    Returns ``(polar, azimuth)`` arrays in rad (polar angle measured from +z). ``round`` is MATLAB's (halves
    away from zero), as in the thesis implementation.
    """
    if isinstance(n_points, bool) or int(n_points) != n_points or n_points < 1:
        raise ValueError(f"n_points: expected a positive integer, got {n_points!r}")
    area = 4.0 * math.pi / n_points
    d = math.sqrt(area)
    m_polar = _round_half_away(math.pi / d)
    d_polar = math.pi / m_polar
    d_azimuth = area / d_polar
    polar: list[float] = []
    azimuth: list[float] = []
    for j in range(m_polar):
        theta = math.pi * (j + 0.5) / m_polar
        m_azimuth = _round_half_away(2.0 * math.pi * math.sin(theta) / d_azimuth)
        for k in range(m_azimuth):
            polar.append(theta)
            azimuth.append(2.0 * math.pi * k / m_azimuth)
    return np.array(polar), np.array(azimuth)


def _round_half_away(x: float) -> int:
    return int(math.floor(abs(x) + 0.5) * (1 if x >= 0 else -1))


def thrust_set_vertices(
    max_thrust: float = CASE_MAX_THRUST, max_tilt: float = CASE_MAX_TILT, n_cone: int = 12, n_sphere: int = 38
) -> np.ndarray:
    """Vertex set V of the discretised ATS (5.9)-(5.10), (n_v, 3) in F0 [N].

    Row 0 is the apex (0 thrust); rows 1..n_cone the cone rim (5.9) at azimuth 2πj/n_cone measured as in
    the thesis (x = sin γ sin α, y = sin γ cos α); then the sphere points of :func:`deserno_sphere_points`
    (``n_sphere`` requested on the whole sphere) with polar angle ``<= max_tilt`` (E4), scaled by f_max (E3).
    """
    if not (max_thrust > 0 and math.isfinite(max_thrust)):
        raise ValueError(f"max_thrust: must be a positive finite number [N], got {max_thrust!r}")
    if not (0.0 < max_tilt < math.pi / 2):
        raise ValueError(f"max_tilt: must be in (0, pi/2) rad, got {max_tilt!r}")
    if isinstance(n_cone, bool) or int(n_cone) != n_cone or n_cone < 3:
        raise ValueError(f"n_cone: expected an integer >= 3, got {n_cone!r}")
    n_cone = int(n_cone)
    alpha = 2.0 * math.pi * np.arange(1, int(n_cone) + 1) / n_cone
    sin_tilt, cos_tilt = math.sin(max_tilt), math.cos(max_tilt)
    rim = max_thrust * np.column_stack([sin_tilt * np.sin(alpha), sin_tilt * np.cos(alpha), np.full(n_cone, cos_tilt)])
    polar, azimuth = deserno_sphere_points(n_sphere)
    keep = polar <= max_tilt + 1e-12
    polar, azimuth = polar[keep], azimuth[keep]
    sin_polar = np.sin(polar)
    cap = max_thrust * np.column_stack([sin_polar * np.cos(azimuth), sin_polar * np.sin(azimuth), np.cos(polar)])
    return np.vstack([np.zeros((1, 3)), rim, cap])


def ats_theoretical_volume(max_thrust: float = CASE_MAX_THRUST, max_tilt: float = CASE_MAX_TILT) -> float:
    """Volume of the continuous ATS (5.24): spherical sector (2/3)·π·f_max²·h, h = f_max·(1 − cos γ) [N³]."""
    return 2.0 / 3.0 * math.pi * max_thrust**2 * max_thrust * (1.0 - math.cos(max_tilt))


@dataclass(frozen=True)
class AvailableThrustSet:
    """Discretised ATS of one quadrotor (5.11) in V- and H-representation (thrust in F0, N).

    ``polytope.normals @ f <= polytope.offsets`` is the H-rep A_f·f <= b_f (coplanar qhull facets merged;
    ``polytope.n_triangulated_facets`` is the unmerged count the thesis reports in Table 5.1).
    """

    max_thrust: float
    max_tilt: float
    n_cone: int
    n_sphere: int
    polytope: Polytope

    @property
    def vertices(self) -> np.ndarray:
        return self.polytope.vertices

    @property
    def normals(self) -> np.ndarray:
        return self.polytope.normals

    @property
    def offsets(self) -> np.ndarray:
        return self.polytope.offsets

    @property
    def precision(self) -> float:
        """volume(conv V) / V_theory (Table 5.1), in [0, 1]."""
        return self.polytope.volume / ats_theoretical_volume(self.max_thrust, self.max_tilt)


@lru_cache(maxsize=16)
def available_thrust_set(
    max_thrust: float = CASE_MAX_THRUST, max_tilt: float = CASE_MAX_TILT, n_cone: int = 12, n_sphere: int = 38
) -> AvailableThrustSet:
    """The discretised ATS (5.9)-(5.11) and its H-rep (qhull). Cached: the ATS is pose-independent.

    Raises ValueError if a generated point is not a vertex of the hull (a broken discretisation).
    """
    points = thrust_set_vertices(max_thrust, max_tilt, n_cone, n_sphere)
    polytope = convex_hull(points)
    if polytope.n_vertices != points.shape[0]:
        raise ValueError(
            f"ATS discretisation ({n_cone=}, {n_sphere=}) has {points.shape[0] - polytope.n_vertices} "
            "non-extreme points"
        )
    # Keep the generation order (apex, rim, cap) rather than qhull's vertex order.
    polytope = Polytope(points, polytope.normals, polytope.offsets, polytope.volume, polytope.n_triangulated_facets)
    return AvailableThrustSet(float(max_thrust), float(max_tilt), int(n_cone), int(n_sphere), polytope)


# ----------------------------------------------------------------------------------------------------------
# Configurations and the model pieces (J, g) used by Ch. 5
# ----------------------------------------------------------------------------------------------------------
def platform_orientation_quat(roll: float, pitch: float, yaw: float = 0.0) -> np.ndarray:
    """Platform quaternion [w, x, y, z] from ZYX Euler angles [rad] (§5.4.3: ZYX, yaw 0)."""
    return euler_zyx_to_quat(roll, pitch, yaw)


def equal_leg_configuration(params: FprParameters, platform_quat, leg_angle: float) -> np.ndarray:
    """q = [p_p = 0, q_p, θ_1 = ... = θ_n = leg_angle] (the position is irrelevant for statics)."""
    return make_configuration(np.zeros(3), platform_quat, np.full(params.n, float(leg_angle)))


def _require_square(params: FprParameters) -> None:
    if params.n != 3:
        raise ValueError(
            f"wrench feasibility H-rep/margins need a square Jacobian (6 + n = 3n, n = 3); got n = {params.n}. "
            "For n > 3, J^T is not invertible (thesis §5.3.3: an inequality-constrained optimisation, "
            "Orsolino 2020, would be needed) - not implemented."
        )


# ----------------------------------------------------------------------------------------------------------
# Available Wrench Set (§5.3.3)
# ----------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class WrenchHalfspaces:
    """H-rep of the AWS (5.21)-(5.22): ``normals @ w <= offsets`` with w = [f_p (F0, N); m_p (Fp, N·m);
    m_l (N·m)]. ``normals = A_aug·J^{-T}`` (3·n_h, 9), ``offsets = b_aug`` (3·n_h,)."""

    normals: np.ndarray
    offsets: np.ndarray

    def contains(self, wrench, tolerance: float = 1e-9) -> np.ndarray:
        return np.all(np.asarray(wrench, dtype=float) @ self.normals.T <= self.offsets + tolerance, axis=-1)


def wrench_halfspaces(ats: AvailableThrustSet, wrench_matrix) -> WrenchHalfspaces:
    """A_w = A_aug · W^{-1}, b_w = b_aug (5.19)-(5.22) with W = J^T square (n = 3) and invertible.

    ``wrench_matrix``: W = J(q)^T, (9, 9). Raises ValueError when W is not square or is singular.
    """
    W = np.asarray(wrench_matrix, dtype=float)
    if W.ndim != 2 or W.shape[0] != W.shape[1] or W.shape[0] % 3 != 0:
        raise ValueError(f"wrench_matrix: need a square 3n×3n matrix (n = 3), got shape {W.shape}")
    if not np.isfinite(W).all():
        raise ValueError("wrench_matrix: contains NaN or inf")
    if np.linalg.cond(W) > 1e12:
        raise ValueError("wrench_matrix: singular (a leg angle at 0? the H-rep needs an invertible J)")
    n = W.shape[0] // 3
    W_inv = np.linalg.inv(W)
    normals = np.concatenate([ats.normals @ W_inv[3 * i : 3 * i + 3, :] for i in range(n)], axis=0)
    return WrenchHalfspaces(normals, np.tile(ats.offsets, n))


def aws_vertices(ats: AvailableThrustSet, wrench_matrix) -> np.ndarray:
    """V-rep of the AWS (5.13)-(5.16): W·[v_k1; ...; v_kn] for all n_v^n vertex combinations, (n_v^n, 6+n).

    For n = 3 (W square, invertible) every row is a vertex of the AWS (no pruning needed); for n > 3 the
    rows are the Minkowski-sum candidates, a superset of the vertices.
    """
    W = np.asarray(wrench_matrix, dtype=float)
    n = W.shape[1] // 3
    images = [ats.vertices @ W[:, 3 * i : 3 * i + 3].T for i in range(n)]
    return minkowski_sum_points(images)


@dataclass(frozen=True)
class DecomposedWrenchSets:
    """Decomposed AWS (5.26), each the Minkowski sum of the per-quadrotor images of the ATS.

    ``force``: F_p in F0 [N] (pose-independent, = n·ATS). ``platform_moment``: M_p in Fp [N·m].
    ``leg_moment``: M_l [N·m], a box (None for n != 3, where it is not 3-D); ``leg_moment_bounds`` (n, 2):
    the per-leg [min, max] (the box's sides, any n).
    """

    force: Polytope
    platform_moment: Polytope
    leg_moment: Polytope | None
    leg_moment_bounds: np.ndarray


def decomposed_wrench_sets(ats: AvailableThrustSet, wrench_matrix) -> DecomposedWrenchSets:
    """F_p, M_p, M_l of (5.26) from the wrench matrix W = J^T, (6+n, 3n) (any n >= 3).

    Rows 0:3 of W_i are I3 (force), rows 3:6 are J_ωi^T (platform moment, Fp), row 6+i is l·y_li^T (leg i
    moment) (spec §2.2.3). Each set is the hull of the Minkowski-sum candidates of the per-quadrotor images
    (n_v^n points; the thesis's "irredundant per-quadrotor sets first" gives the same hull).
    """
    W = np.asarray(wrench_matrix, dtype=float)
    n = W.shape[1] // 3
    blocks = [W[:, 3 * i : 3 * i + 3] for i in range(n)]

    def summed(rows: slice) -> Polytope:
        return convex_hull(minkowski_sum_points([ats.vertices @ b[rows, :].T for b in blocks]))

    leg_values = np.stack([ats.vertices @ W[6 + i, 3 * i : 3 * i + 3] for i in range(n)])  # (n, n_v)
    bounds = np.column_stack([leg_values.min(axis=1), leg_values.max(axis=1)])
    leg_box = None
    if n == 3:
        leg_box = convex_hull(np.array(np.meshgrid(*bounds, indexing="ij")).reshape(3, -1).T)
    return DecomposedWrenchSets(
        force=summed(slice(0, 3)),
        platform_moment=summed(slice(3, 6)),
        leg_moment=leg_box,
        leg_moment_bounds=bounds,
    )


# ----------------------------------------------------------------------------------------------------------
# Static feasibility and margins (§5.4)
# ----------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FeasibilityMargins:
    """Static feasibility (5.27)-(5.28) and the margins (5.29), closed form (E6).

    ``force`` [N]: distance from f_p,g to the nearest facet of F^s_p (5.33). ``moment`` [N·m]: distance from
    m_p,g to the nearest facet of M^s_p (5.34). Both 0 when ``feasible`` is False (the thesis plots 0 there).
    """

    feasible: bool
    force: float
    moment: float


def static_margins(halfspaces: WrenchHalfspaces, gravity_wrench) -> FeasibilityMargins:
    """Closed-form margins (5.29)-(5.35) with E6: per facet row j, the point-to-hyperplane distance in the
    slice, then the min over j.

    ``s = b_w − A_w·w_g``; infeasible if any ``s_j < 0``; ``margin_F = min_j s_j / ‖A_w[j, 0:3]‖`` and
    ``margin_M = min_j s_j / ‖A_w[j, 3:6]‖`` over rows with a non-zero block (the per-facet QP of Table 5.3,
    ``min ‖x − x_g‖² s.t. a_j^T x = b_j``, has exactly this value; redundant rows give larger distances).
    """
    w_g = np.asarray(gravity_wrench, dtype=float)
    force, moment, feasible = _margins_batch(halfspaces.normals[None], halfspaces.offsets, w_g[None])
    return FeasibilityMargins(bool(feasible[0]), float(force[0]), float(moment[0]))


def _margins_batch(normals: np.ndarray, offsets: np.ndarray, w_g: np.ndarray):
    """Vectorised closed-form margins for K configurations: normals (K, m, 9), offsets (m,), w_g (K, 9)."""
    slack = offsets[None, :] - np.einsum("kmj,kj->km", normals, w_g)
    feasible = np.all(slack >= -INFEASIBILITY_TOLERANCE, axis=1)
    out = []
    for block in (slice(0, 3), slice(3, 6)):
        norms = np.linalg.norm(normals[:, :, block], axis=2)
        with np.errstate(divide="ignore", invalid="ignore"):
            distance = np.where(norms > 1e-12, slack / norms, np.inf)
        margin = np.min(distance, axis=1)
        out.append(np.where(feasible, np.maximum(margin, 0.0), 0.0))
    return out[0], out[1], feasible


@dataclass(frozen=True)
class StaticSlice:
    """A static available set in R^3 (5.33)/(5.34): ``normals @ x <= offsets``, with the equilibrium
    point ``point`` (f_p,g in F0 [N] or m_p,g in Fp [N·m]). Rows with a zero normal are dropped (they only
    decide feasibility, which ``feasible`` records)."""

    normals: np.ndarray
    offsets: np.ndarray
    point: np.ndarray
    feasible: bool


def _slice(halfspaces: WrenchHalfspaces, gravity_wrench, block: slice) -> StaticSlice:
    w_g = np.asarray(gravity_wrench, dtype=float)
    others = np.ones(w_g.shape[0], dtype=bool)
    others[block] = False
    A = halfspaces.normals[:, block]
    b = halfspaces.offsets - halfspaces.normals[:, others] @ w_g[others]
    keep = np.linalg.norm(A, axis=1) > 1e-12
    feasible = bool(np.all(b[~keep] >= -INFEASIBILITY_TOLERANCE)) and bool(
        np.all(A[keep] @ w_g[block] <= b[keep] + INFEASIBILITY_TOLERANCE)
    )
    return StaticSlice(A[keep], b[keep], w_g[block].copy(), feasible)


def force_slice(halfspaces: WrenchHalfspaces, gravity_wrench) -> StaticSlice:
    """F^s_p (5.30), (5.33): the AWS with m_p, m_l fixed at their gravity values, as a set of f_p (F0, N)."""
    return _slice(halfspaces, gravity_wrench, slice(0, 3))


def moment_slice(halfspaces: WrenchHalfspaces, gravity_wrench) -> StaticSlice:
    """M^s_p (5.31)-(5.32) (E7), (5.34): the AWS with f_p, m_l fixed at their gravity values, as m_p (Fp, N·m)."""
    return _slice(halfspaces, gravity_wrench, slice(3, 6))


def feasibility_margins(
    params: FprParameters, ats: AvailableThrustSet, platform_quat, leg_angles
) -> FeasibilityMargins:
    """Margins at q = [0, platform_quat, leg_angles] (leg_angles (n,) rad, or one angle for all legs).

    Uses J (2.20) from :func:`fpr_model.kinematics.jacobian` and w_g = g(q) (2.86)-(2.91) with E2 from
    :func:`fpr_model.dynamics.gravity`. Returns all-zero margins when J is singular (θ_i = 0).
    """
    _require_square(params)
    leg_angles = np.broadcast_to(np.asarray(leg_angles, dtype=float), (params.n,))
    q = make_configuration(np.zeros(3), platform_quat, leg_angles)
    J = jacobian(params, q)
    if not _invertible(J):
        return FeasibilityMargins(False, 0.0, 0.0)
    return static_margins(wrench_halfspaces(ats, J.T), gravity(params, q))


def _invertible(J: np.ndarray) -> bool:
    return bool(np.linalg.cond(J) < 1e12)


# ----------------------------------------------------------------------------------------------------------
# Leg-angle sweeps and optimal legs (§5.5)
# ----------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MarginCurve:
    """Margins for equal leg angles at one platform orientation. Angles in rad; force N, moment N·m."""

    leg_angles: np.ndarray
    force: np.ndarray
    moment: np.ndarray
    feasible: np.ndarray


def margin_curve(params: FprParameters, ats: AvailableThrustSet, platform_quat, leg_angles=None) -> MarginCurve:
    """Margins for θ_1 = ... = θ_n = each of ``leg_angles`` (default 1°..89°, 1° steps), vectorised:
    J and w_g per angle from the model, then one batched J^{-T} (numpy) and the closed-form margins (E6).
    Angles where J is singular get margins 0 and feasible False.
    """
    _require_square(params)
    angles = DEFAULT_LEG_ANGLES if leg_angles is None else np.atleast_1d(np.asarray(leg_angles, dtype=float))
    if not np.isfinite(angles).all():
        raise ValueError("leg_angles: contains NaN or inf")
    K, n = angles.shape[0], params.n
    J = np.empty((K, 3 * n, 6 + n))
    w_g = np.empty((K, 6 + n))
    for k, theta in enumerate(angles):
        q = make_configuration(np.zeros(3), platform_quat, np.full(n, theta))
        J[k] = jacobian(params, q)
        w_g[k] = gravity(params, q)
    regular = np.linalg.cond(J) < 1e12
    force = np.zeros(K)
    moment = np.zeros(K)
    feasible = np.zeros(K, dtype=bool)
    if regular.any():
        J_inv_T = np.linalg.inv(np.swapaxes(J[regular], 1, 2))  # (K', 9, 9)  J^{-T}
        # A_w rows of quadrotor i: A_f · (J^{-T})[3i:3i+3, :]  (5.21)-(5.22)
        normals = np.einsum("hc,kicj->kihj", ats.normals, J_inv_T.reshape(-1, n, 3, 6 + n)).reshape(
            -1, n * ats.normals.shape[0], 6 + n
        )
        f, m, ok = _margins_batch(normals, np.tile(ats.offsets, n), w_g[regular])
        force[regular], moment[regular], feasible[regular] = f, m, ok
    return MarginCurve(angles.copy(), force, moment, feasible)


@dataclass(frozen=True)
class OptimalLegAngles:
    """θ*_F, θ*_M (rad) maximising the force / moment margin over the sweep, their margins, and the curve."""

    force_angle: float
    force_margin: float
    moment_angle: float
    moment_margin: float
    curve: MarginCurve


def optimal_leg_angles(
    params: FprParameters, ats: AvailableThrustSet, platform_quat, leg_angles=None
) -> OptimalLegAngles:
    """§5.5 steps 2-3: sweep equal leg angles (default 1°..89°), argmax of each margin (first on ties)."""
    curve = margin_curve(params, ats, platform_quat, leg_angles)
    i_f = int(np.argmax(curve.force))
    i_m = int(np.argmax(curve.moment))
    return OptimalLegAngles(
        force_angle=float(curve.leg_angles[i_f]),
        force_margin=float(curve.force[i_f]),
        moment_angle=float(curve.leg_angles[i_m]),
        moment_margin=float(curve.moment[i_m]),
        curve=curve,
    )


@dataclass(frozen=True)
class OrientationGrid:
    """§5.5 step 4 (Figs. 5.13-5.14): optimal equal leg angles over a roll × pitch grid (yaw 0).

    ``rolls`` (R,), ``pitches`` (P,) [rad]; the other arrays are (R, P): angles in rad, margins N / N·m.
    """

    rolls: np.ndarray
    pitches: np.ndarray
    force_angle: np.ndarray
    force_margin: np.ndarray
    moment_angle: np.ndarray
    moment_margin: np.ndarray


def orientation_grid(
    params: FprParameters,
    ats: AvailableThrustSet,
    rolls: Sequence[float],
    pitches: Sequence[float],
    leg_angles=None,
    progress: Callable[[int, int], None] | None = None,
) -> OrientationGrid:
    """Optimal leg angles for every (roll, pitch) of the grid [rad]; ``progress(done, total)`` after each."""
    rolls = np.asarray(rolls, dtype=float)
    pitches = np.asarray(pitches, dtype=float)
    shape = (rolls.size, pitches.size)
    arrays = [np.zeros(shape) for _ in range(4)]
    total, done = rolls.size * pitches.size, 0
    for i, roll in enumerate(rolls):
        for j, pitch in enumerate(pitches):
            best = optimal_leg_angles(params, ats, platform_orientation_quat(roll, pitch), leg_angles)
            for array, value in zip(
                arrays, (best.force_angle, best.force_margin, best.moment_angle, best.moment_margin), strict=True
            ):
                array[i, j] = value
            done += 1
            if progress is not None:
                progress(done, total)
    return OrientationGrid(rolls, pitches, *arrays)


# ----------------------------------------------------------------------------------------------------------
# Teleoperation support: the leg-angle range with enough margin at a commanded roll/pitch
# ----------------------------------------------------------------------------------------------------------
_CURVE_CACHE: OrderedDict = OrderedDict()
_CURVE_CACHE_SIZE = 4096
_CURVE_CACHE_LOCK = threading.Lock()  # callers may run in a multi-threaded executor


def feasible_leg_angle_range(
    params: FprParameters,
    roll: float,
    pitch: float,
    min_force_margin: float,
    min_moment_margin: float,
    *,
    max_thrust: float = CASE_MAX_THRUST,
    max_tilt: float = CASE_MAX_TILT,
    leg_angle_step: float = math.radians(1.0),
    orientation_step: float = math.radians(1.0),
) -> tuple[float, float] | None:
    """Range ``(lo, hi)`` [rad] of equal leg angles whose force margin >= ``min_force_margin`` [N] and moment
    margin >= ``min_moment_margin`` [N·m] at platform roll/pitch [rad] (ZYX, yaw 0), or None if none.

    Meant for a 50 Hz teleoperation filter: the margin curve (θ = 1°..89° in ``leg_angle_step``, 17-vertex
    ATS with (``max_thrust``, ``max_tilt``)) is cached per orientation cell of ``orientation_step`` (roll and
    pitch are rounded to that grid), so a call is a dictionary hit (~10 µs) while the orientation stays in a cell
    and one sweep (~10 ms) when it moves to a new cell (LRU of 4096 cells). Thresholds are applied per call.

    The returned range is the largest contiguous run of qualifying sweep angles, its ends refined by linear
    interpolation of the margins towards the neighbouring non-qualifying angle (at most one step wider).
    Non-finite inputs raise ValueError (the caller keeps its previous limits).
    """
    for name, value in (
        ("roll", roll),
        ("pitch", pitch),
        ("min_force_margin", min_force_margin),
        ("min_moment_margin", min_moment_margin),
        ("leg_angle_step", leg_angle_step),
        ("orientation_step", orientation_step),
    ):
        if not math.isfinite(float(value)):
            raise ValueError(f"{name}: must be finite, got {value!r}")
    if leg_angle_step <= 0 or orientation_step <= 0:
        raise ValueError("leg_angle_step and orientation_step must be > 0")
    roll_cell = round(float(roll) / orientation_step)
    pitch_cell = round(float(pitch) / orientation_step)
    key = (params, roll_cell, pitch_cell, float(orientation_step), float(max_thrust), float(max_tilt),
           float(leg_angle_step))
    with _CURVE_CACHE_LOCK:
        curve = _CURVE_CACHE.get(key)
        if curve is not None:
            _CURVE_CACHE.move_to_end(key)
    if curve is None:
        ats = available_thrust_set(float(max_thrust), float(max_tilt))
        n_steps = int(math.floor((math.radians(89.0) - math.radians(1.0)) / leg_angle_step + 1e-9))
        angles = math.radians(1.0) + leg_angle_step * np.arange(n_steps + 1)
        quat = platform_orientation_quat(roll_cell * orientation_step, pitch_cell * orientation_step)
        curve = margin_curve(params, ats, quat, angles)
        with _CURVE_CACHE_LOCK:
            _CURVE_CACHE[key] = curve
            if len(_CURVE_CACHE) > _CURVE_CACHE_SIZE:
                _CURVE_CACHE.popitem(last=False)
    return qualifying_range(curve, min_force_margin, min_moment_margin)


def qualifying_range(
    curve: MarginCurve, min_force_margin: float, min_moment_margin: float
) -> tuple[float, float] | None:
    """Largest contiguous run of ``curve`` angles with both margins >= thresholds (and feasible), its ends
    interpolated linearly towards the first failing neighbour. None if no angle qualifies."""
    excess = np.minimum(curve.force - min_force_margin, curve.moment - min_moment_margin)
    ok = (excess >= 0.0) & curve.feasible
    if not ok.any():
        return None
    best_start, best_len, start = 0, 0, None
    for k, flag in enumerate(np.append(ok, False)):
        if flag and start is None:
            start = k
        elif not flag and start is not None:
            if k - start > best_len:
                best_start, best_len = start, k - start
            start = None
    first, last = best_start, best_start + best_len - 1
    angles = curve.leg_angles

    def crossing(inside: int, outside: int) -> float:
        a, b = excess[inside], excess[outside]
        t = a / (a - b) if a - b > 0 else 0.0
        return float(angles[inside] + t * (angles[outside] - angles[inside]))

    lo = crossing(first, first - 1) if first > 0 else float(angles[first])
    hi = crossing(last, last + 1) if last < angles.size - 1 else float(angles[last])
    return lo, hi


def clear_leg_angle_range_cache() -> None:
    """Forget the cached margin curves of :func:`feasible_leg_angle_range` (e.g. after a parameter change)."""
    with _CURVE_CACHE_LOCK:
        _CURVE_CACHE.clear()
