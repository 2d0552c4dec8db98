#!/usr/bin/env bash
# Install PyPI's roslibpy (gramaziokohler/roslibpy, MIT) and its Twisted/autobahn stack as a
# test peer of `tfbus web`: `pip install --target` into .peer-roslibpy/ (never into the
# project's venv: Twisted stays out of tfbus's environment). Used by
# tests/web/test_web_clients.py, which runs roslibpy's TFClient in a subprocess with
# PYTHONPATH=DIR. Exits 0 and "roslibpy: ready (DIR)" only when the project's python imports
# roslibpy's TFClient from DIR; otherwise 1 and "roslibpy: unavailable: REASON".
# Idempotent and bounded.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VERSION="${TFBUS_ROSLIBPY_VERSION:-2.1.0}"
DIR="${TFBUS_ROSLIBPY_DIR:-$ROOT/.peer-roslibpy/roslibpy-$VERSION}"
LIMIT="${TFBUS_ROSLIBPY_INSTALL_TIMEOUT:-600}"
PY="${PYTHON:-$ROOT/.venv/bin/python}"

unavailable() { echo "roslibpy: unavailable: $*"; exit 1; }

works() {
  PYTHONPATH="$DIR" timeout 120 "$PY" -c 'import roslibpy, roslibpy.tf; roslibpy.tf.TFClient'
}

[ -x "$PY" ] || PY="$(command -v python3)"
[ -x "$PY" ] || unavailable "no python to install with (set PYTHON)"
if [ -f "$DIR/.tfbus-roslibpy-ok" ]; then
    why="$(works 2>&1)" || unavailable "installed in $DIR, but it does not work: $why"
    echo "roslibpy: ready ($DIR, already installed)"; exit 0
fi
rm -rf "$DIR"; mkdir -p "$DIR"
out="$(timeout "$LIMIT" "$PY" -m pip install -q --disable-pip-version-check \
    --target "$DIR" "roslibpy==$VERSION" 2>&1)" \
    || unavailable "pip install --target $DIR roslibpy==$VERSION failed or took over $LIMIT s: $(printf "%s" "$out" | tail -c 400)"
why="$(works 2>&1)" || unavailable "installed in $DIR, but it does not work: $why"
touch "$DIR/.tfbus-roslibpy-ok"
echo "roslibpy: ready ($DIR)"
