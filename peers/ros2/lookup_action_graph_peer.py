"""rclpy's view of a LookupTransform action server (run in the ROS 2 venv, on Fast DDS).

usage: lookup_action_graph_peer.py ACTION SECONDS [send]

Prints READY, then spins an ``rclpy.action.ActionClient(LookupTransform, ACTION)`` until
``server_is_ready()`` (rcl_action_server_is_available: the three services' servers and the
status and feedback publishers are in the graph and matched) or SECONDS pass, and prints
one JSON line: {"ready": bool, "actions": rclpy.action.get_action_names_and_types(node)}.
With ``send``: then sends one goal (map <- base_link) and prints {"sent": true} once the
request is written, then spins two more seconds (its reply cannot come: the request and
reply of a service do not cross DDS vendors) and prints {"replied": bool}.
"""

import json
import sys
import time

import rclpy
from rclpy.action import ActionClient, get_action_names_and_types
from tf2_msgs.action import LookupTransform

action, seconds = sys.argv[1], float(sys.argv[2])
rclpy.init()
node = rclpy.create_node("lookup_action_graph_peer")
client = ActionClient(node, LookupTransform, action)
print("READY", flush=True)
end = time.monotonic() + seconds
ready = False
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
    if client.server_is_ready():
        ready = True
        break
actions = [[name, list(types)] for name, types in get_action_names_and_types(node)]
print(json.dumps({"ready": ready, "actions": actions}), flush=True)
if ready and sys.argv[3:] == ["send"]:
    goal = LookupTransform.Goal(target_frame="map", source_frame="base_link")
    future = client.send_goal_async(goal)
    print(json.dumps({"sent": True}), flush=True)
    end = time.monotonic() + 2.0
    while time.monotonic() < end and not future.done():
        rclpy.spin_once(node, timeout_sec=0.1)
    print(json.dumps({"replied": future.done()}), flush=True)
client.destroy()
node.destroy_node()
rclpy.shutdown()
