"""Benchmark tfbus's BufferCore against the real tf2 (``tf2_py``) in the same run.

    .venv/bin/python benchmarks/bench_core.py [--quick] [--no-tf2]

Prints, on this machine:

* lookup latency (µs per call) for chains of depth 1, 2, 8 and 32 (root <- leaf), at
  time 0, at interpolated times that vary from call to call (so no result caching can
  help), and at one fixed interpolated time;
* ``set_transform`` rate (single calls, 100 Hz samples of many frames, cache pruning on),
  and ns per call on a chain of 10 links stored in order (target: <= 0.35x tf2_py);
* lookup policies (``tfbus.core.policy``): ``lookup_transform(..., policy=P)`` per call
  against the exact lookup on the same never-repeated times, measured interleaved
  (target: <= 1.5x the exact lookup);
* memory per cached sample (1000 frames x 10 s x 100 Hz = 1M samples): tracemalloc and
  RSS growth for tfbus, RSS growth for tf2 (C++ allocations are invisible to tracemalloc).

The tf2 half runs ``peers/debian/tf2_side.py`` under ``/usr/bin/python3`` (Debian
``python3-tf2``); the scenario (stamps, query times, sizes) is handed over as JSON so both
sides do exactly the same work. Targets: lookups no slower than tf2_py,
set_transform at least half of tf2_py's rate, at most 72 bytes per cached sample;
and a never-repeated depth-2 lookup at most 0.20x tf2_py, with a breakdown of
where its time goes and the floor (building the same TransformStamped, no lookup).
Figures only: nothing here asserts a timing.
"""

from __future__ import annotations

import argparse
import gc
import json
import select
import shutil
import subprocess
import sys
import time
import tracemalloc
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.core import COMPILED, BufferCore
from tfbus.core.policy import Clamp, Nearest, Previous, Window

NS = 1_000_000_000
TF2_PYTHON = "/usr/bin/python3"
TF2_SIDE = Path(__file__).resolve().parents[1] / "peers" / "debian" / "tf2_side.py"
TF2_CPP = Path(__file__).resolve().parents[1] / "peers" / "debian" / "tf2_buffer_core_bench.cpp"
MEMORY_TARGET = 72  # bytes per cached sample
POLICY_TARGET = 1.5  # a policy lookup vs the exact one, same times
LOOKUP_DEPTH2_TARGET = 0.20  # target: never-repeated depth-2 lookup vs tf2_py


def scenario(quick: bool) -> dict[str, Any]:
    """Everything both sides need, so that they run identical workloads."""
    period = NS // 100  # 100 Hz
    t0 = 1_700_000_000 * NS  # epoch-sized stamps, like a real robot
    n_chain = 1001  # 10 s at 100 Hz on every link: [t0, t0 + 10 s]
    span = (n_chain - 1) * period
    # Varying query times strictly between samples, spread over the whole history, and
    # never repeated (not across calls, not across repeats): no result memo can help.
    calls = 5_000 if quick else 20_000
    repeats = 3 if quick else 5
    queries: list[int] = []
    seen: set[int] = set()
    k = 0
    while len(queries) < calls * repeats:
        q = t0 + 1 + (k * 2_654_435_761) % (span - 2)
        k += 1
        if (q - t0) % period and q not in seen:
            seen.add(q)
            queries.append(q)
    return {
        "cache_time_s": 10.0,
        "period_ns": period,
        "chain_stamps": [t0 + k * period for k in range(n_chain)],
        "depths": [1, 2, 8, 32],
        "query_ns": queries,
        "fixed_ns": t0 + span // 2 + period // 3,
        "calls": calls,
        "repeats": repeats,
        "set_t0_ns": t0,
        "set_frames": 100,
        "set_stamps": 500 if quick else 2_000,  # 20 s at 100 Hz: pruning is active
        "chain_steps": 500 if quick else 2_000,  # set_transform on a chain of 10 links
        "mem_frames": 100 if quick else 1_000,
        "mem_samples": 1_000,  # 10 s at 100 Hz, all within cache_time
    }


