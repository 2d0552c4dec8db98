"""Sensor-stream benchmarks, each against the real peer in the same run.

* ``lookup_transforms``: N = 10 000 times, a chain of depth 8, every link interpolated
  (each link's samples at its own stamps), vs a loop of ``tf2_py`` lookups
  (``/usr/bin/python3``, Debian python3-tf2, ROS 1 geometry2 0.7.6). Target ≤ 0.03x,
  aim ≤ 100 ns per time.
  Then small N (1 to 128 random times): the batch against a loop of single lookups, and
  the N from which the batch is faster.
* A 720-beam scan projected and transformed into odom (laser_geometry's interpolation)
  vs the C++ laser_geometry (``peers/debian/laser_geometry_bench.cpp``, built here with g++
  and pkg-config), CPU time on both sides (each single-threaded). Target ≤ 2x.
* A point cloud of N float32 points (10**4 and 10**6) through ``do_transform_cloud``, and
  ``(N, 3)`` float64 points through ``transform_points``, each vs bare numpy
  ``pts @ R.T + t`` on float64 ``(N, 3)`` points, alternated; with the minor page faults of
  one call (a temporary the size of the cloud faults it in); CPU time (numpy runs on one
  thread here), so the ratio holds on a loaded machine. Target ≤ 1.3x.
* MessageFilter: throughput when transforms are ready (target ≥ 20 000 messages/s), and
  the wake-up of a waiting message after its transform arrives (median; target ≤ 0.1 ms),
  on asyncio and trio.

Prints figures; asserts nothing. ``python benchmarks/bench_sensors.py [--quick]``.
"""

from __future__ import annotations

import os

# Numpy's OpenBLAS worker threads spin on a 2-core machine and take the core the batched
# lookup's second thread runs on; nothing here uses BLAS.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import math
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import anyio
import numpy as np

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.buffer import Buffer
from tfbus.clock import ManualClock
from tfbus.core import BufferCore
from tfbus.filters import MessageFilter
from tfbus.laser import LaserProjection
from tfbus.sensor_msgs import LaserScan

TF2_PYTHON = "/usr/bin/python3"
HERE = Path(__file__).resolve().parent
DEPTH = 8
SAMPLES = 1001  # per link, 10 ms apart
STEP_NS = 10_000_000
BASE_NS = 1_000 * 1_000_000_000
ROUNDS = 3  # alternating rounds of each side; the best of each is reported


def _value(k: int, j: int) -> tuple[float, ...]:
    a = 0.01 * j * k
    return (0.1 * k + 0.01 * j, -0.2 * k, 0.3, 0.0, 0.6 * math.sin(a / 2),
            0.8 * math.sin(a / 2), math.cos(a / 2))  # fmt: skip


def chain_core() -> BufferCore:
    core = BufferCore(cache_time=100.0)
    for k in range(1, DEPTH + 1):
        for j in range(SAMPLES):
            v = _value(k, j)
            core.set_transform(TransformStamped(
                Header(Time.from_ns(BASE_NS + j * STEP_NS + k * 1000), f"f{k - 1}"), f"f{k}",
                Transform(Vector3(*v[:3]), Quaternion(*v[3:]))))  # fmt: skip
    return core


def query_times(n: int) -> np.ndarray[Any, np.dtype[np.int64]]:
    rng = np.random.default_rng(7)
    lo, hi = BASE_NS + STEP_NS, BASE_NS + (SAMPLES - 2) * STEP_NS
    return np.sort(rng.integers(lo, hi, n)).astype(np.int64)


def best(
    fn: Any, repeat: int, log: list[float] | None = None, clock: Any = time.perf_counter
) -> float:
    out = math.inf
    for _ in range(repeat):
        t0 = clock()
        fn()
        dt = clock() - t0
        out = min(out, dt)
        if log is not None:
            log.append(dt)
    return out


