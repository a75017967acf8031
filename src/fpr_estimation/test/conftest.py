"""Make the source trees of fpr_estimation, fpr_model and fpr_sim importable (also without a colcon build)."""

import os
import sys

_SRC = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
for package in ("fpr_estimation", "fpr_model", "fpr_sim"):
    path = os.path.join(_SRC, package)
    if path not in sys.path:
        sys.path.insert(0, path)
