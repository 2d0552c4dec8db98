"""An independent rmw_zenoh peer for tfbus's tests: ROBOTIS' ``zenoh-ros2-sdk`` (PyPI,
Apache-2.0) publishing or subscribing ``tf2_msgs/msg/TFMessage`` through a Zenoh router.

Runs with the interpreter of the venv ``scripts/install/install_zenoh_ros2_sdk.sh`` makes
(never imported by tfbus). Message definitions come from ``peers/rmw_zenoh/msg/`` (the
SDK would clone them from GitHub at run time otherwise); the SDK computes the type hash
from them itself. The session is a client of the router, multicast scouting off.

    python sdk_peer.py PORT hash                 print the SDK's TFMessage type hash
    python sdk_peer.py PORT sub                  subscribe /tf and /tf_static
    python sdk_peer.py PORT pub CHILD X          publish /tf_static and /tf (CHILD, X) once
                                                 per line read on stdin

``sub`` prints ``ready`` once subscribed, then one JSON line per transform received:
``{"topic", "frame_id", "child_frame_id", "sec", "nanosec", "t": [x, y, z], "q": [x, y, z,
w]}``. ``pub`` prints ``ready`` once declared, the attachment of its first put
(``attachment <hex>``) and ``sent N`` after each /tf put. Both end when stdin closes.
"""

from __future__ import annotations

import json
import os
import sys
import threading
from pathlib import Path

HERE = Path(__file__).resolve().parent
TF = "tf2_msgs/msg/TFMessage"


def main() -> int:
    port, mode = int(sys.argv[1]), sys.argv[2]
    os.environ["ZENOH_CONFIG_OVERRIDE"] = (
        'mode="client";scouting/multicast/enabled=false;'
        f'connect/endpoints=["tcp/127.0.0.1:{port}"]')
    from zenoh_ros2_sdk import ROS2Publisher, ROS2Subscriber, get_registry
    from zenoh_ros2_sdk.qos import QosDurability, QosProfile
    from zenoh_ros2_sdk.session import ZenohSession
    from zenoh_ros2_sdk.utils import get_type_hash, load_dependencies_recursive

    registry = get_registry(str(HERE / "msg"))
    if mode == "hash":
        path = registry.get_msg_file_path(TF)
        assert path is not None
        text = path.read_text()
        print(get_type_hash(TF, msg_definition=text,
                            dependencies=load_dependencies_recursive(TF, text, registry)))
        return 0
    lock = threading.Lock()

    def out(line: str) -> None:
        with lock:
            print(line, flush=True)

    static_qos = QosProfile(durability=QosDurability.TRANSIENT_LOCAL, history_depth=100)
    common = {"router_ip": "127.0.0.1", "router_port": port, "domain_id": 0}
    if mode == "sub":
        def printer(topic: str):  # type: ignore[no-untyped-def]
            def on_message(msg) -> None:  # type: ignore[no-untyped-def]
                for t in msg.transforms:
                    tr, rot = t.transform.translation, t.transform.rotation
                    out(json.dumps({
                        "topic": topic, "frame_id": t.header.frame_id,
                        "child_frame_id": t.child_frame_id, "sec": t.header.stamp.sec,
                        "nanosec": t.header.stamp.nanosec, "t": [tr.x, tr.y, tr.z],
                        "q": [rot.x, rot.y, rot.z, rot.w]}))
            return on_message

        subs = [ROS2Subscriber("/tf", TF, printer("/tf"), node_name="sdk_listener", **common),
                ROS2Subscriber("/tf_static", TF, printer("/tf_static"), qos=static_qos,
                               node_name="sdk_static_listener", **common)]
        out("ready")
        sys.stdin.read()
        for sub in subs:
            sub.close()
        return 0
    child, x = sys.argv[3], float(sys.argv[4])
    pub = ROS2Publisher("/tf", TF, node_name="sdk_talker", **common)
    static_pub = ROS2Publisher("/tf_static", TF, node_name="sdk_talker", qos=static_qos,
                               **common)
    store = ZenohSession.get_instance().store.types

    def message(parent: str, child_frame: str, sec: int, tx: float) -> dict[str, object]:
        header = store["std_msgs/msg/Header"](
            stamp=store["builtin_interfaces/msg/Time"](sec=sec, nanosec=125),
            frame_id=parent)
        transform = store["geometry_msgs/msg/Transform"](
            translation=store["geometry_msgs/msg/Vector3"](x=tx, y=-0.5, z=2.0),
            rotation=store["geometry_msgs/msg/Quaternion"](x=0.0, y=0.6, z=0.0, w=0.8))
        return {"transforms": [store["geometry_msgs/msg/TransformStamped"](
            header=header, child_frame_id=child_frame, transform=transform)]}

    attachment = pub._create_attachment(0, 0)  # what its puts carry (seq, stamp, gid)
    out("attachment " + bytes(attachment).hex())
    out("ready")
    for sent, _line in enumerate(sys.stdin, 1):
        static_pub.publish(**message("base_link", child + "_static", 11, -x))
        pub.publish(**message("odom", child, 12, x))
        out(f"sent {sent}")
    pub.close()
    static_pub.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
