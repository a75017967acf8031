"""Rotations and quaternions: the one rotation module of the fpr project (thesis Appendix A).

Conventions (DESIGN.md §2, spec §0.1):

- Quaternions are numpy arrays ``[w, x, y, z]`` (scalar first), Hamilton product (A.48).
- A rotation matrix / quaternion maps **body** coordinates to **world** coordinates:
  ``v_world = R @ v_body = q ∘ [0, v_body] ∘ q̄`` (A.38), (A.55).
- Angular rates ``body_rate`` are expressed in the body frame (``Aω`` of the thesis).
- Euler ZYX: ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (A.43); Euler ZXZ: ``R = Rz(psi1) @ Rx(phi) @ Rz(psi2)``
  (A.44). Angles in radians.

Errata applied (spec §0.2): E13 (Rodrigues), E14 (third component of (A.62)), E15 (yaw of (A.72)),
E16 (ZXZ from matrix entries), E17 (det R = +1).

Most functions accept leading batch dimensions (``(..., 4)`` quaternions, ``(..., 3, 3)`` matrices);
the documented signatures are the scalar ones.

Each formula is written once, as a kernel on components (``_hamilton``, :func:`rotation_entries`,
``_euler_zyx_quat``, ``_euler_zyx_angles``) that works on plain floats as on numpy arrays: a single quaternion,
vector or angle is evaluated on Python floats (numpy costs about 1 µs per call on 4-vectors, the float
arithmetic tens of ns: these run several times per control step and per simulator step), a batch on arrays.
"""

from __future__ import annotations

import math

import numpy as np

from fpr_model._math import cross3, skew_batch
from fpr_model._validation import as_angles, as_array, as_scalar, as_trailing

__all__ = [
    "attitude_error_vector",
    "quat_angle",
    "euler_rate_matrix",
    "euler_rate_matrix_dot",
    "euler_rate_matrix_inverse",
    "euler_zxz_to_rotmat",
    "euler_zyx_to_quat",
    "euler_zyx_to_rotmat",
    "quat_conjugate",
    "quat_derivative",
    "quat_error",
    "quat_from_axis_angle",
    "quat_from_rotvec",
    "quat_integrate",
    "quat_inverse",
    "quat_left_matrix",
    "quat_multiply",
    "quat_normalize",
    "quat_right_matrix",
    "quat_rotate",
    "quat_to_axis_angle",
    "quat_to_euler_zyx",
    "quat_to_rotmat",
    "quat_to_rotvec",
    "rot_x",
    "rot_y",
    "rot_z",
    "rotmat_to_euler_zxz",
    "rotmat_to_euler_zyx",
    "rotation_entries",
    "rotmat_to_quat",
    "skew",
]

#: Below this sine of the middle Euler angle, the Euler decompositions are treated as gimbal-locked.
GIMBAL_LOCK_TOLERANCE = 1e-12


# --------------------------------------------------------------------------------------------------------
# Basic matrices
# --------------------------------------------------------------------------------------------------------
def skew(v) -> np.ndarray:
    """Skew-symmetric cross-product matrix ``[v]×`` (A.50), so that ``skew(a) @ b == cross(a, b)``.

    ``v``: (3,) or (..., 3). Returns (3, 3) or (..., 3, 3).
    """
    v = as_trailing("v", v, (3,))
    return skew_batch(v)


def _elementary(angle, axis: int, name: str) -> np.ndarray:
    a = as_angles(name, angle)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    out[..., axis, axis] = 1.0
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


def rot_x(a) -> np.ndarray:
    """Elementary rotation about x by ``a`` rad (A.40): ``[[1,0,0],[0,c,-s],[0,s,c]]``."""
    return _elementary(a, 0, "a")


def rot_y(a) -> np.ndarray:
    """Elementary rotation about y by ``a`` rad (A.41): ``[[c,0,s],[0,1,0],[-s,0,c]]``."""
    return _elementary(a, 1, "a")


def rot_z(a) -> np.ndarray:
    """Elementary rotation about z by ``a`` rad (A.42): ``[[c,-s,0],[s,c,0],[0,0,1]]``."""
    return _elementary(a, 2, "a")


