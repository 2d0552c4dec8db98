"""The tf2_py half of ``bench_check.py``: one round of the core cases on the real tf2.

Runs under Debian's ``/usr/bin/python3`` (``python3-tf2``, ROS 1 geometry2 0.7.6), never
imports tfbus. Reads the scenario as JSON on stdin (``bench_check.scenario``), prints one
JSON object: seconds per call (or per time) of each case, measured as tfbus's side
measures it (the best of ``runs`` runs within the round).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import rospy  # type: ignore[import-not-found]
from geometry_msgs.msg import TransformStamped  # type: ignore[import-not-found]
from tf2_side import best_per_call, chain, fresh_zero, message, new_core, ros_time


def set_chain(sc: dict[str, Any]) -> float:
    """``set_transform`` per call: a chain of ``links`` links, in order, step by step."""
    c = sc["set_chain"]
    msgs = [
        message(f"f{i}", f"f{i + 1}", c["t0_ns"] + k * c["period_ns"], k + i)
        for k in range(c["steps"])
        for i in range(c["links"])
    ]
    best = math.inf
    for _ in range(sc["runs"]):
        core = new_core(c["cache_time_s"])
        setter = core.set_transform
        start = time.perf_counter()
        for m in msgs:
            setter(m, "bench")
        best = min(best, (time.perf_counter() - start) / len(msgs))
    return best


def lookups(sc: dict[str, Any]) -> dict[str, float]:
    """Never-repeated interpolated lookups per depth, and time 0 after an insert."""
    lk = sc["lookup"]
    out: dict[str, float] = {}
    calls, runs = lk["calls"], sc["runs"]
    varying = [ros_time(ns) for ns in lk["query_ns"]]
    for depth in lk["depths"]:
        core = chain(lk, depth)
        leaf = f"f{depth}"

        def fn(t: Any, lookup: Any = core.lookup_transform_core, leaf: str = leaf) -> Any:
            return lookup("f0", leaf, t)

        out[f"{depth}/interp"] = best_per_call(
            fn, [varying[r * calls : (r + 1) * calls] for r in range(runs)]
        )
        if depth == 2:
            out["2/zero_fresh"] = fresh_zero(core, leaf, {**lk, "repeats": runs})
    return out


def batch_loop(sc: dict[str, Any]) -> dict[str, float]:
    """A loop of single lookups over each order of the batch times (depth 8, every link
    interpolated), seconds per time."""
    b = sc["batch"]
    core = new_core(100.0)
    for k in range(1, b["depth"] + 1):
        for j in range(b["samples"]):
            a = 0.01 * j * k
            m = TransformStamped()
            m.header.frame_id = f"f{k - 1}"
            m.child_frame_id = f"f{k}"
            m.header.stamp = ros_time(b["base"] + j * b["step"] + k * 1000)
            m.transform.translation.x = 0.1 * k + 0.01 * j
            m.transform.translation.y = -0.2 * k
            m.transform.translation.z = 0.3
            m.transform.rotation.y = 0.6 * math.sin(a / 2)
            m.transform.rotation.z = 0.8 * math.sin(a / 2)
            m.transform.rotation.w = math.cos(a / 2)
            core.set_transform(m, "bench")
    leaf = f"f{b['depth']}"
    lookup = core.lookup_transform_core
    out: dict[str, float] = {}
    for name, ns in b["orders"].items():
        times = [rospy.Time(t // 10**9, t % 10**9) for t in ns]
        start = time.perf_counter()
        for t in times:
            lookup("f0", leaf, t)
        out[name] = (time.perf_counter() - start) / len(times)
    return out


def main() -> None:
    sc = json.load(sys.stdin)
    result: dict[str, Any] = {"set_chain": set_chain(sc), **lookups(sc)}
    result["batch"] = batch_loop(sc)
    json.dump(result, sys.stdout)


if __name__ == "__main__":
    main()
