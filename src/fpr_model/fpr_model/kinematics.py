"""First- and second-order kinematics of the FPR (thesis §2.4).

IKM ``v = J(q) ν`` (2.20): ``v = [v_1; ...; v_n]`` quadrotor CoM velocities (world, m/s),
``ν = [v_p (world); ω_p (Fp); θ̇]``. FKM ``ν = J^† v`` (2.21). Second order ``v̇ = J ν̇ + J̇ ν``
(2.22)-(2.24).

J is singular when a leg lies in the platform plane (θ_i = 0) and regular on (0, π/2] (Six 2018; spec §1.2).
The forward models refuse configurations outside that range or with ``cond(J) > CONDITION_LIMIT``.

:class:`JacobianAt` holds J at one configuration and, on first use, its pseudo-inverse J^† with that check: a
control step builds it once and uses it for the FKM (2.21), the actuation wrench (2.28) and the thrust
distribution (3.32) of the same configuration, instead of recomputing J (and its SVD) in each.
"""

from __future__ import annotations

import numpy as np

from fpr_model._math import cross, skew_batch
from fpr_model._validation import as_array
from fpr_model.geometry import ParsedConfiguration, _parse_configuration, model_constants
from fpr_model.parameters import FprParameters

__all__ = [
    "CONDITION_LIMIT",
    "JacobianAt",
    "SingularConfigurationError",
    "check_regular_configuration",
    "forward_acceleration",
    "forward_kinematics",
    "jacobian",
    "jacobian_at",
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


def _check_leg_range(parsed: ParsedConfiguration) -> None:
    angles = parsed.leg_angles
    bad = np.flatnonzero((angles <= 0.0) | (angles > 0.5 * np.pi))
    if bad.size:
        raise SingularConfigurationError(
            f"q: leg angle(s) {angles[bad].tolist()} rad of leg(s) {(bad + 1).tolist()} outside (0, pi/2]"
        )


def _check_condition(J: np.ndarray) -> float:
    """cond(J) (2-norm, by SVD); SingularConfigurationError when it exceeds :data:`CONDITION_LIMIT`."""
    condition = float(np.linalg.cond(J))
    if not condition <= CONDITION_LIMIT:
        raise SingularConfigurationError(f"q: J is (near) singular, cond(J) = {condition:.3g}")
    return condition


def _frobenius(a: np.ndarray) -> float:
    flat = a.ravel()
    return float(np.dot(flat, flat)) ** 0.5


def _pseudo_inverse(J: np.ndarray) -> np.ndarray:
    """J^† of a regular J: J^{-1} (LU) for n = 3, ``R^{-1} Qᵀ`` from the reduced QR ``J = Q R`` (the
    least-squares pseudo-inverse, = (JᵀJ)^{-1} Jᵀ) for n > 3. SingularConfigurationError when
    ``cond(J) > CONDITION_LIMIT``.

    The test needs no SVD in the regular case: ``cond(J) = ‖J‖₂ ‖J^†‖₂ ≤ ‖J‖_F ‖J^†‖_F`` (the 2-norm is at most
    the Frobenius norm), so ``‖J‖_F ‖J^†‖_F ≤ CONDITION_LIMIT`` proves ``cond(J) ≤ CONDITION_LIMIT``. Only when
    that bound fails (it exceeds cond(J) by at most a factor 6 + n, so only near a singularity) is cond(J)
    computed exactly. The accepted configurations are therefore exactly those of ``np.linalg.cond(J) ≤
    CONDITION_LIMIT``, as in :func:`check_regular_configuration`."""
    try:
        if J.shape[0] == J.shape[1]:
            inverse = np.linalg.inv(J)
        else:
            Q, R = np.linalg.qr(J)
            inverse = np.linalg.solve(R, Q.T)
    except np.linalg.LinAlgError:
        inverse = None
    if inverse is None or not _frobenius(J) * _frobenius(inverse) <= CONDITION_LIMIT:
        _check_condition(J)
        if inverse is None:  # exactly singular in floating point although cond(J) rounds below the limit
            raise SingularConfigurationError("q: J is singular")
    return inverse


class JacobianAt:
    """J(q) (2.20) at one configuration and its pseudo-inverse J^† (computed, with the singularity test of
    :func:`check_regular_configuration` on cond(J), on first use of :attr:`inverse`).

    Attributes: ``configuration`` (the parsed q), ``matrix`` J ∈ R^{3n×(6+n)} (world rows, ν columns)."""

    __slots__ = ("configuration", "matrix", "_inverse")

    def __init__(self, configuration: ParsedConfiguration, matrix: np.ndarray) -> None:
        self.configuration = configuration
        self.matrix = matrix
        self._inverse: np.ndarray | None = None

    @property
    def inverse(self) -> np.ndarray:
        """J^† ∈ R^{(6+n)×3n}: J^{-1} for n = 3, the least-squares pseudo-inverse for n > 3 (J has full column
        rank). Raises SingularConfigurationError when ``cond(J) > CONDITION_LIMIT``."""
        if self._inverse is None:
            self._inverse = _pseudo_inverse(self.matrix)
        return self._inverse

    def velocity(self, uav_velocities: np.ndarray) -> np.ndarray:
        """FKM (2.21): ``ν = J^† v`` from v = [v_1; …; v_n] (3n,) [m/s, world]; ν (6+n,) (unchecked input)."""
        return self.inverse @ uav_velocities

    def thrusts(self, tau: np.ndarray) -> np.ndarray:
        """Thrust distribution (3.32): ``f = (Jᵀ)^† τ = (J^†)ᵀ τ`` (n = 3: J^{-T} τ; n > 3: the minimum-norm
        f with ``Jᵀ f = τ`` (2.28)), τ (6+n,) [N, N·m] in the wrench layout; f (n, 3) [N, world]."""
        return (tau @ self.inverse).reshape(-1, 3)


def _jacobian_at(params: FprParameters, parsed: ParsedConfiguration, check_leg_range: bool) -> JacobianAt:
    if check_leg_range:
        _check_leg_range(parsed)
    return JacobianAt(parsed, _jacobian_from(params, parsed))


def jacobian_at(params: FprParameters, q, check_leg_range: bool = True) -> JacobianAt:
    """:class:`JacobianAt` for q (7+n,); SingularConfigurationError at once if ``check_leg_range`` and a leg angle
    is outside (0, π/2], and on the first use of J^† if ``cond(J) > CONDITION_LIMIT``."""
    return _jacobian_at(params, _parse_configuration(params, q), check_leg_range)


def check_regular_configuration(params: FprParameters, q, J: np.ndarray | None = None,
                                check_leg_range: bool = True) -> float:
    """Raise SingularConfigurationError if a leg angle is outside (0, π/2] (when ``check_leg_range``) or
    ``cond(J) > CONDITION_LIMIT``; return cond(J) otherwise."""
    parsed = _parse_configuration(params, q)
    if check_leg_range:
        _check_leg_range(parsed)
    return _check_condition(_jacobian_from(params, parsed) if J is None else J)


def _stacked(params: FprParameters, name: str, value) -> np.ndarray:
    """(n, 3) or (3n,) quadrotor vectors as a checked (3n,) array."""
    size = 3 * params.n
    if np.size(value) != size:
        raise ValueError(f"{name}: expected {params.n}x3 values, got shape {np.shape(value)}")
    return as_array(name, np.asarray(value, dtype=float).reshape(-1), (size,))


def forward_kinematics(params: FprParameters, q, uav_velocities, check_leg_range: bool = True) -> np.ndarray:
    """FKM (2.21): ``ν = J^† v`` from the quadrotor velocities (n, 3) or (3n,), world, m/s.

    J^† = J^{-1} for n = 3, the least-squares pseudo-inverse for n > 3. Raises SingularConfigurationError
    near singular configurations (see :func:`check_regular_configuration`).
    """
    parsed = _parse_configuration(params, q)
    v = _stacked(params, "uav_velocities", uav_velocities)
    return _jacobian_at(params, parsed, check_leg_range).velocity(v)


def forward_acceleration(params: FprParameters, q, nu, uav_accelerations,
                         check_leg_range: bool = True) -> np.ndarray:
    """Second-order FKM (2.24): ``ν̇ = J^† (v̇ − J̇ ν)``, quadrotor accelerations (n, 3) or (3n,), world,
    m/s²."""
    parsed = _parse_configuration(params, q)
    nu = as_array("nu", nu, (6 + params.n,))
    a = _stacked(params, "uav_accelerations", uav_accelerations)
    return _jacobian_at(params, parsed, check_leg_range).velocity(a - jacobian_dot(params, q, nu) @ nu)
