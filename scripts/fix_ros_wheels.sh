#!/usr/bin/env bash
# The ROS 2 Jazzy PyPI wheels export CMake targets that point at the wheel builder's Python
# (/opt/python/cp311-cp311/...). Re-point them at this venv's Python and numpy headers so that
# rosidl can build fpr_msgs (toolchain.md §3). Idempotent; ~0.2 s.
set -euo pipefail
VENV="$1"
PYINC=$("$VENV/bin/python" -c "import sysconfig; print(sysconfig.get_paths()['include'])")
NPINC=$("$VENV/bin/python" -c "import numpy; print(numpy.get_include())")
{ grep -rlE "/opt/python/cp311-cp311/(include|lib)" "$VENV/share" 2>/dev/null || true; } | xargs -r sed -i \
  -e "s#/opt/python/cp311-cp311/include/python3.11#$PYINC#g" \
  -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$NPINC#g"