def _transform(k: int) -> Transform:
    s = 0.01 * (k % 11)
    return Transform(
        Vector3(1.0 + 0.001 * (k % 7), 0.5, -0.25), Quaternion(s, 0.0, 0.0, (1.0 - s * s) ** 0.5)
    )


def _message(parent: str, child: str, stamp_ns: int, k: int) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(stamp_ns), parent), child, _transform(k))


def _chain(sc: dict[str, Any], depth: int) -> BufferCore:
    core = BufferCore(cache_time=sc["cache_time_s"])
    for k, stamp in enumerate(sc["chain_stamps"]):
        for i in range(depth):
            core.set_transform(_message(f"f{i}", f"f{i + 1}", stamp, k + i), "bench")
    return core


def _best_per_call(fn: Callable[[Time], object], runs: Sequence[Sequence[Time]]) -> float:
    """Fastest run's seconds per call; each run calls ``fn`` on its own arguments."""
    best = float("inf")
    for args in runs:
        start = time.perf_counter()
        for a in args:
            fn(a)
        best = min(best, (time.perf_counter() - start) / len(args))
    return best


def _fresh_zero(core: BufferCore, leaf: str, sc: dict[str, Any]) -> float:
    """Time-0 lookups each right after an insert on an unrelated link (so no memo can
    serve them), minus the cost of the inserts alone (best of each)."""
    calls, period = sc["calls"], sc["period_ns"]
    stamps = iter(range(sc["set_t0_ns"], 1 << 62, period))  # 100 Hz on the x <- y link
    zero = Time(0)
    lookup = core.lookup_transform
    setter = core.set_transform
    for _ in range(2 * calls):  # reach the steady state: a full cache, pruning on insert
        setter(_message("x", "y", next(stamps), 0), "bench")
    best_both: float = float("inf")
    best_alone: float = float("inf")
    for _ in range(sc["repeats"]):
        msgs = [_message("x", "y", next(stamps), k) for k in range(calls)]
        start = time.perf_counter()
        for m in msgs:
            setter(m, "bench")
        best_alone = min(best_alone, time.perf_counter() - start)
        msgs = [_message("x", "y", next(stamps), k) for k in range(calls)]
        start = time.perf_counter()
        for m in msgs:
            setter(m, "bench")
            lookup("f0", leaf, zero)
        best_both = min(best_both, time.perf_counter() - start)
    best: float = (best_both - best_alone) / calls
    return best


def tfbus_lookups(sc: dict[str, Any]) -> dict[str, float]:
    out: dict[str, float] = {}
    calls, repeats = sc["calls"], sc["repeats"]
    varying = [Time.from_ns(ns) for ns in sc["query_ns"]]
    for depth in sc["depths"]:
        core = _chain(sc, depth)
        leaf = f"f{depth}"

        def fn(t: Time, lookup: Any = core.lookup_transform, leaf: str = leaf) -> object:
            return lookup("f0", leaf, t)

        # Repeated queries first (a result memo, if any, may serve them), then queries
        # that are never repeated, then time 0 right after inserts.
        out[f"{depth}/zero"] = _best_per_call(fn, [[Time(0)] * calls] * repeats)
        out[f"{depth}/fixed"] = _best_per_call(
            fn, [[Time.from_ns(sc["fixed_ns"])] * calls] * repeats
        )
        out[f"{depth}/interp"] = _best_per_call(
            fn, [varying[r * calls : (r + 1) * calls] for r in range(repeats)]
        )
        out[f"{depth}/zero_fresh"] = _fresh_zero(core, leaf, sc)
    return out


