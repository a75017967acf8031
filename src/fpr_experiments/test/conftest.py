"""fpr_experiments tests: the ROS-free cores run with plain pytest; node-building tests need the workspace
environment (scripts/run_tests.sh sources it) and run under scripts/isolated.sh's network isolation. Makes the
``synthetic`` helper and ``import fpr_experiments`` work from the source tree."""

import os
import sys

_HERE = os.path.dirname(os.path.abspath(__file__))
for path in (_HERE, os.path.dirname(_HERE)):
    if path not in sys.path:
        sys.path.insert(0, path)
