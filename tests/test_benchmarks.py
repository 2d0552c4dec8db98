"""``benchmarks/`` stands alone: every benchmark imports with the
``bench`` extra alone, nothing from ``tests/`` and none of the ``test`` extra's packages.

Each benchmark module is loaded (its ``__main__`` block not run) in a fresh interpreter
where the ``test`` extra's top-level packages cannot be imported and ``tests/`` is not on
``sys.path``. The peer programs the benchmarks run beside tfbus live in ``peers/`` (they
run in other interpreters: Debian's ROS 1 Python, the ROS 2 venv) and are not loaded here.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = sorted(p for p in (ROOT / "benchmarks").glob("*.py") if not p.name.startswith("_"))

TEST_ONLY = ("pytest", "_pytest", "hypothesis", "ruff", "mypy", "build", "yaml")
"""Top-level packages of the ``test`` extra (pyproject.toml) that ``bench`` lacks."""

_LOAD = """
import importlib.abc, json, runpy, sys
blocked, tests = set(json.loads(sys.argv[2])), sys.argv[3]

class TestExtraAbsent(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.partition(".")[0] in blocked:
            raise ModuleNotFoundError(f"No module named {name!r} (the test extra)", name=name)
        return None

sys.meta_path.insert(0, TestExtraAbsent())
sys.argv = [sys.argv[1]]
runpy.run_path(sys.argv[0], run_name="benchmark_import_check")
print(json.dumps(sorted(
    name for name, mod in list(sys.modules.items())
    if str(getattr(mod, "__file__", None) or "").startswith(tests)
)))
"""


def test_the_list_of_benchmarks_is_not_empty() -> None:
    assert {p.name for p in BENCHMARKS} >= {"bench_check.py", "bench_ros1.py", "soak_ros1.py"}


@pytest.mark.parametrize("bench", BENCHMARKS, ids=lambda p: p.name)
def test_a_benchmark_imports_without_tests_or_the_test_extra(
    bench: Path, tmp_path: Path
) -> None:
    res = subprocess.run(
        [sys.executable, "-c", _LOAD, str(bench), json.dumps(TEST_ONLY), str(ROOT / "tests")],
        cwd=tmp_path,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    assert json.loads(res.stdout.strip().splitlines()[-1]) == []


def _bench_latency(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_latency.py"), *args],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=180,
    )


def test_bench_latency_runs_every_path_with_the_zenoh_config_values_given() -> None:
    res = _bench_latency(
        "--paths", "raw,raw+loop,raw+loops", "--modes", "batched", "--rates", "50",
        "--seconds", "0.4",
        "--zenoh-config", "transport/link/tx/queue/batching/enabled=false",
        "--zenoh-config", "transport/link/tx/lease=4000",
    )
    assert res.returncode == 0, res.stderr[-2000:]
    lines = res.stdout.splitlines()
    assert (
        "zenoh config, every path: transport/link/tx/queue/batching/enabled=false"
        " transport/link/tx/lease=4000"
    ) in lines
    rows = [line.split() for line in lines if line.startswith("batched")]
    assert len(rows) == 1 and rows[0][:2] == ["batched", "50"]
    assert "-" not in rows[0]  # every path received probes


@pytest.mark.parametrize(
    ("item", "error"),
    [
        ("a/lease", "--zenoh-config wants PATH=JSON, got 'a/lease'"),
        ("a/lease=4s", "--zenoh-config a/lease: not a JSON value: '4s'"),
    ],
)
def test_bench_latency_refuses_a_zenoh_config_value_that_is_not_path_equals_json(
    item: str, error: str
) -> None:
    res = _bench_latency("--paths", "raw", "--rates", "50", "--seconds", "0.4",
                         "--zenoh-config", item)
    assert res.returncode == 1 and error in res.stderr


def test_bench_check_sensors_group_names_its_rows_and_fails_a_row_whose_peer_is_missing(
    tmp_path: Path,
) -> None:
    # No g++ on PATH (an empty directory): the C++ laser_geometry cannot be built, so its
    # row is "not run" and FAILs; the point-cloud rows (numpy, always here) still run.
    res = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_check.py"), "--only", "sensors",
         "--rounds", "3"],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT), "PATH": str(tmp_path)},
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )  # fmt: skip
    assert res.returncode == 1, res.stdout + res.stderr[-3000:]
    lines = res.stdout.splitlines()
    laser = [ln for ln in lines if "project_laser 720 beams vs C++ projectLaser" in ln]
    assert len(laser) == 1 and laser[0].split()[0] == "FAIL", res.stdout
    assert "not run: g++ not found" in laser[0]
    for name in ("transform_points 10^6 points vs bare numpy",
                 "do_transform_cloud 10^6 points vs bare numpy"):  # fmt: skip
        row = [ln for ln in lines if name in ln]
        assert len(row) == 1 and row[0].split()[0] in ("PASS", "FAIL"), res.stdout
        assert "not run" not in row[0] and "target <= 1.2x numpy" in row[0]
    assert not any("Zenoh" in ln or "ROS 1" in ln or "tf2_py" in ln.split("target")[0]
                   for ln in lines[1:]), res.stdout  # fmt: skip


def test_bench_check_refuses_an_unknown_group_and_names_the_groups() -> None:
    res = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_check.py"), "--only", "sensors,laser"],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert res.returncode == 2
    assert "unknown group laser" in res.stderr
    assert "ros1cpu, sensors, zenoh, demo" in res.stderr



_CHECKED_FLOOR = """
import sys
import anyio
import bench_bus

backend = sys.argv[1]


async def main() -> None:
    check = bench_bus._cancel_check(backend)
    with anyio.CancelScope() as scope:
        scope.cancel()
        await check()
        raise AssertionError("the check did not raise in a cancelled scope")
    assert scope.cancelled_caught
    await check()
    got = await bench_bus.checked_floor_run(5, 1, backend)
    assert len(got.samples_ns) == 5 and all(ns > 0 for ns in got.samples_ns)
    print("checked")


anyio.run(main, backend=backend)
"""


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_the_checked_wake_up_floor_checks_for_cancellation_as_a_publish_does(
    backend: str,
) -> None:
    """``bench_bus.checked_floor_run`` (the wake-up floor with the check a publish makes
    before publishing, beside ``make bench-check``'s wake-up rows) runs on both backends,
    and its check is a real one: inside a cancelled scope it raises the cancellation, as
    ``send_transform`` does, and outside one it returns. (In a child interpreter: a
    benchmark module puts the checkout on ``sys.path``.)"""
    done = subprocess.run(
        [sys.executable, "-c", _CHECKED_FLOOR, backend], cwd=ROOT / "benchmarks",
        capture_output=True, text=True, timeout=120,
    )
    assert done.returncode == 0 and done.stdout.strip() == "checked", done.stderr[-3000:]


_BUS_PARTS = """
import sys
import anyio
import bench_bus

backend = sys.argv[1]


async def main() -> None:
    for part in bench_bus.PARTS:
        got = await bench_bus.latency_run(5, 1, None, False, part)
        assert len(got.samples_ns) == 5 and all(ns > 0 for ns in got.samples_ns), part
    try:
        await bench_bus.latency_run(5, 1, None, False, "nothing")
    except ValueError:
        print("parts")


anyio.run(main, backend=backend)
"""


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_the_bus_path_in_parts_wakes_the_waiter_for_every_part(backend: str) -> None:
    """``bench_bus.latency_run``'s parts (the listener's handler alone, after the publish
    cancellation check, through the bus's delivery: ``make bench-check``'s wake-up info
    rows) each wake the awaiting lookup for every sample on both backends (a part that
    stored nothing would leave the waiter blocked until the time limit), and a part
    that is not one of them is refused. (In a child interpreter: a benchmark module puts
    the checkout on ``sys.path``.)"""
    done = subprocess.run(
        [sys.executable, "-c", _BUS_PARTS, backend], cwd=ROOT / "benchmarks",
        capture_output=True, text=True, timeout=120,
    )
    assert done.returncode == 0 and done.stdout.strip() == "parts", done.stderr[-3000:]


def test_the_seed_demo_floor_pair_prints_the_tutorial_line() -> None:
    """``bench_demo_ros1.py``'s Python floor pair (beside ``make bench-check``'s seed demo
    row) needs no ROS, only a socket of its own on 127.0.0.1, and does the demo's job: its
    listener prints the tutorial's line for its broadcaster's transform (base_laser 10 cm
    forward and 20 cm up of base_link: (1.0, 0.2, 0.0) -> (1.1, 0.2, 0.2)), and both end
    quietly on SIGINT, as ``run_pair`` ends them."""
    import ros1_peers

    port = str(ros1_peers.free_port())
    script = str(ROOT / "benchmarks" / "bench_demo_ros1.py")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    broadcaster = ros1_peers.Proc([sys.executable, script, "--floor-broadcaster", port], env)
    try:
        listener = ros1_peers.Proc([sys.executable, script, "--floor-listener", port], env)
        try:
            line = listener.wait_for(
                r"base_laser: \(1\.00, 0\.20\. 0\.00\) -----> base_link: \((.*)\) at time",
                timeout=60.0,
            )
            assert line.group(1) == "1.10, 0.20, 0.20"
        finally:
            assert listener.stop(signal.SIGINT, timeout=30.0) == 0, listener.drain()
    finally:
        assert broadcaster.stop(signal.SIGINT, timeout=30.0) == 0, broadcaster.drain()


_CPP_SERVER = """
import json, os, sys, tempfile
from pathlib import Path
import bench_check, bench_core

