#!/usr/bin/env bash
# Build (once) the real ROS 2 peers' venvs used by tests/test_ros2.py and
# benchmarks/bench_ros2.py, with the shared recipe ../shared/ros2/setup_ros2_tf_env.sh:
#   .venv-ros2/     rclpy + rmw_fastrtps_cpp (ROS 2 Kilted wheels from PyPI) + tf2_msgs
#   .venv-cyclone/  cyclonedds-python alone (the recipe's non-ROS side)
# in the repository root. Idempotent: a venv that already imports rclpy and tf2_msgs is
# kept (~1 s). Time-bounded (TFBUS_ROS2_INSTALL_TIMEOUT, default 900 s). Exits 0 with a
# line "ros2-env: unavailable: REASON" when the install is impossible (no python3.11,
# cmake or g++, no recipe, no PyPI); the tests then skip with that reason.
#   usage: scripts/install_ros2_env.sh            (env: TFBUS_ROS2_RECIPE=path/to/recipe.sh)
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
RECIPE="${TFBUS_ROS2_RECIPE:-$ROOT/../shared/ros2/setup_ros2_tf_env.sh}"
V="$ROOT/.venv-ros2"
CV="$ROOT/.venv-cyclone"
STAMP="$V/.tfbus-ros2-ok"
LIMIT="${TFBUS_ROS2_INSTALL_TIMEOUT:-900}"

unavailable() { echo "ros2-env: unavailable: $*"; exit 0; }

check() {
  "$V/bin/python" -c "import rclpy, tf2_msgs.msg, geometry_msgs.msg" >/dev/null 2>&1
}

if [ -f "$STAMP" ] && check; then
  echo "ros2-env: ready ($V)"
  exit 0
fi
[ -f "$RECIPE" ] || unavailable "recipe not found: $RECIPE"
command -v "${PY311:-python3.11}" >/dev/null 2>&1 || unavailable "python3.11 not found (the ROS 2 wheels are cp311-only)"
command -v cmake >/dev/null 2>&1 || unavailable "cmake not found (needed to generate tf2_msgs)"
command -v g++ >/dev/null 2>&1 || unavailable "g++ not found (needed to compile tf2_msgs)"

# One install at a time (pytest-xdist workers, two terminals): flock on a lock file.
exec 9>"$ROOT/.venv-ros2.lock"
if command -v flock >/dev/null 2>&1; then
  flock -w "$LIMIT" 9 || unavailable "another install held the lock for ${LIMIT}s"
  if [ -f "$STAMP" ] && check; then echo "ros2-env: ready ($V)"; exit 0; fi
fi

rm -rf "$V"   # a half-built venv from an interrupted run
echo "ros2-env: building $V and $CV with $RECIPE (about 30 s with a warm pip cache, 3-4 min cold)"
t0=$(date +%s)
LOG="$(mktemp)"
if ! timeout "$LIMIT" bash "$RECIPE" "$V" "$CV" >"$LOG" 2>&1; then
  tail -n 15 "$LOG" | grep -v "^WARNING: Location" >&2
  rm -f "$LOG"
  rm -rf "$V"
  unavailable "the recipe failed or timed out after $(( $(date +%s) - t0 ))s (wheels not installable here?)"
fi
grep -E "^(tf2_msgs OK|timing:)" "$LOG"
rm -f "$LOG"
check || { rm -rf "$V"; unavailable "the built venv cannot import rclpy/tf2_msgs"; }
touch "$STAMP"
echo "ros2-env: ready ($V) in $(( $(date +%s) - t0 ))s"
