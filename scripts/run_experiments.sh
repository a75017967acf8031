#!/usr/bin/env bash
# Set the workspace up if needed, then run thesis experiments under the network isolation of DESIGN.md §6:
#   bash scripts/run_experiments.sh all --realism hardware --jobs 2   # every experiment, full durations, 2 at a
#                                                  # time, the calibrated hardware profile; writes docs/results.md
#   bash scripts/run_experiments.sh table_3_4      # one experiment (reports/table_3_4/)
#   bash scripts/run_experiments.sh list           # what there is
# Arguments after the name go to `ros2 run fpr_experiments run` (--quick, --seed S, --cameras images|emulated,
# --processes, --variant V, --jobs N, ...). `all` takes about 45 min on one core (--jobs 2: about 35 min); run it on a
# quiet machine.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
if [[ "${1:-list}" == "list" ]]; then
  exec bash "$ROOT/scripts/isolated.sh" ros2 run fpr_experiments list -v
fi
exec bash "$ROOT/scripts/isolated.sh" ros2 run fpr_experiments run "$@"
