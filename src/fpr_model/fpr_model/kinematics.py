"""First- and second-order kinematics of the FPR (thesis §2.4).

IKM ``v = J(q) ν`` (2.20): ``v = [v_1; ...; v_n]`` quadrotor CoM velocities (world, m/s),
``ν = [v_p (world); ω_p (Fp); θ̇]``. FKM ``ν = J^† v`` (2.21). Second order ``v̇ = J ν̇ + J̇ ν``
(2.22)-(2.24).

J is singular when a leg lies in the platform plane (θ_i = 0) and regular on (0, π/2] (Six 2018; spec §1.2).
The forward models refuse configurations outside that range or with ``cond(J) > CONDITION_LIMIT``.
"""

from __future__ import annotations

import numpy as np

from fpr_model._math import cross, skew_batch
from fpr_model._validation import as_array
from fpr_model.geometry import ParsedConfiguration, _parse_configuration, model_constants
from fpr_model.parameters import FprParameters

__all__ = [
    "CONDITION_LIMIT",
    "SingularConfigurationError",
    "check_regular_configuration",
    "forward_acceleration",
    "forward_kinematics",
    "jacobian",
    "jacobian_dot",
    "uav_accelerations",
    "uav_velocities",
]

#: Largest accepted 2-norm condition number of J in the forward models. For Table B.1, cond(J) is about 16 at
#: θ = 45°, 190 at 5°, 1.9e3 at 0.5° and 1.9e4 at 0.05° (it grows like 1/θ): 1e6 accepts leg angles down to
#: about 1e-3 degree, where one mm/s of quadrotor velocity already maps to metres per second of leg rate.
CONDITION_LIMIT = 1e6


class SingularConfigurationError(ValueError):
    """The configuration is (near) a singularity of J: a leg angle outside (0, π/2] or cond(J) too large."""


def _jacobian_from(params: FprParameters, parsed: ParsedConfiguration) -> np.ndarray:
    constants = model_constants(params)
    n = constants.n
    template = params._cache.get("jacobian_template")
    if template is None:
        template = np.zeros((n, 3, 6 + n))
        template[:, :, :3] = np.eye(3)
        params._cache["jacobian_template"] = template
    J = template.copy()
    R = parsed.rotation
    lever = constants.anchors + params.leg_length * parsed.leg_rotations[:, :, 0]  # ρ_i = P -> B_i in Fp
    J[:, :, 3:6] = -(R @ skew_batch(lever))  # J_ωi = −R_p [ρ_i]x
    legs = np.arange(n)
    J[legs, :, 6 + legs] = params.leg_length * (parsed.leg_rotations[:, :, 1] @ R.T)  # l·y_li
    return J.reshape(3 * n, 6 + n)


def jacobian(params: FprParameters, q) -> np.ndarray:
    """Kinematic Jacobian J(q) ∈ R^{3n×(6+n)} of (2.20): ``v = J ν``.

    Block row i: ``[1_3, J_ωi, l·y_li in column 6+i]`` with ``J_ωi = −R_p [r·p_r_i + l·p_l_i]×`` (the
    platform-rate lever of B_i, ``J_ωi ω = R_p (ω × ρ_i)``) and ``y_li = R_p pR_li e_y`` (world).
    """
    return _jacobian_from(params, _parse_configuration(params, q))


def jacobian_dot(params: FprParameters, q, nu) -> np.ndarray:
    """Time derivative J̇(q, ν) ∈ R^{3n×(6+n)} of (2.23).

    ``J̇_ωi = −R_p ([ω_p]× [ρ_i]× + [ρ̇_i]×)`` with ``ρ̇_i = l θ̇_i pR_li e_y`` (Fp), and
    ``ẏ_li = R_p (ω_p × pR_li e_y − θ̇_i pR_li e_x)``; the first three columns are zero.
    """
    parsed = _parse_configuration(params, q)
    constants = model_constants(params)
    n = constants.n
    nu = as_array("nu", nu, (6 + n,))
    omega, rates = nu[3:6], nu[6:]
    R = parsed.rotation
    leg_x = parsed.leg_rotations[:, :, 0]
    leg_y = parsed.leg_rotations[:, :, 1]
    lever = constants.anchors + params.leg_length * leg_x
    lever_rate = params.leg_length * rates[:, None] * leg_y
    omega_skew = skew_batch(omega)
    Jd = np.zeros((n, 3, 6 + n))
    Jd[:, :, 3:6] = -(R @ (omega_skew @ skew_batch(lever) + skew_batch(lever_rate)))
    y_rate = (cross(omega, leg_y) - rates[:, None] * leg_x) @ R.T
    legs = np.arange(n)
    Jd[legs, :, 6 + legs] = params.leg_length * y_rate
    return Jd.reshape(3 * n, 6 + n)


