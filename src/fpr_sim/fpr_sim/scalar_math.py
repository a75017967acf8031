"""Plain-float forms of fpr_model's rotation algebra for the 1 kHz plant loop (numpy costs ~1 µs per call on
3-vectors; these cost tens of ns). Nothing is defined here: :func:`rotation_entries` is fpr_model's own kernel
of ``quat_to_rotmat`` (A.60), re-exported for the plant.
"""

from __future__ import annotations

from fpr_model.rotations import rotation_entries

__all__ = ["rotation_entries"]
