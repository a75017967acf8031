"""Geometry of the FPR: configuration vector, leg anchors, leg rotations, inverse geometric model (thesis
§2.3).

Configuration ``q ∈ R^{7+n} = [p_p (3, world, m), q_p (4, [w,x,y,z], platform -> world), θ (n, rad)]`` (2.1).
Velocity ``ν ∈ R^{6+n} = [v_p (3, world, m/s), ω_p (3, platform frame Fp, rad/s), θ̇ (n, rad/s)]`` (2.2).

θ_i is the angle between the platform plane and leg i; θ_i = 0: leg in the platform plane (singular);
θ_i = π/2: leg perpendicular to the platform, pointing down (spec §0.1).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from fpr_model._math import cross, cross3, dot3, norm3, skew_batch
from fpr_model._validation import as_array, as_scalar, as_vector
from fpr_model.parameters import FprParameters, leg_mass_properties
from fpr_model.rotations import _quat_integrate_rotvec, _quat_to_rotmat, rotation_entries

__all__ = [
    "Configuration",
    "Velocity",
    "desired_uav_rotation",
    "difference_configuration",
    "integrate_configuration",
    "inverse_geometric_model",
    "leg_anchor_angles",
    "leg_angles_from_positions",
    "make_configuration",
    "platform_to_leg_rotation",
    "split_configuration",
    "split_velocity",
]


class Configuration(NamedTuple):
    """Parts of q: platform position (world, m), platform quaternion [w,x,y,z], leg angles (rad)."""

    platform_position: np.ndarray
    platform_quat: np.ndarray
    leg_angles: np.ndarray


class Velocity(NamedTuple):
    """Parts of ν: platform velocity (world, m/s), platform angular rate (Fp, rad/s), leg rates (rad/s)."""

    platform_velocity: np.ndarray
    platform_rate: np.ndarray
    leg_rates: np.ndarray


def leg_anchor_angles(n: int) -> np.ndarray:
    """α_i = 2π(i−1)/n, i = 1..n (thesis (2.7) with erratum E1): angle of P->A_i from x_p [rad]."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 3:
        raise ValueError(f"n: expected an integer >= 3, got {n!r}")
    return 2.0 * np.pi * np.arange(n) / n


def platform_to_leg_rotation(alpha, theta) -> np.ndarray:
    """``pR_li = Rz(α) Rx(−π/2) Rz(θ)`` (2.8): leg frame F_li -> platform frame Fp.

    ``[[cα cθ, −cα sθ, −sα], [sα cθ, −sα sθ, cα], [−sθ, −cθ, 0]]``. Broadcasts over array inputs
    (returns (..., 3, 3)).
    """
    alpha = np.asarray(alpha, dtype=float)
    theta = np.asarray(theta, dtype=float)
    if not (np.isfinite(alpha).all()):
        raise ValueError("alpha: contains NaN or inf")
    if not (np.isfinite(theta).all()):
        raise ValueError("theta: contains NaN or inf")
    alpha, theta = np.broadcast_arrays(alpha, theta)
    return _leg_rotations(np.cos(alpha), np.sin(alpha), theta)


def _leg_rotations(cos_alpha: np.ndarray, sin_alpha: np.ndarray, theta: np.ndarray) -> np.ndarray:
    ct, st = np.cos(theta), np.sin(theta)
    out = np.empty(np.shape(theta) + (3, 3))
    out[..., 0, 0] = cos_alpha * ct
    out[..., 0, 1] = -cos_alpha * st
    out[..., 0, 2] = -sin_alpha
    out[..., 1, 0] = sin_alpha * ct
    out[..., 1, 1] = -sin_alpha * st
    out[..., 1, 2] = cos_alpha
    out[..., 2, 0] = -st
    out[..., 2, 1] = -ct
    out[..., 2, 2] = 0.0
    return out