def policy_lookups(sc: dict[str, Any]) -> dict[str, float]:
    """CPU seconds per ``lookup_transform(root, leaf, t, policy=P)`` on never-repeated
    interpolated times, keyed ``"depth/policy"`` (``"depth/exact"`` for no policy). The
    policies and the exact lookup take turns on every chunk of 250 times, and the time
    is this process's CPU time (``time.process_time``), not the wall clock: other work
    on the machine neither lands on one side only nor counts at all. The best of the
    rounds counts."""
    period_s = sc["period_ns"] / NS
    policies: dict[str, Any] = {
        "exact": None,
        "Nearest(period/2)": Nearest(period_s / 2),
        "Clamp(10 periods)": Clamp(10 * period_s),
        "Previous()": Previous(),
        "Window(10 periods)": Window(10 * period_s),
    }
    calls = sc["calls"]
    times = [Time.from_ns(ns) for ns in sc["query_ns"][:calls]]
    chunks = [times[k : k + 250] for k in range(0, calls, 250)]
    clock = time.process_time
    out: dict[str, float] = {}
    for depth in sc["depths"]:
        core = _chain(sc, depth)
        leaf = f"f{depth}"
        lookup = core.lookup_transform
        best = dict.fromkeys(policies, float("inf"))
        for _ in range(2 * sc["repeats"] + 1):
            spent = dict.fromkeys(policies, 0.0)
            for chunk in chunks:
                for name, policy in policies.items():
                    start = clock()
                    if policy is None:
                        for t in chunk:
                            lookup("f0", leaf, t)
                    else:
                        for t in chunk:
                            lookup("f0", leaf, t, policy=policy)
                    spent[name] += clock() - start
            for name in policies:
                best[name] = min(best[name], spent[name] / calls)
        for name, seconds in best.items():
            out[f"{depth}/{name}"] = seconds
    return out


def report_policies(sc: dict[str, Any], figures: dict[str, float]) -> None:
    head = "lookup_transform(..., policy=P)"
    print(f"\n{head:36} {'tfbus':>12} {'exact':>12} {'P/exact':>10}  target")
    print("-" * 90)
    for depth in sc["depths"]:
        exact = figures[f"{depth}/exact"]
        for key, seconds in figures.items():
            d, name = key.split("/", 1)
            if int(d) != depth or name == "exact":
                continue
            ratio = seconds / exact
            verdict = "ok" if ratio <= POLICY_TARGET else "SLOWER"
            print(
                f"depth {depth:>2}, {name:<27} {_us(seconds):>12} {_us(exact):>12} "
                f"{ratio:9.2f}x  <= {POLICY_TARGET}x exact  {verdict}"
            )


def tfbus_set_chain(sc: dict[str, Any]) -> float:
    """Seconds per ``set_transform`` on a chain of 10 links stored in order, 100 Hz steps
    (best of the repeats, a fresh buffer each)."""
    msgs = [
        _message(f"f{i}", f"f{i + 1}", sc["set_t0_ns"] + k * sc["period_ns"], k + i)
        for k in range(sc["chain_steps"])
        for i in range(10)
    ]
    best = float("inf")
    for _ in range(sc["repeats"]):
        setter = BufferCore(cache_time=sc["cache_time_s"]).set_transform
        start = time.perf_counter()
        for m in msgs:
            setter(m, "bench")
        best = min(best, (time.perf_counter() - start) / len(msgs))
    return best


def tfbus_set_rate(sc: dict[str, Any]) -> float:
    core = BufferCore(cache_time=sc["cache_time_s"])
    frames = sc["set_frames"]
    msgs = [
        _message("root", f"c{f}", sc["set_t0_ns"] + k * sc["period_ns"], k)
        for k in range(sc["set_stamps"])
        for f in range(frames)
    ]
    setter = core.set_transform
    start = time.perf_counter()
    for m in msgs:
        setter(m, "bench")
    return len(msgs) / (time.perf_counter() - start)


def _rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096


def _fill(core: BufferCore, sc: dict[str, Any]) -> None:
    tf = _transform(3)
    for f in range(sc["mem_frames"]):
        child = f"c{f}"
        for k in range(sc["mem_samples"]):
            stamp = Time.from_ns(sc["set_t0_ns"] + k * sc["period_ns"])
            core.set_transform(TransformStamped(Header(stamp, "root"), child, tf), "bench")


