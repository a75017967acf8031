"""Cheap input checks shared by the public functions of :mod:`fpr_model`.

Every public function that takes a configuration, a velocity, a quaternion, ... converts it with one of
these helpers, so that a wrong shape or a NaN/inf raises a ``ValueError`` that names the argument.
"""

from __future__ import annotations

import math

import numpy as np

#: arrays up to this size are checked element by element in Python (0.7 µs for 4-18 values against 1.7 µs for
#: ``np.isfinite(a).all()``: these helpers run ~11,000 times per simulated second in the graph, issue 15)
_SMALL = 32


def _finite(array: np.ndarray) -> bool:
    """Every element of the float array finite."""
    if array.size <= _SMALL:
        return all(map(math.isfinite, array.ravel().tolist()))
    return bool(np.isfinite(array).all())


def as_array(name: str, value, shape: tuple[int, ...]) -> np.ndarray:
    """Return ``value`` as a float array of exactly ``shape``; raise ValueError naming ``name`` otherwise."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: cannot convert to a float array ({error})") from None
    if array.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {array.shape}")
    if not _finite(array):
        raise ValueError(f"{name}: contains NaN or inf")
    return array


def as_trailing(name: str, value, trailing: tuple[int, ...]) -> np.ndarray:
    """Return ``value`` as a float array whose last dimensions are ``trailing`` (leading batch dims
    allowed)."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: cannot convert to a float array ({error})") from None
    k = len(trailing)
    if array.ndim < k or array.shape[array.ndim - k:] != trailing:
        raise ValueError(f"{name}: expected shape (..., {', '.join(map(str, trailing))}), got {array.shape}")
    if not _finite(array):
        raise ValueError(f"{name}: contains NaN or inf")
    return array


def as_scalar(name: str, value) -> float:
    """Return ``value`` as a finite Python float; raise ValueError naming ``name`` otherwise."""
    try:
        number = float(value)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: expected a real number ({error})") from None
    if not np.isfinite(number):
        raise ValueError(f"{name}: must be finite, got {number}")
    return number


def as_angles(name: str, value) -> np.ndarray:
    """Return ``value`` (scalar or array of angles) as a finite float array."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: cannot convert to a float array ({error})") from None
    if not _finite(array):
        raise ValueError(f"{name}: contains NaN or inf")
    return array


def as_vector(name: str, value, min_size: int = 0) -> np.ndarray:
    """Return ``value`` as a finite 1-D float array of length >= ``min_size``."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: cannot convert to a float array ({error})") from None
    if array.ndim != 1 or array.size < min_size:
        raise ValueError(f"{name}: expected a vector of length >= {min_size}, got shape {array.shape}")
    if not _finite(array):
        raise ValueError(f"{name}: contains NaN or inf")
    return array


def all_finite(*values) -> bool:
    """True when every value (a real number, or an array or sequence of them) is finite; no exception.

    The per-cycle check of a small message's fields: Python floats are tested with ``math.isfinite`` (a numpy
    call per field would cost about 1 µs)."""
    for value in values:
        if isinstance(value, float | int):
            if not math.isfinite(value):
                return False
        elif not _finite(np.asarray(value, dtype=float)):
            return False
    return True
