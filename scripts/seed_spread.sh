#!/usr/bin/env bash
# Fly the experiments with thesis values again with other seeds (other robots and noise realisations, the realism
# values frozen) and write docs/seed_spread.md: which of the thesis's orderings and ratios survive another seed
# (fpr_experiments.spread), under the network isolation of DESIGN.md §6:
#   bash scripts/seed_spread.sh --seeds own 1 2 --jobs 2        # about 25 min per seed with 2 jobs
#   bash scripts/seed_spread.sh --seeds own 1 2 --report-only   # rebuild it from reports/seeds/seed_*/
# Run it on a quiet machine.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
exec bash "$ROOT/scripts/isolated.sh" ros2 run fpr_experiments spread "$@"