def tfbus_memory(sc: dict[str, Any]) -> dict[str, float]:
    samples = sc["mem_frames"] * sc["mem_samples"]
    gc.collect()
    before = _rss_bytes()
    core = BufferCore(cache_time=sc["cache_time_s"])
    _fill(core, sc)
    gc.collect()
    rss = (_rss_bytes() - before) / samples
    del core
    gc.collect()
    tracemalloc.start()
    core = BufferCore(cache_time=sc["cache_time_s"])
    base, _ = tracemalloc.get_traced_memory()
    _fill(core, sc)
    gc.collect()
    current, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {"traced_bytes_per_sample": (current - base) / samples, "rss_bytes_per_sample": rss}


# ---------------------------------------------------------------------- C++ tf2 reference
#
# The core rows against Debian's tf2::BufferCore called from C++ (``tf2_buffer_core_bench.cpp``,
# built with g++ and pkg-config): the same workloads on both sides, handed over on stdin.

CPP_DEPTHS = (1, 2, 8, 64)
FILL_SAMPLES = 200  # a link's first samples: the phase in which its storage grows


def cpp_scenario(calls: int = 5_000, repeats: int = 3, mem_frames: int = 200) -> dict[str, Any]:
    """The workloads of the C++ reference rows (both sides run exactly these):

    * lookups on chains f0 <- ... <- f<depth> of 1001 samples per link (10 s at 100 Hz),
      at ``calls * repeats`` interpolated times never repeated, spread over the whole
      history (``interp``) and within its newest 100 ms (``recent``: what a robot asks);
    * ``set_transform`` on a star of 10 links, every link at each 100 Hz stamp in turn: a
      fresh buffer's first 200 samples per link (``fill``), and 500 more after 1100 (the
      steady state: a full 10 s cache, pruning on every insert);
    * memory per sample: RSS growth of ``mem_frames`` x 1000 samples, frame by frame.
    """
    base = scenario(True)
    t0, period = base["set_t0_ns"], base["period_ns"]
    span = (len(base["chain_stamps"]) - 1) * period
    spread: list[int] = []
    recent: list[int] = []
    window = 10 * period
    k = 0
    while len(spread) < calls * repeats:
        q = t0 + 1 + (k * 2_654_435_761) % (span - 2)
        k += 1
        if (q - t0) % period:
            spread.append(q)
    k = 0
    while len(recent) < calls * repeats:
        q = t0 + span - window + 1 + (k * 7_919) % (window - 2)
        k += 1
        if (q - t0) % period:
            recent.append(q)
    return {
        "cache_time_s": base["cache_time_s"],
        "period_ns": period,
        "t0_ns": t0,
        "chain_stamps": base["chain_stamps"],
        "depths": list(CPP_DEPTHS),
        "calls": calls,
        "repeats": repeats,
        "spread_ns": spread,
        "recent_ns": recent,
        "fill_links": 10,
        "fill_samples": FILL_SAMPLES,
        "fill_buffers": 20,
        "steady_links": 10,
        "steady_warm": 1_100,
        "steady_samples": 500,
        "mem_frames": mem_frames,
        "mem_samples": 1_000,
    }


def _cpp_input(sc: dict[str, Any]) -> str:
    head = [
        round(sc["cache_time_s"] * NS), sc["period_ns"], sc["t0_ns"], len(sc["chain_stamps"]),
        len(sc["depths"]), *sc["depths"], sc["calls"], sc["repeats"],
    ]  # fmt: skip
    tail = [
        sc["fill_links"], sc["fill_samples"], sc["fill_buffers"],
        sc["steady_links"], sc["steady_warm"], sc["steady_samples"],
        sc["mem_frames"], sc["mem_samples"],
    ]  # fmt: skip
    return " ".join(map(str, [*head, *sc["spread_ns"], *sc["recent_ns"], *tail])) + "\n"


def build_cpp(out_dir: Path) -> Path | str:
    """Build the C++ reference into ``out_dir``: its path, or why it cannot be built."""
    if shutil.which("g++") is None or shutil.which("pkg-config") is None:
        return "no g++ / pkg-config"
    flags = subprocess.run(
        ["pkg-config", "--cflags", "--libs", "tf2"], capture_output=True, text=True, check=False
    )
    if flags.returncode:
        return "no tf2 for pkg-config (scripts/install/install_ros1.sh installs libtf2-dev)"
    exe = out_dir / "tf2_buffer_core_bench"
    built = subprocess.run(
        ["g++", "-O2", "-o", str(exe), str(TF2_CPP), *flags.stdout.split()],
        capture_output=True,
        text=True,
        check=False,
    )
    if built.returncode:
        return f"g++ failed: {built.stderr.strip()[-300:]}"
    return exe


