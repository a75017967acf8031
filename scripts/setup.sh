#!/usr/bin/env bash
# Idempotent workspace setup for machines without a ROS 2 install (Debian 12 / Python 3.11 / x86_64):
#   1. a project virtual environment .venv with exactly pinned ROS 2 Jazzy wheels and dependencies,
#   2. the wheels' CMake path fix (scripts/fix_ros_wheels.sh),
#   3. the `ros2 run` stand-in, only when no real `ros2` command exists,
#   4. `colcon build --symlink-install` of every package under src/ (fpr_msgs through rosidl).
# Each step is skipped when its inputs did not change, so a no-change run takes about a second.
# On a native ROS 2 Jazzy install do not use this script: see README.md.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${FPR_VENV:-$ROOT/.venv}"
PYTHON="${FPR_PYTHON:-python3.11}"
command -v "$PYTHON" >/dev/null 2>&1 || PYTHON=python3
LOG_DIR="$ROOT/log/setup"
mkdir -p "$LOG_DIR"

exec 9>"$ROOT/.setup.lock"
flock 9   # concurrent callers (parallel test runs) wait for one setup

say() { printf '[setup] %s\n' "$*" >&2; }

# ---- 1. virtual environment -------------------------------------------------------------
req_hash=$(cat "$ROOT/requirements.lock" | sha256sum | cut -d' ' -f1)
if [[ ! -x "$VENV/bin/python" ]]; then
  say "creating virtual environment $VENV ($("$PYTHON" --version))"
  "$PYTHON" -m venv "$VENV"
fi
if [[ "$(cat "$VENV/.fpr-requirements" 2>/dev/null)" != "$req_hash" ]]; then
  say "installing pinned requirements (requirements.lock), log: log/setup/pip.log"
  if ! "$VENV/bin/python" -m pip install --no-input -r "$ROOT/requirements.lock" >"$LOG_DIR/pip.log" 2>&1; then
    grep -v '^WARNING: Location' "$LOG_DIR/pip.log" | tail -30 >&2
    say "pip install failed"; exit 1
  fi
  bash "$ROOT/scripts/fix_ros_wheels.sh" "$VENV"
  echo "$req_hash" >"$VENV/.fpr-requirements"
fi

# ---- 2. ros2 stand-in -------------------------------------------------------------------
if [[ ! -e "$VENV/bin/ros2" ]]; then
  if ! PATH="$(echo "$PATH" | tr ':' '\n' | grep -v "^$VENV/bin$" | paste -sd:)" command -v ros2 >/dev/null 2>&1; then
    say "no ros2 command found: installing the 'ros2 run' stand-in into $VENV/bin"
    install -m 0755 "$ROOT/scripts/ros2_standin.py" "$VENV/bin/ros2"
  fi
elif ! cmp -s "$ROOT/scripts/ros2_standin.py" "$VENV/bin/ros2"; then
  install -m 0755 "$ROOT/scripts/ros2_standin.py" "$VENV/bin/ros2"
fi

# ---- 3. colcon build ----------------------------------------------------------------------
# With --symlink-install, edits to existing Python modules need no rebuild; a rebuild is needed when
# the set of files or any manifest, message, CMake or config file changes.
# Standard message packages the wheels lack (vendor/, see vendor/COLCON_IGNORE): built only when the venv's own
# Python cannot import them (a real ROS 2 install has them).
vendor_paths=()
for pkg in "$ROOT"/vendor/*/; do
  name=$(basename "$pkg")
  if ! env -u PYTHONPATH -u AMENT_PREFIX_PATH "$VENV/bin/python" -c "import $name.msg" >/dev/null 2>&1; then
    vendor_paths+=("vendor/$name")
  fi
done
src_hash=$(cd "$ROOT" && { find src vendor colcon.meta -type f -not -path '*/__pycache__/*' -not -name '*.pyc' -not -name '*.so' | LC_ALL=C sort;
  find src vendor colcon.meta -type f \( -name package.xml -o -name setup.py -o -name setup.cfg -o -name CMakeLists.txt \
    -o -name '*.msg' -o -name '*.yaml' -o -name '*.c' -o -name colcon.meta \) -print0 | LC_ALL=C sort -z | xargs -0 cat;
  echo "${vendor_paths[*]}"; } | sha256sum | cut -d' ' -f1)
if [[ "$(cat "$ROOT/install/.fpr-build" 2>/dev/null)" != "$src_hash" || ! -f "$ROOT/install/setup.bash" ]]; then
  say "colcon build --symlink-install (log: log/setup/colcon.log)"
  (
    cd "$ROOT"
    export PATH="$VENV/bin:$PATH" VIRTUAL_ENV="$VENV" CMAKE_PREFIX_PATH="$VENV" AMENT_PREFIX_PATH="$VENV"
    export PYTHONWARNINGS=ignore::DeprecationWarning
    if ! colcon build --symlink-install --base-paths src "${vendor_paths[@]}" \
        --cmake-args -DPython3_EXECUTABLE="$VENV/bin/python" \
        >"$LOG_DIR/colcon.log" 2>&1; then
      tail -40 "$LOG_DIR/colcon.log" >&2
      say "colcon build failed"; exit 1
    fi
  )
  echo "$src_hash" >"$ROOT/install/.fpr-build"
fi
