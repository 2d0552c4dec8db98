"""The tf2_py half of ``bench_core.py``: the same scenarios on the real tf2.

Runs under Debian's ``/usr/bin/python3`` (``python3-tf2``, ROS 1 geometry2 0.7.6), never
imports tfbus. Reads the scenario as JSON on stdin (see ``bench_core.scenario``) and
prints the figures as one JSON object on stdout.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any

import rospy  # type: ignore[import-not-found]
import tf2_py  # type: ignore[import-not-found]
from geometry_msgs.msg import TransformStamped  # type: ignore[import-not-found]

NS = 1_000_000_000


def ros_time(ns: int) -> Any:
    return rospy.Time(ns // NS, ns % NS)


def message(parent: str, child: str, stamp_ns: int, k: int) -> Any:
    m = TransformStamped()
    m.header.frame_id = parent
    m.child_frame_id = child
    m.header.stamp = ros_time(stamp_ns)
    m.transform.translation.x = 1.0 + 0.001 * (k % 7)
    m.transform.translation.y = 0.5
    m.transform.translation.z = -0.25
    # A unit quaternion that changes a little from sample to sample.
    s = 0.01 * (k % 11)
    m.transform.rotation.x = s
    m.transform.rotation.y = 0.0
    m.transform.rotation.z = 0.0
    m.transform.rotation.w = (1.0 - s * s) ** 0.5
    return m


def new_core(cache_time_s: float) -> Any:
    return tf2_py.BufferCore(rospy.Duration.from_sec(cache_time_s))


def chain(sc: dict[str, Any], depth: int) -> Any:
    core = new_core(sc["cache_time_s"])
    for k, stamp in enumerate(sc["chain_stamps"]):
        for i in range(depth):
            core.set_transform(message(f"f{i}", f"f{i + 1}", stamp, k + i), "bench")
    return core


def best_per_call(fn: Any, runs: list[list[Any]]) -> float:
    """Fastest run's seconds per call; each run calls ``fn`` on its own arguments."""
    best = float("inf")
    for args in runs:
        start = time.perf_counter()
        for a in args:
            fn(a)
        best = min(best, (time.perf_counter() - start) / len(args))
    return best


def fresh_zero(core: Any, leaf: str, sc: dict[str, Any]) -> float:
    """Time-0 lookups each right after an insert on an unrelated link, minus the inserts
    alone (best of each)."""
    calls, period = sc["calls"], sc["period_ns"]
    stamps = iter(range(sc["set_t0_ns"], 1 << 62, period))  # 100 Hz on the x <- y link
    zero = rospy.Time(0)
    lookup = core.lookup_transform_core
    setter = core.set_transform
    for _ in range(2 * calls):  # reach the steady state: a full cache, pruning on insert
        setter(message("x", "y", next(stamps), 0), "bench")
    best_both: float = float("inf")
    best_alone: float = float("inf")
    for _ in range(sc["repeats"]):
        msgs = [message("x", "y", next(stamps), k) for k in range(calls)]
        start = time.perf_counter()
        for m in msgs:
            setter(m, "bench")
        best_alone = min(best_alone, time.perf_counter() - start)
        msgs = [message("x", "y", next(stamps), k) for k in range(calls)]
        start = time.perf_counter()
        for m in msgs:
            setter(m, "bench")
            lookup("f0", leaf, zero)
        best_both = min(best_both, time.perf_counter() - start)
    best = (best_both - best_alone) / calls
    return best


def lookups(sc: dict[str, Any]) -> dict[str, float]:
    out: dict[str, float] = {}
    calls, repeats = sc["calls"], sc["repeats"]
    varying = [ros_time(ns) for ns in sc["query_ns"]]
    for depth in sc["depths"]:
        core = chain(sc, depth)
        leaf = f"f{depth}"

        def fn(t: Any, lookup: Any = core.lookup_transform_core, leaf: str = leaf) -> Any:
            return lookup("f0", leaf, t)

        # Repeated queries first (a result memo, if any, may serve them), then queries
        # that are never repeated, then time 0 right after inserts.
        out[f"{depth}/zero"] = best_per_call(fn, [[rospy.Time(0)] * calls] * repeats)
        out[f"{depth}/fixed"] = best_per_call(fn, [[ros_time(sc["fixed_ns"])] * calls] * repeats)
        out[f"{depth}/interp"] = best_per_call(
            fn, [varying[r * calls : (r + 1) * calls] for r in range(repeats)]
        )
        out[f"{depth}/zero_fresh"] = fresh_zero(core, leaf, sc)
    return out


def set_rate(sc: dict[str, Any]) -> float:
    core = new_core(sc["cache_time_s"])
    frames = sc["set_frames"]
    msgs = [
        message("root", f"c{f}", sc["set_t0_ns"] + k * sc["period_ns"], k)
        for k in range(sc["set_stamps"])
        for f in range(frames)
    ]
    setter = core.set_transform
    start = time.perf_counter()
    for m in msgs:
        setter(m, "bench")
    return len(msgs) / (time.perf_counter() - start)


def set_chain(sc: dict[str, Any]) -> float:
    """Seconds per ``set_transform`` on a chain of 10 links stored in order (best of the
    repeats, a fresh buffer each)."""
    msgs = [
        message(f"f{i}", f"f{i + 1}", sc["set_t0_ns"] + k * sc["period_ns"], k + i)
        for k in range(sc["chain_steps"])
        for i in range(10)
    ]
    best = float("inf")
    for _ in range(sc["repeats"]):
        setter = new_core(sc["cache_time_s"]).set_transform
        start = time.perf_counter()
        for m in msgs:
            setter(m, "bench")
        best = min(best, (time.perf_counter() - start) / len(msgs))
    return best


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096


def memory(sc: dict[str, Any]) -> dict[str, float]:
    core = new_core(sc["cache_time_s"])
    m = message("root", "c0", 0, 0)
    before = rss_bytes()
    for f in range(sc["mem_frames"]):
        m.child_frame_id = f"c{f}"
        for k in range(sc["mem_samples"]):
            m.header.stamp = ros_time(sc["set_t0_ns"] + k * sc["period_ns"])
            core.set_transform(m, "bench")
    grown = rss_bytes() - before
    samples = sc["mem_frames"] * sc["mem_samples"]
    return {"rss_bytes_per_sample": grown / samples, "samples": samples}


def main() -> None:
    sc = json.load(sys.stdin)
    result: dict[str, Any] = {"lookup_s": lookups(sc), "set_per_s": set_rate(sc)}
    result["set_chain_s"] = set_chain(sc)
    result.update(memory(sc))
    json.dump(result, sys.stdout)


if __name__ == "__main__":
    main()
