#!/usr/bin/env bash
# Install Debian's ROS 1 python3-tf2-geometry-msgs and python3-tf2-sensor-msgs (0.7.6),
# the reference implementations the registered transforms of tfbus.convert are checked
# against (tests/geometry/test_convert_reference.py, run under /usr/bin/python3). Idempotent and
# time-bounded; exits 0 with a reason when the install is impossible (not root, no apt).
set -u
check() {
    /usr/bin/python3 -c "import tf2_geometry_msgs, tf2_sensor_msgs" >/dev/null 2>&1
}
if check; then
    echo "tf2-msgs-py: ready"
    exit 0
fi
if [ "$(id -u)" != "0" ]; then
    echo "tf2-msgs-py: unavailable: not root, cannot apt-get install python3-tf2-geometry-msgs python3-tf2-sensor-msgs"
    exit 0
fi
if ! command -v apt-get >/dev/null; then
    echo "tf2-msgs-py: unavailable: no apt-get"
    exit 0
fi
export DEBIAN_FRONTEND=noninteractive
PKGS="python3-tf2-geometry-msgs python3-tf2-sensor-msgs"
timeout 900 apt-get -o DPkg::Lock::Timeout=600 install -y -q --no-install-recommends $PKGS \
    >/dev/null 2>&1 || {
    timeout 600 apt-get -o DPkg::Lock::Timeout=600 update -q >/dev/null 2>&1
    timeout 900 apt-get -o DPkg::Lock::Timeout=600 install -y -q --no-install-recommends $PKGS \
        >/dev/null 2>&1
}
if check; then
    echo "tf2-msgs-py: ready"
else
    echo "tf2-msgs-py: unavailable: apt-get install $PKGS failed"
fi
exit 0