TF2_SCRIPT = r"""
import json, math, sys, time
import rospy, tf2_py
from geometry_msgs.msg import TransformStamped
sc = json.load(sys.stdin)
core = tf2_py.BufferCore(rospy.Duration.from_sec(100.0))
for k in range(1, sc["depth"] + 1):
    for j in range(sc["samples"]):
        a = 0.01 * j * k
        m = TransformStamped()
        m.header.frame_id = "f%d" % (k - 1)
        m.child_frame_id = "f%d" % k
        ns = sc["base"] + j * sc["step"] + k * 1000
        m.header.stamp = rospy.Time(ns // 10**9, ns % 10**9)
        m.transform.translation.x = 0.1 * k + 0.01 * j
        m.transform.translation.y = -0.2 * k
        m.transform.translation.z = 0.3
        m.transform.rotation.y = 0.6 * math.sin(a / 2)
        m.transform.rotation.z = 0.8 * math.sin(a / 2)
        m.transform.rotation.w = math.cos(a / 2)
        core.set_transform(m, "bench")
times = [rospy.Time(t // 10**9, t % 10**9) for t in sc["times"]]
leaf = "f%d" % sc["depth"]
best = float("inf")
for _ in range(3):
    t0 = time.perf_counter()
    for t in times:
        core.lookup_transform_core("f0", leaf, t)
    best = min(best, time.perf_counter() - t0)
print(json.dumps({"loop_s": best}))
"""


def bench_lookups(n: int) -> None:
    print(f"\nlookup_transforms: N = {n} times, depth {DEPTH}, every link interpolated")
    core = chain_core()
    times = query_times(n)
    sc = {"depth": DEPTH, "samples": SAMPLES, "base": BASE_NS, "step": STEP_NS,
          "times": times.tolist()}  # fmt: skip
    # The machine may be shared: alternate the two sides and keep each one's best round.
    ours = single = ref = math.inf
    runs: list[float] = []
    load0 = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    for _ in range(ROUNDS):
        ours = min(ours, best(lambda: core.lookup_transforms("f0", f"f{DEPTH}", times), 7, runs))
        single = min(single, best(lambda: [
            core.lookup_transform("f0", f"f{DEPTH}", Time.from_ns(int(t)))
            for t in times[:2000]], 3) * n / 2000)  # fmt: skip
        run = subprocess.run([TF2_PYTHON, "-c", TF2_SCRIPT], input=json.dumps(sc),
                             capture_output=True, text=True, check=False)  # fmt: skip
        if run.returncode:
            print(f"  tf2_py: unavailable ({run.stderr.strip()[-200:]})")
            ref = math.nan
            break
        ref = min(ref, json.loads(run.stdout)["loop_s"])
    med = statistics.median(runs)
    load1 = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    print(f"  (load average {load0:.2f} -> {load1:.2f} on {os.cpu_count()} CPUs; best of each side"
          " reported, medians in brackets where kept)")  # fmt: skip
    print(f"  tfbus lookup_transforms     {ours * 1e3:8.2f} ms  {ours / n * 1e9:7.0f} ns/time"
          f"  [median {med / n * 1e9:.0f} ns/time]")  # fmt: skip
    print(f"  tfbus single-lookup loop    {single * 1e3:8.2f} ms  {single / n * 1e9:7.0f} ns/time")
    if math.isnan(ref):
        return
    print(f"  tf2_py lookup loop          {ref * 1e3:8.2f} ms  {ref / n * 1e9:7.0f} ns/time")
    print(f"  ratio tfbus batch / tf2_py loop: {ours / ref:.4f}x (target <= 0.03x)"
          f"  [our median / tf2_py best: {med / ref:.4f}x]")  # fmt: skip


def bench_small_batches() -> None:
    """Where the batch starts paying: ``lookup_transforms`` of N random times vs a loop of
    ``lookup_transform`` over the same N, depth 8 (medians of 200 draws each)."""
    print(f"\nlookup_transforms vs a lookup_transform loop, small N, depth {DEPTH}")
    core = chain_core()
    rng = np.random.default_rng(5)
    pool = query_times(4096)
    leaf = f"f{DEPTH}"
    even = None
    for n in (1, 2, 4, 8, 16, 32, 64, 128):
        batch, loop = [], []
        for _ in range(200):
            times = rng.choice(pool, n, replace=False)
            stamps = [Time.from_ns(int(t)) for t in times]
            t0 = time.perf_counter()
            core.lookup_transforms("f0", leaf, times)
            batch.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            for t in stamps:
                core.lookup_transform("f0", leaf, t)
            loop.append(time.perf_counter() - t0)
        b, lo = statistics.median(batch), statistics.median(loop)
        if even is None and b < lo:
            even = n
        print(f"  N = {n:4d}   batch {b * 1e6:7.2f} us   loop {lo * 1e6:7.2f} us   {b / lo:5.2f}x")
    verdict = f"the batch is faster from N = {even} on" if even else "the loop is faster at every N"
    print(f"  {verdict}")


