"""roslibpy clients that subscribe to ``/tf`` on ``tfbus web`` and then leave with a close
handshake (``Ros.close()``, as a program does on exit): run in a subprocess by tests/web.

``python roslibpy_leaving_client.py PORT N`` opens N connections in one process (one
reactor), each subscribes to ``/tf`` and, at its first message, closes; prints
``left N`` once every connection is closed, then ends the reactor.
"""

import sys
import threading

import roslibpy

port, n = int(sys.argv[1]), int(sys.argv[2])
heard = threading.Semaphore(0)
clients = []
for _ in range(n):
    ros = roslibpy.Ros("127.0.0.1", port)
    ros.run(timeout=60)
    topic = roslibpy.Topic(ros, "/tf", "tf2_msgs/TFMessage")
    topic.subscribe(lambda message: heard.release())
    clients.append((ros, topic))
for _ in range(n):
    if not heard.acquire(timeout=60):
        sys.exit("no /tf message within 60 s")
for ros, _topic in clients:
    ros.close(timeout=60)  # a WebSocket close handshake while /tf flows
print(f"left {n}", flush=True)
clients[0][0].terminate()
