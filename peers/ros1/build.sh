#!/usr/bin/env bash
# Build the ROS 1 tutorial's two C++ nodes (tf_broadcaster.cpp, tf_listener.cpp, here)
# against Debian's ROS 1 (roscpp + tf, found by pkg-config).  usage: build.sh OUT_DIR
# Idempotent: a binary newer than its source is kept. Bounded: each compile has a time
# limit (TFBUS_ROS1_BUILD_TIMEOUT, default 300 s). On failure it says why on stderr
# ("ros1-peers: cannot build: REASON") and exits 1.
set -uo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
OUT="${1:?usage: build.sh OUT_DIR}"
LIMIT="${TFBUS_ROS1_BUILD_TIMEOUT:-300}"
export PATH="/usr/bin:$PATH"   # Debian's pkg-config and ROS .pc files, not a venv's

fail() { echo "ros1-peers: cannot build: $*" >&2; exit 1; }

command -v g++ >/dev/null 2>&1 || fail "g++ not found (apt-get install g++)"
command -v pkg-config >/dev/null 2>&1 || fail "pkg-config not found (apt-get install pkg-config)"
FLAGS="$(pkg-config --cflags --libs roscpp tf 2>&1)" \
  || fail "pkg-config does not know roscpp/tf: $FLAGS (scripts/install/install_ros1.sh installs them)"
mkdir -p "$OUT" || fail "cannot create $OUT"
for node in tf_broadcaster tf_listener; do
  src="$HERE/$node.cpp"
  bin="$OUT/$node"
  [ -f "$src" ] || fail "$src is missing"
  if [ -x "$bin" ] && [ "$bin" -nt "$src" ]; then
    continue
  fi
  # shellcheck disable=SC2086  # FLAGS is a list of words
  if ! log="$(timeout "$LIMIT" g++ -std=c++14 -O2 -o "$bin.tmp" "$src" $FLAGS 2>&1)"; then
    rm -f "$bin.tmp"
    fail "g++ failed or timed out (${LIMIT} s) on $node.cpp: $(printf '%s' "$log" | tail -n 5)"
  fi
  mv "$bin.tmp" "$bin"
done
echo "ros1-peers: built $OUT/tf_broadcaster $OUT/tf_listener"
