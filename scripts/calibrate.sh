#!/usr/bin/env bash
# Calibrate fpr_sim's `hardware` realism profile on the calibration set (thesis Table 3.2 impedance row and
# Table 4.2 C row; fpr_experiments.calibration), under the network isolation of DESIGN.md §6:
#   bash scripts/calibrate.sh --jobs 2 --seeds own 0 --write   # writes docs/calibration.md and
#                                                        # src/fpr_sim/config/realism/hardware/90_calibrated.yaml
# Each evaluation flies every calibration flight in its own isolated process; about 3 min per evaluation with
# 2 jobs. Run it on a quiet machine.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
exec bash "$ROOT/scripts/isolated.sh" ros2 run fpr_experiments calibrate "$@"
