"""The part of turtlesim that turtle_tf2's ``turtle_tf2_listener.py`` talks to, on Debian's
ROS 1 (run with ``/usr/bin/python3`` by ``tests/compat/test_compat_programs.py``, never
imported; ``turtlesim.srv`` generated from turtlesim's ``Spawn.srv`` on ``PYTHONPATH``):

* the ``/spawn`` service (``turtlesim/Spawn``), answering with the name asked for, as
  turtlesim does for a free name (the turtles' poses come on ``/tf`` from the test);
* a subscriber of ``/turtle2/cmd_vel`` printing one JSON line per ``Twist`` received,
  with the publisher's caller id: ``{"callerid", "linear": [x, y, z], "angular": [...]}``.

Prints ``READY`` once both exist; ends on SIGINT (rospy's handler)."""

import json
import sys

sys.path.append("/usr/lib/python3/dist-packages")

import rospy
import turtlesim.srv
from geometry_msgs.msg import Twist


def main() -> None:
    rospy.init_node("turtlesim_peer")

    def on_twist(message: Twist) -> None:
        lin, ang = message.linear, message.angular
        print(json.dumps({"callerid": message._connection_header.get("callerid", ""),
                          "linear": [lin.x, lin.y, lin.z], "angular": [ang.x, ang.y, ang.z]}),
              flush=True)

    rospy.Service("/spawn", turtlesim.srv.Spawn,
                  lambda request: turtlesim.srv.SpawnResponse(request.name))
    rospy.Subscriber("/turtle2/cmd_vel", Twist, on_twist, queue_size=100)
    print("READY", flush=True)
    rospy.spin()


if __name__ == "__main__":
    main()