# --------------------------------------------------------------------------------------------------------
# Per-parameter constants, computed once per parameters object.
# --------------------------------------------------------------------------------------------------------
class ModelConstants(NamedTuple):
    """Constants derived from the parameters (all in Fp or F_li as noted); cached on the parameters object."""

    n: int
    cos_alpha: np.ndarray  # (n,)
    sin_alpha: np.ndarray  # (n,)
    anchors: np.ndarray  # (n, 3) a_i = r·p_r_i, P -> A_i in Fp [m]
    joint_axes: np.ndarray  # (n, 3) k_i = pR_li e_z = [−sα, cα, 0] in Fp
    leg_masses: np.ndarray  # (n,) m_i = m_l + m_b,i
    leg_first_moments: np.ndarray  # (n, 3) in F_li about A_i
    leg_inertias: np.ndarray  # (n, 3, 3) in F_li about A_i
    leg_inertia_z: np.ndarray  # (n, 3) I_i e_z
    leg_spatial_inertias: np.ndarray  # (n, 6, 6) [[I, [h]x], [[h]x^T, m 1]] in F_li at A_i
    platform_first_moment: np.ndarray  # (3,) m_p s_p in Fp
    platform_spatial_inertia: np.ndarray  # (6, 6) at P in Fp
    total_mass: float
    anchors_skew: np.ndarray  # (n, 3, 3) [a_i]x
    anchor_shift_inertia: np.ndarray  # (3, 3) Σ m_i (|a_i|² 1 − a_i a_iᵀ)
    static_first_moment: np.ndarray  # (3,) m_p s_p + Σ m_i a_i (θ-independent part of the first moment)
    leg_rotation_basis: np.ndarray  # (3, n, 3, 3): pR_li = cos θ_i·[0] + sin θ_i·[1] + [2]


def _spatial_inertia(mass, first_moment, inertia) -> np.ndarray:
    out = np.zeros(np.shape(mass) + (6, 6))
    hx = skew_batch(first_moment)
    out[..., :3, :3] = inertia
    out[..., :3, 3:] = hx
    out[..., 3:, :3] = np.swapaxes(hx, -1, -2)
    out[..., 3:, 3:] = np.asarray(mass)[..., None, None] * np.eye(3)
    return out


def model_constants(params: FprParameters) -> ModelConstants:
    """The per-parameter constants, computed on first use and cached on ``params`` (immutable)."""
    if not isinstance(params, FprParameters):
        raise ValueError(f"params: expected FprParameters, got {type(params).__name__}")
    cached = params._cache.get("constants")
    if cached is not None:
        return cached
    n = params.n
    alpha = leg_anchor_angles(n)
    ca, sa = np.cos(alpha), np.sin(alpha)
    zeros = np.zeros(n)
    anchors = params.platform_radius * np.stack([ca, sa, zeros], axis=1)
    axes = np.stack([-sa, ca, zeros], axis=1)
    legs = leg_mass_properties(params)
    platform_first_moment = params.platform_mass * params.platform_com
    shift = np.einsum("i,ijk->jk", legs.masses, np.einsum("ij,ij->i", anchors, anchors)[:, None, None]
                      * np.eye(3) - np.einsum("ij,ik->ijk", anchors, anchors))
    constants = ModelConstants(
        n=n,
        cos_alpha=ca,
        sin_alpha=sa,
        anchors=anchors,
        joint_axes=axes,
        leg_masses=legs.masses,
        leg_first_moments=legs.first_moments,
        leg_inertias=legs.inertias,
        leg_inertia_z=np.ascontiguousarray(legs.inertias[:, :, 2]),
        leg_spatial_inertias=_spatial_inertia(legs.masses, legs.first_moments, legs.inertias),
        platform_first_moment=platform_first_moment,
        platform_spatial_inertia=_spatial_inertia(params.platform_mass, platform_first_moment,
                                                  params.platform_inertia),
        total_mass=params.total_mass,
        anchors_skew=skew_batch(anchors),
        anchor_shift_inertia=shift,
        static_first_moment=platform_first_moment + legs.masses @ anchors,
        leg_rotation_basis=np.stack([
            _leg_rotations(ca, sa, np.zeros(n)),
            _leg_rotations(ca, sa, np.full(n, 0.5 * np.pi)),
            np.zeros((n, 3, 3)),
        ]),
    )
    # Split pR_li(θ) = cos θ·A + sin θ·B + D exactly: column 2 is constant, columns 0-1 are cos/sin mixes.
    basis = constants.leg_rotation_basis
    basis[2][:, :, 2] = basis[0][:, :, 2]
    basis[0][:, :, 2] = 0.0
    basis[1][:, :, 2] = 0.0
    basis[np.abs(basis) < 1e-15] = 0.0  # cos(π/2) round-off
    for array in constants:
        if isinstance(array, np.ndarray):
            array.setflags(write=False)
    params._cache["constants"] = constants
    return constants


# --------------------------------------------------------------------------------------------------------
# Configuration helpers
# --------------------------------------------------------------------------------------------------------
class ParsedConfiguration(NamedTuple):
    position: np.ndarray  # (3,)
    quat: np.ndarray  # (4,) unit
    rotation: np.ndarray  # (3, 3) R_p
    leg_angles: np.ndarray  # (n,)
    leg_rotations: np.ndarray  # (n, 3, 3) pR_li


