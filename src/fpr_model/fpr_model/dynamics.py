"""Dynamics of the FPR passive structure with the quadrotors as point masses at the leg tips (thesis §2.5).

Equation of motion (2.26), with the external wrench of the paper (spec §1.3)::

    M(q) ν̇ + C(q, ν) ν + g(q) = τ + τ_e,        τ = J(q)ᵀ f  (2.28)

- ``q = [p_p (world, m), q_p ([w,x,y,z], Fp -> world), θ (rad)]`` ∈ R^{7+n};
  ``ν = [v_p (world, m/s), ω_p (Fp, rad/s), θ̇ (rad/s)]`` ∈ R^{6+n}; ``ν̇`` likewise (a_p in world, ω̇_p in
  Fp).
- Wrench layout everywhere: ``[f_p (world, N), m_p (Fp, about P, N·m), leg joint moments (N·m)]`` (2.27).
- ``f = [f_1; ...; f_n]``: quadrotor thrust vectors, world frame, N.

Algorithms (Pinocchio-style free functions on the immutable :class:`~fpr_model.parameters.FprParameters`):

- :func:`inverse_dynamics`: recursive Newton-Euler in Khalil's 3-D form, the thesis's own algorithm
  (2.33)-(2.45), gravity as a fictitious platform acceleration (2.39).
- :func:`mass_matrix`: composite-rigid-body algorithm (2.51)-(2.63), evaluated in closed form in Fp at P.
- :func:`coriolis_matrix`: ``C = Σ_k J_kᵀ (I_k J̇_k + B_k J_k)`` over the bodies k (platform, legs),
  with J_k the body Jacobians in body coordinates (Featherstone spatial vectors ``[ω; v]``), I_k the
  constant body spatial inertias and ``B_k = (I_k V_k) ×̄*`` (2.69)-(2.70), a skew-symmetric factorisation
  of ``V_k ×* I_k V_k``. Hence ``C ν`` is the exact velocity-product term and ``Ṁ = C + Cᵀ`` (2.65)
  holds exactly. This is a valid (admissible, [Echeandia 2021]) choice; it is not term-by-term the (2.68)
  factorisation of the thesis.
- :func:`gravity`: static model (2.86)-(2.91) with erratum E2 (spec §2.2.4).

Inertia reference points: see :mod:`fpr_model.parameters` (I_l about A_i, I_p about P).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fpr_model._math import cross, cross3, skew_batch
from fpr_model._validation import as_array, as_scalar
from fpr_model.geometry import (
    ParsedConfiguration,
    _parse_configuration,
    integrate_configuration,
    model_constants,
)
from fpr_model.kinematics import JacobianAt, _jacobian_at, _jacobian_from
from fpr_model.parameters import FprParameters

__all__ = [
    "ModelTerms",
    "actuation_wrench",
    "bias_forces",
    "coriolis_matrix",
    "forward_dynamics",
    "gravity",
    "integrate_configuration",
    "inverse_dynamics",
    "kinetic_energy",
    "mass_matrix",
    "mass_matrix_rnea",
    "model_terms",
    "potential_energy",
    "rk4_step",
    "thrusts_from_wrench",
]

_E_Z = np.array([0.0, 0.0, 1.0])


def _velocity(params: FprParameters, value, name: str) -> np.ndarray:
    return as_array(name, value, (6 + params.n,))


# --------------------------------------------------------------------------------------------------------
# Recursive Newton-Euler (thesis §2.5.2)
# --------------------------------------------------------------------------------------------------------
def _rnea_reference(params: FprParameters, parsed: ParsedConfiguration, nu: np.ndarray, nu_dot: np.ndarray,
                    gravity_on: bool) -> np.ndarray:
    """The thesis's algorithm literally (§2.5.2 listing): legs in their own frames F_li. Test oracle."""
    c = model_constants(params)
    R = parsed.rotation
    Rl = parsed.leg_rotations  # pR_li, (n, 3, 3)
    omega, omega_dot = nu[3:6], nu_dot[3:6]
    rates, rates_dot = nu[6:], nu_dot[6:]
    accel = nu_dot[:3].copy()
    if gravity_on:
        accel[2] += params.gravity  # a_p − g_vec, g_vec = [0, 0, −g]  (2.39)
    pa = R.T @ accel
    # Platform Newton-Euler (2.43), about P in Fp.
    hp = c.platform_first_moment
    force = params.platform_mass * pa + cross(omega_dot, hp) + cross(omega, cross(omega, hp))
    inertia_p = params.platform_inertia
    moment = inertia_p @ omega_dot + cross(hp, pa) + cross(omega, inertia_p @ omega)
    # Forward recursion to the legs (2.33)-(2.34), in F_li.
    a = c.anchors
    omega_in_leg = np.einsum("nji,j->ni", Rl, omega)  # pR_liᵀ ω
    omega_leg = omega_in_leg.copy()
    omega_leg[:, 2] += rates
    acc_anchor = pa + cross(omega_dot, a) + cross(omega, cross(omega, a))  # (n, 3) in Fp
    acc_leg = np.einsum("nji,nj->ni", Rl, acc_anchor)
    omega_dot_leg = np.einsum("nji,j->ni", Rl, omega_dot)
    omega_dot_leg[:, 2] += rates_dot
    omega_dot_leg[:, 0] += rates * omega_in_leg[:, 1]  # θ̇ (ω_p × e_z) = θ̇ [ω_y, −ω_x, 0]
    omega_dot_leg[:, 1] -= rates * omega_in_leg[:, 0]
    # Leg Newton-Euler (2.40), about A_i in F_li.
    h = c.leg_first_moments
    inertia = c.leg_inertias
    force_leg = (c.leg_masses[:, None] * acc_leg + cross(omega_dot_leg, h)
                 + cross(omega_leg, cross(omega_leg, h)))
    moment_leg = (np.einsum("nij,nj->ni", inertia, omega_dot_leg) + cross(h, acc_leg)
                  + cross(omega_leg, np.einsum("nij,nj->ni", inertia, omega_leg)))
    # Backward recursion (2.43)-(2.45).
    force_leg_p = np.einsum("nij,nj->ni", Rl, force_leg)
    moment_leg_p = np.einsum("nij,nj->ni", Rl, moment_leg)
    force = force + force_leg_p.sum(axis=0)
    moment = moment + (moment_leg_p + cross(a, force_leg_p)).sum(axis=0)
    return np.concatenate([R @ force, moment, moment_leg[:, 2]])