def _scan(beams: int) -> LaserScan:
    inc = 2 * math.pi / beams
    return LaserScan(
        header=Header(Time(1005, 10_000_000), "base_laser"), angle_min=-math.pi,
        angle_max=-math.pi + (beams - 1) * inc, angle_increment=inc,
        time_increment=1.0 / 40 / beams, scan_time=0.025, range_min=0.05, range_max=30.0,
        ranges=(1.0 + 0.01 * (np.arange(beams) % 300)).astype(np.float32),
        intensities=np.arange(beams, dtype=np.float32),
    )  # fmt: skip


def _laser_core() -> BufferCore:
    core = BufferCore(cache_time=100.0)
    for j in range(501):
        t = j * 0.02
        yaw = t + math.pi / 2
        core.set_transform(TransformStamped(
            Header(Time(1000) + _dur(t), "odom"), "base_link",
            Transform(Vector3(2 * math.cos(t), 2 * math.sin(t), 0.0),
                      Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))))  # fmt: skip
    core.set_transform_static(
        TransformStamped(
            Header(Time(0), "base_link"), "base_laser", Transform(Vector3(0.1, 0.0, 0.2))
        )
    )
    return core


def _dur(t: float) -> Any:
    from tfbus.time import Duration

    return Duration.from_sec(t)


def _repeat(reps: int, fn: Any, *args: Any, **kwargs: Any) -> None:
    """Call ``fn`` ``reps`` times, dropping each result at once (as a node that publishes
    its cloud and moves on; the C++ side reuses one output message)."""
    for _ in range(reps):
        fn(*args, **kwargs)


def laser_cpp_missing() -> str | None:
    """Why the C++ laser_geometry cannot be built here, or None when it can."""
    if shutil.which("g++") is None:
        return "g++ not found"
    if subprocess.run(["pkg-config", "--exists", "laser_geometry"], check=False).returncode:
        return "laser_geometry not installed (bash scripts/install/install_laser_geometry.sh)"
    return None