def _parse_configuration(params: FprParameters, q, name: str = "q") -> ParsedConfiguration:
    """Validate q (shape (7+n,), finite, non-zero quaternion); normalise the quaternion; rotations."""
    constants = model_constants(params)
    q = as_array(name, q, (7 + constants.n,))
    w, x, y, z = q[3:7].tolist()
    norm2 = w * w + x * x + y * y + z * z
    if norm2 < 1e-12:
        raise ValueError(f"{name}: platform quaternion q[3:7] has (near) zero norm {norm2 ** 0.5}")
    if norm2 != 1.0:
        scale = norm2 ** -0.5
        w, x, y, z = w * scale, x * scale, y * scale, z * scale
    rotation = np.array(rotation_entries(w, x, y, z)).reshape(3, 3)  # (A.60) on plain floats
    theta = q[7:]
    basis = constants.leg_rotation_basis
    leg_rotations = (np.cos(theta)[:, None, None] * basis[0] + np.sin(theta)[:, None, None] * basis[1]
                     + basis[2])
    return ParsedConfiguration(q[:3], np.array([w, x, y, z]), rotation, theta, leg_rotations)


def make_configuration(platform_position, platform_quat, leg_angles) -> np.ndarray:
    """q = [p_p, q_p (normalised), θ] ∈ R^{7+n} from its parts (n = len(leg_angles) >= 3)."""
    position = as_array("platform_position", platform_position, (3,))
    quat = as_array("platform_quat", platform_quat, (4,))
    norm = np.linalg.norm(quat)
    if norm < 1e-6:
        raise ValueError(f"platform_quat: (near) zero norm {norm}")
    angles = as_vector("leg_angles", leg_angles, 3)
    return np.concatenate([position, quat / norm, angles])


def split_configuration(q) -> Configuration:
    """Split q ∈ R^{7+n} into (platform_position, platform_quat, leg_angles) (copies)."""
    q = as_vector("q", q, 10)
    return Configuration(q[:3].copy(), q[3:7].copy(), q[7:].copy())


def split_velocity(nu) -> Velocity:
    """Split ν ∈ R^{6+n} into (platform_velocity, platform_rate, leg_rates) (copies)."""
    nu = as_vector("nu", nu, 9)
    return Velocity(nu[:3].copy(), nu[3:6].copy(), nu[6:].copy())


def integrate_configuration(q, nu, dt) -> np.ndarray:
    """q ⊕ ν·dt: position and leg angles by Euler, quaternion by the exact exponential map of the
    body-frame rate: ``q_p ∘ exp(ω_p dt / 2)`` (renormalised). dt in s (may be negative)."""
    q = as_vector("q", q, 10)
    nu = as_array("nu", nu, (q.size - 1,))
    dt = as_scalar("dt", dt)
    out = q.copy()
    out[:3] += nu[:3] * dt
    out[7:] += nu[6:] * dt
    out[3:7] = _quat_integrate_rotvec(q[3:7], nu[3:6] * dt)
    return out


def difference_configuration(q0, q1) -> np.ndarray:
    """The constant velocity ν′ that takes q0 to q1 in unit time: ``integrate_configuration(q0, ν′, 1) ==
    q1``.

    Rotation part: ``ω′ = rotvec(q_p0^{-1} ∘ q_p1)`` (shortest rotation, body frame of q0).
    """
    q0 = as_vector("q0", q0, 10)
    q1 = as_array("q1", q1, q0.shape)
    from fpr_model.rotations import quat_error, quat_to_rotvec

    out = np.empty(q0.size - 1)
    out[:3] = q1[:3] - q0[:3]
    quat0 = q0[3:7] / np.linalg.norm(q0[3:7])
    out[3:6] = quat_to_rotvec(quat_error(quat0, q1[3:7] / np.linalg.norm(q1[3:7])))
    out[6:] = q1[7:] - q0[7:]
    return out


# --------------------------------------------------------------------------------------------------------
# Inverse geometric model
# --------------------------------------------------------------------------------------------------------
def inverse_geometric_model(params: FprParameters, q) -> np.ndarray:
    """IGM (2.5)-(2.9): quadrotor CoM positions ``p_i = p_p + R_p (r·p_r_i + l·pR_li e_x)``, (n, 3), world, m.

    The spherical-joint offset d is neglected (thesis §2.3.3).
    """
    parsed = _parse_configuration(params, q)
    constants = model_constants(params)
    body = constants.anchors + params.leg_length * parsed.leg_rotations[:, :, 0]
    return parsed.position + body @ parsed.rotation.T


