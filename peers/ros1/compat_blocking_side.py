"""One process of ``bench_compat.py``'s ROS 1 rows (the master at ``ROS_MASTER_URI``):

* ``publisher`` (Debian's python3, rospy): for each line ``i`` read on stdin, publishes
  one ``/tf`` message ``map -> bench`` stamped ``1000 + i`` s (``-1``, sent until the
  waiter has it, first: it says the publisher is connected).
* ``tfbus-wait N`` / ``rospy-wait N``: a thread blocked in ``tf2_ros`` ``Buffer``'s
  ``lookup_transform("map", "bench", 1000 + i s, timeout=5 s)`` (``tfbus.compat.tf2_ros``
  with its ROS 1 ``TransformListener(buffer)``, or Debian's tf2_ros on rospy); prints
  ``WAITING i`` once it waits, then measures from the message's arrival in this process
  (a callback on ``/tf`` registered before the listener's: the bus's for tfbus, a rospy
  Subscriber for rospy) to the call's return; at the end prints the N delays (seconds)
  as one JSON line ``DELAYS [...]``.
* ``tfbus-idle S`` / ``rospy-idle S``: a process holding only a Buffer and a ROS 1
  TransformListener, idle for S s; prints ``CPU <fraction of a core>`` (process CPU time
  over wall time, ``time.process_time``).
"""

from __future__ import annotations

import json
import sys
import threading
import time
from typing import Any

MODE = sys.argv[1]
BASE = 1000


def publisher() -> None:
    import rospy  # type: ignore[import-not-found]
    from geometry_msgs.msg import TransformStamped  # type: ignore[import-not-found]
    from tf2_msgs.msg import TFMessage  # type: ignore[import-not-found]

    rospy.init_node("bench_blocking_publisher")
    pub = rospy.Publisher("/tf", TFMessage, queue_size=100, tcp_nodelay=True)
    print("PUBLISHING", flush=True)
    for line in sys.stdin:
        i = int(line)
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = "map", "bench"
        t.header.stamp = rospy.Time(BASE + i)
        t.transform.translation.x = float(i)
        t.transform.rotation.w = 1.0
        pub.publish(TFMessage([t]))


def waiter(n: int, lookup: Any, stamp: Any, timeout: Any, waiting: Any,
           arrivals: dict[int, float]) -> None:
    lookup("map", "bench", stamp(BASE - 1), timeout)  # the publisher is connected
    print("WARM", flush=True)
    delays = []
    for i in range(n):
        returned: list[float] = []

        def wait(i: int = i, returned: list[float] = returned) -> None:
            lookup("map", "bench", stamp(BASE + i), timeout)
            returned.append(time.perf_counter())

        thread = threading.Thread(target=wait)
        thread.start()
        waiting(thread)
        print(f"WAITING {i}", flush=True)
        thread.join(30.0)
        delays.append(returned[0] - arrivals[BASE + i])
    print("DELAYS", json.dumps(delays), flush=True)


def tfbus_wait(n: int) -> None:
    from tfbus import Time
    from tfbus.compat import tf2_ros
    from tfbus.compat._loop import background, ros1_bus
    from tfbus.topics import TF_TOPIC

    arrivals: dict[int, float] = {}

    def arrived(message: Any) -> None:
        for t in message.transforms:
            arrivals[t.header.stamp.ns // 1_000_000_000] = time.perf_counter()

    bus = ros1_bus()
    background.call(bus.subscribe_callback, TF_TOPIC, arrived)  # before the listener's
    buffer = tf2_ros.Buffer()
    tf2_ros.TransformListener(buffer)
    print("READY", flush=True)

    def waiting(_thread: threading.Thread) -> None:
        deadline = time.monotonic() + 10.0
        while background.call(lambda: buffer.buffer.pending_waits) < 1:
            if time.monotonic() > deadline:
                raise RuntimeError("the blocking call never waited")
            time.sleep(0.001)

    waiter(n, buffer.lookup_transform, Time.from_sec, 5.0, waiting, arrivals)


def rospy_wait(n: int) -> None:
    import rospy
    import tf2_ros  # type: ignore[import-not-found]
    from tf2_msgs.msg import TFMessage

    rospy.init_node("bench_blocking_rospy")
    arrivals: dict[int, float] = {}

    def arrived(message: Any) -> None:
        for t in message.transforms:
            arrivals[t.header.stamp.secs] = time.perf_counter()

    rospy.Subscriber("/tf", TFMessage, arrived, queue_size=100, tcp_nodelay=True)
    buffer = tf2_ros.Buffer()
    tf2_ros.TransformListener(buffer)
    print("READY", flush=True)

    def waiting(_thread: threading.Thread) -> None:
        time.sleep(0.05)  # rospy's Buffer says nothing of its wait: give it time to start

    waiter(n, buffer.lookup_transform, lambda s: rospy.Time(s), rospy.Duration(5.0),
           waiting, arrivals)


def idle(which: str, seconds: float) -> None:
    if which == "tfbus":
        from tfbus.compat import tf2_ros

        buffer = tf2_ros.Buffer()
        tf2_ros.TransformListener(buffer)
    else:
        import rospy
        import tf2_ros

        rospy.init_node("bench_idle_rospy")
        buffer = tf2_ros.Buffer()
        tf2_ros.TransformListener(buffer)
    time.sleep(2.0)  # joined the graph; then idle
    cpu0, wall0 = time.process_time(), time.monotonic()
    time.sleep(seconds)
    cpu = (time.process_time() - cpu0) / (time.monotonic() - wall0)
    print(f"CPU {cpu:.6f}", flush=True)


if MODE == "publisher":
    publisher()
elif MODE == "tfbus-wait":
    tfbus_wait(int(sys.argv[2]))
elif MODE == "rospy-wait":
    rospy_wait(int(sys.argv[2]))
elif MODE in ("tfbus-idle", "rospy-idle"):
    idle(MODE.split("-")[0], float(sys.argv[2]))
else:
    raise SystemExit(f"unknown mode {MODE!r}")
