"""ENU/FLU (ROS, REP-103) <-> NED/FRD (PX4, MAVLink) conversions: the one conversion module of the project.

Used only at the MAVLink boundary: by ``fpr_px4_bridge`` and by the simulator's PX4 emulator (DESIGN.md §2,
spec ``px4_ros_facts.md`` §1.7).

- World vectors (positions, velocities, accelerations, forces in the world frame):
  ENU ``(x_east, y_north, z_up)`` <-> NED ``(x_north, y_east, z_down)``: ``(x, y, z) -> (y, x, −z)``.
  The map is its own inverse.
- Body vectors (body velocity, angular rates, body forces/moments):
  FLU ``(forward, left, up)`` <-> FRD ``(forward, right, down)``: ``(x, y, z) -> (x, −y, −z)``. Self-inverse.
- Attitudes (quaternion ``[w, x, y, z]``, body -> world):
  ``q_NED_FRD = q_NE ∘ q_ENU_FLU ∘ q_x(π)`` with ``q_NE = (0, √2/2, √2/2, 0)`` (rotation matrix
  ``[[0,1,0],[1,0,0],[0,0,−1]]``) and ``q_x(π) = (0, 1, 0, 0)``. Both output quaternions are returned
  with ``w >= 0`` (``q`` and ``−q`` are the same attitude).
- Yaw: ``ψ_NED = π/2 − ψ_ENU`` (wrapped to (−π, π]). ENU yaw +90° (facing north) is NED yaw 0.

All functions accept leading batch dimensions.
"""

from __future__ import annotations

import numpy as np

from fpr_model._validation import as_angles, as_trailing
from fpr_model.rotations import _hamilton, _quat_multiply

__all__ = [
    "Q_NE",
    "Q_X_PI",
    "R_NE",
    "enu_to_ned",
    "flu_to_frd",
    "frd_to_flu",
    "ned_to_enu",
    "quat_enu_flu_to_ned_frd",
    "quat_ned_frd_to_enu_flu",
    "rotmat_enu_flu_to_ned_frd",
    "rotmat_ned_frd_to_enu_flu",
    "yaw_enu_to_ned",
    "yaw_ned_to_enu",
]

_HALF_SQRT2 = np.sqrt(0.5)
#: Quaternion of the world-frame swap ENU <-> NED (a rotation by π about (x + y)/√2; self-inverse).
Q_NE = np.array([0.0, _HALF_SQRT2, _HALF_SQRT2, 0.0])
#: Quaternion of the body-frame flip FLU <-> FRD (a rotation by π about x; self-inverse).
Q_X_PI = np.array([0.0, 1.0, 0.0, 0.0])
#: Rotation matrix of ``Q_NE``.
R_NE = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
_R_X_PI = np.diag([1.0, -1.0, -1.0])


def _swap_world(v) -> np.ndarray:
    """``(x, y, z) -> (y, x, −z)`` of a validated (..., 3) array; one vector on plain floats (np.stack costs
    ~7 µs, and the bridges and the emulated PX4s convert every MAVLink frame: issue 15)."""
    if v.ndim == 1:
        x, y, z = v.tolist()
        return np.array([y, x, -z])
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


def enu_to_ned(v) -> np.ndarray:
    """World vector ENU -> NED: ``(x, y, z) -> (y, x, −z)``. ``v`` (..., 3)."""
    return _swap_world(as_trailing("v", v, (3,)))


def ned_to_enu(v) -> np.ndarray:
    """World vector NED -> ENU: ``(x, y, z) -> (y, x, −z)``. ``v`` (..., 3)."""
    return _swap_world(as_trailing("v", v, (3,)))


def flu_to_frd(v) -> np.ndarray:
    """Body vector FLU -> FRD: ``(x, y, z) -> (x, −y, −z)``. ``v`` (..., 3)."""
    v = as_trailing("v", v, (3,))
    return v * np.array([1.0, -1.0, -1.0])


def frd_to_flu(v) -> np.ndarray:
    """Body vector FRD -> FLU: ``(x, y, z) -> (x, −y, −z)``. ``v`` (..., 3)."""
    v = as_trailing("v", v, (3,))
    return v * np.array([1.0, -1.0, -1.0])


def _canonical(q: np.ndarray) -> np.ndarray:
    return np.where(q[..., :1] < 0.0, -q, q)


_CONJUGATE = np.array([1.0, -1.0, -1.0, -1.0])
_Q_NE_FLOATS = Q_NE.tolist()
_Q_X_PI_FLOATS = Q_X_PI.tolist()
_Q_NE_INVERSE_FLOATS = (Q_NE * _CONJUGATE).tolist()
_Q_X_PI_INVERSE_FLOATS = (Q_X_PI * _CONJUGATE).tolist()


def _sandwich(left: list[float], q: np.ndarray, right: list[float]) -> np.ndarray:
    """``left ∘ q ∘ right`` with ``w >= 0`` for a validated (..., 4) ``q``: one quaternion on plain floats, the
    Hamilton products in the same order as the array path (the same bits), ~3× faster (every MAVLink attitude)."""
    if q.ndim == 1:
        out = _hamilton(*_hamilton(*left, *q.tolist()), *right)
        return np.array([-v for v in out] if out[0] < 0.0 else out)
    return _canonical(_quat_multiply(_quat_multiply(np.array(left), q), np.array(right)))


def quat_enu_flu_to_ned_frd(q) -> np.ndarray:
    """Attitude FLU->ENU (ROS) to FRD->NED (PX4): ``q_NE ∘ q ∘ q_x(π)``, returned with ``w >= 0``."""
    return _sandwich(_Q_NE_FLOATS, as_trailing("q", q, (4,)), _Q_X_PI_FLOATS)


def quat_ned_frd_to_enu_flu(q) -> np.ndarray:
    """Attitude FRD->NED (PX4) to FLU->ENU (ROS): ``q_NE^{-1} ∘ q ∘ q_x(π)^{-1}``, returned with ``w >=
    0``."""
    return _sandwich(_Q_NE_INVERSE_FLOATS, as_trailing("q", q, (4,)), _Q_X_PI_INVERSE_FLOATS)


def rotmat_enu_flu_to_ned_frd(R) -> np.ndarray:
    """Rotation matrix FLU->ENU to FRD->NED: ``R_NE @ R @ Rx(π)``. ``R`` (..., 3, 3)."""
    R = as_trailing("R", R, (3, 3))
    return R_NE @ R @ _R_X_PI


def rotmat_ned_frd_to_enu_flu(R) -> np.ndarray:
    """Rotation matrix FRD->NED to FLU->ENU: ``R_NE @ R @ Rx(π)`` (both factors are self-inverse)."""
    R = as_trailing("R", R, (3, 3))
    return R_NE @ R @ _R_X_PI


def _wrap(angle: np.ndarray) -> np.ndarray:
    wrapped = np.mod(angle + np.pi, 2.0 * np.pi) - np.pi  # [−π, π)
    return np.where(wrapped == -np.pi, np.pi, wrapped)


def yaw_enu_to_ned(yaw):
    """Heading ENU (from east, counter-clockwise) -> NED (from north, clockwise): ``π/2 − yaw``, in (−π,
    π]."""
    yaw = as_angles("yaw", yaw)
    out = _wrap(0.5 * np.pi - yaw)
    return float(out) if out.ndim == 0 else out


def yaw_ned_to_enu(yaw):
    """Heading NED -> ENU: ``π/2 − yaw``, wrapped to (−π, π]."""
    yaw = as_angles("yaw", yaw)
    out = _wrap(0.5 * np.pi - yaw)
    return float(out) if out.ndim == 0 else out
