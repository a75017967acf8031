"""Plain-float forms of fpr_model's rotation algebra for the 1 kHz plant loop (numpy costs ~1 µs per call on
3-vectors; these cost tens of ns). Same formulas as fpr_model.rotations (checked in test/test_plant_kernels.py):
nothing new is defined here, only the evaluation on Python floats.
"""

from __future__ import annotations

__all__ = ["rotation_entries"]


def rotation_entries(w: float, x: float, y: float, z: float) -> tuple[float, ...]:
    """Row-major entries (r00, r01, …, r22) of ``fpr_model.rotations.quat_to_rotmat([w, x, y, z])`` (A.60),
    body -> world, the quaternion used as given (not normalised)."""
    return (w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
            2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x),
            2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z)
