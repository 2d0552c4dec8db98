"""The seed demo over ROS 1, CPU against the tutorial's own C++ pair, same run.

The ROS tutorial "Setting up your robot using tf" has two C++ nodes: a 100 Hz
``robot_tf_publisher`` (base_link -> base_laser) and a 1 Hz ``robot_tf_listener``
(``peers/ros1/tf_broadcaster.cpp`` and ``tf_listener.cpp``, built here against
Debian's roscpp and tf). tfbus runs the same two nodes as ``tfbus demo broadcaster`` and
``tfbus demo listener`` on ``--bus ros1:`` (one process each, as the tutorial's two
terminals). Both pairs run on one roscore on 127.0.0.1, in alternating rounds; each round
measures the CPU time (user + system, from ``/proc/PID/stat``) the two processes of a
pair use over a window that starts once the listener prints its first tutorial line
(start-up, imports and registration are not counted) and lasts ``--seconds``. The CPU
time is the sum of each thread's run time in nanoseconds (``/proc/PID/task/*/schedstat``,
the scheduler's own account) rather than ``/proc/PID/stat``'s 10 ms ticks, which over an
8 s window at ~1 % of a core counted 8 +- 1 ticks a process (a thread that ends inside the
window loses its share; these nodes' threads live as long as the node). Each process's
wake-ups per second (voluntary context switches of all its threads) are printed beside
its CPU: the C++ nodes wake several times per message (roscpp's threads), tfbus's once.

Prints each round, then per side the min/median/max CPU as a percentage of one core, the
ratio tfbus / C++ (target <= 1.5x) and the 1-minute load average. Figures only; nothing
is asserted. Needs Debian's ROS 1 (``scripts/install/install_ros1.sh``) and g++.

    .venv/bin/python benchmarks/bench_demo_ros1.py            # 3 rounds of 20 s
    .venv/bin/python benchmarks/bench_demo_ros1.py --quick    # 3 rounds of 8 s
    .venv/bin/python benchmarks/bench_demo_ros1.py --baseline /tmp/old-tree  # + that tree's pair
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "peers" / "ros1"))  # the ROS 1 peers: one home, shared with the tests

from proc_cpu import cpu_and_wakeups  # noqa: E402
from ros1_peers import Master, Proc, ros1_missing, start_master  # noqa: E402

TFBUS = [sys.executable, "-m", "tfbus.cli"]


def run_pair(
    master: Master, commands: list[list[str]], seconds: float
) -> list[tuple[float, float]]:
    """Start a broadcaster and a listener, wait (bounded) for the listener's first tutorial
    line, then measure both processes over ``seconds``: per process (share of a core,
    wake-ups per second)."""
    procs: list[Proc] = []
    try:
        for cmd in commands:
            procs.append(master.run(*cmd))
        procs[1].wait_for(r"base_laser: \(1\.00, 0\.20\. 0\.00\) -----> base_link", timeout=60.0)
        before = [cpu_and_wakeups(p.proc.pid) for p in procs]
        t0 = time.monotonic()
        time.sleep(seconds)  # the measurement window itself (a benchmark, not a test)
        after = [cpu_and_wakeups(p.proc.pid) for p in procs]
        wall = time.monotonic() - t0
        return [
            ((a[0] - b[0]) / wall, (a[1] - b[1]) / wall) for a, b in zip(after, before, strict=True)
        ]
    finally:
        for p in reversed(procs):
            p.stop(signal.SIGINT, timeout=10.0)


DEMO_PACKAGES = ("roscpp", "tf")
"""What the tutorial's C++ pair builds against."""


def build(out: Path) -> None:
    """The tutorial's C++ pair (``peers/ros1/build.sh``) built into ``out``.

    Raises:
        subprocess.CalledProcessError: the build failed."""
    subprocess.run(["bash", str(ROOT / "peers" / "ros1" / "build.sh"), str(out)],
                   check=True, capture_output=True, timeout=600)  # fmt: skip


