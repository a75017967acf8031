#!/usr/bin/env bash
# Set the workspace up if needed, then run the main job under the network isolation of DESIGN.md §6.
# Until the simulated swarm exists, the main job is the model self-check (thesis Table 2.1 reproduction).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
exec bash "$ROOT/scripts/isolated.sh" ros2 run fpr_model selfcheck "$@"