calls = []
def side(name, values):
    it = iter(values)
    def measure(k):
        calls.append((name, k))
        return next(it)
    return measure
paired = bench_check._paired(side("ours", [2.0, 1.0, 3.0]), side("theirs", [4.0, 4.0, 2.0]), 3)
out = {"paired": paired, "order": calls}
sc = bench_core.cpp_scenario(calls=50, repeats=2, mem_frames=2)
with tempfile.TemporaryDirectory() as tmp:
    exe = bench_core.build_cpp(Path(tmp))
    if isinstance(exe, str):
        print(json.dumps({"skip": exe}))
        raise SystemExit(0)
    ours = bench_core.CppSideOurs(sc)
    before = sorted(os.sched_getaffinity(0))
    with bench_core.CppServer(exe, sc) as server:
        with bench_check._same_cpu(server.proc.pid):
            out["pinned"] = [sorted(os.sched_getaffinity(0)),
                             sorted(os.sched_getaffinity(server.proc.pid))]
            out["round"] = bench_check.cpp_round(ours, server)
        out["restored"] = sorted(os.sched_getaffinity(0)) == before
        try:
            server.measure("lookup 3 interp 0")  # no chain of depth 3
        except RuntimeError as exc:
            out["refused"] = str(exc)
        out["ended"] = server.proc.poll() is not None
    out["one_shot"] = sorted(bench_core.cpp_round(exe, sc))