class _BodyConstants(NamedTuple):
    """Platform (index 0) and legs (1..n) stacked: origins P and A_i in Fp, joint axes, masses."""

    origins: np.ndarray  # (n+1, 3), A_0 = 0
    origins_skew: np.ndarray  # (n+1, 3, 3)
    axes: np.ndarray  # (n+1, 3), k_0 = 0
    axes_skew: np.ndarray  # (n+1, 3, 3)
    masses: np.ndarray  # (n+1,)


def _body_constants(params: FprParameters) -> _BodyConstants:
    cached = params._cache.get("body_constants")
    if cached is None:
        c = model_constants(params)
        origins = np.vstack([np.zeros(3), c.anchors])
        axes = np.vstack([np.zeros(3), c.joint_axes])
        cached = _BodyConstants(origins, skew_batch(origins), axes, skew_batch(axes),
                                np.concatenate([[params.platform_mass], c.leg_masses]))
        params._cache["body_constants"] = cached
    return cached


def _body_inertias_in_platform(params: FprParameters,
                               parsed: ParsedConfiguration) -> tuple[np.ndarray, np.ndarray]:
    """First moments (n+1, 3) and rotational inertias (n+1, 3, 3) of the platform (about P) and of the
    composite legs (about A_i), all in Fp coordinates: ``pR_li ms_i`` and ``pR_li I_i pR_liᵀ``."""
    c = model_constants(params)
    Rl = parsed.leg_rotations
    first = np.empty((c.n + 1, 3))
    first[0] = c.platform_first_moment
    first[1:] = (Rl @ c.leg_first_moments[:, :, None])[:, :, 0]
    inertia = np.empty((c.n + 1, 3, 3))
    inertia[0] = params.platform_inertia
    inertia[1:] = Rl @ c.leg_inertias @ np.swapaxes(Rl, 1, 2)
    return first, inertia


