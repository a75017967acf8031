#!/usr/bin/env bash
# Set the workspace up if needed, then run the whole test suite (every package's test/ and tests/) with
# pytest under the network isolation of DESIGN.md §6. Extra arguments go to pytest, e.g.
#   scripts/run_tests.sh src/fpr_model/test -k jacobian
# Exits with pytest's status.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
if [[ $# -eq 0 ]]; then set -- src/*/test tests; fi
status=0
bash "$ROOT/scripts/isolated.sh" python -m pytest "$@" || status=$?
rm -f /dev/shm/lttng-ust-wait-* 2>/dev/null || true
exit $status
