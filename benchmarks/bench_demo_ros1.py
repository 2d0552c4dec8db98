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
    .venv/bin/python benchmarks/bench_demo_ros1.py --uvloop   # + the pair on --backend uvloop
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "peers" / "ros1"))  # the ROS 1 peers: one home, shared with the tests

from proc_cpu import cpu_and_wakeups  # noqa: E402
from ros1_peers import Master, Proc, free_port, ros1_missing, start_master  # noqa: E402

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


FLOOR = "Python floor pair"
"""The side :func:`floor_broadcaster` and :func:`floor_listener` make (see them)."""


UVLOOP = "tfbus pair on uvloop"
"""The side of tfbus's demo pair run with ``--backend uvloop`` (asyncio on uvloop's loop)."""


def pairs(out: Path, uri: str, floor: bool = False,
          uvloop: bool = False) -> dict[str, list[list[str]]]:
    """The sides' commands (broadcaster, listener) on the master ``uri``
    (``ros1:http://...``): the C++ pair built into ``out``, tfbus's demo pair and, with
    ``floor``, the Python floor pair (:data:`FLOOR`, on a free 127.0.0.1 port of its
    own; no master); with ``uvloop``, tfbus's demo pair on uvloop (:data:`UVLOOP`)."""
    sides = {
        "C++ tutorial pair": [[str(out / "tf_broadcaster")], [str(out / "tf_listener")]],
        "tfbus demo pair": [[*TFBUS, "demo", "broadcaster", "--bus", uri],
                            [*TFBUS, "demo", "listener", "--bus", uri]],
    }  # fmt: skip
    if floor:
        port = str(free_port())
        here = [sys.executable, str(Path(__file__).resolve())]
        sides[FLOOR] = [[*here, "--floor-broadcaster", port], [*here, "--floor-listener", port]]
    if uvloop:
        sides[UVLOOP] = [[*TFBUS, "demo", "broadcaster", "--bus", uri, "--backend", "uvloop"],
                         [*TFBUS, "demo", "listener", "--bus", uri, "--backend", "uvloop"]]
    return sides


