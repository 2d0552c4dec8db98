#!/usr/bin/env bash
# Install ROBOTIS' zenoh-ros2-sdk (PyPI, Apache-2.0), an independent Python implementation of
# rmw_zenoh's wire, as a test peer of tfbus's rmw_zenoh transport: its own venv in
# .peer-zenoh-ros2-sdk/ (never the project's venv: it pins its own eclipse-zenoh, rosbags,
# GitPython), never copied into the repository. Used by tests/transports/test_rmw_zenoh_sdk.py,
# which runs peers/rmw_zenoh/sdk_peer.py with this venv's python.
# Exits 0 and "zenoh-ros2-sdk: ready (DIR)" only when the SDK imports and computes
# tf2_msgs/msg/TFMessage's type hash from the message definitions in peers/rmw_zenoh/msg/
# (no clone from GitHub); otherwise 1 and "zenoh-ros2-sdk: unavailable: REASON".
# Idempotent (a working venv is kept, ~1 s) and bounded (TFBUS_ZENOH_ROS2_SDK_TIMEOUT, default
# 600 s, for pip).
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VERSION="${TFBUS_ZENOH_ROS2_SDK_VERSION:-0.1.8}"
DIR="${TFBUS_ZENOH_ROS2_SDK_DIR:-$ROOT/.peer-zenoh-ros2-sdk/sdk-$VERSION}"
LIMIT="${TFBUS_ZENOH_ROS2_SDK_TIMEOUT:-600}"
PY="${PYTHON:-python3}"
HASH="RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"

unavailable() { echo "zenoh-ros2-sdk: unavailable: $*"; exit 1; }

works() {  # the SDK computes TFMessage's type hash from peers/rmw_zenoh/msg/
  local got
  got="$(HOME="$DIR/home" timeout 120 "$DIR/bin/python" "$ROOT/peers/rmw_zenoh/sdk_peer.py" 0 hash 2>&1)" \
    || { echo "$got" | tail -c 400; return 1; }
  [ "$(echo "$got" | tail -n 1)" = "$HASH" ] || { echo "type hash $got, expected $HASH"; return 1; }
}

if [ -f "$DIR/.tfbus-sdk-ok" ]; then
  why="$(works 2>&1)" || unavailable "installed in $DIR, but it does not work: $why"
  echo "zenoh-ros2-sdk: ready ($DIR, already installed)"; exit 0
fi
command -v "$PY" >/dev/null 2>&1 || unavailable "no $PY to make a venv with"
rm -rf "$DIR"; mkdir -p "$DIR/home"
timeout 300 "$PY" -m venv "$DIR" >/dev/null 2>&1 || unavailable "$PY -m venv $DIR failed"
out="$(timeout "$LIMIT" "$DIR/bin/python" -m pip install -q --disable-pip-version-check \
    "zenoh-ros2-sdk==$VERSION" 2>&1)" \
    || unavailable "pip install zenoh-ros2-sdk==$VERSION failed or took over $LIMIT s: $(printf "%s" "$out" | tail -c 400)"
why="$(works 2>&1)" || unavailable "installed in $DIR, but it does not work: $why"
touch "$DIR/.tfbus-sdk-ok"
echo "zenoh-ros2-sdk: ready ($DIR)"