print(json.dumps(out))
"""


def test_the_cpp_tf2_server_is_measured_in_pairs_on_one_cpu() -> None:
    """``bench-check``'s C++ tf2 group: ``_paired`` alternates the two sides a measurement
    at a time (ours first in even pairs) and judges the median of the pairs' ratios; the
    C++ program's ``--serve`` mode answers each of the commands ``cpp_round`` sends with a
    time per call and refuses a lookup on a chain it does not have (its process ends, the
    caller gets a RuntimeError naming it); ``_same_cpu`` pins this thread and the server
    to one CPU for the block and restores this thread's CPUs after it; the one-shot mode
    still prints every figure."""
    done = subprocess.run(
        [sys.executable, "-c", _CPP_SERVER], cwd=ROOT / "benchmarks",
        env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["paired"] == [1.0, 2.0, 0.5]  # ratios 0.5, 0.25, 1.5: median 0.5
    assert out["order"] == [["ours", 0], ["theirs", 0], ["theirs", 1], ["ours", 1],
                            ["ours", 2], ["theirs", 2]]
    if "skip" in out:
        pytest.skip(f"the C++ tf2 side cannot be built here: {out['skip']}")
    (cpu,), (server_cpu,) = out["pinned"]
    assert cpu == server_cpu
    assert out["restored"]
    keys = [f"{d}/{label}" for d in (1, 2, 8, 64) for label in ("interp", "recent")]
    assert sorted(out["round"]) == sorted([*keys, "fill_s", "steady_s"])
    for ours_s, theirs_s, ratio in out["round"].values():
        assert 0 < ours_s < 1e-3 and 0 < theirs_s < 1e-3 and 0.01 < ratio < 100
    assert "bad lookup command" in out["refused"] and out["ended"]
    assert out["one_shot"] == ["fill_s", "lookup_s", "rss_bytes_per_sample", "steady_s"]
