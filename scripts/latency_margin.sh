#!/usr/bin/env bash
# Fly Ch. 3 experiments at several command-uplink latencies and seeds (hardware profile, realism values frozen) and
# write docs/latency_margin.md: in how many seeds each controller kept control at each latency
# (fpr_experiments.margin), under the network isolation of DESIGN.md §6:
#   bash scripts/latency_margin.sh --experiment fig_3_4 --experiment table_3_3 --experiment table_4_6 \
#       --latencies 0 0.01 0.02 --seeds own 1 2 3 4 5 --jobs 2   # about 45 min with 2 jobs
#   bash scripts/latency_margin.sh ... --report-only         # rebuild it from reports/margin/
# The flights are deterministic (lockstep): the machine's load changes their wall time only.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
exec bash "$ROOT/scripts/isolated.sh" ros2 run fpr_experiments margin "$@"