def cpp_round(exe: Path, sc: dict[str, Any]) -> dict[str, Any]:
    """One run of the C++ side: ``{"lookup_s": {"<depth>/interp" | "<depth>/recent": s},
    "fill_s": s, "steady_s": s, "rss_bytes_per_sample": bytes}`` (CPU seconds per call,
    best of ``repeats`` runs).

    Raises:
        RuntimeError: the program failed (its stderr).
    """
    run = subprocess.run(
        [str(exe)], input=_cpp_input(sc), capture_output=True, text=True, check=False, timeout=600
    )
    if run.returncode:
        raise RuntimeError(f"C++ tf2 side failed: {run.stderr.strip()[-300:]}")
    result: dict[str, Any] = json.loads(run.stdout)
    return result


def _star(sc: dict[str, Any], first: int, count: int) -> list[TransformStamped]:
    t0, period, links = sc["t0_ns"], sc["period_ns"], sc["fill_links"]
    return [
        _message("root", f"c{i}", t0 + k * period, k + i)
        for k in range(first, first + count)
        for i in range(links)
    ]


class CppServer:
    """A ``tf2_buffer_core_bench --serve`` process on scenario ``sc``: one C++ measurement
    per :meth:`measure` (this process's thread CPU seconds per call of one ``fill``,
    ``steady`` or ``lookup D interp|recent R``, as :class:`CppSideOurs`'s methods of the
    same names measure tfbus), so that a caller can alternate the two sides a measurement
    at a time. A context manager: the process is ended on exit (``quit``, then killed by
    its PID if it has not ended within 10 s).

    Raises:
        RuntimeError: the program failed or answered something else than a number (its
            stderr), or did not answer within ``timeout`` s.
    """

    def __init__(self, exe: Path, sc: dict[str, Any], timeout: float = 60.0) -> None:
        self.timeout = timeout
        self.proc = subprocess.Popen(
            [str(exe), "--serve"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True,
        )
        assert self.proc.stdin is not None
        self.proc.stdin.write(_cpp_input(sc))
        self.proc.stdin.flush()
        ready = self._line()
        if ready != "READY":
            err = self.close()
            raise RuntimeError(f"C++ tf2 side did not start: {ready!r} {err.strip()[-300:]}")

    def _line(self) -> str:
        out = self.proc.stdout
        assert out is not None
        readable, _, _ = select.select([out], [], [], self.timeout)
        line = out.readline() if readable else ""
        if not line:
            err = self.close()
            raise RuntimeError(f"C++ tf2 side gave no answer: {err.strip()[-300:]}")
        return line.strip()

    def measure(self, command: str) -> float:
        """The C++ side's CPU seconds per call of ``command`` (one measurement)."""
        assert self.proc.stdin is not None
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()
        return float(self._line())

    def close(self) -> str:
        """End the process (``quit``; killed if it has not ended within 10 s); returns
        what it wrote on stderr (once; empty after)."""
        if self.proc.stderr is None or self.proc.stderr.closed:
            return ""
        if self.proc.poll() is None:
            try:
                assert self.proc.stdin is not None
                self.proc.stdin.write("quit\n")
                self.proc.stdin.close()
            except (BrokenPipeError, OSError):
                pass
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)
        err = self.proc.stderr.read()
        for stream in (self.proc.stdout, self.proc.stderr):
            if stream is not None:
                stream.close()
        return err

    def __enter__(self) -> CppServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class CppSideOurs:
    """tfbus's half of the C++ reference rows: the buffers and messages built once, each
    of :meth:`fill`, :meth:`steady` and :meth:`lookup` measuring what one command of
    ``tf2_buffer_core_bench --serve`` measures (:class:`CppServer`). Times are this
    thread's CPU seconds per call (``time.thread_time``, as the C++ side's
    ``CLOCK_THREAD_CPUTIME_ID``: other work preempting either side on a shared machine
    stays out of the ratios)."""

    def __init__(self, sc: dict[str, Any]) -> None:
        self.sc = sc
        chain = {"cache_time_s": sc["cache_time_s"], "chain_stamps": sc["chain_stamps"]}
        self.chains = {d: _chain(chain, d) for d in sc["depths"]}
        calls = sc["calls"]
        self.times = {
            label: [
                [Time.from_ns(ns) for ns in sc[key][r * calls : (r + 1) * calls]]
                for r in range(sc["repeats"])
            ]
            for label, key in (("interp", "spread_ns"), ("recent", "recent_ns"))
        }
        self.fill_messages = _star(sc, 0, sc["fill_samples"])
        self.warm = _star(sc, 0, sc["steady_warm"])
        self.steady_messages = _star(sc, sc["steady_warm"], sc["steady_samples"])

    def lookup(self, depth: int, label: str, r: int) -> float:
        """Seconds per call of repeat ``r``'s lookups from f0 to the depth ``depth`` leaf
        (``label`` ``interp`` or ``recent``)."""
        clock = time.thread_time
        lookup = self.chains[depth].lookup_transform
        leaf = f"f{depth}"
        run = self.times[label][r]
        start = clock()
        for t in run:
            lookup("f0", leaf, t)
        return (clock() - start) / len(run)

    def fill(self) -> float:
        """Seconds per ``set_transform`` of a fresh buffer's first samples of each link."""
        clock = time.thread_time
        setter = BufferCore(cache_time=self.sc["cache_time_s"]).set_transform
        messages = self.fill_messages
        start = clock()
        for m in messages:
            setter(m, "bench")
        return (clock() - start) / len(messages)

    def steady(self) -> float:
        """Seconds per ``set_transform`` once every link holds a full cache (a buffer
        warmed untimed first)."""
        clock = time.thread_time
        setter = BufferCore(cache_time=self.sc["cache_time_s"]).set_transform
        for m in self.warm:
            setter(m, "bench")
        messages = self.steady_messages
        start = clock()
        for m in messages:
            setter(m, "bench")
        return (clock() - start) / len(messages)