def floor_broadcaster(port: int, rate: float = 100.0) -> None:
    """The floor of the tutorial's broadcaster in Python (a child process, run until
    SIGINT): one asyncio task on absolute deadlines at ``rate`` Hz (``asyncio.sleep`` to
    each) reads the wall clock, writes the stamp and sequence number into one TCPROS
    frame of a one-transform ``TFMessage`` (base_link -> base_laser, serialised once at
    start by tfbus's codec) and writes it to each connected listener's socket
    (``transport.write``). What any asyncio node pays to send the tutorial's stream:
    the loop's wake-up, a timer, a clock read and a socket write a message; no master, no
    bus, no transport layers, no serialisation a message. Listens on 127.0.0.1:``port``;
    a listener is sent a TCPROS connection header first. The process imports tfbus's
    ROS 1 transport first (a tfbus-sized process: cache misses a wake-up grow with the
    process, not with the work)."""
    import asyncio
    import struct

    import tfbus.transports.ros1.transport  # noqa: F401  (a tfbus-sized process)
    from tfbus.codecs.ros1 import TF_MD5SUM, TFCodec
    from tfbus.demos.tutorial import LASER_OFFSET
    from tfbus.messages import Header, TransformStamped
    from tfbus.time import Time
    from tfbus.transports.ros1.tcpros import encode_header

    frame = bytearray(TFCodec().encode_framed(
        [TransformStamped(Header(Time(0), "base_link"), "base_laser", LASER_OFFSET)]))
    # uint32 frame length, uint32 array length, then the header: uint32 seq, time
    if struct.unpack_from("<III", frame, 8) != (0, 0, 0):
        raise SystemExit("the frame's layout is not the one expected")
    hello = encode_header({"callerid": "/floor_broadcaster", "topic": "/tf",
                           "md5sum": TF_MD5SUM, "type": "tf2_msgs/TFMessage"})  # fmt: skip
    listeners: list[asyncio.Transport] = []

    class Link(asyncio.Protocol):
        def connection_made(self, transport: asyncio.BaseTransport) -> None:
            assert isinstance(transport, asyncio.Transport)  # a TCP connection's
            transport.get_extra_info("socket").setsockopt(
                socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            transport.write(hello)
            listeners.append(transport)

        def connection_lost(self, exc: Exception | None) -> None:
            listeners[:] = [t for t in listeners if not t.is_closing()]

    async def main() -> None:
        loop = asyncio.get_running_loop()
        await loop.create_server(Link, "127.0.0.1", port)
        pack_into = struct.pack_into
        period = 1.0 / rate
        deadline = loop.time()
        seq = 0
        while True:
            ns = time.time_ns()
            seq += 1
            pack_into("<III", frame, 8, seq, ns // 1_000_000_000, ns % 1_000_000_000)
            data = bytes(frame)
            for transport in listeners:
                transport.write(data)
            deadline += period
            await asyncio.sleep(deadline - loop.time())

    with contextlib.suppress(KeyboardInterrupt):  # SIGINT ends it (run_pair's stop)
        asyncio.run(main())


def floor_listener(port: int) -> None:
    """The floor of the tutorial's listener in Python (a child process, run until
    SIGINT): connects to :func:`floor_broadcaster` on 127.0.0.1:``port`` (retrying, 60 s
    at most); the asyncio loop's read callback splits the TCPROS frames
    (``tfbus.transports.ros1.tcpros.FrameSplitter``), decodes each with tfbus's compiled
    decoder and stores its transforms in a tfbus ``Buffer`` (``set_transforms``: the
    bare reader + store of ``bench_ros1_floor.py``); a task wakes every second
    (``asyncio.sleep`` to absolute deadlines), transforms (1.0, 0.2, 0.0) from base_laser
    into base_link at the latest time (``Buffer.lookup_transform``,
    ``do_transform_point``) and prints the tutorial's line. No master, no bus, no
    listener layers."""
    import asyncio

    from bench_ros1_floor import SplitReader

    import tfbus.transports.ros1.transport  # noqa: F401  (a tfbus-sized process)
    from tfbus import Buffer
    from tfbus.codecs import ros1 as ros1_codec
    from tfbus.convert import do_transform_point
    from tfbus.demos.tutorial import LASER_POINT, format_info
    from tfbus.messages import Header, PointStamped
    from tfbus.time import Time
    from tfbus.transports.ros1.tcpros import FrameSplitter

    buffer = Buffer()
    decode = ros1_codec._compiled_ros1 or ros1_codec.TFCodec().decode
    store = buffer.set_transforms

    def sink(raw: Any) -> None:
        store(iter(decode(raw)), "/floor_broadcaster", False)

    splitter = FrameSplitter(lambda _header: setattr(splitter, "sink", sink), 1 << 20, 1 << 24)

    async def main() -> None:
        loop = asyncio.get_running_loop()
        for _ in range(3000):  # 60 s
            try:
                transport, _ = await loop.create_connection(
                    lambda: SplitReader(splitter), "127.0.0.1", port)
                break
            except OSError:
                await asyncio.sleep(0.02)
        else:
            raise SystemExit(f"no floor broadcaster on port {port} within 60 s")
        transport.get_extra_info("socket").setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        laser = PointStamped(Header(Time(0), "base_laser"), LASER_POINT)
        deadline = loop.time()
        while True:
            deadline += 1.0
            await asyncio.sleep(deadline - loop.time())
            if buffer.can_transform("base_link", "base_laser", Time(0)):
                ts = buffer.lookup_transform("base_link", "base_laser", Time(0))
                print(format_info(buffer.clock.now(), laser, do_transform_point(laser, ts)),
                      flush=True)

    with contextlib.suppress(KeyboardInterrupt):  # SIGINT ends it (run_pair's stop)
        asyncio.run(main())


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0] if __doc__ else "")
    parser.add_argument("--quick", action="store_true", help="rounds of 8 s instead of 20 s")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds (default 3)")
    parser.add_argument("--baseline", metavar="TREE", default=None,
                        help="also run the tfbus pair from another checkout (e.g. a scratch "
                             "worktree of an earlier commit, its .so files built) as a third "
                             "side of each round, and print tfbus / that")  # fmt: skip
    parser.add_argument("--floor", action="store_true",
                        help="also run the Python floor pair (floor_broadcaster, "
                             "floor_listener) as a side of each round")  # fmt: skip
    parser.add_argument("--uvloop", action="store_true",
                        help="also run tfbus's demo pair with --backend uvloop as a side of "
                             "each round (pip install uvloop)")  # fmt: skip
    parser.add_argument("--floor-broadcaster", type=int, metavar="PORT", help=argparse.SUPPRESS)
    parser.add_argument("--floor-listener", type=int, metavar="PORT", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.floor_broadcaster is not None:
        floor_broadcaster(args.floor_broadcaster)
        return
    if args.floor_listener is not None:
        floor_listener(args.floor_listener)
        return
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
            sides = pairs(out, uri, floor=args.floor, uvloop=args.uvloop)
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
    med = {name: statistics.median(v) for name, v in shares.items()}
    split = {name: [statistics.median(p[i] for p in v) for i in (0, 1)]
             for name, v in parts.items()}  # fmt: skip
    cpp, ours = med["C++ tutorial pair"], med["tfbus demo pair"]
    (cpp_b, cpp_l), (our_b, our_l) = split["C++ tutorial pair"], split["tfbus demo pair"]
    print(f"  split tfbus / C++ (medians): broadcaster {our_b / cpp_b:.2f}x, "
          f"listener {our_l / cpp_l:.2f}x")  # fmt: skip
    print(f"  ratio tfbus / C++ (medians) {ours / cpp:.2f}x (target <= 1.5x); "
          f"load {os.getloadavg()[0]:.1f}")  # fmt: skip
    if FLOOR in med:
        floor_b, floor_l = split[FLOOR]
        print(f"  floor: {FLOOR} / C++ {med[FLOOR] / cpp:.2f}x (broadcaster "
              f"{floor_b / cpp_b:.2f}x, listener {floor_l / cpp_l:.2f}x); tfbus / floor "
              f"{ours / med[FLOOR]:.2f}x (broadcaster {our_b / floor_b:.2f}x, listener "
              f"{our_l / floor_l:.2f}x)")  # fmt: skip
    if UVLOOP in med:
        uv_b, uv_l = split[UVLOOP]
        print(f"  {UVLOOP} / C++ {med[UVLOOP] / cpp:.2f}x (broadcaster {uv_b / cpp_b:.2f}x, "
              f"listener {uv_l / cpp_l:.2f}x); on uvloop / on asyncio's loop "
              f"{med[UVLOOP] / ours:.2f}x")  # fmt: skip
    if "tfbus @ baseline" in med:
        base = med["tfbus @ baseline"]
        print(f"  ratio tfbus @ baseline / C++ (medians) {base / cpp:.2f}x; "
              f"tfbus / tfbus @ baseline {ours / base:.2f}x")  # fmt: skip


if __name__ == "__main__":
    main()
