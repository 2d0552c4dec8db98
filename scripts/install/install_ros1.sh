#!/usr/bin/env bash
# Install Debian's ROS 1 (roscore, roscpp, tf, tf2_ros, their tools) for the ROS 1 interop
# tests and benchmarks. Exits 0 only when a roscore started on 127.0.0.1 answers the master
# API; otherwise 1 with the reason (scripts/install/_peer.sh). Idempotent and bounded in time.
set -u
PEER="ros1"
PKGS="ros-core-dev libtf-dev libtf2-ros-dev python3-rospy python3-rosbag python3-tf2-ros tf-tools tf2-tools"
APT_FLAGS=""
# shellcheck source=scripts/install/_peer.sh
. "$(dirname "${BASH_SOURCE[0]}")/_peer.sh"
present() {
    # shellcheck disable=SC2086
    dpkg_have $PKGS && [ -x /usr/bin/roscore ] && [ -x /usr/bin/rosrun ] \
        && pkg-config --exists roscpp tf tf2_ros
}
works() { /usr/bin/python3 "$(dirname "${BASH_SOURCE[0]}")/../../peers/ros1/ros1_peers.py" --check-master; }
peer_install
