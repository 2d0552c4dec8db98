"""Run a script of calls on Debian's real ``tf2_py.BufferCore`` (ROS 1 geometry2 0.7.6).

Runs under ``/usr/bin/python3`` (``python3-tf2``), never imports tfbus: the test side of
``tests/core/test_chain.py``. Reads JSON on stdin::

    {"cache_time_s": 10.0, "ops": [op, ...]}

where an op is ``["new"]`` (a fresh BufferCore from here on), ``["set", parent, child,
stamp_ns, [tx, ty, tz], [qx, qy, qz, qw], static]`` or ``["call", method_name,
[arg, ...]]`` (an argument ``{"t": ns}`` is a ``rospy.Time``). Prints one JSON line
per call: ``{"ok": result}`` (a list, tuple, bool, str, number, a Time as
``{"t": ns}``, a TransformStamped as ``{"tf": [frame_id, child, stamp_ns, [t], [q]]}``)
or ``{"err": exception class name, "msg": text}``.
"""

from __future__ import annotations

import json
import sys
from typing import Any

import rospy  # type: ignore[import-not-found]
import tf2_py  # type: ignore[import-not-found]
from geometry_msgs.msg import TransformStamped  # type: ignore[import-not-found]

NS = 1_000_000_000


def decode(value: Any) -> Any:
    if isinstance(value, dict) and "t" in value:
        return rospy.Time(value["t"] // NS, value["t"] % NS)
    return value


def encode(value: Any) -> Any:
    if isinstance(value, (list, tuple)):
        return [encode(v) for v in value]
    if isinstance(value, rospy.Time):
        return {"t": value.to_nsec()}
    if isinstance(value, TransformStamped):
        t, q = value.transform.translation, value.transform.rotation
        return {"tf": [value.header.frame_id, value.child_frame_id,
                       value.header.stamp.to_nsec(), [t.x, t.y, t.z], [q.x, q.y, q.z, q.w]]}
    return value


def main() -> None:
    script = json.load(sys.stdin)
    core = tf2_py.BufferCore(rospy.Duration.from_sec(script.get("cache_time_s", 10.0)))
    out = []
    for op in script["ops"]:
        if op[0] == "new":
            core = tf2_py.BufferCore(rospy.Duration.from_sec(script.get("cache_time_s", 10.0)))
            continue
        if op[0] == "set":
            _, parent, child, ns, t, q, static = op
            m = TransformStamped()
            m.header.frame_id, m.child_frame_id = parent, child
            m.header.stamp = rospy.Time(ns // NS, ns % NS)
            (m.transform.translation.x, m.transform.translation.y,
             m.transform.translation.z) = t
            (m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z,
             m.transform.rotation.w) = q
            (core.set_transform_static if static else core.set_transform)(m, "side")
            continue
        _, name, args = op
        try:
            result = getattr(core, name)(*[decode(a) for a in args])
        except Exception as e:  # reported to the test: class and text
            out.append({"err": type(e).__name__, "msg": str(e)})
        else:
            out.append({"ok": encode(result)})
    for line in out:
        print(json.dumps(line))


if __name__ == "__main__":
    main()
