#!/usr/bin/env bash
# Issue 15 re-measured before and after on this machine (benchmarks/bench_before_after.py says why and how):
#   1. clone this repository's main-as-it-was (bench_before_after.BASELINE_COMMIT) into FPR_BASELINE_DIR (default
#      $TMPDIR/fpr-baseline-<commit>) and set it up with its own scripts/setup.sh (pip may need the package
#      index, so outside the network isolation; no ROS node runs in this step), once;
#   2. copy the baseline flight (benchmarks/baseline/swarm_graph_rtf.py) into it;
#   3. run bench_before_after.py through scripts/isolated.sh: every flight of either side inside the isolation.
# Usage: bash benchmarks/before_after.sh [--cases ...] [--seconds 12] [--repeats 2]; quiet machine only.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# the one commit the issue's figures belong to, named once in bench_before_after.py (stdlib imports only)
COMMIT="$(python3 -c "import sys; sys.path.insert(0, sys.argv[1]); import bench_before_after as b; print(b.BASELINE_COMMIT)" "$ROOT/benchmarks")"
DIR="${FPR_BASELINE_DIR:-${TMPDIR:-/tmp}/fpr-baseline-$COMMIT}"
say() { printf '[before_after] %s\n' "$*" >&2; }
if [[ ! -f "$DIR/.fpr-baseline-ready" ]]; then
  if ! git -C "$ROOT" cat-file -e "$COMMIT^{commit}" 2>/dev/null; then
    say "commit $COMMIT is not in this clone (a shallow clone?): git fetch --unshallow"
    exit 1
  fi
  say "checking out $COMMIT into $DIR and setting it up (about 2 min, log: $DIR/log/setup)"
  rm -rf "$DIR"
  git clone -q --no-checkout "$ROOT" "$DIR"
  git -C "$DIR" checkout -q --detach "$COMMIT"
  # its setup with none of this workspace's environment (venv, install, PYTHONPATH)
  PATH="$(echo "$PATH" | tr ':' '\n' | grep -v "^$ROOT/" | paste -sd:)" \
    env -u VIRTUAL_ENV -u PYTHONPATH -u AMENT_PREFIX_PATH -u COLCON_PREFIX_PATH -u CMAKE_PREFIX_PATH \
    -u LD_LIBRARY_PATH -u _ROS_WHEELS_BOOTSTRAP_COMPLETE bash "$DIR/scripts/setup.sh"
  touch "$DIR/.fpr-baseline-ready"
fi
cp "$ROOT/benchmarks/baseline/swarm_graph_rtf.py" "$DIR/tests/fpr_baseline_rtf.py"
exec bash "$ROOT/scripts/isolated.sh" python "$ROOT/benchmarks/bench_before_after.py" --baseline-dir "$DIR" "$@"
