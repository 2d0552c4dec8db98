"""The part of turtlesim that turtle_tf2's ``turtle_tf2_listener.py`` talks to, on Debian's
ROS 1 (run with ``/usr/bin/python3`` by ``tests/compat/test_compat_programs.py``, never
imported; ``turtlesim.srv`` and ``turtlesim.msg`` generated from turtlesim's ``Spawn.srv``
and ``Pose.msg`` on ``PYTHONPATH``)::

    ros1_turtle_peer.py [NAME X Y THETA]


* the ``/spawn`` service (``turtlesim/Spawn``), answering with the name asked for, as
  turtlesim does for a free name (the turtles' poses come on ``/tf`` from the test);
* a subscriber of ``/turtle2/cmd_vel`` printing one JSON line per ``Twist`` received,
  with the publisher's caller id: ``{"callerid", "linear": [x, y, z], "angular": [...]}``;
* with NAME X Y THETA, turtle NAME's ``turtlesim/Pose`` on ``/NAME/pose`` at 20 Hz, as
  turtlesim publishes a turtle standing still.

Prints ``READY`` once both exist; ends on SIGINT (rospy's handler)."""

import json
import sys
import threading

sys.path.append("/usr/lib/python3/dist-packages")

import rospy
import turtlesim.msg
import turtlesim.srv
from geometry_msgs.msg import Twist


def main() -> None:
    rospy.init_node("turtlesim_peer")

    printing = threading.Lock()  # rospy calls back in a thread per publisher connection

    def on_twist(message: Twist) -> None:
        lin, ang = message.linear, message.angular
        line = json.dumps({"callerid": message._connection_header.get("callerid", ""),
                           "linear": [lin.x, lin.y, lin.z], "angular": [ang.x, ang.y, ang.z]})
        with printing:
            print(line, flush=True)

    rospy.Service("/spawn", turtlesim.srv.Spawn,
                  lambda request: turtlesim.srv.SpawnResponse(request.name))
    rospy.Subscriber("/turtle2/cmd_vel", Twist, on_twist, queue_size=100)
    print("READY", flush=True)
    if len(sys.argv) < 5:
        rospy.spin()
        return
    name, x, y, theta = sys.argv[1], *(float(v) for v in sys.argv[2:5])
    pose = rospy.Publisher(f"/{name}/pose", turtlesim.msg.Pose, queue_size=10)
    rate = rospy.Rate(20.0)
    while not rospy.is_shutdown():
        pose.publish(turtlesim.msg.Pose(x=x, y=y, theta=theta))
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break


if __name__ == "__main__":
    main()
