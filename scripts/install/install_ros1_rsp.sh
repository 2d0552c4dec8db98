#!/usr/bin/env bash
# Install Debian's ROS 1 robot_state_publisher, roscore and the rospy message packages the
# recording script and tests/robot/test_robot_state.py's live test use. Exits 0 only when
# the node's binary is in place, rospy imports its messages and a roscore on 127.0.0.1
# answers; otherwise 1 with the reason (scripts/install/_peer.sh). Idempotent and bounded in time.
set -u
PEER="ros1-robot-state-publisher"
PKGS="ros-robot-state-publisher ros-core-dev python3-rospy python3-rosgraph python3-sensor-msgs python3-tf2-msgs"
APT_FLAGS=""
# shellcheck source=scripts/install/_peer.sh
. "$(dirname "${BASH_SOURCE[0]}")/_peer.sh"
present() {
    # shellcheck disable=SC2086
    dpkg_have $PKGS && [ -x /usr/lib/robot_state_publisher/robot_state_publisher ]
}
works() {
    /usr/bin/python3 -c "import rospy, sensor_msgs.msg, tf2_msgs.msg" \
        && /usr/bin/python3 "$(dirname "${BASH_SOURCE[0]}")/../../peers/ros1/ros1_peers.py" --check-master
}
peer_install