def uav_velocities(params: FprParameters, q, nu) -> np.ndarray:
    """IKM (2.20): quadrotor CoM velocities ``J(q) ν``, shape (n, 3), world frame, m/s."""
    J = jacobian(params, q)
    nu = as_array("nu", nu, (J.shape[1],))
    return (J @ nu).reshape(-1, 3)


def uav_accelerations(params: FprParameters, q, nu, nu_dot) -> np.ndarray:
    """Second-order IKM (2.22): ``J ν̇ + J̇ ν``, shape (n, 3), world frame, m/s²."""
    J = jacobian(params, q)
    nu = as_array("nu", nu, (J.shape[1],))
    nu_dot = as_array("nu_dot", nu_dot, (J.shape[1],))
    return (J @ nu_dot + jacobian_dot(params, q, nu) @ nu).reshape(-1, 3)


def check_regular_configuration(params: FprParameters, q, J: np.ndarray | None = None,
                                check_leg_range: bool = True) -> float:
    """Raise SingularConfigurationError if a leg angle is outside (0, π/2] (when ``check_leg_range``) or
    ``cond(J) > CONDITION_LIMIT``; return cond(J) otherwise."""
    parsed = _parse_configuration(params, q)
    if check_leg_range:
        angles = parsed.leg_angles
        bad = np.flatnonzero((angles <= 0.0) | (angles > 0.5 * np.pi))
        if bad.size:
            raise SingularConfigurationError(
                f"q: leg angle(s) {angles[bad].tolist()} rad of leg(s) {(bad + 1).tolist()} outside (0, pi/2]"
            )
    if J is None:
        J = _jacobian_from(params, parsed)
    condition = float(np.linalg.cond(J))
    if not condition <= CONDITION_LIMIT:
        raise SingularConfigurationError(
            f"q: J is (near) singular, cond(J) = {condition:.3g} > {CONDITION_LIMIT:g}"
        )
    return condition


def _solve_jacobian(J: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    if J.shape[0] == J.shape[1]:
        return np.linalg.solve(J, rhs)
    return np.linalg.lstsq(J, rhs, rcond=None)[0]  # J^† rhs (least squares, J has full column rank)


def forward_kinematics(params: FprParameters, q, uav_velocities, check_leg_range: bool = True) -> np.ndarray:
    """FKM (2.21): ``ν = J^† v`` from the quadrotor velocities (n, 3) or (3n,), world, m/s.

    J^† = J^{-1} for n = 3, the least-squares pseudo-inverse for n > 3. Raises SingularConfigurationError
    near singular configurations (see :func:`check_regular_configuration`).
    """
    parsed = _parse_configuration(params, q)
    J = _jacobian_from(params, parsed)
    v = np.asarray(uav_velocities, dtype=float).reshape(-1) if np.size(uav_velocities) == J.shape[0] else None
    if v is None:
        raise ValueError(
            f"uav_velocities: expected {J.shape[0] // 3}x3 values, got shape {np.shape(uav_velocities)}"
        )
    v = as_array("uav_velocities", v, (J.shape[0],))
    check_regular_configuration(params, q, J, check_leg_range)
    return _solve_jacobian(J, v)


def forward_acceleration(params: FprParameters, q, nu, uav_accelerations,
                         check_leg_range: bool = True) -> np.ndarray:
    """Second-order FKM (2.24): ``ν̇ = J^† (v̇ − J̇ ν)``, quadrotor accelerations (n, 3) or (3n,), world,
    m/s²."""
    parsed = _parse_configuration(params, q)
    J = _jacobian_from(params, parsed)
    nu = as_array("nu", nu, (J.shape[1],))
    if np.size(uav_accelerations) != J.shape[0]:
        raise ValueError(
            f"uav_accelerations: expected {J.shape[0] // 3}x3 values, got shape {np.shape(uav_accelerations)}"
        )
    a = as_array("uav_accelerations", np.asarray(uav_accelerations, dtype=float).reshape(-1), (J.shape[0],))
    check_regular_configuration(params, q, J, check_leg_range)
    return _solve_jacobian(J, a - jacobian_dot(params, q, nu) @ nu)
