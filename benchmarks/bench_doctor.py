"""``tfbus doctor`` speed and memory: MB/s and peak RSS against ``tfbus bag-info`` on the
same recording.

A ROS 1 bag (``--format mcap``: a ROS 2 bag folder holding one MCAP file) of about
``--size-mb`` MB is written (streamed through tfbus's writer: a
robot-like mix, 10 dynamic frames per /tf message at 100 Hz and one /tf_static), then
each command runs in its own process and is timed; its peak anonymous RSS (``RssAnon``
sampled every 20 ms: what it allocates) and its peak RSS (``VmHWM`` sampled likewise,
which also counts the recording's pages the reader maps) are printed. ``diagnose()`` is
also timed in this process (no interpreter start-up). The anonymous RSS should not grow
with the file: the doctor keeps per-link state only.
Prints figures only.

    .venv/bin/python benchmarks/bench_doctor.py [--size-mb 50] [--format ros1|mcap]
        [--keep PATH]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

from tfbus import Header, Quaternion, TFMessage, Time, Transform, TransformStamped, Vector3
from tfbus.bag import BagMessage, write_bag

ROOT = Path(__file__).resolve().parents[1]
PER_MSG = 10
BYTES_PER_MSG = 1000  # about, for a ROS 1 TFMessage of 10 transforms with its record header


def messages(n: int) -> Iterator[BagMessage]:
    """One /tf_static, then ``n`` /tf messages of :data:`PER_MSG` frames at 100 Hz."""
    t0 = 1_700_000_000 * 10**9
    yield BagMessage(Time.from_ns(t0), "/tf_static", TFMessage([TransformStamped(
        Header(Time.from_ns(t0), "base_link"), "laser", Transform(Vector3(0.1, 0.0, 0.2)))]),
        "/bench")
    rot = Quaternion(0.0, 0.0, 0.0, 1.0)
    for k in range(n):
        stamp = Time.from_ns(t0 + k * 10_000_000)
        tfs = [TransformStamped(Header(stamp, "odom" if j == 0 else
                                       "base_link" if j == 1 else f"link{j - 1}"),
                                "base_link" if j == 0 else f"link{j}",
                                Transform(Vector3(0.01 * k, 0.0, 0.0), rot))
               for j in range(PER_MSG)]
        yield BagMessage(Time.from_ns(stamp.ns + 2_000_000), "/tf", TFMessage(tfs), "/bench")


def _status_kib(pid: int, key: str) -> int:
    """A ``/proc/PID/status`` field in KiB (0 once the process is gone)."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def run_child(*args: str) -> tuple[float, float, float]:
    """Run ``python -m tfbus.cli ARGS``: (seconds, peak anonymous RSS MB, peak RSS MB).

    Peak RSS (``VmHWM``, the high-water mark of the process after its ``exec``; not
    ``ru_maxrss``, which on Linux also counts this benchmark's own RSS copied by
    ``fork`` before the ``exec``) counts the pages of the recording the reader maps
    (file-backed, given back under pressure); the anonymous RSS (``RssAnon``) is the
    memory the process allocates. Both are sampled every 20 ms."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "tfbus.cli", *args], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    anon = hwm = 0
    while True:
        anon = max(anon, _status_kib(proc.pid, "RssAnon"))
        hwm = max(hwm, _status_kib(proc.pid, "VmHWM"))
        pid, status, _usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        time.sleep(0.02)
    elapsed = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode not in (0, 1):
        raise SystemExit(f"tfbus {' '.join(args)} exited {proc.returncode}")
    return elapsed, anon / 1024, hwm / 1024


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size-mb", type=float, default=50.0, help="recording size (MB)")
    parser.add_argument("--format", choices=("ros1", "mcap"), default="ros1",
                        help="recording format (default ros1)")
    parser.add_argument("--keep", type=Path, default=None,
                        help="write the recording here and keep it (default: a temp dir)")
    args = parser.parse_args()
    n = max(1, int(args.size_mb * 1e6 / BYTES_PER_MSG))
    tmp = Path(tempfile.mkdtemp(prefix="bench_doctor_"))
    default = tmp / ("bench.bag" if args.format == "ros1" else "bench")
    path = args.keep if args.keep is not None else default
    try:
        start = time.perf_counter()
        write_bag(path, messages(n), format=args.format)
        files = [path] if path.is_file() else list(path.iterdir())
        size = sum(f.stat().st_size for f in files) / 1e6
        print(f"recording: {path} ({size:.1f} MB, {n + 1} messages, {n * PER_MSG + 1} "
              f"transforms), written in {time.perf_counter() - start:.1f} s")
        from tfbus.doctor import diagnose

        start = time.perf_counter()
        report = diagnose(path)
        t = time.perf_counter() - start
        print(f"diagnose() in process: {t:.2f} s, {size / t:.1f} MB/s, "
              f"{report.transforms / t / 1e3:.0f} k transforms/s, "
              f"{len(report.findings)} findings")
        print(f"{'command':<16} {'seconds':>8} {'MB/s':>8} {'peak anon MB':>13} "
              f"{'peak RSS MB':>12}")
        for name, argv in (("tfbus bag-info", ("bag-info", str(path))),
                           ("tfbus doctor", ("doctor", "--bag", str(path), "--json"))):
            t, anon, rss = run_child(*argv)
            print(f"{name:<16} {t:>8.2f} {size / t:>8.1f} {anon:>13.1f} {rss:>12.1f}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