def _rnea(params: FprParameters, parsed: ParsedConfiguration, nu: np.ndarray, nu_dot: np.ndarray,
          gravity_on: bool, body_terms: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """RNEA (2.33)-(2.45) with every body's Newton-Euler equation written in Fp coordinates about its own
    origin (P for the platform, A_i for leg i), platform and legs batched. Same equations as the listing."""
    b = _body_constants(params)
    first, inertia = body_terms if body_terms is not None else _body_inertias_in_platform(params, parsed)
    R = parsed.rotation
    n = params.n
    omega, omega_dot = nu[3:6], nu_dot[3:6]
    rates = np.zeros(n + 1)
    rates[1:] = nu[6:]
    rates_dot = np.zeros(n + 1)
    rates_dot[1:] = nu_dot[6:]
    accel = nu_dot[:3].copy()
    if gravity_on:
        accel[2] += params.gravity  # a_p − g_vec, g_vec = [0, 0, −g]  (2.39)
    pa = R.T @ accel
    # Forward recursion (2.33)-(2.34): ω_i = ω + θ̇_i k_i, ω̇_i = ω̇ + θ̈_i k_i + θ̇_i ω × k_i,
    # a_Ai = a_P + ω̇ × a_i + ω × (ω × a_i).
    omega_body = omega + rates[:, None] * b.axes
    omega_dot_body = omega_dot + rates_dot[:, None] * b.axes - rates[:, None] * (b.axes_skew @ omega)
    acc_body = (pa - b.origins_skew @ omega_dot + np.outer(b.origins @ omega, omega)
                - (omega @ omega) * b.origins)
    # Newton-Euler about each origin (2.31), (2.40), (2.43).
    force = (b.masses[:, None] * acc_body + cross(omega_dot_body, first)
             + omega_body * np.einsum("ij,ij->i", omega_body, first)[:, None]
             - np.einsum("ij,ij->i", omega_body, omega_body)[:, None] * first)
    moment = (np.einsum("kij,kj->ki", inertia, omega_dot_body) + cross(first, acc_body)
              + cross(omega_body, np.einsum("kij,kj->ki", inertia, omega_body)))
    # Backward recursion (2.43)-(2.45): wrench about P, joint moments k_i · n_i.
    out = np.empty(6 + n)
    out[:3] = R @ force.sum(axis=0)
    out[3:6] = (moment + cross(b.origins, force)).sum(axis=0)
    out[6:] = np.einsum("ij,ij->i", b.axes[1:], moment[1:])
    return out


def inverse_dynamics(params: FprParameters, q, nu, nu_dot, gravity: bool = True) -> np.ndarray:
    """Generalised force ``τ = M ν̇ + C ν + g`` by recursive Newton-Euler (thesis (2.33)-(2.45)).

    Khalil's form: forward recursion of the leg frame velocities and accelerations (2.33)-(2.34) from the
    platform, Newton-Euler equations of each body about its frame origin (2.31), (2.40), (2.43), backward
    recursion of the leg reaction wrenches (2.44), projection on the joint axes (2.45). Gravity enters as
    the fictitious platform acceleration ``R_pᵀ (a_p − g_vec)`` (2.39); ``gravity=False`` drops it.

    Args: ``q`` (7+n,), ``nu`` (6+n,), ``nu_dot`` (6+n,) as in the module docstring.
    Returns: (6+n,) ``[f_p (world, N), m_p (Fp, N·m), joint moments (N·m)]``.
    """
    parsed = _parse_configuration(params, q)
    nu = _velocity(params, nu, "nu")
    nu_dot = _velocity(params, nu_dot, "nu_dot")
    return _rnea(params, parsed, nu, nu_dot, bool(gravity))


def bias_forces(params: FprParameters, q, nu) -> np.ndarray:
    """``c(q, ν) = C(q, ν) ν + g(q)`` (2.25): RNEA with ν̇ = 0 (thesis §2.5.2), (6+n,), wrench layout."""
    parsed = _parse_configuration(params, q)
    nu = _velocity(params, nu, "nu")
    return _rnea(params, parsed, nu, np.zeros_like(nu), True)


def mass_matrix_rnea(params: FprParameters, q) -> np.ndarray:
    """M(q) column by column with RNEA, ν = 0, g = 0 and unit accelerations (thesis §2.5.2 algorithm).

    Slow reference (6+n calls of the thesis's RNEA listing, legs in their own frames), kept as the test
    oracle of :func:`mass_matrix` (Table 2.1) and of the batched RNEA of :func:`inverse_dynamics`.
    """
    parsed = _parse_configuration(params, q)
    size = 6 + params.n
    zero = np.zeros(size)
    return np.column_stack([_rnea_reference(params, parsed, zero, unit, False) for unit in np.eye(size)])


# --------------------------------------------------------------------------------------------------------
# Composite-rigid-body algorithm (thesis §2.5.3)
# --------------------------------------------------------------------------------------------------------
def _mass_matrix(params: FprParameters, parsed: ParsedConfiguration,
                 body_terms: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    c = model_constants(params)
    b = _body_constants(params)
    n = c.n
    R = parsed.rotation
    first, inertia = body_terms if body_terms is not None else _body_inertias_in_platform(params, parsed)
    a = b.origins  # (n+1, 3), zero for the platform
    # Composite platform inertia about P in Fp (2.53), (2.59): parallel-axis shift of each leg from A_i to P,
    # I_P = I_A + m([a]xᵀ[a]x) + [a]xᵀ[h]x + [h]xᵀ[a]x, with [x]xᵀ[y]x = (x·y) 1 − y xᵀ.
    ha = first.T @ a
    inertia_c = inertia.sum(axis=0) + c.anchor_shift_inertia - ha - ha.T
    trace = 2.0 * (ha[0, 0] + ha[1, 1] + ha[2, 2])
    inertia_c[0, 0] += trace
    inertia_c[1, 1] += trace
    inertia_c[2, 2] += trace
    hx, hy, hz = (c.static_first_moment + first[1:].sum(axis=0)).tolist()
    template = params._cache.get("mass_matrix_template")
    if template is None:
        template = np.zeros((6 + n, 6 + n))
        template[:3, :3] = c.total_mass * np.eye(3)
        template[6:, 6:] = np.diag(c.leg_inertias[:, 2, 2])  # e_zᵀ I_i e_z, constant
        params._cache["mass_matrix_template"] = template
    M = template.copy()
    # Platform block S_pᵀ I_C S_p (2.63) with S_p = [[0, 1], [R_pᵀ, 0]] (2.61).
    M_omega_v = np.array([[0.0, -hz, hy], [hz, 0.0, -hx], [-hy, hx, 0.0]]) @ R.T
    M[3:6, :3] = M_omega_v
    M[:3, 3:6] = M_omega_v.T
    M[3:6, 3:6] = inertia_c
    # Leg columns S_pᵀ pX*_i I_i S_i (2.63): momentum of leg i per unit θ̇_i, moved to P.
    angular = (inertia[1:] @ c.joint_axes[:, :, None])[:, :, 0]  # pR_li I_i e_z
    linear = (b.axes_skew[1:] @ first[1:, :, None])[:, :, 0]  # k_i × h_i
    M[:3, 6:] = R @ linear.T
    M[3:6, 6:] = (angular + (c.anchors_skew @ linear[:, :, None])[:, :, 0]).T  # + a_i × (k_i × h_i)
    M[6:, :6] = M[:6, 6:].T
    return M


def mass_matrix(params: FprParameters, q) -> np.ndarray:
    """Generalised inertia matrix M(q) ∈ R^{(6+n)×(6+n)} by the composite-rigid-body algorithm (2.51)-(2.63).

    The composite inertia of the platform (2.59) is accumulated directly in Fp about P (the joint transforms
    (2.60) applied in closed form), the platform block is ``S_pᵀ I_C S_p`` with ``S_p`` of (2.61) and the leg
    columns ``S_pᵀ pX*_i I_i S_i`` (2.63). Rows/columns ordered as ν. Symmetric positive definite.
    """
    return _mass_matrix(params, _parse_configuration(params, q))


# --------------------------------------------------------------------------------------------------------
# Coriolis matrix (thesis §2.5.3, (2.64)-(2.85); see module docstring for the factorisation used)
# --------------------------------------------------------------------------------------------------------
_JOINT_CROSS = np.zeros((6, 6))  # S× for S = [e_z; 0]: diag([e_z]x, [e_z]x)
_JOINT_CROSS[0, 1] = _JOINT_CROSS[3, 4] = -1.0
_JOINT_CROSS[1, 0] = _JOINT_CROSS[4, 3] = 1.0
_JOINT_CROSS.setflags(write=False)


def _body_jacobians(params: FprParameters, parsed: ParsedConfiguration, nu: np.ndarray):
    """Body Jacobians Ψ_k (w.r.t. [v_p, ω_p]) and their derivatives, for k = platform, legs; spatial [ω;
    v]."""
    c = model_constants(params)
    n = c.n
    template = params._cache.get("body_jacobian_template")
    if template is None:
        template = np.zeros((n + 1, 6, 6))
        template[0, :3, 3:] = np.eye(3)
        params._cache["body_jacobian_template"] = template
    R = parsed.rotation
    E = np.swapaxes(parsed.leg_rotations, 1, 2)  # rotation Fp -> F_li
    omega = nu[3:6]
    Psi = template.copy()
    Psi[0, 3:, :3] = R.T
    Psi[1:, :3, 3:] = E
    Psi[1:, 3:, :3] = E @ R.T
    Psi[1:, 3:, 3:] = -(E @ c.anchors_skew)
    # Ψ̇ = −θ̇ (S×) Ψ + E-block of Ṡ_p, with Ṡ_p = [[0, 0], [−[ω]x R_pᵀ, 0]].
    Psi_dot = np.zeros((n + 1, 6, 6))
    Psi_dot[1:] = (-nu[6:])[:, None, None] * (_JOINT_CROSS @ Psi[1:])
    wx, wy, wz = omega.tolist()
    omega_skew_rt = np.array([[0.0, -wz, wy], [wz, 0.0, -wx], [-wy, wx, 0.0]]) @ R.T  # [ω]x R_pᵀ
    Psi_dot[0, 3:, :3] = -omega_skew_rt
    Psi_dot[1:, 3:, :3] -= E @ omega_skew_rt
    velocity = Psi @ nu[:6]
    velocity[1:, 2] += nu[6:]
    return Psi, Psi_dot, velocity


def _coriolis_matrix(params: FprParameters, parsed: ParsedConfiguration, nu: np.ndarray) -> np.ndarray:
    c = model_constants(params)
    n = c.n
    inertia = params._cache.get("spatial_inertias")
    if inertia is None:
        inertia = np.concatenate([c.platform_spatial_inertia[None], c.leg_spatial_inertias])
        params._cache["spatial_inertias"] = inertia
    Psi, Psi_dot, velocity = _body_jacobians(params, parsed, nu)
    momentum = (inertia @ velocity[:, :, None])[:, :, 0]  # [μ; p]
    # B = (I V) x̄* = −[[ [μ]x, [p]x ], [ [p]x, 0 ]]  (2.70): skew-symmetric, B V = V x* (I V).
    minus_skew = skew_batch(-momentum.reshape(n + 1, 2, 3))  # −[μ]x, −[p]x
    B = np.zeros((n + 1, 6, 6))
    B[:, :3, :3] = minus_skew[:, 0]
    B[:, :3, 3:] = minus_skew[:, 1]
    B[:, 3:, :3] = minus_skew[:, 1]
    P = inertia @ Psi_dot + B @ Psi  # I_k J̇_k + B_k J_k restricted to the platform columns
    C = np.zeros((6 + n, 6 + n))
    C[:6, :6] = Psi.reshape(-1, 6).T @ P.reshape(-1, 6)  # Σ_k Ψ_kᵀ P_k
    # Leg columns: Ψ_iᵀ B_i S, with B_i S = [e_z × μ; e_z × p] (the joint column of J̇_i is zero).
    BS = B[1:, :, 2]
    C[:6, 6:] = (BS[:, None, :] @ Psi[1:])[:, 0, :].T
    C[6:, :6] = P[1:, 2, :]
    # C[6+i, 6+i] = Sᵀ B_i S = 0 (B_i skew-symmetric).
    return C


def coriolis_matrix(params: FprParameters, q, nu) -> np.ndarray:
    """Coriolis matrix C(q, ν) ∈ R^{(6+n)×(6+n)} with ``C ν`` = velocity-product forces and ``Ṁ = C + Cᵀ``
    (2.65).

    ``C = Σ_k J_kᵀ (I_k J̇_k + B_k(V_k) J_k)`` over the platform and the legs (spatial vectors ``[ω; v]``
    in each
    body frame at its origin, (2.46)-(2.50)), with ``J_p = [S_p, 0]``, ``J̇_p = [Ṡ_p, 0]`` (2.61), (2.82),
    ``J_i = [X_i S_p, S_i e_iᵀ]`` (2.60), (2.62), ``J̇_i = [Ẋ_i S_p + X_i Ṡ_p, 0]`` and
    ``B_k = (I_k V_k) ×̄*`` (2.69)-(2.70). Since every I_k is constant in its body frame,
    ``Ṁ = Σ (J̇ᵀ I J + Jᵀ I J̇) = C + Cᵀ`` (B_k is skew-symmetric), and ``B_k V_k = V_k ×* I_k V_k`` (2.67).
    """
    parsed = _parse_configuration(params, q)
    nu = _velocity(params, nu, "nu")
    return _coriolis_matrix(params, parsed, nu)


# --------------------------------------------------------------------------------------------------------
# Gravity (thesis §2.5.4 with erratum E2)
# --------------------------------------------------------------------------------------------------------
def _total_first_moment(params: FprParameters, parsed: ParsedConfiguration) -> np.ndarray:
    c = model_constants(params)
    return c.static_first_moment + np.einsum("nij,nj->i", parsed.leg_rotations, c.leg_first_moments)


def _gravity(params: FprParameters, parsed: ParsedConfiguration,
             first_moments: np.ndarray | None = None) -> np.ndarray:
    c = model_constants(params)
    p_g = -params.gravity * parsed.rotation[2]  # R_pᵀ g_vec (Fp)
    if first_moments is None:
        h_leg = np.einsum("nij,nj->ni", parsed.leg_rotations, c.leg_first_moments)  # pR_li ms_i
    else:
        h_leg = first_moments[1:]  # of _body_inertias_in_platform
    out = np.empty(6 + c.n)
    out[:2] = 0.0
    out[2] = c.total_mass * params.gravity  # f_p,g = −m_tot g_vec (2.88)
    # p_m_p,g = −(m_p s_p × p_g + Σ [pR_li (ms_i × li_g) + r p_r_i × m_i p_g]) (2.90, E2)
    #         = −h_total × p_g, h_total = m_p s_p + Σ (m_i a_i + pR_li ms_i).
    out[3:6] = cross3(p_g.tolist(), (c.static_first_moment + h_leg.sum(axis=0)).tolist())
    # m_i,g = −e_zᵀ (ms_i × li_g) = −k_i · (pR_li ms_i × p_g) = −(k_i × pR_li ms_i) · p_g  (2.91)
    out[6:] = -((_body_constants(params).axes_skew[1:] @ h_leg[:, :, None])[:, :, 0] @ p_g)
    return out


def gravity(params: FprParameters, q) -> np.ndarray:
    """Generalised gravity wrench g(q) = τ_g (2.86)-(2.91), erratum E2 applied (spec §2.2.4), (6+n,).

    ``f_p,g = [0, 0, m_tot g]`` (world), ``p_m_p,g = −(m_p s_p × p_g + Σ_i [pR_li (ms_i × li_g) + r p_r_i ×
    m_i p_g])`` (Fp), ``m_i,g = −e_zᵀ (ms_i × li_g)``, with ``p_g = R_pᵀ g_vec`` and ``li_g = pR_liᵀ p_g``.
    It is the actuation wrench that holds the robot still, and the gradient of the potential energy
    (w.r.t. p_p, a body-frame rotation of the platform and θ).
    """
    return _gravity(params, _parse_configuration(params, q))


# --------------------------------------------------------------------------------------------------------
# Actuation
# --------------------------------------------------------------------------------------------------------
def _thrust_vector(params: FprParameters, thrusts) -> np.ndarray:
    size = 3 * params.n
    if np.size(thrusts) != size or np.ndim(thrusts) not in (1, 2):
        raise ValueError(f"thrusts: expected {params.n}x3 or {size} values, got shape {np.shape(thrusts)}")
    return as_array("thrusts", np.asarray(thrusts, dtype=float).reshape(size), (size,))


def actuation_wrench(params: FprParameters, q, thrusts) -> np.ndarray:
    """Actuation wrench ``τ = J(q)ᵀ f`` (2.28), thrusts f of shape (n, 3) or (3n,), world frame, N."""
    J = _jacobian_from(params, _parse_configuration(params, q))
    return J.T @ _thrust_vector(params, thrusts)


def thrusts_from_wrench(params: FprParameters, q, tau) -> np.ndarray:
    """Quadrotor thrust vectors ``f = J^{-T} τ`` (thesis (3.32)), shape (n, 3), world frame, N.

    For n > 3 the minimum-norm solution ``f = (Jᵀ)^† τ = J (JᵀJ)^{-1} τ``. Raises
    SingularConfigurationError if
    ``cond(J)`` exceeds :data:`fpr_model.kinematics.CONDITION_LIMIT` (leg angles are not range-checked here).
    See :meth:`fpr_model.kinematics.JacobianAt.thrusts` (used directly by a caller that already has J^†).
    """
    parsed = _parse_configuration(params, q)
    tau = _velocity(params, tau, "tau")
    return _jacobian_at(params, parsed, False).thrusts(tau)


# --------------------------------------------------------------------------------------------------------
# All the model terms of one control step
# --------------------------------------------------------------------------------------------------------
class ModelTerms(NamedTuple):
    """M(q), C(q, ν) (6+n)², g(q) (6+n) of (2.25) and J(q) (2.20) with its pseudo-inverse, at one (q, ν), in
    the frame of q and ν (F0, or F_Fp for the decentralized controllers)."""

    mass: np.ndarray
    coriolis: np.ndarray
    gravity: np.ndarray
    jacobian: JacobianAt


def model_terms(params: FprParameters, jacobian: JacobianAt, nu) -> ModelTerms:
    """M (CRBA, :func:`mass_matrix`), C (:func:`coriolis_matrix`) and g (:func:`gravity`) at the configuration
    of ``jacobian`` (:func:`fpr_model.kinematics.jacobian_at`) and the velocity ν (6+n,): q is parsed once and
    the bodies' inertias in Fp are shared, instead of once per function."""
    parsed = jacobian.configuration
    nu = _velocity(params, nu, "nu")
    body_terms = _body_inertias_in_platform(params, parsed)
    return ModelTerms(_mass_matrix(params, parsed, body_terms), _coriolis_matrix(params, parsed, nu),
                      _gravity(params, parsed, body_terms[0]), jacobian)


# --------------------------------------------------------------------------------------------------------
# Forward dynamics, energies, integration
# --------------------------------------------------------------------------------------------------------
def _forward_dynamics(params, parsed, nu, tau_total, gravity_on: bool) -> np.ndarray:
    body_terms = _body_inertias_in_platform(params, parsed)
    M = _mass_matrix(params, parsed, body_terms)
    bias = _rnea(params, parsed, nu, np.zeros_like(nu), gravity_on, body_terms)
    return np.linalg.solve(M, tau_total - bias)


def forward_dynamics(params: FprParameters, q, nu, tau, external_wrench=None,
                     gravity: bool = True) -> np.ndarray:
    """Generalised acceleration ``ν̇ = M^{-1} (τ + τ_e − C ν − g)`` (2.26), (6+n,) [a_p (world), ω̇_p (Fp),
    θ̈].

    ``τ``, ``external_wrench`` τ_e: (6+n,) wrenches ``[f (world, N), m (Fp, N·m), joint moments]``.
    ``C ν + g`` is evaluated by RNEA with ν̇ = 0, M by CRBA; ``gravity=False`` drops g.
    """
    parsed = _parse_configuration(params, q)
    nu = _velocity(params, nu, "nu")
    total = _velocity(params, tau, "tau")
    if external_wrench is not None:
        total = total + _velocity(params, external_wrench, "external_wrench")
    return _forward_dynamics(params, parsed, nu, total, bool(gravity))


def kinetic_energy(params: FprParameters, q, nu) -> float:
    """T = ½ νᵀ M(q) ν [J]."""
    parsed = _parse_configuration(params, q)
    nu = _velocity(params, nu, "nu")
    return 0.5 * float(nu @ _mass_matrix(params, parsed) @ nu)


def potential_energy(params: FprParameters, q) -> float:
    """Potential energy U = Σ_k m_k g z_k = g (m_tot p_z + e_zᵀ R_p h_total) [J] (z_k: CoM heights, world).

    ``h_total`` is the first moment of the whole robot about P in Fp; U = 0 when P and the CoM are at z = 0.
    """
    parsed = _parse_configuration(params, q)
    c = model_constants(params)
    return params.gravity * (c.total_mass * parsed.position[2]
                             + float(parsed.rotation[2] @ _total_first_moment(params, parsed)))


def rk4_step(params: FprParameters, q, nu, tau, dt, external_wrench=None,
             gravity: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """One fixed-step classical RK4 step of the forward dynamics, τ and τ_e held constant; returns (q, ν).

    The state is integrated in its embedding: ``ṗ_p = v_p``, ``q̇_p = ½ q_p ∘ [0; ω_p]`` (A.84), ``θ̇``,
    ``ν̇`` from
    :func:`forward_dynamics`; the quaternion is re-normalised at the end of the step (4th order overall).
    ``dt`` in s.
    """
    n = params.n
    q = as_array("q", q, (7 + n,)).copy()
    nu = _velocity(params, nu, "nu")
    dt = as_scalar("dt", dt)
    total = _velocity(params, tau, "tau")
    if external_wrench is not None:
        total = total + _velocity(params, external_wrench, "external_wrench")
    gravity_on = bool(gravity)

    def derivative(qs: np.ndarray, vs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        parsed = _parse_configuration(params, qs)
        qd = np.empty(7 + n)
        qd[:3] = vs[:3]
        w, x, y, z = qs[3:7]
        ox, oy, oz = vs[3:6]
        qd[3] = 0.5 * (-x * ox - y * oy - z * oz)
        qd[4] = 0.5 * (w * ox + y * oz - z * oy)
        qd[5] = 0.5 * (w * oy - x * oz + z * ox)
        qd[6] = 0.5 * (w * oz + x * oy - y * ox)
        qd[7:] = vs[6:]
        return qd, _forward_dynamics(params, parsed, vs, total, gravity_on)

    k1q, k1v = derivative(q, nu)
    k2q, k2v = derivative(q + 0.5 * dt * k1q, nu + 0.5 * dt * k1v)
    k3q, k3v = derivative(q + 0.5 * dt * k2q, nu + 0.5 * dt * k2v)
    k4q, k4v = derivative(q + dt * k3q, nu + dt * k3v)
    q_next = q + dt / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
    nu_next = nu + dt / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
    q_next[3:7] /= np.linalg.norm(q_next[3:7])
    return q_next, nu_next
