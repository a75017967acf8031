#!/usr/bin/env bash
# Set the workspace up if needed, then run the main job under the network isolation of DESIGN.md §6: the demo
# experiment of fpr_experiments, `takeoff_landing` (the whole node graph takes off from the ground, flies a roll
# step and lands; progress lines, a summary table, and metrics.json, PNG plots and flight.mcap in
# reports/takeoff_landing/). Extra arguments go to `ros2 run fpr_experiments run takeoff_landing`, e.g.
#   bash scripts/run_demo.sh --quick
#   bash scripts/run_demo.sh --cameras images --output-dir reports/demo_images
#   bash scripts/run_demo.sh --processes          # one process per UAV / ground station / simulator
# `bash scripts/run_demo.sh --selfcheck` runs the model self-check instead (ros2 run fpr_model selfcheck).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
if [[ "${1:-}" == "--selfcheck" ]]; then
  shift
  exec bash "$ROOT/scripts/isolated.sh" ros2 run fpr_model selfcheck "$@"
fi
exec bash "$ROOT/scripts/isolated.sh" ros2 run fpr_experiments run takeoff_landing "$@"