def build_laser_cpp(out: Path) -> Path:
    """``peers/debian/laser_geometry_bench.cpp`` built with g++ into ``out``; its path.

    Raises:
        subprocess.CalledProcessError: pkg-config or g++ failed."""
    exe = out / "laser_geometry_bench"
    flags = subprocess.run(
        ["pkg-config", "--cflags", "--libs", "laser_geometry"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    subprocess.run(
        ["g++", "-O2", "-o", str(exe),
         str(HERE.parent / "peers" / "debian" / "laser_geometry_bench.cpp"), *flags],
        check=True,
    )  # fmt: skip
    return exe


class LaserSide:
    """A ``beams``-beam scan, the odom tree it is transformed through, and the projector."""

    def __init__(self, beams: int) -> None:
        self.beams = beams
        self.core = _laser_core()
        self.scan = _scan(beams)
        self.proj = LaserProjection()

    def round(self, reps: int) -> dict[str, float]:
        """tfbus's CPU seconds per scan (best of 5 runs of ``reps`` calls):
        ``project`` (``project_laser``), ``transform`` (laser_geometry's interpolation)
        and ``per_beam`` (a lookup per beam)."""
        cpu = time.process_time
        proj, scan, core = self.proj, self.scan, self.core
        transform = proj.transform_laser_scan_to_point_cloud
        return {
            "project": best(lambda: _repeat(reps, proj.project_laser, scan), 5, clock=cpu) / reps,
            "transform": best(
                lambda: _repeat(reps, transform, "odom", scan, core), 5, clock=cpu
            ) / reps,
            "per_beam": best(
                lambda: _repeat(reps, transform, "odom", scan, core, interpolation="per_beam"),
                5,
                clock=cpu,
            ) / reps,
        }  # fmt: skip


def laser_cpp_round(exe: Path, beams: int, reps: int) -> dict[str, float]:
    """The C++ laser_geometry's CPU seconds per scan: ``project`` (``projectLaser``) and
    ``transform`` (``transformLaserScanToPointCloud``), best of its own runs."""
    out = subprocess.run(
        [str(exe)], input=f"{beams} {reps}", capture_output=True, text=True, check=True
    ).stdout.split()
    figures = dict(zip(out[::2], out[1::2], strict=True))
    return {
        "project": float(figures["project_ns"]) / 1e9,
        "transform": float(figures["transform_ns"]) / 1e9,
    }


def bench_laser(beams: int, reps: int) -> None:
    print(f"\nlaser: a {beams}-beam scan projected / transformed into odom (CPU time)")
    side = LaserSide(beams)
    have_cpp = laser_cpp_missing() is None
    p = t = pb = cp = ct = math.inf
    with tempfile.TemporaryDirectory() as tmp:
        exe = build_laser_cpp(Path(tmp)) if have_cpp else None
        for _ in range(ROUNDS):  # alternate the sides; keep each one's best round
            ours = side.round(reps)
            p, t, pb = min(p, ours["project"]), min(t, ours["transform"]), min(pb, ours["per_beam"])
            if exe is not None:
                theirs = laser_cpp_round(exe, beams, reps)
                cp, ct = min(cp, theirs["project"]), min(ct, theirs["transform"])
    print(f"  tfbus project_laser                      {p * 1e6:8.1f} µs")
    print(f"  tfbus transform (laser_geometry interp.) {t * 1e6:8.1f} µs")
    print(f"  tfbus transform (per_beam lookups)       {pb * 1e6:8.1f} µs")
    if not have_cpp:
        print("  C++ laser_geometry: unavailable (bash scripts/install/install_laser_geometry.sh)")
        return
    print(f"  C++ laser_geometry projectLaser           {cp * 1e6:8.1f} µs   ratio {p / cp:.2f}x")
    print(f"  C++ laser_geometry transformLaserScan...  {ct * 1e6:8.1f} µs   ratio {t / ct:.2f}x"
          " (target <= 2x)")  # fmt: skip


def _faults(fn: Any) -> int:
    """Minor page faults of one call of ``fn`` (``getrusage``)."""
    import resource

    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    fn()
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


BARE = "bare numpy pts @ R.T + t"
"""The point-cloud rows' reference: bare numpy on float64 ``(N, 3)`` points."""


def cloud_sides(n: int) -> dict[str, Callable[[], object]]:
    """The point-cloud sides on ``n`` points through one transform: :data:`BARE`,
    ``transform_points`` (float64 ``(n, 3)``) and ``do_transform_cloud (float32)`` (a
    ``PointCloud2``), each a call of no arguments."""
    from tfbus.convert import do_transform_cloud
    from tfbus.geometry import to_matrix, transform_points
    from tfbus.sensor_msgs import PointCloud2, PointField

    rng = np.random.default_rng(5)
    pts = rng.standard_normal((n, 3)) * 10.0
    q = np.array([0.1, 0.2, 0.3, 0.9])
    q /= np.linalg.norm(q)
    t = np.array([1.0, -2.0, 0.5])
    rot = to_matrix(t, q)[:3, :3]
    fields = [PointField(name, 4 * k, PointField.FLOAT32) for k, name in enumerate("xyz")]
    cloud = PointCloud2(Header(Time(5), "base_laser"), 1, n, fields, False, 12, 12 * n,
                        pts.astype(np.float32).tobytes(), True)  # fmt: skip
    tf = TransformStamped(
        Header(Time(5), "odom"), "base_laser",
        Transform(Vector3(*t.tolist()), Quaternion(*q.tolist())),
    )  # fmt: skip
    return {
        BARE: lambda: pts @ rot.T + t,
        "transform_points": lambda: transform_points(tf, pts),
        "do_transform_cloud (float32)": lambda: do_transform_cloud(cloud, tf),
    }


def cloud_round(sides: dict[str, Callable[[], object]], reps: int) -> dict[str, float]:
    """One round of every side, one after the other: each one's CPU seconds per call
    (best of 3 runs of ``reps`` calls; numpy runs on one thread here)."""
    times: dict[str, float] = {}
    for name, fn in sides.items():
        times[name] = math.inf
        for _ in range(3):
            t0 = time.process_time()
            for _ in range(reps):
                fn()
            times[name] = min(times[name], (time.process_time() - t0) / reps)
    return times


def bench_cloud(n: int, reps: int) -> None:
    print(f"\npoint cloud: {n} points through one transform (vs bare numpy pts @ R.T + t)")
    sides = cloud_sides(n)
    times = {name: math.inf for name in sides}
    for _ in range(ROUNDS):  # alternate the sides; keep each one's best round (CPU time)
        for name, v in cloud_round(sides, reps).items():
            times[name] = min(times[name], v)
    bare = times[BARE]
    for name, fn in sides.items():
        ratio = f"   ratio {times[name] / bare:.2f}x (target <= 1.3x)"
        if name.startswith("bare"):
            ratio = ""
        print(f"  {name:30s} {times[name] * 1e3:9.3f} ms CPU {_faults(fn):6d} page faults{ratio}")


class _Msg:
    __slots__ = ("header",)

    def __init__(self, header: Header) -> None:
        self.header = header


async def _filter_throughput(n: int) -> float:
    buf = Buffer(clock=ManualClock(Time(1000)))
    buf.set_transform(TransformStamped(Header(Time(1000), "odom"), "base_link", Transform()))
    buf.set_transform(TransformStamped(Header(Time(1010), "odom"), "base_link", Transform()))
    msgs = [_Msg(Header(Time(1005), "base_link")) for _ in range(n)]

    async def source() -> Any:
        for m in msgs:
            yield m

    count = 0
    t0 = time.perf_counter()
    async with MessageFilter(buf, "odom", source(), queue_size=100) as mf:
        async for _ in mf:
            count += 1
    return count / (time.perf_counter() - t0)


async def _filter_wakeup(n: int) -> float:
    buf = Buffer(clock=ManualClock(Time(1000)))
    buf.set_transform(TransformStamped(Header(Time(1000), "odom"), "base_link", Transform()))
    tx, rx = anyio.create_memory_object_stream[_Msg](10)
    lat: list[float] = []
    async with MessageFilter(buf, "odom", rx) as mf:
        it = mf.__aiter__()
        for k in range(1, n + 1):
            await tx.send(_Msg(Header(Time(1000 + k), "base_link")))
            await anyio.sleep(0)
            await anyio.sleep(0)
            t0 = time.perf_counter()
            buf.set_transform(TransformStamped(Header(Time(1000 + k), "odom"), "base_link",
                                               Transform()))  # fmt: skip
            await it.__anext__()
            lat.append(time.perf_counter() - t0)
        tx.close()
    return statistics.median(lat)


def bench_filter(n: int) -> None:
    print("\nMessageFilter")
    for backend in ("asyncio", "trio"):
        rate = anyio.run(_filter_throughput, n, backend=backend)
        wake = anyio.run(_filter_wakeup, min(n, 2000), backend=backend)
        print(f"  {backend:8s} ready transforms: {rate:9.0f} messages/s (target >= 20000); "
              f"wake-up median {wake * 1e3:.3f} ms (target <= 0.1 ms)")  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0] if __doc__ else "")
    parser.add_argument("--quick", action="store_true", help="smaller workloads")
    args = parser.parse_args(argv)
    print(f"tfbus sensor streams — Python {sys.version.split()[0]}")
    bench_lookups(10_000)
    bench_small_batches()
    bench_laser(720, 200 if args.quick else 1000)
    bench_cloud(10_000, 50 if args.quick else 200)
    bench_cloud(1_000_000, 2 if args.quick else 5)
    bench_filter(5_000 if args.quick else 50_000)


if __name__ == "__main__":
    main()
