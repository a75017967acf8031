"""Small, fast 3-D helpers used by the algorithms (no input checking: internal use only): batched numpy forms,
and plain-float forms for single vectors (numpy costs about 1 µs per call on a 3-vector, these tens of ns)."""

from __future__ import annotations

import math

import numpy as np

_LEVI_CIVITA = np.zeros((3, 3, 3))
_LEVI_CIVITA[0, 1, 2] = _LEVI_CIVITA[1, 2, 0] = _LEVI_CIVITA[2, 0, 1] = 1.0
_LEVI_CIVITA[0, 2, 1] = _LEVI_CIVITA[2, 1, 0] = _LEVI_CIVITA[1, 0, 2] = -1.0
_LEVI_CIVITA.setflags(write=False)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over the last axis, broadcasting (several times faster than np.cross for small arrays)."""
    return np.einsum("ijk,...j,...k->...i", _LEVI_CIVITA, a, b)


def skew_batch(v: np.ndarray) -> np.ndarray:
    """[v]× for v of shape (..., 3) -> (..., 3, 3)."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def cross3(a, b) -> tuple[float, float, float]:
    """a × b of two 3-sequences of plain floats."""
    ax, ay, az = a
    bx, by, bz = b
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


def dot3(a, b) -> float:
    """a · b of two 3-sequences of plain floats."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def norm3(a) -> float:
    """‖a‖ of a 3-sequence of plain floats."""
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


def norm_floats(a) -> float:
    """‖a‖ of a short vector (a sequence or 1-D array), evaluated on plain floats."""
    return math.sqrt(sum(v * v for v in np.asarray(a, dtype=float).tolist()))
