#!/usr/bin/env bash
# Set the workspace up if needed, then run the whole test suite (every package's test/ and tests/) with
# pytest under the network isolation of DESIGN.md §6. Extra arguments go to pytest, e.g.
#   scripts/run_tests.sh src/fpr_model/test -k jacobian
# Exits with pytest's status.
#
# Without arguments (the whole suite, what CI runs) the suite is two pytest sessions side by side, one per core,
# each in its own private network namespace (own loopback, own ROS domain: their simulators' MAVLink ports and
# ROS topics cannot meet): the experiments' quick flights (tests/test_experiments_quick.py: the deterministic
# in-process runner, whose results do not depend on the machine's load) beside everything else, which also takes
# one quick flight (fig_3_4) so that both end together (CI machine, 2 cores: 29.6 min with all quick flights on
# one side, 35 min as one session, ~22 min balanced). The second session's output follows the first's; the status is
# non-zero if either failed. FPR_TEST_JOBS=1 runs one session (also chosen when `unshare -n` is not available: the
# two would share 127.0.0.1's ports).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
status=0
QUICK=tests/test_experiments_quick.py
FLIGHTS=test_experiment_runs_quick_and_passes_its_checks  # the quick flights of $QUICK
MOVED=fig_3_4  # the quick flight that runs with the rest
if [[ $# -eq 0 && "${FPR_TEST_JOBS:-2}" != 1 ]] && unshare -n true 2>/dev/null; then
  log="$(mktemp "${TMPDIR:-/tmp}/fpr_tests_quick.XXXXXX")"
  echo "[tests] two sessions side by side: the quick flights of $QUICK but $MOVED (output below, after the other one) and the rest"
  bash "$ROOT/scripts/isolated.sh" python -m pytest "$QUICK" -k "$FLIGHTS and not $MOVED" >"$log" 2>&1 &
  quick_pid=$!
  bash "$ROOT/scripts/isolated.sh" python -m pytest src/*/test tests -k "not $FLIGHTS or $MOVED" || status=$?
  quick_status=0
  wait "$quick_pid" || quick_status=$?
  echo
  echo "[tests] ---------------- the quick flights of $QUICK but $MOVED ----------------"
  cat "$log"
  rm -f "$log"
  echo "[tests] the rest: status $status; the quick flights: status $quick_status"
  if [[ $status -eq 0 ]]; then status=$quick_status; fi
else
  if [[ $# -eq 0 ]]; then set -- src/*/test tests; fi
  bash "$ROOT/scripts/isolated.sh" python -m pytest "$@" || status=$?
fi
rm -f /dev/shm/lttng-ust-wait-* 2>/dev/null || true
exit $status
