#!/usr/bin/env bash
# Install evo (github.com/MichaelGrupp/evo, GPL-3.0), a bag-analysis tool whose tf_cache
# reads /tf into tf2_py's BufferCore, from PyPI as a test peer: `pip install --target` into
# .peer-evo/ (never into the project's venv, never copied into the repository). Used by
# tests/compat/test_compat_evo.py, which runs evo's own CLI on Debian's python3 (Debian's
# tf2_py) and on the ROS 2 venv's python with tf2_py aliased to tfbus.compat.tf2_py.
# Exits 0 and "evo: ready (DIR)" only when Debian's python3 imports evo's tf_cache against
# Debian's tf2_py; otherwise 1 and "evo: unavailable: REASON". Idempotent and bounded.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VERSION="${TFBUS_EVO_VERSION:-1.38.1}"
DIR="${TFBUS_EVO_DIR:-$ROOT/.peer-evo/evo-$VERSION}"
LIMIT="${TFBUS_EVO_INSTALL_TIMEOUT:-600}"
# pip runs from any Python with pip (the project's venv if it is there; else a small venv
# of its own, so the script works before `make test` has made .venv) and installs wheels
# for Debian's python3, which is the interpreter that runs evo.
PIP_PYTHON="${PIP_PYTHON:-}"

unavailable() { echo "evo: unavailable: $*"; exit 1; }

works() {  # Debian's tf2_py under evo's tf_cache: a transform set and looked up
  PYTHONPATH="$DIR" HOME="$(mktemp -d)" timeout 120 /usr/bin/python3 - <<'PY'
import tf2_py  # Debian's python3-tf2-py
from evo.tools import tf_cache
from geometry_msgs.msg import TransformStamped
import rospy
c = tf_cache.TfCache()
t = TransformStamped()
t.header.frame_id, t.child_frame_id = "odom", "base_link"
t.header.stamp = rospy.Time(10)
t.transform.translation.x, t.transform.rotation.w = 1.5, 1.0
c.buffer.set_transform(t, "check")
got = c.buffer.lookup_transform_core("odom", "base_link", rospy.Time(10))
assert got.transform.translation.x == 1.5, got
PY
}

[ -x /usr/bin/python3 ] || unavailable "no /usr/bin/python3 (Debian's ROS 1: sudo bash scripts/install/install_ros1.sh)"
/usr/bin/python3 -c "import tf2_py, rospy" 2>/dev/null \
    || unavailable "Debian's tf2_py or rospy does not import (sudo bash scripts/install/install_ros1.sh)"
if [ -f "$DIR/.tfbus-evo-ok" ]; then
    why="$(works 2>&1)" || unavailable "installed in $DIR, but it does not work: $why"
    echo "evo: ready ($DIR, already installed)"; exit 0
fi
if [ -z "$PIP_PYTHON" ]; then
  if [ -x "$ROOT/.venv/bin/python" ]; then
    PIP_PYTHON="$ROOT/.venv/bin/python"
  else
    PIP_VENV="$ROOT/.peer-evo/pip-venv"
    [ -x "$PIP_VENV/bin/python" ] || timeout 300 "${PYTHON:-python3}" -m venv "$PIP_VENV" \
        || unavailable "could not make a venv to run pip with (${PYTHON:-python3} -m venv $PIP_VENV)"
    PIP_PYTHON="$PIP_VENV/bin/python"
  fi
fi
[ -x "$PIP_PYTHON" ] || unavailable "no $PIP_PYTHON to run pip with"
DEBIAN_PY="$(/usr/bin/python3 -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
rm -rf "$DIR"; mkdir -p "$DIR"
out="$(timeout "$LIMIT" "$PIP_PYTHON" -m pip install -q --disable-pip-version-check \
    --target "$DIR" --python-version "$DEBIAN_PY" --only-binary=:all: "evo==$VERSION" 2>&1)" \
    || unavailable "pip install --target $DIR evo==$VERSION failed or took over $LIMIT s: $(printf "%s" "$out" | tail -c 400)"
why="$(works 2>&1)" || unavailable "installed in $DIR, but it does not work: $why"
touch "$DIR/.tfbus-evo-ok"
echo "evo: ready ($DIR)"
