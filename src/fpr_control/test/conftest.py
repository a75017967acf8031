"""Make ``import fpr_control`` / ``fpr_model`` and the ``closed_loop`` helper work from the source tree."""

import os
import sys

_HERE = os.path.dirname(os.path.abspath(__file__))
for path in (_HERE, os.path.dirname(_HERE), os.path.join(os.path.dirname(os.path.dirname(_HERE)), "fpr_model")):
    if path not in sys.path:
        sys.path.insert(0, path)
