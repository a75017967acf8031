#!/usr/bin/env bash
# Run a command with the network isolation of DESIGN.md §6, so that nothing leaves this machine:
#   - a private network namespace with only loopback (`unshare -n`, lo up), when available (root);
#   - ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (Fast DDS discovery stays on this host) in any case;
#   - a random ROS_DOMAIN_ID unless one is given, so parallel runs do not cross;
#   - the workspace environment (venv + install/setup.bash) sourced.
# Usage: scripts/isolated.sh <command> [args...]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((RANDOM % 100 + 1))}"
export FPR_ROOT="$ROOT"
# the interfaces of this process's network namespace (/proc/self/net/dev is per namespace; /sys/class/net is not)
interfaces() { awk -F: 'NR > 2 { gsub(/ /, "", $1); print $1 }' /proc/self/net/dev 2>/dev/null || true; }
if [[ "${FPR_IN_NETNS:-0}" == 1 && "$(interfaces)" != lo ]]; then
  FPR_IN_NETNS=0  # inherited or set by hand, but this namespace has more than loopback: not isolated yet
fi
if [[ "${FPR_IN_NETNS:-0}" != 1 ]] && unshare -n true 2>/dev/null; then
  export FPR_IN_NETNS=1
  exec unshare -n -- "$0" "$@"
fi
if [[ "${FPR_IN_NETNS:-0}" == 1 ]]; then
  # bring loopback up: iproute2 when present, else a two-line ioctl in Python
  ip link set lo up 2>/dev/null || python3 "$ROOT/scripts/loopback_up.py"
else
  echo "[isolated] unshare -n not available: relying on ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST only" >&2
fi
if [[ -f "$ROOT/.venv/bin/activate" ]]; then
  # shellcheck disable=SC1091
  source "$ROOT/.venv/bin/activate"
fi
if [[ -f "$ROOT/install/setup.bash" ]]; then
  # shellcheck disable=SC1091
  set +u; source "$ROOT/install/setup.bash"; set -u
fi
exec "$@"