_MEMORY_CHILD = """
import json, sys
sys.path.insert(0, sys.argv[1])
import bench_core
sc = {**bench_core.scenario(True), "mem_frames": int(sys.argv[2]), "mem_samples": int(sys.argv[3])}
print(json.dumps(bench_core.tfbus_memory(sc)))
"""


def tfbus_memory_fresh(frames: int, samples: int) -> dict[str, float]:
    """:func:`tfbus_memory` in a fresh interpreter (RSS growth not hidden by memory this
    process freed before): ``traced_bytes_per_sample`` and ``rss_bytes_per_sample``.

    Raises:
        RuntimeError: the interpreter failed (its stderr).
    """
    run = subprocess.run(
        [sys.executable, "-c", _MEMORY_CHILD, str(Path(__file__).parent), str(frames),
         str(samples)],
        capture_output=True,
        text=True,
        check=False,
        timeout=600,
    )  # fmt: skip
    if run.returncode:
        raise RuntimeError(f"memory run failed: {run.stderr.strip()[-300:]}")
    result: dict[str, float] = json.loads(run.stdout.strip().splitlines()[-1])
    return result


def tf2_side(sc: dict[str, Any]) -> dict[str, Any] | str:
    """The tf2_py figures, or why there are none."""
    probe = subprocess.run(
        [TF2_PYTHON, "-c", "import tf2_py, rospy, geometry_msgs.msg"],
        capture_output=True,
        text=True,
        check=False,
    )
    if probe.returncode:
        return f"tf2_py not importable by {TF2_PYTHON} (apt-get install python3-tf2)"
    run = subprocess.run(
        [TF2_PYTHON, str(TF2_SIDE)],
        input=json.dumps(sc),
        capture_output=True,
        text=True,
        check=False,
    )
    if run.returncode:
        return f"tf2 side failed: {run.stderr.strip()[-500:]}"
    result: dict[str, Any] = json.loads(run.stdout)
    return result


