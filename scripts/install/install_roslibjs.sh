#!/usr/bin/env bash
# Install npm's roslib (RobotWebTools/roslibjs, BSD-2-Clause), the JavaScript client web
# robot apps use, as a test peer of `tfbus web`: `npm install roslib@VERSION` into
# .peer-roslibjs/ (never into the repository's tracked files). Used by
# tests/web/test_web_clients.py, which runs its TFClient and ROS2TFClient in Node.
# Exits 0 and "roslibjs: ready (DIR)" only when Node imports the installed roslib and finds
# both clients; otherwise 1 and "roslibjs: unavailable: REASON". Idempotent and bounded.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VERSION="${TFBUS_ROSLIBJS_VERSION:-2.1.0}"
DIR="${TFBUS_ROSLIBJS_DIR:-$ROOT/.peer-roslibjs/roslib-$VERSION}"
LIMIT="${TFBUS_ROSLIBJS_INSTALL_TIMEOUT:-600}"

unavailable() { echo "roslibjs: unavailable: $*"; exit 1; }

works() {  # the installed roslib imported by Node, its two tf clients there
  ROSLIB_DIR="$DIR" timeout 60 node --input-type=module -e '
    import { pathToFileURL } from "node:url";
    const lib = await import(pathToFileURL(process.env.ROSLIB_DIR + "/node_modules/roslib/dist/RosLib.js").href);
    if (typeof lib.TFClient !== "function" || typeof lib.ROS2TFClient !== "function" ||
        typeof lib.Ros !== "function") { console.error("no TFClient/ROS2TFClient/Ros"); process.exit(1); }
  '
}

command -v node >/dev/null 2>&1 || unavailable "no node (apt-get install nodejs npm)"
command -v npm >/dev/null 2>&1 || unavailable "no npm (apt-get install npm)"
if [ -f "$DIR/.tfbus-roslibjs-ok" ]; then
    why="$(works 2>&1)" || unavailable "installed in $DIR, but it does not work: $why"
    echo "roslibjs: ready ($DIR, already installed)"; exit 0
fi
rm -rf "$DIR"; mkdir -p "$DIR"
out="$(cd "$DIR" && timeout "$LIMIT" npm install --no-audit --no-fund --no-save \
    --prefix "$DIR" "roslib@$VERSION" 2>&1)" \
    || unavailable "npm install roslib@$VERSION into $DIR failed or took over $LIMIT s: $(printf "%s" "$out" | tail -c 400)"
why="$(works 2>&1)" || unavailable "installed in $DIR, but it does not work: $why"
touch "$DIR/.tfbus-roslibjs-ok"
echo "roslibjs: ready ($DIR)"
