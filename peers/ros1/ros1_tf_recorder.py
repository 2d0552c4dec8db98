"""A rospy subscriber of ``/tf`` (Debian's ROS 1, run with ``/usr/bin/python3`` by
``tests/compat/test_compat_programs.py``, never imported): prints ``READY``, then one JSON
line per transform received, with the publisher's caller id from the connection header::

    {"callerid": "/node", "parent": ..., "child": ..., "stamp": [secs, nsecs],
     "t": [x, y, z], "r": [x, y, z, w]}

Ends on SIGINT (rospy's handler). rospy calls the callback in a thread per publisher
connection: each line is printed whole under a lock (two publishers' lines printed at
once could otherwise share a line)."""

import json
import sys
import threading

sys.path.append("/usr/lib/python3/dist-packages")

import rospy
from tf2_msgs.msg import TFMessage


def main() -> None:
    rospy.init_node("tf_recorder", disable_signals=False)

    printing = threading.Lock()

    def on_tf(message: TFMessage) -> None:
        who = message._connection_header.get("callerid", "")
        for t in message.transforms:
            tr, r = t.transform.translation, t.transform.rotation
            line = json.dumps({
                "callerid": who, "parent": t.header.frame_id, "child": t.child_frame_id,
                "stamp": [t.header.stamp.secs, t.header.stamp.nsecs],
                "t": [tr.x, tr.y, tr.z], "r": [r.x, r.y, r.z, r.w],
            })
            with printing:
                print(line, flush=True)

    rospy.Subscriber("/tf", TFMessage, on_tf, queue_size=100)
    print("READY", flush=True)
    rospy.spin()


if __name__ == "__main__":
    main()