def _us(seconds: float | None) -> str:
    return "—" if seconds is None else f"{seconds * 1e6:8.2f} µs"


def depth2_breakdown(sc: dict[str, Any]) -> dict[str, float]:
    """Where a never-repeated depth-2 lookup spends its time, seconds per
    call, best of the repeats, on the same query times as the main table:

    * ``full``: ``BufferCore.lookup_transform`` (what users call);
    * ``query``: the one compiled call behind it (``CoreBase._query``: argument checks,
      memo, walk, building the TransformStamped);
    * ``walk``: the compiled walk alone (``CoreBase._cwalk``, ids already resolved,
      result as a plain 7-tuple);
    * ``floor_new`` / ``floor_ctor``: building the same TransformStamped with no lookup
      at all, with ``tuple.__new__`` (the fastest Python can) and with the NamedTuple
      constructors (what user code writes).
    """
    calls, repeats = sc["calls"], sc["repeats"]
    varying = [Time.from_ns(ns) for ns in sc["query_ns"]]
    runs = [varying[r * calls : (r + 1) * calls] for r in range(repeats)]
    core = _chain(sc, 2)
    ids = core._frame_ids
    f0, f2 = ids["f0"], ids["f2"]
    query, walk, lookup = core._query, core._cwalk, core.lookup_transform
    v = (0.1, 0.2, 0.3, 0.0, 0.0, 0.0099, 0.99995)
    new = tuple.__new__

    def floor_new(t: Time) -> object:
        return new(
            TransformStamped,
            (
                new(Header, (t, "f0")),
                "f2",
                new(Transform, (new(Vector3, v[:3]), new(Quaternion, v[3:]))),
            ),
        )

    def floor_ctor(t: Time) -> object:
        return TransformStamped(
            Header(t, "f0"), "f2", Transform(Vector3(*v[:3]), Quaternion(*v[3:]))
        )

    return {
        "full": _best_per_call(lambda t: lookup("f0", "f2", t), runs),
        "query": _best_per_call(lambda t: query("f0", "f2", t), runs),
        "walk": _best_per_call(lambda t: walk(f0, f2, t.ns), runs),
        "call": _best_per_call(lambda t: None, runs),
        "floor_new": _best_per_call(floor_new, runs),
        "floor_ctor": _best_per_call(floor_ctor, runs),
    }


def report_breakdown(b: dict[str, float], ref: dict[str, Any] | str) -> None:
    theirs = ref.get("lookup_s", {}).get("2/interp") if isinstance(ref, dict) else None
    print("\ndepth 2, interp. t, never repeated: where the time goes (µs per call, best run)")
    print(f"  {'lookup_transform (all of it)':44} {_us(b['full']):>10}")
    print(f"  {'  Python wrapper (call + type check)':44} {_us(b['full'] - b['query']):>10}")
    print(f"  {'  compiled query':44} {_us(b['query']):>10}")
    print(
        f"  {'    argument checks + memo + building result':44} "
        f"{_us(b['query'] - b['walk']):>10}"
    )
    print(f"  {'    the walk (+ a 7-tuple)':44} {_us(b['walk'] - b['call']):>10}")
    print(f"  {'floor: same TransformStamped, tuple.__new__':44} {_us(b['floor_new']):>10}")
    print(f"  {'floor: same TransformStamped, constructors':44} {_us(b['floor_ctor']):>10}")
    if theirs:
        ratio = b["full"] / theirs
        verdict = "ok" if ratio <= LOOKUP_DEPTH2_TARGET else "MISS"
        print(
            f"  target: <= {LOOKUP_DEPTH2_TARGET:.2f}x tf2_py "
            f"({_us(theirs).strip()}): {ratio:.2f}x  {verdict}"
        )


