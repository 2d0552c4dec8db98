"""An rclpy ``ActionServer`` of tf2_msgs/action/LookupTransform (run in the ROS 2 venv, on
Fast DDS): what a ROS 2 ``buffer_server`` looks like on the graph.

usage: lookup_action_server_peer.py ACTION

Prints READY once the server exists, spins until SIGTERM, then prints one JSON line
{"goals": N}: the goals its goal callback received.
"""

import json
import signal
import sys

import rclpy
from rclpy.action import ActionServer, GoalResponse
from rclpy.signals import SignalHandlerOptions
from tf2_msgs.action import LookupTransform

goals = 0
running = True


def on_goal(_request: object) -> GoalResponse:
    global goals
    goals += 1
    return GoalResponse.ACCEPT


def execute(handle: object) -> LookupTransform.Result:
    handle.succeed()  # type: ignore[attr-defined]
    return LookupTransform.Result()


def stop(_signum: int, _frame: object) -> None:
    global running
    running = False


rclpy.init(signal_handler_options=SignalHandlerOptions.NO)  # SIGTERM is ours
signal.signal(signal.SIGTERM, stop)
node = rclpy.create_node("lookup_action_server_peer")
server = ActionServer(node, LookupTransform, sys.argv[1], execute, goal_callback=on_goal)
print("READY", flush=True)
while running:
    rclpy.spin_once(node, timeout_sec=0.1)
print(json.dumps({"goals": goals}), flush=True)
server.destroy()
node.destroy_node()
rclpy.shutdown()
