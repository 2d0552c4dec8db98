"""One side of ``bench_compat.py``: the same calls through ``tf2_py.BufferCore``'s API,
on Debian's real tf2_py (``real``, run under ``/usr/bin/python3``) or on
``tfbus.compat.tf2_py`` (``compat``). Prints best seconds per call as one JSON object."""

from __future__ import annotations

import json
import sys
import time
from typing import Any

SIDE = sys.argv[1]
NS = 1_000_000_000
DEPTH, SAMPLES, CALLS, REPEATS = 5, 100, 2000, 7

if SIDE == "real":
    import rospy  # type: ignore[import-not-found]
    import tf2_py  # type: ignore[import-not-found]
    from geometry_msgs.msg import TransformStamped  # type: ignore[import-not-found]

    def stamp(ns: int) -> Any:
        return rospy.Time(ns // NS, ns % NS)

    def msg(parent: str, child: str, ns: int) -> Any:
        m = TransformStamped()
        m.header.frame_id, m.child_frame_id, m.header.stamp = parent, child, stamp(ns)
        m.transform.translation.x = 1.0
        m.transform.rotation.w = 1.0
        return m

    core: Any = tf2_py.BufferCore(rospy.Duration(100))
else:
    from tfbus import Header, Time, Transform, TransformStamped, Vector3
    from tfbus.compat import tf2_py as compat

    def stamp(ns: int) -> Any:
        return Time.from_ns(ns)

    def msg(parent: str, child: str, ns: int) -> Any:
        return TransformStamped(Header(Time.from_ns(ns), parent), child,
                                Transform(Vector3(1.0, 0.0, 0.0)))

    core = compat.BufferCore(100.0)


def best(fn: Any, args: list[Any]) -> float:
    out = float("inf")
    for _ in range(REPEATS):
        start = time.perf_counter()
        for a in args:
            fn(a)
        out = min(out, (time.perf_counter() - start) / len(args))
    return out


msgs = [msg(f"f{i}", f"f{i + 1}", k * 10_000_000) for k in range(SAMPLES) for i in range(DEPTH)]
out = {"set_transform": best(lambda m: core.set_transform(m, "b"), msgs[:CALLS])}
core = core.__class__(*([] if SIDE == "compat" else [rospy.Duration(100)]))
for m in msgs:
    core.set_transform(m, "b")
times = [stamp(10_000_000 + (k * 7_919_993) % (90 * 10_000_000)) for k in range(CALLS)]
leaf = f"f{DEPTH}"
out["lookup_transform_core"] = best(lambda t: core.lookup_transform_core("f0", leaf, t), times)
out["can_transform_core"] = best(lambda t: core.can_transform_core("f0", leaf, t), times)
out["_chain"] = best(lambda t: core._chain("f0", t, leaf, t, "f0"), times[:500])
print(json.dumps(out))