def report(sc: dict[str, Any], ours: dict[str, Any], ref: dict[str, Any] | str) -> None:
    theirs = ref if isinstance(ref, dict) else {}
    head = "lookup_transform(root, leaf, t)"
    print(f"{head:36} {'tfbus':>12} {'tf2_py':>12} {'tfbus/tf2':>10}  target")
    print("-" * 90)
    labels = {
        "interp": "interp. t, never repeated",
        "zero_fresh": "time 0, after an insert",
        "fixed": "interp. t, repeated",
        "zero": "time 0, repeated",
    }
    for depth in sc["depths"]:
        for key, label in labels.items():
            name = f"{depth}/{key}"
            a = ours["lookup_s"][name]
            b = theirs.get("lookup_s", {}).get(name)
            ratio = f"{a / b:9.2f}x" if b else ""
            verdict = "" if b is None else ("ok" if a <= b else "SLOWER")
            print(
                f"depth {depth:>2}, {label:<25} {_us(a):>12} {_us(b):>12} {ratio:>10}"
                f"  <= tf2_py  {verdict}"
            )
    a = ours["set_per_s"]
    b = theirs.get("set_per_s")
    ratio = f"{a / b:9.2f}x" if b else ""
    verdict = "" if b is None else ("ok" if a >= b / 2 else "TOO SLOW")
    print(
        f"{'set_transform, single calls':36} {a / 1e6:8.3f} M/s "
        f"{'—' if b is None else f'{b / 1e6:8.3f} M/s':>12} {ratio:>10}  >= 0.5x tf2_py  {verdict}"
    )
    a, b = ours["set_chain_s"], theirs.get("set_chain_s")
    ratio = f"{a / b:9.2f}x" if b else ""
    verdict = "" if b is None else ("ok" if a <= 0.35 * b else "SLOWER")
    print(
        f"{'set_transform, chain of 10, in order':36} {a * 1e9:8.0f} ns "
        f"{'—' if b is None else f'{b * 1e9:8.0f} ns':>12} {ratio:>10}  <= 0.35x tf2_py  {verdict}"
    )
    traced = ours["traced_bytes_per_sample"]
    verdict = "ok" if traced <= MEMORY_TARGET else "TOO BIG"
    samples = sc["mem_frames"] * sc["mem_samples"]
    tf2_rss = theirs.get("rss_bytes_per_sample")
    print(
        f"{f'memory/sample, {samples:,} (traced)':36} {traced:9.1f} B {'':>12} {'':>10}"
        f"  <= {MEMORY_TARGET} B  {verdict}"
    )
    print(
        f"{'memory/sample (RSS growth)':36} {ours['rss_bytes_per_sample']:9.1f} B "
        f"{'—' if tf2_rss is None else f'{tf2_rss:9.1f} B':>12}"
    )
    if isinstance(ref, str):
        print(f"\n(no tf2 comparison: {ref})")


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller workloads (~20 s)")
    parser.add_argument("--no-tf2", action="store_true", help="skip the tf2_py comparison")
    args = parser.parse_args(argv)
    sc = scenario(args.quick)
    started = time.perf_counter()
    core = "compiled core" if COMPILED else "pure-Python core (TFBUS_PURE_PYTHON)"
    print(f"tfbus BufferCore ({core}) vs tf2_py — Python {sys.version.split()[0]}", flush=True)
    ours: dict[str, Any] = {"lookup_s": tfbus_lookups(sc)}
    policies = policy_lookups(sc)
    breakdown = depth2_breakdown(sc)  # in the same state as the lookups above
    ours["set_per_s"] = tfbus_set_rate(sc)
    ours["set_chain_s"] = tfbus_set_chain(sc)
    ours.update(tfbus_memory(sc))
    ref = "skipped (--no-tf2)" if args.no_tf2 else tf2_side(sc)
    # Other work may share the machine: measure tfbus's lookups again after tf2's and
    # keep the best of the two (bracketing tf2's run), so a burst of load during one
    # side does not decide the ratio.
    again = tfbus_lookups(sc)
    ours["lookup_s"] = {k: min(v, again[k]) for k, v in ours["lookup_s"].items()}
    again_b = depth2_breakdown(sc)
    breakdown = {k: min(v, again_b[k]) for k, v in breakdown.items()}
    report(sc, ours, ref)
    report_breakdown(breakdown, ref)
    report_policies(sc, policies)
    print(f"\n({time.perf_counter() - started:.1f} s)")


if __name__ == "__main__":
    main()