# --------------------------------------------------------------------------------------------------------
# Quaternion algebra
# --------------------------------------------------------------------------------------------------------
def _components(a: np.ndarray) -> list:
    """The last-axis components of ``a``: Python floats for one vector, arrays over the batch otherwise."""
    if a.ndim == 1:
        return a.tolist()
    return [a[..., k] for k in range(a.shape[-1])]


def _assemble(components, batched: bool) -> np.ndarray:
    """Inverse of :func:`_components`: stack the components on the last axis."""
    return np.stack(components, axis=-1) if batched else np.array(components)


def _hamilton(aw, ax, ay, az, bw, bx, by, bz) -> tuple:
    """Components of the Hamilton product ``a ∘ b`` (A.48) (floats or arrays)."""
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def _quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    batched = a.ndim > 1 or b.ndim > 1
    if batched:
        a, b = np.broadcast_arrays(a, b)
    return _assemble(_hamilton(*_components(a), *_components(b)), batched)


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product ``a ∘ b`` (A.48): ``[a0 b0 − a·b ; a0 b + b0 a + a × b]``. Shapes (..., 4)."""
    return _quat_multiply(as_trailing("a", a, (4,)), as_trailing("b", b, (4,)))


def quat_conjugate(q) -> np.ndarray:
    """Conjugate ``q̄ = [q0, −q1:3]`` (A.47)."""
    q = as_trailing("q", q, (4,))
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_inverse(q) -> np.ndarray:
    """Inverse ``q^{-1} = q̄ / ‖q‖²``; raises ValueError for a zero quaternion."""
    q = as_trailing("q", q, (4,))
    norm2 = np.sum(q * q, axis=-1, keepdims=True)
    if np.any(norm2 <= 0.0):
        raise ValueError("q: zero quaternion has no inverse")
    return q * np.array([1.0, -1.0, -1.0, -1.0]) / norm2


def inverse_pose(position, quat) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of a pose: for the child frame's origin ``position`` and orientation ``quat`` [w, x, y, z] in
    the parent, the parent's origin and orientation in the child: ``(−R^T t, q^-1)``."""
    inverse = quat_inverse(np.asarray(quat, dtype=float))
    return -quat_rotate(inverse, np.asarray(position, dtype=float)), inverse


def quat_normalize(q) -> np.ndarray:
    """Unit quaternion ``q / ‖q‖``; raises ValueError on a zero, NaN or inf quaternion."""
    q = as_trailing("q", q, (4,))
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-300):
        raise ValueError("q: cannot normalize a zero quaternion")
    return q / norm


def quat_rotate(q, v) -> np.ndarray:
    """Rotate ``v`` by the unit quaternion ``q`` (A.55): ``[0; z] = q ∘ [0; v] ∘ q̄``, i.e. ``R(q) @ v``.

    Uses ``z = v + 2 q0 (u × v) + 2 u × (u × v)`` with ``u = q1:3`` (no normalisation is applied).
    One q and one v (the estimators' and bridges' per-message case) are rotated on plain floats with the same
    operations in the same order as the array form, so the result is bit-identical (``test_rotations``), at
    ~1/5 of the cost (issue 15).
    """
    single = _single_rotation(q, v)
    if single is not None:
        return np.array(single)
    q = as_trailing("q", q, (4,))
    v = as_trailing("v", v, (3,))
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + q[..., :1] * t + np.cross(u, t)


def _single_rotation(q, v) -> tuple[float, float, float] | None:
    """:func:`quat_rotate` of one float64 (4,) array ``q`` and one (3,) array ``v``, both finite, as plain floats;
    None for anything else (the array path then converts, checks and raises)."""
    if type(q) is not np.ndarray or type(v) is not np.ndarray or q.shape != (4,) or v.shape != (3,) \
            or q.dtype != np.float64 or v.dtype != np.float64:
        return None
    w, x, y, z = q.tolist()
    vector = v.tolist()
    if not all(map(math.isfinite, (w, x, y, z, *vector))):
        return None
    u = (x, y, z)
    cx, cy, cz = cross3(u, vector)
    t = (2.0 * cx, 2.0 * cy, 2.0 * cz)  # np.cross's component order and operations (a1 b2 − a2 b1, …)
    ux, uy, uz = cross3(u, t)
    return vector[0] + w * t[0] + ux, vector[1] + w * t[1] + uy, vector[2] + w * t[2] + uz


