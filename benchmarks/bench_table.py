"""tf lookups as a table operator over a fleet of recordings: rows/s per core.

Writes R synthetic recordings (tfbus's own writer, MCAP; each 60 s of ``map -> odom``
at 10 Hz and ``odom -> base_link`` at 50 Hz with a gap, statics once at the start) and Q
queries spread over them (``map -> laser``, ``odom -> imu``, ``base_link -> laser``;
stamps inside and outside the data), then times:

* ``loop``: what a user writes today: per recording ``load_buffer``, then a Python loop
  of ``BufferCore.lookup_transform`` per row (try/except for the rows tf2 refuses);
* ``table.lookup``: per recording ``load_buffer``, then one ``tfbus.table.lookup`` of its
  rows (same buffers; the lookups alone are timed for both, loading separately);
* ``lookup_by_recording``: the rows naming their recording, loading included, one
  process;
* ``ray 1 / ray 2``: ``tfbus.table.ray.lookup(shuffle=False)``'s task on a local Ray
  cluster of 1 and 2 CPUs, alternated over ``--rounds`` rounds, loading included
  (cluster start, worker start and Ray Data's per-cluster actors excluded: a long-lived
  cluster has them; ``--ray-cold`` starts the actors inside the run), Ray Data's
  per-operator resource reservation off (``--ray-reserve``: on, Ray's default, which
  starts the second worker's first task 1-5 s late here). The same 4 blocks
  for both (``--ray-blocks``): ``tfbus.table.ray.balanced_dataset``'s blocks of equal
  cost, each recording in one (``--ray-split rows``: equal row slices of the rows
  ordered by recording). Printed per run: wall rows/s; each worker's task CPU
  (``time.process_time`` in the task), its process's CPU and its time in tasks; the
  first task's start and the last one's end; the CPU of the driver (``getrusage``) and
  of each of Ray's other processes (GCS, raylet, Ray Data's actors, ...: ``/proc`` per
  PID) during the run, and their share of all the CPU used; the recordings each task read
  (checked: no more than its rows name). On a shared machine the wall ratio follows the
  other jobs; the CPU figures do not: the busiest worker's task CPU bounds what two idle
  cores can give, and Ray's share is what its own processes take from them.

``--big MB`` writes a ~MB MB MCAP and ROS 1 bag (random-walk values, 10 links at 100 Hz),
reads three 10 s windows and walks every window (``iter_windows``), each in a fresh
process (peak RSS ``VmHWM``, MB/s), and deletes them.

``--memory MB`` instead measures peak RSS (``VmHWM``, reset after the imports; a fresh
process each; Linux) of a whole ``load_buffer`` vs a 10 s window
(``load_buffer(start=, end=)``) and of a walk with ``iter_windows(width=10)`` over one
generated MCAP of about MB megabytes.

Prints figures only, with the machine's load average.

    .venv/bin/python benchmarks/bench_table.py [--recordings 100] [--queries 1000000]
        [--no-ray | --ray-only] [--ray-blocks 4] [--ray-split cost|rows] [--ray-cold]
        [--ray-reserve]
        [--memory 1000] [--big 1000]
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import os
import random
import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from tfbus import Header, Quaternion, TFMessage, Time, Transform, TransformStamped, Vector3
from tfbus.bag import BagMessage, load_buffer, write_bag

SEC = 1_000_000_000
T0 = 1_700_000_000 * SEC
PAIRS = [("map", "laser"), ("odom", "imu"), ("base_link", "laser")]


def _ts(parent: str, child: str, ns: int, x: float, yaw: float) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), parent), child,
        Transform(Vector3(x, 0.5 * x, 0.0),
                  Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))))


def recording(seed: int, seconds: float) -> list[BagMessage]:
    """60 s of a robot's tf: statics at the start, map -> odom at 10 Hz, odom ->
    base_link at 50 Hz with a gap from 40 % to 45 %."""
    rng = random.Random(seed)
    out = [BagMessage(Time.from_ns(T0), "/tf_static", TFMessage([
        _ts("base_link", "laser", T0, 0.2, 0.0), _ts("base_link", "imu", T0, 0.1, 1.0)]),
        "/static")]
    steps = int(seconds * 50)
    for k in range(1, steps):
        ns = T0 + k * SEC // 50
        t = k / 50
        tfs = []
        if not 0.40 <= k / steps < 0.45:
            tfs.append(_ts("odom", "base_link", ns - rng.randrange(10**6), math.cos(t), 0.3 * t))
        if k % 5 == 0:
            tfs.append(_ts("map", "odom", ns, 0.01 * t, 0.001 * t + seed))
        out.append(BagMessage(Time.from_ns(ns), "/tf", TFMessage(tfs), "/robot"))
    return out


def fleet(directory: Path, n: int, seconds: float) -> list[str]:
    paths = []
    for i in range(n):
        folder = directory / f"robot{i:03d}"
        write_bag(folder, recording(i, seconds), format="mcap")
        paths.append(str(next(folder.glob("*.mcap"))))
    return paths


def queries(paths: list[str], n: int, seconds: float, outside: float = 0.0,
            seed: int = 1) -> Any:
    """``n`` rows over ``paths`` (sorted by recording); a fraction ``outside`` of them
    1 s before or after the data (rows tf2 refuses with an ExtrapolationException)."""
    import pyarrow as pa

    rng = np.random.default_rng(seed)
    which = np.sort(rng.integers(0, len(paths), n))
    pair = rng.integers(0, len(PAIRS), n)
    stamps = T0 + rng.integers(SEC // 2, int((seconds - 0.5) * SEC), n)
    out = rng.random(n) < outside
    stamps[out] = np.where(rng.random(int(out.sum())) < 0.5, T0 - SEC,
                           T0 + int((seconds + 1) * SEC))
    return pa.table({
        "recording": pa.array([paths[k] for k in which]),
        "target_frame": [PAIRS[k][0] for k in pair],
        "source_frame": [PAIRS[k][1] for k in pair],
        "stamp": pa.array(stamps, pa.int64()),
    })


def _groups(table: Any) -> list[tuple[str, Any]]:
    import pyarrow.compute as pc

    names = table.column("recording")
    return [(name, table.filter(pc.equal(names, name)))
            for name in pc.unique(names).to_pylist()]


TF2_PYTHON = "/usr/bin/python3"
"""Debian's python3 with ``python3-tf2`` (ROS 1 geometry2 0.7.6's tf2_py), as
``benchmarks/bench_core.py`` runs it."""

TF2_SCRIPT = r"""
import json, sys, time
import rospy, tf2_py
from geometry_msgs.msg import TransformStamped
NS = 10**9
job = json.load(sys.stdin)
cores = []
for rec in job["recordings"]:
    core = tf2_py.BufferCore(rospy.Duration(10**6))
    for parent, child, ns, x, y, z, qx, qy, qz, qw, static in rec["transforms"]:
        m = TransformStamped()
        m.header.frame_id = parent
        m.child_frame_id = child
        m.header.stamp = rospy.Time(ns // NS, ns % NS)
        t, r = m.transform.translation, m.transform.rotation
        t.x, t.y, t.z, r.x, r.y, r.z, r.w = x, y, z, qx, qy, qz, qw
        (core.set_transform_static if static else core.set_transform)(m, "bench")
    cores.append((core, rec["queries"]))
ok = 0
start = time.process_time()
for core, rows in cores:
    lookup = core.lookup_transform_core
    for target, source, ns in rows:
        try:
            lookup(target, source, rospy.Time(ns // NS, ns % NS))
            ok += 1
        except tf2_py.TransformException:
            pass
print(json.dumps({"cpu_s": time.process_time() - start, "ok": ok}))
"""
"""The tf2_py loop (what a user of tf2 writes: ``BufferCore.lookup_transform_core`` per
row, try/except): fills one tf2 BufferCore per recording, then times the loop alone in
CPU seconds. Never imports tfbus."""


def tf2_job(groups: list[tuple[str, Any]], limit: int) -> dict[str, Any]:
    """The first ``limit`` recordings' transforms (as :func:`load_buffer` reads them)
    and rows, as JSON values for :data:`TF2_SCRIPT`."""
    from tfbus.bag import read_messages

    recordings = []
    for name, rows in groups[:limit]:
        transforms = []
        for rec in read_messages(name):
            for t in rec.message.transforms:
                (x, y, z), (qx, qy, qz, qw) = t.transform
                transforms.append([t.header.frame_id, t.child_frame_id, t.header.stamp.ns,
                                   x, y, z, qx, qy, qz, qw, rec.is_static])
        recordings.append({"transforms": transforms, "queries": [
            list(r) for r in zip(rows.column("target_frame").to_pylist(),
                                 rows.column("source_frame").to_pylist(),
                                 rows.column("stamp").to_pylist(), strict=True)]})
    return {"recordings": recordings}


def tf2_round(job: dict[str, Any]) -> tuple[float, int, int] | str:
    """One timed tf2_py loop: (CPU seconds, rows answered, rows), or why there is none."""
    import json
    import subprocess

    if not Path(TF2_PYTHON).exists():
        return f"no {TF2_PYTHON}"
    run = subprocess.run([TF2_PYTHON, "-c", TF2_SCRIPT], input=json.dumps(job),
                         capture_output=True, text=True, check=False, timeout=1800)
    if run.returncode:
        return f"tf2_py side failed: {run.stderr.strip()[-300:]}"
    out = json.loads(run.stdout.strip().splitlines()[-1])
    rows = sum(len(r["queries"]) for r in job["recordings"])
    return float(out["cpu_s"]), int(out["ok"]), rows


def _spread(rates: list[float]) -> str:
    """min / median / max rows/s."""
    return (f"{min(rates):12,.0f} {float(np.median(rates)):12,.0f} {max(rates):12,.0f}")


def bench_single(table: Any, rounds: int, tf2_recordings: int) -> None:
    """Rows/s per core (CPU time of this process: ``time.process_time``) of the tfbus
    loop, the tf2_py loop (first ``tf2_recordings`` recordings) and
    ``tfbus.table.lookup``, alternated over ``rounds`` rounds; then the whole path with
    loading (wall time)."""
    from tfbus.errors import TransformException
    from tfbus.table import lookup, lookup_by_recording

    groups = _groups(table)
    t = time.perf_counter()
    buffers = {name: load_buffer(name) for name, _ in groups}
    print(f"  load_buffer of every recording: {time.perf_counter() - t:.2f} s")
    job = tf2_job(groups, tf2_recordings)
    triples = {name: list(zip(rows.column("target_frame").to_pylist(),
                              rows.column("source_frame").to_pylist(),
                              rows.column("stamp").to_pylist(), strict=True))
               for name, rows in groups}
    n = table.num_rows
    rates: dict[str, list[float]] = {"loop": [], "tf2": [], "table": []}
    tf2_note = ""
    for r in range(rounds):
        ok_loop = 0
        c = time.process_time()
        for name, _rows in groups:
            buffer = buffers[name]
            for target, source, ns in triples[name]:
                try:
                    buffer.lookup_transform(target, source, Time.from_ns(ns))
                    ok_loop += 1
                except TransformException:
                    pass
        rates["loop"].append(n / (time.process_time() - c))
        tf2 = tf2_round(job)
        if isinstance(tf2, str):
            tf2_note = tf2
        else:
            cpu_s, ok_tf2, tf2_rows = tf2
            rates["tf2"].append(tf2_rows / cpu_s)
        ok_table = 0
        c = time.process_time()
        results = [lookup(rows, buffers[name]) for name, rows in groups]
        rates["table"].append(n / (time.process_time() - c))
        oks = [res.column("status").to_pylist().count("ok") for res in results]
        ok_table = sum(oks)
        assert ok_loop == ok_table, (ok_loop, ok_table)
        if not isinstance(tf2, str) and ok_tf2 != sum(oks[:len(job["recordings"])]):
            print(f"  tf2_py answered {ok_tf2} rows, tfbus "
                  f"{sum(oks[:len(job['recordings'])])} of the same")
        print(f"  round {r + 1}: load {os.getloadavg()[0]:.1f}; {ok_table / n * 100:.0f} % "
              f"of rows answered", flush=True)
    print(f"  rows/s per core (CPU time), {rounds} rounds:        min       median          max")
    print(f"  loop of tfbus lookup_transform     {_spread(rates['loop'])}")
    if rates["tf2"]:
        tf2_n = sum(len(r["queries"]) for r in job["recordings"])
        print(f"  loop of tf2_py lookup_transform_core {_spread(rates['tf2'])}  "
              f"({len(job['recordings'])} recordings, {tf2_n} rows)")
    else:
        print(f"  loop of tf2_py: not run ({tf2_note})")
    print(f"  tfbus.table.lookup                 {_spread(rates['table'])}")
    med = {k: float(np.median(v)) for k, v in rates.items() if v}
    print(f"  table.lookup / tfbus loop: {med['table'] / med['loop']:.1f}x (medians)"
          + (f"; / tf2_py loop: {med['table'] / med['tf2']:.1f}x" if "tf2" in med else ""))
    t = time.perf_counter()
    lookup_by_recording(table)
    print(f"  lookup_by_recording (with loads)   {n / (time.perf_counter() - t):12,.0f} rows/s")


RAY_BLOCKS = 4
"""Blocks of the query Dataset, the same for 1 and 2 CPUs (the same tasks, spread over
one or two workers): by default ``tfbus.table.ray.balanced_dataset``'s blocks of equal
cost (two per worker of the 2-CPU run, each recording in one block); ``--ray-split
rows``: slices of equal row counts (recordings in order; a recording cut by a slice
is read by both tasks)."""


def _ray_task(batch: Any) -> Any:
    """``tfbus.table.ray``'s unshuffled task (``_answer_batch``, whole recordings, each
    worker keeping 2), measured in the worker: the batch's answers plus constant columns
    ``_pid``, ``_cpu_s`` (``time.process_time`` of the task), ``_loads`` (recordings read
    by it: ``load_buffer`` calls), ``_recordings`` (distinct recordings in it) and
    ``_start`` / ``_end`` (``time.time()`` around the task)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    from tfbus.table import ray as tfray

    start = time.time()
    buffers = tfray._WORKER_BUFFERS.get(2)
    before = 0 if buffers is None else buffers.loads
    c = time.process_time()
    out = tfray._answer_batch(batch, "recording", None, 5.0, 2)
    cpu = time.process_time() - c
    loads = tfray._WORKER_BUFFERS[2].loads - before
    n = out.num_rows
    distinct = len(pc.unique(batch.column("recording")))
    end = time.time()
    for name, value, kind in (("_pid", os.getpid(), pa.int64()), ("_cpu_s", cpu, pa.float64()),
                              ("_loads", loads, pa.int64()),
                              ("_recordings", distinct, pa.int64()),
                              ("_start", start, pa.float64()), ("_end", end, pa.float64())):
        out = out.append_column(name, pa.array(np.full(n, value), kind))
    return out


def _cpu_by_process() -> dict[int, tuple[str, float]]:
    """CPU seconds (user + system) of this process's descendants (a local Ray cluster:
    GCS, raylet, workers, ...), by PID: (name, seconds), from ``/proc/PID/stat``."""
    import psutil

    out = {}
    for child in psutil.Process().children(recursive=True):
        try:
            times = child.cpu_times()
            name = child.name()
            if name.startswith("python"):  # Ray's agents and monitors: by their script
                scripts = [Path(a) for a in child.cmdline()[1:] if a.endswith(".py")]
                name = "/".join(scripts[0].parts[-2:]) if scripts else name
            out[child.pid] = (name, times.user + times.system)
        except psutil.Error:
            continue
    return out


def _ray_warm(seconds: float) -> int:
    """A task that imports what :func:`_ray_task` needs, holds its CPU ``seconds`` (so
    that tasks started together run in distinct workers) and returns its process id."""
    import tfbus.table.ray  # noqa: F401

    time.sleep(seconds)
    return os.getpid()


def _ray_run(table: Any, cpus: int, blocks: int, split: str, warm_data: bool,
             reserve: bool, out: Any) -> None:
    import resource
    import sys

    import pyarrow as pa
    import ray
    from ray import cloudpickle

    from tfbus.table import ray as tfray

    # This script is no module the workers can import: its task goes by value.
    cloudpickle.register_pickle_by_value(sys.modules[_ray_task.__module__])
    ray.init(num_cpus=cpus, include_dashboard=False, log_to_driver=False,
             configure_logging=False)
    try:
        context = ray.data.DataContext.get_current()
        context.enable_progress_bars = False
        # Ray Data's per-operator resource reservation (on by default) holds the second
        # task back by 1-5 s on a 2-CPU cluster (measured: the second worker's first
        # start); off, both tasks start at once.
        context.op_resource_reservation_enabled = reserve
        if split == "rows":
            step = -(-table.num_rows // blocks)
            ds = ray.data.from_arrow([table.slice(k * step, step) for k in range(blocks)])
        else:
            ds = tfray.balanced_dataset(table, blocks=blocks)
        # ``cpus`` workers started, tfbus imported in each, before the clock starts: tasks
        # that hold a CPU each for a second at once, until as many processes answered.
        hold = ray.remote(num_cpus=1)(_ray_warm)
        for _ in range(20):
            if len(set(ray.get([hold.remote(1.0) for _ in range(cpus)], timeout=600))) == cpus:
                break
        if warm_data:
            # Ray Data's per-cluster actors (``_StatsActor``, ``_AutoscalingCoordinatorActor``:
            # about 1.2 CPU-s each to start, on this machine) started by a first tiny
            # Dataset, as in a long-lived cluster, so that they do not take the run's cores.
            ray.data.range(2, override_num_blocks=1).materialize()
        before = _cpu_by_process()
        usage = resource.getrusage(resource.RUSAGE_SELF)
        t = time.perf_counter()
        t0 = time.time()
        result = ds.map_batches(_ray_task, batch_format="pyarrow", batch_size=None,
                                num_cpus=1.0)
        stats: list[tuple[int, float, int, int, int, float, float]] = []
        for batch in result.iter_batches(batch_format="pyarrow", batch_size=None):
            if batch.num_rows:
                row = batch.slice(0, 1).to_pylist()[0]
                stats.append((row["_pid"], row["_cpu_s"], batch.num_rows, row["_loads"],
                              row["_recordings"], row["_start"] - t0, row["_end"] - t0))
        wall = time.perf_counter() - t
        after_usage = resource.getrusage(resource.RUSAGE_SELF)
        after = _cpu_by_process()
        driver = (after_usage.ru_utime + after_usage.ru_stime
                  - usage.ru_utime - usage.ru_stime)
        ray_cpu: dict[str, float] = {}  # Ray's processes other than the task workers
        workers = {p for p, *_ in stats}
        worker_cpu = {}
        for pid, (name, seconds) in after.items():
            used = seconds - before.get(pid, (name, 0.0))[1]
            if pid in workers:
                worker_cpu[pid] = used
            else:
                ray_cpu[name] = ray_cpu.get(name, 0.0) + used
        out.put((wall, stats, worker_cpu, driver, ray_cpu, pa.__version__))
    finally:
        ray.shutdown()


def bench_ray(table: Any, cpus: int, blocks: int = RAY_BLOCKS,
              split: str = "cost", warm_data: bool = True,
              reserve: bool = False) -> dict[str, Any]:
    """One run of ``tfbus.table.ray``'s unshuffled task on a fresh local cluster of
    ``cpus`` CPUs (in a child process, so each run has its own cluster), loading
    included, cluster start excluded: wall seconds, per-worker task CPU seconds, rows,
    recordings read, each task's start and end, and the CPU seconds of the driver
    (``getrusage``) and of Ray's other processes (GCS, raylet, others) during the run."""
    ctx = multiprocessing.get_context("spawn")
    out = ctx.Queue()
    proc = ctx.Process(target=_ray_run, args=(table, cpus, blocks, split, warm_data, reserve,
                                                   out))
    proc.start()
    wall, stats, worker_cpu, driver, ray_cpu, _ = out.get(timeout=3600)
    proc.join(timeout=120)
    rows = sum(s[2] for s in stats)
    assert rows == table.num_rows, (rows, table.num_rows)
    per_worker: dict[int, float] = {}
    busy: dict[int, float] = {}
    for pid, cpu, _n, _loads, _recs, start, end in stats:
        per_worker[pid] = per_worker.get(pid, 0.0) + cpu
        busy[pid] = busy.get(pid, 0.0) + (end - start)
    return {"wall": wall, "rows": rows, "tasks": len(stats), "per_worker": per_worker,
            "busy": busy, "worker_cpu": worker_cpu, "loads": sum(s[3] for s in stats),
            "batch_recordings": sum(s[4] for s in stats),
            "first": min(s[5] for s in stats), "last": max(s[6] for s in stats),
            "driver": driver, "ray_cpu": ray_cpu, "load": os.getloadavg()[0],
            "timeline": sorted((s[5], s[6], s[0], s[1]) for s in stats)}


def bench_ray_rounds(table: Any, rounds: int, blocks: int = RAY_BLOCKS,
                     split: str = "cost", warm_data: bool = True,
                     reserve: bool = False) -> None:
    """Ray with 1 and 2 CPUs alternated over ``rounds`` rounds (the order swapped each
    round): wall rows/s, task CPU per worker and rows per task-CPU-second, the
    recordings each task read (no more than the recordings of its rows), each worker's
    time in tasks, the first task's start and the last's end, and the CPU of the driver
    and of Ray's own processes during the run (figures that do not follow the machine's
    other load: CPU seconds, not wall)."""
    import pyarrow.compute as pc

    n_recordings = len(pc.unique(table.column("recording")))
    runs: dict[int, list[dict[str, Any]]] = {1: [], 2: []}
    print(f"  ray: {blocks} blocks ({'equal cost' if split == 'cost' else 'equal rows'}), "
          f"Ray Data's actors {'started before' if warm_data else 'started in'} the run, "
          f"op_resource_reservation_enabled={reserve}")
    for r in range(rounds):
        for cpus in ((1, 2) if r % 2 == 0 else (2, 1)):
            run = bench_ray(table, cpus, blocks, split, warm_data, reserve)
            runs[cpus].append(run)
            cpu = sum(run["per_worker"].values())
            workers = ", ".join(f"{c:.2f}" for c in sorted(run["per_worker"].values()))
            busy = ", ".join(f"{c:.2f}" for c in sorted(run["busy"].values()))
            process = ", ".join(f"{c:.2f}" for c in sorted(run["worker_cpu"].values()))
            others = ", ".join(f"{k} {v:.2f}" for k, v in sorted(run["ray_cpu"].items()))
            overhead = run["driver"] + sum(run["ray_cpu"].values())
            total = overhead + sum(run["worker_cpu"].values())
            assert run["loads"] <= run["batch_recordings"], run
            print(f"  round {r + 1}, ray {cpus} CPU: {run['rows'] / run['wall']:10,.0f} rows/s "
                  f"wall ({run['wall']:.2f} s); task CPU {cpu:.2f} s over "
                  f"{len(run['per_worker'])} worker(s) [{workers}] = "
                  f"{run['rows'] / cpu:10,.0f} rows/CPU-s; worker process CPU [{process}]; "
                  f"in tasks [{busy}] s, first start {run['first']:.2f} s, last end "
                  f"{run['last']:.2f} s; driver CPU {run['driver']:.2f} s, {others}: Ray's "
                  f"share {overhead / total * 100:.0f} % of {total:.2f} CPU-s; recordings "
                  f"read {run['loads']} (tasks' recordings {run['batch_recordings']}, fleet "
                  f"{n_recordings}); load {run['load']:.1f}", flush=True)
            names = {pid: f"w{k}" for k, pid in enumerate(sorted(run["per_worker"]))}
            print("    tasks (worker start-end s, task CPU s): " + ", ".join(
                f"{names[pid]} {a:.2f}-{b:.2f} ({c:.2f})"
                for a, b, pid, c in run["timeline"]), flush=True)
    def floor(x: dict[str, Any]) -> float:
        """The least wall time the run's CPU allows on two idle cores: its busiest
        worker process's CPU, or its workers' CPU over what the driver and Ray's
        processes leave of two cores (they take ``r`` CPU-seconds per wall second while
        the Dataset runs: T = workers / (2 - r)), whichever is more."""
        rate = (x["driver"] + sum(x["ray_cpu"].values())) / x["wall"]
        workers = x["worker_cpu"].values()
        return float(max(max(workers), sum(workers) / (2.0 - rate)))

    med = {c: {"wall": float(np.median([x["rows"] / x["wall"] for x in v])),
               "cpu": float(np.median([x["rows"] / sum(x["per_worker"].values()) for x in v])),
               "busiest": float(np.median([max(x["per_worker"].values()) for x in v])),
               "floor": float(np.median([floor(x) for x in v])),
               "ray": float(np.median([(x["driver"] + sum(x["ray_cpu"].values())) / x["wall"]
                                       for x in v]))}
           for c, v in runs.items()}
    print(f"  ray medians of {rounds}: wall {med[1]['wall']:,.0f} -> {med[2]['wall']:,.0f} "
          f"rows/s ({med[2]['wall'] / med[1]['wall']:.2f}x); rows/CPU-s "
          f"{med[1]['cpu']:,.0f} -> {med[2]['cpu']:,.0f}; busiest worker's task CPU "
          f"{med[1]['busiest']:.2f} -> {med[2]['busiest']:.2f} s (a bound on the speed-up on "
          f"idle cores: {med[1]['busiest'] / med[2]['busiest']:.2f}x); the driver and Ray's "
          f"processes {med[1]['ray']:.2f} -> {med[2]['ray']:.2f} CPU-s per wall second; "
          f"least wall the CPU allows on two idle cores {med[1]['floor']:.2f} -> "
          f"{med[2]['floor']:.2f} s (their ratio, Ray's own CPU counted: "
          f"{med[1]['floor'] / med[2]['floor']:.2f}x)")


# ------------------------------------------------------------------------ memory


def _status_kb(field: str) -> int:
    """A ``/proc/self/status`` field in kB (VmRSS: now; VmHWM: the peak)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise KeyError(field)


def _peak(kind: str, path: str, out: Any) -> None:
    """Peak resident memory of one kind of read, in a fresh process: the peak is reset
    (``/proc/self/clear_refs``, Linux) after the imports, then read after the read."""
    from tfbus.bag import iter_windows

    load_buffer(path, start=Time.from_ns(T0), end=Time.from_ns(T0 + 1))  # (imports)
    Path("/proc/self/clear_refs").write_text("5")
    before = _status_kb("VmRSS")
    t = time.perf_counter()
    if kind == "whole":
        load_buffer(path)
    elif kind == "window":
        load_buffer(path, start=Time.from_ns(T0 + 100 * SEC), end=Time.from_ns(T0 + 110 * SEC))
    else:
        for _w in iter_windows(path, 10.0, margin=1.0):
            pass
    out.put((kind, _status_kb("VmHWM") - before, _status_kb("VmHWM"),
             time.perf_counter() - t))


def bench_memory(directory: Path, megabytes: float) -> None:
    # About 170 bytes a message with two transforms (MCAP, zstd-compressed chunks).
    seconds = megabytes * 1e6 / (50 * 210)
    folder = directory / "big"
    t = time.perf_counter()
    write_bag(folder, recording(7, seconds), format="mcap")
    path = next(folder.glob("*.mcap"))
    print(f"memory: {path.stat().st_size / 1e6:.0f} MB MCAP, {seconds:.0f} s of tf "
          f"(written in {time.perf_counter() - t:.0f} s)")
    ctx = multiprocessing.get_context("spawn")
    for kind in ("window", "iter_windows", "whole"):
        out = ctx.Queue()
        proc = ctx.Process(target=_peak, args=(kind, str(path), out))
        proc.start()
        name, grown, peak, secs = out.get(timeout=3600)
        proc.join(timeout=120)
        print(f"  {name:13s} peak RSS {peak / 1024:6.0f} MB, {grown / 1024:6.1f} MB above "
              f"the process before the read, in {secs:.1f} s")


# ------------------------------------------------------------------- big recordings

BIG_PER_MSG = 10
"""Transforms per ``/tf`` message of the big recordings (a robot's dynamic links)."""


def big_messages(n: int, seed: int = 3) -> Iterator[BagMessage]:
    """One ``/tf_static`` (``base_link -> laser``), then ``n`` ``/tf`` messages at 100 Hz of
    :data:`BIG_PER_MSG` links (``odom -> base_link -> link1 -> ... -> link9``) with
    random-walk values (so that compressed MCAP chunks are not much smaller than ROS 1's),
    bag time 2 ms after the header stamps. Streamed: nothing but the current message
    held."""
    rng = np.random.default_rng(seed)
    yield BagMessage(Time.from_ns(T0), "/tf_static", TFMessage([
        _ts("base_link", "laser", T0, 0.2, 0.0)]), "/static")
    parents = ["odom", "base_link", *[f"link{j}" for j in range(1, BIG_PER_MSG - 1)]]
    children = ["base_link", *[f"link{j}" for j in range(1, BIG_PER_MSG)]]
    x = np.zeros(BIG_PER_MSG)
    yaw = np.zeros(BIG_PER_MSG)
    for k in range(n):
        ns = T0 + k * 10_000_000
        x += rng.normal(0.0, 0.01, BIG_PER_MSG)
        yaw += rng.normal(0.0, 0.01, BIG_PER_MSG)
        tfs = [_ts(parents[j], children[j], ns, float(x[j]), float(yaw[j]))
               for j in range(BIG_PER_MSG)]
        yield BagMessage(Time.from_ns(ns + 2_000_000), "/tf", TFMessage(tfs), "/robot")


def write_big(directory: Path, fmt: str, megabytes: float) -> tuple[Path, int]:
    """A recording of about ``megabytes`` MB (``fmt`` ``"mcap"``: a ROS 2 bag folder's
    ``.mcap``; ``"ros1"``: a ``.bag``): the bytes per message measured on a 20,000-message
    sample first, then the file streamed. Returns (path, messages)."""
    sample = directory / f"sample_{fmt}"
    write_bag(sample if fmt == "mcap" else sample.with_suffix(".bag"),
              big_messages(20_000), format=fmt)
    sample_file = next(sample.glob("*.mcap")) if fmt == "mcap" else sample.with_suffix(".bag")
    per_msg = sample_file.stat().st_size / 20_000
    shutil.rmtree(sample, ignore_errors=True)
    sample.with_suffix(".bag").unlink(missing_ok=True)
    n = max(1, int(megabytes * 1e6 / per_msg))
    target = directory / ("big_mcap" if fmt == "mcap" else "big.bag")
    write_bag(target, big_messages(n), format=fmt)
    path = next(target.glob("*.mcap")) if fmt == "mcap" else target
    return path, n


def _big_read(kind: str, path: str, n: int, out: Any) -> None:
    """One read of a big recording in a fresh process: peak RSS (``VmHWM``, reset after
    the imports through ``/proc/self/clear_refs``), RSS before, seconds, CPU seconds and
    what was read. ``kind``: ``windows`` (three 10 s windows at 10, 50 and 90 % of the
    span, ``load_buffer(start=, end=)``) or ``iter_windows`` (every 10 s window of the
    file, margin 1 s)."""
    from tfbus.bag import iter_windows

    load_buffer(path, start=Time.from_ns(T0), end=Time.from_ns(T0 + 1))  # (imports)
    Path("/proc/self/clear_refs").write_text("5")
    before = _status_kb("VmRSS")
    t, c = time.perf_counter(), time.process_time()
    span = n * 10_000_000
    got = 0
    if kind == "windows":
        for frac in (0.1, 0.5, 0.9):
            lo = T0 + int(frac * span)
            buffer = load_buffer(path, start=Time.from_ns(lo), end=Time.from_ns(lo + 10 * SEC))
            buffer.lookup_transform("odom", "link9", Time.from_ns(lo + 5 * SEC))
            got += 1
    else:
        for w in iter_windows(path, 10.0, margin=1.0):
            got += w.messages
    out.put((kind, _status_kb("VmHWM"), before, time.perf_counter() - t,
             time.process_time() - c, got))


def bench_big(directory: Path, megabytes: float, formats: list[str]) -> None:
    """Peak memory and MB/s of windowed reads of a ~``megabytes`` MB MCAP and ROS 1 bag
    (each read in a fresh process; the files deleted after)."""
    ctx = multiprocessing.get_context("spawn")
    for fmt in formats:
        t = time.perf_counter()
        path, n = write_big(directory, fmt, megabytes)
        size = path.stat().st_size
        print(f"big {fmt}: {size / 1e6:,.0f} MB, {n:,} /tf messages of {BIG_PER_MSG} "
              f"transforms ({n / 100:,.0f} s at 100 Hz), written in "
              f"{time.perf_counter() - t:.0f} s; load {os.getloadavg()[0]:.1f}", flush=True)
        try:
            for kind in ("windows", "iter_windows"):
                out = ctx.Queue()
                proc = ctx.Process(target=_big_read, args=(kind, str(path), n, out))
                proc.start()
                name, peak, before, secs, cpu, got = out.get(timeout=7200)
                proc.join(timeout=120)
                rate = f"{size / 1e6 / secs:7.1f} MB/s of the file" if kind != "windows" \
                    else "(three windows)"
                print(f"  {name:13s} peak RSS {peak / 1024:6.0f} MB ({(peak - before) / 1024:6.1f} "
                      f"MB above the process before), {secs:6.1f} s wall, {cpu:6.1f} s CPU "
                      f"{rate}; {got:,} {'windows' if kind == 'windows' else 'messages'}; "
                      f"load {os.getloadavg()[0]:.1f}", flush=True)
        finally:
            if fmt == "mcap":
                shutil.rmtree(path.parent, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--recordings", type=int, default=100)
    ap.add_argument("--queries", type=int, default=1_000_000)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--outside", type=float, default=0.0, metavar="FRACTION",
                    help="fraction of rows outside the data (tf2 refuses them)")
    ap.add_argument("--no-ray", action="store_true")
    ap.add_argument("--ray-only", action="store_true",
                    help="only the Ray rounds (1 and 2 CPUs alternated)")
    ap.add_argument("--ray-blocks", type=int, default=RAY_BLOCKS, metavar="N",
                    help="blocks of the Ray Dataset (the same for 1 and 2 CPUs)")
    ap.add_argument("--ray-split", choices=("cost", "rows"), default="cost",
                    help="Ray blocks of equal cost, each recording in one (balanced_dataset), "
                         "or equal row slices")
    ap.add_argument("--ray-reserve", action="store_true",
                    help="keep Ray Data's per-operator resource reservation (its default)")
    ap.add_argument("--ray-cold", action="store_true",
                    help="start Ray Data's per-cluster actors inside the timed run")
    ap.add_argument("--rounds", type=int, default=3, help="alternated timing rounds (>= 3)")
    ap.add_argument("--tf2-recordings", type=int, default=5, metavar="N",
                    help="recordings the tf2_py loop runs on (its rows/s is per row)")
    ap.add_argument("--memory", type=float, default=0.0, metavar="MB",
                    help="measure peak memory on one recording of about MB megabytes")
    ap.add_argument("--big", type=float, default=0.0, metavar="MB",
                    help="peak memory and MB/s of windowed reads of a ~MB MB MCAP and "
                         "ROS 1 bag (written, read, deleted)")
    ap.add_argument("--big-formats", default="mcap,ros1", metavar="LIST")
    args = ap.parse_args()
    from tfbus.core import COMPILED

    print(f"cpus={os.cpu_count()} load={os.getloadavg()[0]:.1f} "
          f"core={'compiled' if COMPILED else 'pure-Python'}")
    directory = Path(tempfile.mkdtemp(prefix="bench_table_"))
    try:
        if args.memory:
            bench_memory(directory, args.memory)
            return
        if args.big:
            bench_big(directory, args.big, args.big_formats.split(","))
            return
        t = time.perf_counter()
        paths = fleet(directory, args.recordings, args.seconds)
        table = queries(paths, args.queries, args.seconds, args.outside)
        print(f"{args.recordings} recordings of {args.seconds:.0f} s, {args.queries} queries, "
              f"{args.outside * 100:.0f} % outside the data "
              f"(written in {time.perf_counter() - t:.1f} s)")
        if not args.ray_only:
            bench_single(table, args.rounds, args.tf2_recordings)
        if not args.no_ray:
            bench_ray_rounds(table, args.rounds, args.ray_blocks, args.ray_split,
                             not args.ray_cold, args.ray_reserve)
        print(f"load after: {os.getloadavg()[0]:.1f}")
    finally:
        shutil.rmtree(directory, ignore_errors=True)


if __name__ == "__main__":
    main()
