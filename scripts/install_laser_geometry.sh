#!/usr/bin/env bash
# Install ROS 1 laser_geometry (C++ headers + library, Python bindings) from Debian, for
# the differential tests in tests/sensors/test_laser.py. Idempotent and time-bounded; exits 0 with
# a reason when the install is impossible (not root, no apt).
set -u
if pkg-config --exists laser_geometry 2>/dev/null && command -v g++ >/dev/null; then
    echo "laser_geometry already installed"
    exit 0
fi
if [ "$(id -u)" != "0" ]; then
    echo "not root: cannot apt-get install liblaser-geometry-dev python3-laser-geometry g++"
    exit 0
fi
if ! command -v apt-get >/dev/null; then
    echo "no apt-get: install liblaser-geometry-dev (ROS 1 laser_geometry) by hand"
    exit 0
fi
export DEBIAN_FRONTEND=noninteractive
timeout 900 apt-get -o DPkg::Lock::Timeout=600 install -y -q --no-install-recommends \
    liblaser-geometry-dev python3-laser-geometry g++ pkg-config >/dev/null 2>&1 || {
    timeout 600 apt-get -o DPkg::Lock::Timeout=600 update -q >/dev/null 2>&1
    timeout 900 apt-get -o DPkg::Lock::Timeout=600 install -y -q --no-install-recommends \
        liblaser-geometry-dev python3-laser-geometry g++ pkg-config >/dev/null 2>&1 || {
        echo "apt-get install liblaser-geometry-dev failed"
        exit 0
    }
}
echo "installed laser_geometry"