def rotation_entries(w, x, y, z) -> tuple:
    """Row-major entries ``(r00, r01, …, r22)`` of the rotation matrix of the quaternion ``[w, x, y, z]``
    (A.60), body -> world, the quaternion used as given (not normalised). Plain floats (or arrays of them):
    the kernel of :func:`quat_to_rotmat`, for callers that want the entries, not a matrix."""
    return (w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
            2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x),
            2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z)


def _quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    entries = rotation_entries(*_components(q))
    if q.ndim == 1:
        return np.array(entries).reshape(3, 3)
    out = np.empty(q.shape[:-1] + (3, 3))
    for k, entry in enumerate(entries):
        out[..., k // 3, k % 3] = entry
    return out


def quat_tilt(q) -> np.ndarray | float:
    """Tilt [rad]: the angle between the body z axis of ``q`` ([w, x, y, z], body -> world, or (N, 4)) and the
    world z axis, from R_33 = 1 - 2(x² + y²)."""
    q = np.asarray(q, dtype=float)
    cos_tilt = 1.0 - 2.0 * (q[..., 1] ** 2 + q[..., 2] ** 2)
    tilt = np.arccos(np.clip(cos_tilt, -1.0, 1.0))
    return float(tilt) if tilt.ndim == 0 else tilt


def quat_to_rotmat(q) -> np.ndarray:
    """Rotation matrix of a unit quaternion (A.60), body -> world. ``q`` (..., 4) -> (..., 3, 3).

    The quaternion is used as given (not normalised): pass unit quaternions.
    """
    return _quat_to_rotmat(as_trailing("q", q, (4,)))


def rotmat_to_quat(R) -> np.ndarray:
    """Unit quaternion of a rotation matrix, with ``w >= 0`` (A.61)-(A.66), erratum E14 applied.

    The four branches (A.62)-(A.65) compute the largest of ``|q0|, |q1|, |q2|, |q3|`` from the diagonal
    (A.61) and the others from the off-diagonal sums and differences. The selection rules (A.66) are
    exactly "the largest of 1+r11+r22+r33, 1+r11−r22−r33, 1−r11+r22−r33, 1−r11−r22+r33", which is how
    they are evaluated here (this also settles ties). The third component of the q0-branch is
    ``(r13 − r31) / (4 q0)`` (E14). The result is normalised, then its sign chosen so that ``w >= 0``.
    """
    R = as_trailing("R", R, (3, 3))
    if R.ndim == 2:
        return _rotmat_to_quat_single(R)
    r11, r12, r13 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    r21, r22, r23 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    r31, r32, r33 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    diag = np.stack(
        [1 + r11 + r22 + r33, 1 + r11 - r22 - r33, 1 - r11 + r22 - r33, 1 - r11 - r22 + r33], axis=-1
    )
    branch = np.argmax(diag, axis=-1)
    # 4 q_k^2 = diag_k; each candidate row is 4 q_k · q.
    four_qk_q = np.stack(
        [
            np.stack([diag[..., 0], r32 - r23, r13 - r31, r21 - r12], axis=-1),  # q0-branch (A.62), E14
            np.stack([r32 - r23, diag[..., 1], r12 + r21, r13 + r31], axis=-1),  # q1-branch (A.63)
            np.stack([r13 - r31, r12 + r21, diag[..., 2], r23 + r32], axis=-1),  # q2-branch (A.64)
            np.stack([r21 - r12, r13 + r31, r23 + r32, diag[..., 3]], axis=-1),  # q3-branch (A.65)
        ],
        axis=-2,
    )
    chosen = np.take_along_axis(four_qk_q, branch[..., None, None], axis=-2)[..., 0, :]
    q = chosen / np.linalg.norm(chosen, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def _rotmat_to_quat_single(R: np.ndarray) -> np.ndarray:
    """:func:`rotmat_to_quat` of one validated (3, 3) matrix in plain floats: the same operations in the same
    order as the array path, hence the same bits (tested), ~10x faster (the estimators and /tf call it per
    message). The norm sums the squares in order, as numpy's reduction of 4 elements does."""
    (r11, r12, r13), (r21, r22, r23), (r31, r32, r33) = R.tolist()
    diag = (1 + r11 + r22 + r33, 1 + r11 - r22 - r33, 1 - r11 + r22 - r33, 1 - r11 - r22 + r33)
    branch = max(range(4), key=diag.__getitem__)  # the first largest, as np.argmax
    if branch == 0:
        chosen = (diag[0], r32 - r23, r13 - r31, r21 - r12)  # (A.62), E14
    elif branch == 1:
        chosen = (r32 - r23, diag[1], r12 + r21, r13 + r31)  # (A.63)
    elif branch == 2:
        chosen = (r13 - r31, r12 + r21, diag[2], r23 + r32)  # (A.64)
    else:
        chosen = (r21 - r12, r13 + r31, r23 + r32, diag[3])  # (A.65)
    a, b, c, d = chosen
    norm = math.sqrt(((a * a + b * b) + c * c) + d * d)
    q = [a / norm, b / norm, c / norm, d / norm]
    if q[0] < 0.0:
        q = [-v for v in q]
    return np.array(q)


def quat_from_axis_angle(axis, angle) -> np.ndarray:
    """Quaternion ``[cos(angle/2), sin(angle/2)·u]`` of a rotation by ``angle`` rad about ``axis`` (A.56).

    ``axis`` is normalised; raises ValueError if it is zero.
    """
    axis = as_trailing("axis", axis, (3,))
    angle = as_angles("angle", angle)
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(norm < 1e-300):
        raise ValueError("axis: zero rotation axis")
    half = 0.5 * angle[..., None]
    return np.concatenate([np.cos(half), np.sin(half) * axis / norm], axis=-1)


def quat_to_axis_angle(q) -> tuple[np.ndarray, float]:
    """Unit axis and angle in [0, π] of the rotation of ``q`` (shortest: ``q`` and ``−q`` are one attitude).

    For the identity the axis is ``[1, 0, 0]`` and the angle 0. Scalar input only (shape (4,)).
    """
    q = quat_normalize(_as_quat(q))
    if q[0] < 0.0:
        q = -q
    s = float(np.linalg.norm(q[1:]))
    angle = 2.0 * float(np.arctan2(s, q[0]))
    if s < 1e-300:
        return np.array([1.0, 0.0, 0.0]), 0.0
    return q[1:] / s, angle


def quat_from_rotvec(rv) -> np.ndarray:
    """Quaternion ``exp(rv/2)`` of the rotation vector ``rv`` (axis · angle, rad). Exact, smooth at 0."""
    return _quat_from_rotvec(as_trailing("rv", rv, (3,)))


def _quat_from_rotvec(rv: np.ndarray) -> np.ndarray:
    angle = np.linalg.norm(rv, axis=-1, keepdims=True)
    # sin(angle/2)/angle = 0.5 * sinc(angle / (2π)) with numpy's normalised sinc.
    return np.concatenate([np.cos(0.5 * angle), 0.5 * np.sinc(angle / (2.0 * np.pi)) * rv], axis=-1)


def _quat_integrate_rotvec(q: np.ndarray, rotvec: np.ndarray) -> np.ndarray:
    """``q ∘ exp(rotvec/2)``, renormalised (unchecked inputs; see :func:`quat_integrate`)."""
    out = _quat_multiply(q, _quat_from_rotvec(rotvec))
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def quat_to_rotvec(q) -> np.ndarray:
    """Rotation vector (axis · angle, angle in [0, π]) of the unit quaternion ``q`` (the log map)."""
    q = quat_normalize(as_trailing("q", q, (4,)))
    q = np.where(q[..., :1] < 0.0, -q, q)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    w = q[..., :1]
    angle = 2.0 * np.arctan2(s, w)
    small = s < 1e-8
    # angle / s -> 2 / w (1 - s²/(3 w²) + ...) for small s; w ≈ 1 there.
    factor = np.where(small, 2.0 / w * (1.0 - s * s / (3.0 * w * w)), angle / np.where(small, 1.0, s))
    return factor * q[..., 1:]


# --------------------------------------------------------------------------------------------------------
# Euler angles
# --------------------------------------------------------------------------------------------------------
def _euler_zyx_quat(cr, sr, cp, sp, cy, sy) -> tuple:
    """Components of ``qz(yaw) ∘ qy(pitch) ∘ qx(roll)`` (A.67)-(A.71) from the cosines and sines of the half
    angles (floats or arrays)."""
    return (cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy)


def euler_zyx_to_quat(roll, pitch, yaw) -> np.ndarray:
    """Quaternion ``qz(yaw) ∘ qy(pitch) ∘ qx(roll)`` of ZYX Euler angles (A.67)-(A.71), rad."""
    if isinstance(roll, float) and isinstance(pitch, float) and isinstance(yaw, float):  # one attitude: floats
        if not (math.isfinite(roll) and math.isfinite(pitch) and math.isfinite(yaw)):
            for name, angle in (("roll", roll), ("pitch", pitch), ("yaw", yaw)):
                as_angles(name, angle)  # raises on NaN / inf, naming the argument
        hr, hp, hy = 0.5 * roll, 0.5 * pitch, 0.5 * yaw
        return np.array(_euler_zyx_quat(math.cos(hr), math.sin(hr), math.cos(hp), math.sin(hp),
                                        math.cos(hy), math.sin(hy)))
    hr = 0.5 * as_angles("roll", roll)
    hp = 0.5 * as_angles("pitch", pitch)
    hy = 0.5 * as_angles("yaw", yaw)
    return np.stack(_euler_zyx_quat(np.cos(hr), np.sin(hr), np.cos(hp), np.sin(hp), np.cos(hy), np.sin(hy)),
                    axis=-1)


def quat_to_euler_zyx(q) -> tuple[float, float, float]:
    """ZYX Euler angles ``(roll, pitch, yaw)`` of a unit quaternion (A.72, erratum E15), rad.

    ``roll = atan2(2(q0q1 + q2q3), q0² − q1² − q2² + q3²)``, ``pitch = asin(2(q0q2 − q1q3))``,
    ``yaw = atan2(2(q0q3 + q1q2), q0² + q1² − q2² − q3²)``. At the gimbal lock (pitch = ±π/2) roll is set
    to 0 and the whole rotation about z is reported as yaw. Scalar input (shape (4,)); the quaternion is
    normalised first (ValueError if zero).
    """
    w, x, y, z = _as_quat(q).tolist()
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if norm < 1e-300:
        raise ValueError("q: cannot normalize a zero quaternion")
    r = rotation_entries(w / norm, x / norm, y / norm, z / norm)
    return _euler_zyx_angles(r[3], r[0], r[6], r[7], r[8], r[1], r[4])


def euler_zyx_to_rotmat(roll, pitch, yaw) -> np.ndarray:
    """``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (A.43)."""
    return rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)


def _euler_zyx_angles(r21: float, r11: float, r31: float, r32: float, r33: float, r12: float,
                      r22: float) -> tuple[float, float, float]:
    """(A.72) from the entries r_ij (1-based, plain floats) of R: see :func:`rotmat_to_euler_zyx`."""
    cos_pitch = math.hypot(r32, r33)
    if cos_pitch < GIMBAL_LOCK_TOLERANCE:
        return 0.0, math.asin(min(max(-r31, -1.0), 1.0)), math.atan2(-r12, r22)
    # atan2 rather than asin(−r31): better conditioned near ±π/2
    return math.atan2(r32, r33), math.atan2(-r31, cos_pitch), math.atan2(r21, r11)


def rotmat_to_euler_zyx(R) -> tuple[float, float, float]:
    """ZYX Euler angles ``(roll, pitch, yaw)`` of a rotation matrix (A.72), pitch in [−π/2, π/2].

    ``roll = atan2(r32, r33)``, ``pitch = asin(−r31)``, ``yaw = atan2(r21, r11)``; at the gimbal lock
    (|cos pitch| < 1e-12) roll = 0 and ``yaw = atan2(−r12, r22)``.
    """
    (r11, r12, _), (r21, r22, _), (r31, r32, r33) = as_array("R", R, (3, 3)).tolist()
    return _euler_zyx_angles(r21, r11, r31, r32, r33, r12, r22)


def euler_zxz_to_rotmat(psi1, phi, psi2) -> np.ndarray:
    """``R = Rz(psi1) @ Rx(phi) @ Rz(psi2)`` (A.44), rad (Appendix D calibration constants)."""
    return rot_z(psi1) @ rot_x(phi) @ rot_z(psi2)


def rotmat_to_euler_zxz(R) -> tuple[float, float, float]:
    """ZXZ Euler angles ``(psi1, phi, psi2)`` with phi in [0, π] (erratum E16: matrix forms).

    ``psi1 = atan2(r13, −r23)``, ``phi = acos(r33)`` (evaluated as ``atan2(hypot(r13, r23), r33)``, which
    is the same angle but accurate near 0 and π), ``psi2 = atan2(r31, r32)``. At the singularity
    (sin phi < 1e-12) psi2 = 0 and ``psi1 = atan2(r21, r11)``.
    """
    R = as_array("R", R, (3, 3))
    sin_phi = float(np.hypot(R[0, 2], R[1, 2]))
    phi = float(np.arctan2(sin_phi, R[2, 2]))
    if sin_phi < GIMBAL_LOCK_TOLERANCE:
        return float(np.arctan2(R[1, 0], R[0, 0])), phi, 0.0
    return float(np.arctan2(R[0, 2], -R[1, 2])), phi, float(np.arctan2(R[2, 0], R[2, 1]))


# --------------------------------------------------------------------------------------------------------
# Quaternion product matrices and rotational kinematics
# --------------------------------------------------------------------------------------------------------
def quat_left_matrix(q) -> np.ndarray:
    """``Q(q)`` of (A.53): ``q ∘ p = Q(q) @ p``."""
    q0, q1, q2, q3 = _as_quat(q)
    return np.array(
        [[q0, -q1, -q2, -q3], [q1, q0, -q3, q2], [q2, q3, q0, -q1], [q3, -q2, q1, q0]], dtype=float
    )


def quat_right_matrix(q) -> np.ndarray:
    """``Q̄(q)`` of (A.54): ``p ∘ q = Q̄(q) @ p``."""
    q0, q1, q2, q3 = _as_quat(q)
    return np.array(
        [[q0, -q1, -q2, -q3], [q1, q0, q3, -q2], [q2, -q3, q0, q1], [q3, q2, -q1, q0]], dtype=float
    )


def euler_rate_matrix(roll, pitch) -> np.ndarray:
    """``D`` of (A.78): body rate ``ω = D @ [roll_rate, pitch_rate, yaw_rate]`` for ZYX angles.

    ``D = [[1, 0, −sϑ], [0, cϕ, cϑ sϕ], [0, −sϕ, cϑ cϕ]]`` (ϕ roll, ϑ pitch). Singular at pitch = ±π/2.
    """
    roll = as_scalar("roll", roll)
    pitch = as_scalar("pitch", pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    return np.array([[1.0, 0.0, -sp], [0.0, cr, cp * sr], [0.0, -sr, cp * cr]])


def euler_rate_matrix_inverse(roll, pitch) -> np.ndarray:
    """``D^{-1}`` of (A.80): ``η̇ = D^{-1} @ ω``; raises ValueError at the gimbal lock (cos pitch ≈ 0)."""
    roll = as_scalar("roll", roll)
    pitch = as_scalar("pitch", pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    if abs(cp) < GIMBAL_LOCK_TOLERANCE:
        raise ValueError("pitch: D is singular at pitch = ±π/2 (gimbal lock)")
    return np.array([[1.0, sr * sp / cp, cr * sp / cp], [0.0, cr, -sr], [0.0, sr / cp, cr / cp]])


def euler_rate_matrix_dot(roll, pitch, roll_rate, pitch_rate) -> np.ndarray:
    """Time derivative ``Ḋ`` of (A.82), so that ``ω̇ = D @ η̈ + Ḋ @ η̇`` (A.81)."""
    roll = as_scalar("roll", roll)
    pitch = as_scalar("pitch", pitch)
    dr = as_scalar("roll_rate", roll_rate)
    dp = as_scalar("pitch_rate", pitch_rate)
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    return np.array(
        [
            [0.0, 0.0, -cp * dp],
            [0.0, -dr * sr, -dp * sp * sr + dr * cp * cr],
            [0.0, -dr * cr, -dp * sp * cr - dr * cp * sr],
        ]
    )


def quat_derivative(q, body_rate) -> np.ndarray:
    """``q̇ = ½ q ∘ [0; ω]`` (A.84), ``ω`` the body-frame angular rate in rad/s."""
    q = as_trailing("q", q, (4,))
    body_rate = as_trailing("body_rate", body_rate, (3,))
    pure = np.concatenate([np.zeros(body_rate.shape[:-1] + (1,)), body_rate], axis=-1)
    return 0.5 * _quat_multiply(q, pure)


def quat_integrate(q, body_rate, dt) -> np.ndarray:
    """Exact integration of a constant body rate over ``dt`` s: ``q ∘ exp(ω dt / 2)``, renormalised."""
    q = as_trailing("q", q, (4,))
    body_rate = as_trailing("body_rate", body_rate, (3,))
    dt = as_scalar("dt", dt)
    return _quat_integrate_rotvec(q, body_rate * dt)


def quat_angle(q_a, q_b) -> float:
    """Angle [rad, in [0, π]] of the rotation between two attitudes ``q_a``, ``q_b`` [w, x, y, z] (not necessarily
    normalized): the angle of ``q_a^{-1} ∘ q_b``, = 2 acos |⟨q_a, q_b⟩| / (|q_a| |q_b|) (sign-invariant).

    Evaluated on plain floats (every controller checks each received ζ_j with it, 250 times per simulated second
    for n = 6: issue 15); raises ValueError naming the argument for a wrong shape, NaN/inf or a zero quaternion."""
    aw, ax, ay, az = as_array("q_a", q_a, (4,)).tolist()
    bw, bx, by, bz = as_array("q_b", q_b, (4,)).tolist()
    norms = math.sqrt(aw * aw + ax * ax + ay * ay + az * az) * math.sqrt(bw * bw + bx * bx + by * by + bz * bz)
    if not norms > 0.0:
        raise ValueError("quat_angle: a zero quaternion is no attitude")
    return 2.0 * math.acos(min(1.0, abs(aw * bw + ax * bx + ay * by + az * bz) / norms))


def quat_error(q, q_des) -> np.ndarray:
    """Error quaternion ``q_err = q^{-1} ∘ q_des`` (thesis (3.28)): the rotation from ``q`` to ``q_des``,
    expressed in the frame of ``q`` (body frame)."""
    q = as_trailing("q", q, (4,))
    q_des = as_trailing("q_des", q_des, (4,))
    batched = q.ndim > 1 or q_des.ndim > 1
    if batched:
        q, q_des = np.broadcast_arrays(q, q_des)
    w, x, y, z = _components(q)
    norm2 = w * w + x * x + y * y + z * z
    if np.any(norm2 <= 0.0) if batched else norm2 <= 0.0:
        raise ValueError("q: zero quaternion has no inverse")
    return _assemble(_hamilton(w / norm2, -x / norm2, -y / norm2, -z / norm2, *_components(q_des)), batched)


def attitude_error_vector(q, q_des) -> np.ndarray:
    """Brescianini attitude error ``ε_o = sgn(q_err,0) · q_err,1:3`` (thesis (3.28)-(3.29)), body frame.

    ``sgn(x) = +1`` for ``x >= 0``, ``−1`` otherwise. For small errors ``ε_o ≈ δφ / 2`` (spec §0.1 item 3).
    """
    err = quat_error(q, q_des)
    if err.ndim == 1:
        return err[1:] if err[0] >= 0.0 else -err[1:]
    return np.where(err[..., :1] >= 0.0, 1.0, -1.0) * err[..., 1:]


def _as_quat(q) -> np.ndarray:
    return as_array("q", q, (4,))
