#!/usr/bin/env bash
# Install Debian's ROS 1 (roscore, roscpp, tf, tf2_ros, their tools) for the ROS 1 interop
# tests and benchmarks. Idempotent and bounded in time; exits 0 with a reason on stdout
# when it cannot install (not root, no apt-get), so callers can skip with that reason.
set -u
pkgs="ros-core-dev libtf-dev libtf2-ros-dev python3-rospy python3-rosbag python3-tf2-ros tf-tools tf2-tools"
have() { for p in $pkgs; do dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || return 1; done; }
if have; then echo "ROS 1 packages present"; exit 0; fi
if [ "$(id -u)" != 0 ]; then echo "cannot install ROS 1: not root (apt-get install $pkgs)"; exit 0; fi
if ! command -v apt-get >/dev/null 2>&1; then echo "cannot install ROS 1: no apt-get"; exit 0; fi
export DEBIAN_FRONTEND=noninteractive
timeout 600 apt-get -o DPkg::Lock::Timeout=600 update -qq >/dev/null 2>&1
if ! timeout 1200 apt-get -o DPkg::Lock::Timeout=600 install -y -qq $pkgs >/dev/null 2>&1; then
    echo "cannot install ROS 1: apt-get install $pkgs failed"; exit 0
fi
have && echo "ROS 1 packages installed" || echo "cannot install ROS 1: packages still missing after apt-get"
exit 0
