#!/usr/bin/env bash
# Set the workspace up if needed, then run the fault-injection matrix of issue 12 (fpr_experiments.faults) under the
# network isolation of DESIGN.md §6:
#   bash scripts/run_faults.sh --results docs/safety.md          # 3 nodes x (dead, restarted after 2 s) x 5 seeds
#   bash scripts/run_faults.sh --nodes controller --seeds 0 --alternatives guard no_guard land_now
# Each case is one multi-process flight (~1 min wall); the default matrix takes about 30 min per alternative. Run it
# on a quiet machine; the flights' logs, MCAPs and PX4 logs go to reports/faults/.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
exec bash "$ROOT/scripts/isolated.sh" ros2 run fpr_experiments faults "$@"