def leg_angles_from_positions(params: FprParameters, platform_position, platform_quat, uav_positions,
                              signed: bool = False) -> np.ndarray:
    """Leg angles from the platform pose and the quadrotor positions (2.11)-(2.12), rad, shape (n,).

    ``θ_i = acos(PA_i · A_iB_i / (‖PA_i‖ ‖A_iB_i‖))`` with ``PA_i = R_p r p_r_i`` and
    ``A_iB_i = p_i − (p_p + PA_i)`` (world frame). Evaluated as ``atan2(‖PA_i × A_iB_i‖, PA_i · A_iB_i)``
    (same angle in [0, π], accurate near 0). With ``signed=True`` the angle is measured in the leg plane,
    positive below the platform: ``atan2(−z_p · A_iB_i, p_r_i · A_iB_i)`` (Fp components), which equals
    the thesis value on the nominal branch and becomes negative when a quadrotor rises above the platform
    plane.
    """
    position = as_array("platform_position", platform_position, (3,))
    quat = as_array("platform_quat", platform_quat, (4,))
    norm = np.linalg.norm(quat)
    if norm < 1e-6:
        raise ValueError(f"platform_quat: (near) zero norm {norm}")
    constants = model_constants(params)
    uav = as_array("uav_positions", uav_positions, (constants.n, 3))
    rotation = _quat_to_rotmat(quat / norm)
    leg_vectors = (uav - position) @ rotation - constants.anchors  # A_iB_i in Fp
    radial = np.stack([constants.cos_alpha, constants.sin_alpha, np.zeros(constants.n)], axis=1)
    along = np.einsum("ij,ij->i", leg_vectors, radial)
    if signed:
        return np.arctan2(-leg_vectors[:, 2], along)
    across = np.linalg.norm(cross(radial, leg_vectors), axis=1)
    return np.arctan2(across, along)


def desired_uav_rotation(thrust_vector: np.ndarray, leg_direction: np.ndarray, beta: float,
                         fallback_radial: np.ndarray | None = None) -> np.ndarray:
    """Desired quadrotor attitude (body FLU -> the frame F of the vectors, e.g. F0 or F_Fp):
    R^d_i = [x^d, z^d × x^d, z^d] (3.38) with z^d = f_i/‖f_i‖ (3.36) and (3.37) (erratum E12: columns):
    ``x' = l_i × z^d`` (normalised), ``x^d = AxisAngle(z^d, β − π/2) x'``; l_i = unit A_i -> B_i in F.
    This puts x^d at the signed angle +β about z^d from the horizontal projection of −l_i (spec §1.7).
    The axis-angle rotation is Rodrigues' formula (A.58, erratum E13), on plain floats (3-vectors).

    If l_i ∥ z^d the rule is undefined; then ``fallback_radial`` (the outward leg anchor direction, or x of F)
    replaces l_i. A zero thrust vector gives z^d = +z."""
    f = np.asarray(thrust_vector, dtype=float).tolist()
    norm = norm3(f)
    z_axis = (f[0] / norm, f[1] / norm, f[2] / norm) if norm > 1e-9 else (0.0, 0.0, 1.0)
    x_prime = cross3(np.asarray(leg_direction, dtype=float).tolist(), z_axis)
    if norm3(x_prime) < 1e-6:
        radial = (np.asarray(fallback_radial, dtype=float).tolist() if fallback_radial is not None
                  else (1.0, 0.0, 0.0))
        x_prime = cross3(radial, z_axis)
        if norm3(x_prime) < 1e-6:
            x_prime = cross3((0.0, 1.0, 0.0), z_axis)
    norm = norm3(x_prime)
    x_prime = (x_prime[0] / norm, x_prime[1] / norm, x_prime[2] / norm)
    # (A.58): x = cos φ x' + sin φ (z × x') + (1 − cos φ)(z · x') z, φ = β − π/2
    angle = beta - 0.5 * math.pi
    c, s = math.cos(angle), math.sin(angle)
    zx = cross3(z_axis, x_prime)
    along = (1.0 - c) * dot3(z_axis, x_prime)
    x_axis = [c * x_prime[k] + s * zx[k] + along * z_axis[k] for k in range(3)]
    along = dot3(x_axis, z_axis)  # remove round-off
    x_axis = [x_axis[k] - z_axis[k] * along for k in range(3)]
    norm = norm3(x_axis)
    x_axis = (x_axis[0] / norm, x_axis[1] / norm, x_axis[2] / norm)
    y_axis = cross3(z_axis, x_axis)
    return np.array([[x_axis[0], y_axis[0], z_axis[0]],
                     [x_axis[1], y_axis[1], z_axis[1]],
                     [x_axis[2], y_axis[2], z_axis[2]]])
