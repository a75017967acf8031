#!/usr/bin/env bash
# Set the workspace up if needed, then run the main job under the network isolation of DESIGN.md §6:
# the simulated-swarm demo (demo/run_demo.py: the whole node graph flies a scripted mission and writes
# metrics.json, PNG plots and an MCAP log to reports/demo/). Extra arguments go to the demo, e.g.
#   bash scripts/run_demo.sh --quick
#   bash scripts/run_demo.sh --mode non_communicating --output-dir reports/demo_nc
#   bash scripts/run_demo.sh --help
# `bash scripts/run_demo.sh --selfcheck` runs the model self-check instead (ros2 run fpr_model selfcheck).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
if [[ "${1:-}" == "--selfcheck" ]]; then
  shift
  exec bash "$ROOT/scripts/isolated.sh" ros2 run fpr_model selfcheck "$@"
fi
exec bash "$ROOT/scripts/isolated.sh" python "$ROOT/demo/run_demo.py" "$@"
