#!/usr/bin/env bash
# Install Debian's ROS 1 robot_state_publisher, roscore and the rospy message packages the
# recording script and tests/robot/test_robot_state.py's live test use. Idempotent and bounded
# in time; exits 0 with a reason on stdout when it cannot install (not root, no apt-get,
# apt failed), so the test can skip with that reason.
set -u
pkgs="ros-robot-state-publisher ros-core-dev python3-rospy python3-rosgraph python3-sensor-msgs python3-tf2-msgs"
have() {
    for p in $pkgs; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || return 1
    done
}
if have; then echo "ROS 1 robot_state_publisher present"; exit 0; fi
if [ "$(id -u)" != 0 ]; then echo "cannot install ROS 1 robot_state_publisher: not root (apt-get install $pkgs)"; exit 0; fi
if ! command -v apt-get >/dev/null 2>&1; then echo "cannot install ROS 1 robot_state_publisher: no apt-get"; exit 0; fi
export DEBIAN_FRONTEND=noninteractive
timeout 600 apt-get -o DPkg::Lock::Timeout=600 update -qq >/dev/null 2>&1
if ! timeout 1200 apt-get -o DPkg::Lock::Timeout=600 install -y -qq $pkgs >/dev/null 2>&1; then
    echo "cannot install ROS 1 robot_state_publisher: apt-get install $pkgs failed"; exit 0
fi
if have; then echo "ROS 1 robot_state_publisher installed"; else echo "cannot install ROS 1 robot_state_publisher: packages still missing after apt-get"; fi
exit 0