def pairs(out: Path, uri: str) -> dict[str, list[list[str]]]:
    """The two sides' commands (broadcaster, listener) on the master ``uri``
    (``ros1:http://...``): the C++ pair built into ``out``, and tfbus's demo pair."""
    return {
        "C++ tutorial pair": [[str(out / "tf_broadcaster")], [str(out / "tf_listener")]],
        "tfbus demo pair": [[*TFBUS, "demo", "broadcaster", "--bus", uri],
                            [*TFBUS, "demo", "listener", "--bus", uri]],
    }  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0] if __doc__ else "")
    parser.add_argument("--quick", action="store_true", help="rounds of 8 s instead of 20 s")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds (default 3)")
    parser.add_argument("--baseline", metavar="TREE", default=None,
                        help="also run the tfbus pair from another checkout (e.g. a scratch "
                             "worktree of an earlier commit, its .so files built) as a third "
                             "side of each round, and print tfbus / that")  # fmt: skip
    args = parser.parse_args(argv)
    seconds = 8.0 if args.quick else 20.0
    why = ros1_missing(DEMO_PACKAGES)
    if why:
        print(f"seed demo over ROS 1: unavailable ({why})")
        return
    with tempfile.TemporaryDirectory(prefix="tfbus-bench-demo-") as tmp:
        out = Path(tmp) / "bin"
        build(out)
        master = start_master(Path(tmp) / "home")
        try:
            uri = f"ros1:{master.uri}"
            sides = pairs(out, uri)
            if args.baseline is not None:
                tree = str(Path(args.baseline).resolve())
                base = ["env", f"PYTHONPATH={tree}", sys.executable, "-m", "tfbus.cli"]
                sides["tfbus @ baseline"] = [[*base, "demo", "broadcaster", "--bus", uri],
                                             [*base, "demo", "listener", "--bus", uri]]  # fmt: skip
            shares: dict[str, list[float]] = {name: [] for name in sides}
            parts: dict[str, list[tuple[float, float]]] = {name: [] for name in sides}
            print(f"seed demo over ROS 1: {args.rounds} rounds of {seconds:.0f} s, "
                  "broadcaster 100 Hz + listener 1 Hz, CPU of both processes")  # fmt: skip
            for k in range(args.rounds):
                for name, commands in sides.items():
                    (broadcaster, b_wake), (listener, l_wake) = run_pair(master, commands,
                                                                         seconds)  # fmt: skip
                    shares[name].append(broadcaster + listener)
                    parts[name].append((broadcaster, listener))
                    print(f"  round {k + 1}  {name:18s} {(broadcaster + listener) * 100:6.2f} % "
                          f"of a core (broadcaster {broadcaster * 100:.2f}, {b_wake:.0f} "
                          f"wake-ups/s; listener {listener * 100:.2f}, {l_wake:.0f} "
                          "wake-ups/s)")  # fmt: skip
        finally:
            master.stop()
    for name, values in shares.items():
        low, mid, high = (100 * f(values) for f in (min, statistics.median, max))
        b_mid = 100 * statistics.median(b for b, _ in parts[name])
        l_mid = 100 * statistics.median(li for _, li in parts[name])
        print(f"  {name:18s} min {low:6.2f} %  median {mid:6.2f} %  max {high:6.2f} %  "
              f"(medians: broadcaster {b_mid:.2f} %, listener {l_mid:.2f} %)")  # fmt: skip
    cpp, ours, *rest = (statistics.median(v) for v in shares.values())
    (cpp_b, our_b, *_), (cpp_l, our_l, *_) = (
        [statistics.median(p[i] for p in v) for v in parts.values()] for i in (0, 1)
    )
    print(f"  split tfbus / C++ (medians): broadcaster {our_b / cpp_b:.2f}x, "
          f"listener {our_l / cpp_l:.2f}x")  # fmt: skip
    print(f"  ratio tfbus / C++ (medians) {ours / cpp:.2f}x (target <= 1.5x); "
          f"load {os.getloadavg()[0]:.1f}")  # fmt: skip
    if rest:
        print(f"  ratio tfbus @ baseline / C++ (medians) {rest[0] / cpp:.2f}x; "
              f"tfbus / tfbus @ baseline {ours / rest[0]:.2f}x")  # fmt: skip


if __name__ == "__main__":
    main()
