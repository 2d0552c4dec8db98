"""ROS 1 interop speed: a C++ roscpp publisher on /tf, received at once by a C++ roscpp
subscriber and by a tfbus process (``Bus(transport=Ros1Transport())``), same run.

Prints, per scenario (rate x frames per message x seconds): each receiver's CPU time per
message (each thread's scheduler run time in ns, ``/proc/PID/task/*/schedstat``:
``benchmarks/proc_cpu.py``), one-way latency median and
p99 (receive time - header.stamp, both on this machine's wall clock) for C++ and tfbus,
their ratio (target: tfbus ≤ 1.5x C++), and messages/transforms received of those sent
(target: none lost at 100 Hz x 50 frames for 60 s), with the 1-minute load average.
``--repeat N`` runs each scenario N times (a fresh pair of subscribers each time) and
adds the median of the per-run figures: on a shared machine one run is noisy. The
50-frame scenario runs once per ``--modes`` entry (default all, see :data:`MODES`):
``queue`` is the receive-latency target's row (a queued ``async for`` subscription against a roscpp
callback), ``callback`` a tfbus callback subscription against the same roscpp callback,
``listener`` a tfbus ``TransformListener`` into a ``Buffer`` against a
``tf2_ros::TransformListener`` into a ``tf2_ros::Buffer``. The publisher's values are
constant (a robot's fixed joints, or one standing still); with ``queue`` in the modes, a
``queue, moving`` scenario follows where every value changes in every message (a robot
moving every joint; ``ros1/bench_pub.cpp``), so a decoder that reuses repeated values is
also timed where it cannot. Figures only; nothing is asserted.

Needs Debian's ROS 1 (``scripts/install/install_ros1.sh``) and g++. Everything on 127.0.0.1.

    .venv/bin/python benchmarks/bench_ros1.py           # 10 s at 1 frame, 60 s at 50 frames
    .venv/bin/python benchmarks/bench_ros1.py --quick   # 5 s and 10 s
    .venv/bin/python benchmarks/bench_ros1.py --quick --repeat 5
    .venv/bin/python benchmarks/bench_ros1.py --modes queue  # the receive-latency row alone
    .venv/bin/python benchmarks/bench_ros1.py --quick --repeat 3 --modes callback,listener \
        --skip-one-frame --baseline /tmp/old-tree   # receive CPU, alternated with that tree
    .venv/bin/python benchmarks/bench_ros1.py --quick --modes callback,listener --uvloop

``--uvloop`` runs the tfbus side's event loop on uvloop (anyio's ``use_uvloop``; uvloop
importable in the venv or on ``PYTHONPATH``, which the tfbus side inherits after the tree
it imports): the asyncio loop's own cost per wake-up is most of the receive floor
(``bench_ros1_floor.py``).
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

from proc_cpu import cpu_seconds  # noqa: E402
from ros1_peers import Master, Proc, ros1_missing, start_master  # noqa: E402

BENCH_PACKAGES = ("roscpp", "tf2_msgs")
"""What the C++ publisher and subscriber of ``peers/ros1/`` build against."""


UVLOOP_ENV = "BENCH_ROS1_UVLOOP"
"""Set to ``1`` in the tfbus side's environment by ``--uvloop``: its event loop is uvloop's."""


def build(out: Path) -> None:
    flags = subprocess.run(
        ["pkg-config", "--cflags", "--libs", "roscpp", "tf2_msgs"],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PATH": "/usr/bin:" + os.environ.get("PATH", "")},
    ).stdout.split()
    for name in ("bench_pub", "bench_sub"):
        subprocess.run(
            ["g++", "-O2", "-o", str(out / name), str(ROOT / "peers" / "ros1" / f"{name}.cpp"),
             *flags],
            check=True,
        )
    listener_flags = subprocess.run(
        ["pkg-config", "--cflags", "--libs", "roscpp", "tf2_msgs", "tf2_ros"],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PATH": "/usr/bin:" + os.environ.get("PATH", "")},
    ).stdout.split()
    subprocess.run(
        ["g++", "-O2", "-o", str(out / "bench_listener"),
         str(ROOT / "peers" / "ros1" / "bench_listener.cpp"), *listener_flags],
        check=True,
    )


MODES = ("queue", "callback", "listener", "floor")
"""How each side receives, per ``--modes``:

* ``queue``: C++ ``bench_sub`` (a roscpp subscription callback) vs a tfbus queued
  subscription read by ``async for`` (the receive-latency target's row, kept as it was: tfbus's
  time includes handing the message from the read callback to the waiting task).
* ``callback``: the same C++ subscriber vs a tfbus callback subscription
  (:meth:`tfbus.Bus.subscribe_callback`), the counterpart of a roscpp callback.
* ``listener``: C++ ``bench_listener`` (``tf2_ros::TransformListener`` into a
  ``tf2_ros::Buffer``, time taken by the buffer's transforms-changed signal after the
  message's last transform is stored) vs a tfbus ``TransformListener`` into a ``Buffer``
  (time taken by a callback subscribed after the listener's, so when the whole message
  is stored).
* ``floor``: the same C++ subscriber vs the Python floor of ``queue``
  (:func:`floor_subscriber`: a bare asyncio reader handing each message to a task
  through an ``asyncio.Queue``, no tfbus between them), in columns named ``floor``.
"""


def tfbus_subscriber(mode: str) -> None:
    """The tfbus side (a child process): print READY, receive /tf until SIGINT/SIGTERM,
    then the same report as bench_sub."""
    import anyio

    from tfbus import Buffer, Bus, TransformListener
    from tfbus.transports.ros1 import Ros1Transport

    lat: list[float] = []
    counts = [0, 0]

    def record(msg: Any) -> None:
        now = time.time_ns()
        counts[0] += 1
        counts[1] += len(msg.transforms)
        if msg.transforms:
            lat.append((now - msg.transforms[0].header.stamp.ns) / 1e3)

    async def main() -> None:
        async with Bus(transport=Ros1Transport(node_name="/tfbus_bench")) as bus:
            sub = bus.subscribe("/tf", queue_size=100_000) if mode == "queue" else None
            async with contextlib.AsyncExitStack() as stack:
                listener = None
                if mode == "listener":
                    listener = TransformListener(Buffer(), bus)
                    await stack.enter_async_context(listener)
                if mode in ("callback", "listener"):
                    stack.enter_context(bus.subscribe_callback("/tf", record))
                with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
                    print("READY", flush=True)
                    if sub is None:  # callbacks record; wait for the signal
                        async for _ in signals:
                            break
                    else:
                        async with anyio.create_task_group() as tg:

                            async def stop() -> None:
                                async for _ in signals:
                                    tg.cancel_scope.cancel()
                                    return

                            tg.start_soon(stop)
                            async for msg in sub:
                                record(msg)
                if listener is not None:  # transforms received = transforms stored
                    counts[1] = listener.statistics().stored

    anyio.run(main, backend_options={"use_uvloop": os.environ.get(UVLOOP_ENV) == "1"})
    _print_report(counts, lat)


def _print_report(counts: list[int], lat: list[float]) -> None:
    """A Python side's report, as ``bench_sub`` prints it (read by :func:`report`):
    messages and transforms received, then each latency in us."""
    print(f"received {counts[0]} {counts[1]}\nlatencies", flush=True)
    print("\n".join(f"{v:.3f}" for v in lat), flush=True)


def floor_subscriber() -> None:
    """The Python floor of the ``queue`` row (a child process, the ``floor`` mode): no
    tfbus between the socket and the waiting task. The bare asyncio reader of
    ``bench_ros1_floor.py`` (the publisher's endpoint asked of the master, asyncio's read
    callback splitting the frames with ``FrameSplitter``, each message decoded by the
    codec's compiled decoder) puts each message's transforms into an ``asyncio.Queue``; a
    task awaiting it takes the receive time, as the tfbus side's ``async for`` does. The
    same READY line (printed before it connects: the publisher, started after it, waits
    for its second subscriber) and report as :func:`tfbus_subscriber`; its CPU figure also
    counts its polls of the master for the publisher's endpoint, after READY. The process
    imports tfbus's ROS 1 transport first (a tfbus-sized process)."""
    import asyncio

    import bench_ros1_floor

    from tfbus.codecs import ros1 as ros1_codec

    # READY at once: the publisher is started after it, and waits for its second
    # subscriber (this one) before it sends; the endpoint is asked of it once it runs.
    print("READY", flush=True)
    host, port, hello, splitter, _ = bench_ros1_floor._connect(False)
    decode = ros1_codec._compiled_ros1 or ros1_codec.TFCodec().decode
    queue: asyncio.Queue[Any] = asyncio.Queue()
    put = queue.put_nowait
    lat: list[float] = []
    counts = [0, 0]

    def message(raw: Any) -> None:
        put(decode(raw))

    def header(_raw: Any) -> None:  # the publisher's connection header
        splitter.sink = message

    splitter.sink = header

    async def consume() -> None:
        while True:
            transforms = await queue.get()
            now = time.time_ns()
            counts[0] += 1
            counts[1] += len(transforms)
            if transforms:
                lat.append((now - transforms[0].header.stamp.ns) / 1e3)

    async def main() -> None:
        loop = asyncio.get_running_loop()
        stop = asyncio.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        transport, _ = await loop.create_connection(
            lambda: bench_ros1_floor.SplitReader(splitter), host, port)
        transport.get_extra_info("socket").setsockopt(
            socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        transport.write(hello)
        task = asyncio.create_task(consume())
        await stop.wait()
        task.cancel()
        transport.close()

    asyncio.run(main())
    _print_report(counts, lat)


def report(proc: Proc) -> tuple[int, int, list[float]]:
    proc.stop(signal.SIGINT, timeout=30.0)
    lines = proc.drain()
    i = next(k for k, line in enumerate(lines) if line.startswith("received "))
    _, msgs, tfs = lines[i].split()
    lat = [float(x) for x in lines[i + 2 :] if x.strip()]
    return int(msgs), int(tfs), lat


def pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, int(q * len(s)))]


def scenario(
    master: Master, bins: Path, rate: float, frames: int, seconds: float, mode: str = "queue",
    moving: bool = False, cpu: list[tuple[float, float]] | None = None, tree: Path = ROOT,
) -> tuple[float, float, float, float, bool]:
    """One run (``mode``: see :data:`MODES`; ``moving``: every value changes in every
    message, else they are constant, see ``ros1/bench_pub.cpp``): prints its line; returns
    C++ and tfbus median and p99, and whether tfbus received every transform sent.

    Each receiver's CPU time (its threads' scheduler run time in ns,
    :func:`proc_cpu.cpu_seconds`) from the publisher's start to its last message, per
    message received, is printed too and appended to ``cpu`` as ``(C++ s, tfbus s)`` when
    given.
    ``tree``: the checkout whose tfbus the tfbus side imports (``--baseline``)."""
    if mode == "listener":
        cpp = master.run(str(bins / "bench_listener"), str(frames))
    else:
        cpp = master.run(str(bins / "bench_sub"))
    env = dict(master.env)
    extra = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p and p != str(ROOT)]
    env["PYTHONPATH"] = os.pathsep.join([str(tree), *extra])  # e.g. where uvloop is
    tfb = Proc([sys.executable, __file__, "--tfbus-sub", mode], env)
    cpp.wait_for("READY", 30)
    tfb.wait_for("READY", 60)
    cpu0 = (cpu_seconds(cpp.proc.pid), cpu_seconds(tfb.proc.pid))
    pub = master.run(str(bins / "bench_pub"), str(rate), str(frames), str(seconds),
                     *(["moving"] if moving else []))
    m = pub.wait_for(r"sent (\d+) (\d+)", seconds + 60)
    time.sleep(0.2)  # the last message's receipt (a benchmark, not a test)
    c_cpu, t_cpu = (cpu_seconds(p.proc.pid) - c0
                    for p, c0 in zip((cpp, tfb), cpu0, strict=True))  # fmt: skip
    pub.stop()
    sent_msgs, sent_tfs = int(m.group(1)), int(m.group(2))
    c_msgs, c_tfs, c_lat = report(cpp)
    t_msgs, t_tfs, t_lat = report(tfb)
    c50, c99 = statistics.median(c_lat), pct(c_lat, 0.99)
    t50, t99 = statistics.median(t_lat), pct(t_lat, 0.99)
    c_cpu, t_cpu = c_cpu / max(c_msgs, 1), t_cpu / max(t_msgs, 1)
    if cpu is not None:
        cpu.append((c_cpu, t_cpu))
    load = os.getloadavg()[0]
    label = f"{mode}, moving" if moving else mode
    if tree != ROOT:
        label += " @ baseline"
    if env.get(UVLOOP_ENV) == "1":
        label += " @ uvloop"
    side = "floor" if mode == "floor" else "tfbus"  # the Python side's name
    print(
        f"{rate:5.0f} Hz x {frames:3d} frames x {seconds:4.0f} s | {label:8s} | "
        f"load {load:4.2f} | "
        f"C++ {c50:7.1f} / {c99:7.1f} us | {side} {t50:7.1f} / {t99:7.1f} us | "
        f"ratio {t50 / c50:4.2f} / {t99 / c99:4.2f} | "
        f"CPU/msg C++ {c_cpu * 1e6:6.1f} us, {side} {t_cpu * 1e6:6.1f} us, "
        f"ratio {t_cpu / max(c_cpu, 1e-9):4.2f} | "
        f"received C++ {c_msgs}/{sent_msgs} msgs {c_tfs}/{sent_tfs} tfs, "
        f"{side} {t_msgs}/{sent_msgs} msgs {t_tfs}/{sent_tfs} tfs "
        f"({t_tfs / seconds:,.0f} transforms/s)",
        flush=True,
    )
    return c50, c99, t50, t99, t_msgs == sent_msgs and t_tfs == sent_tfs


def repeated(
    master: Master, bins: Path, rate: float, frames: int, seconds: float, repeat: int,
    mode: str = "queue", moving: bool = False, baseline: Path | None = None,
) -> None:
    """``repeat`` runs of one scenario, then the medians of their figures; with a
    ``baseline`` checkout, each run is followed by one whose tfbus side imports that
    checkout's tfbus (alternated, same master), and the CPU medians of both are printed."""
    cpu: list[tuple[float, float]] = []
    base_cpu: list[tuple[float, float]] = []
    runs = []
    for _ in range(repeat):
        runs.append(scenario(master, bins, rate, frames, seconds, mode, moving, cpu))
        if baseline is not None:
            scenario(master, bins, rate, frames, seconds, mode, moving, base_cpu, baseline)
    label = f"{mode}, moving" if moving else mode
    side = "floor" if mode == "floor" else "tfbus"  # the Python side's name
    for name, got in ((side, cpu), ("tfbus @ baseline", base_cpu)):
        if got:
            per = [t / c for c, t in got]
            print(f"  CPU per message, {label}: {name} / C++ min {min(per):.2f} median "
                  f"{statistics.median(per):.2f} max {max(per):.2f} ({len(got)} runs; "
                  f"{name} median {statistics.median(t for _, t in got) * 1e6:.1f} us, C++ "
                  f"{statistics.median(c for c, _ in got) * 1e6:.1f} us)", flush=True)  # fmt: skip
    if repeat < 2:
        return
    c50, c99, t50, t99 = (statistics.median(r[i] for r in runs) for i in range(4))
    ratio = statistics.median(r[2] / r[0] for r in runs)
    ratio99 = statistics.median(r[3] / r[1] for r in runs)
    print(
        f"{rate:5.0f} Hz x {frames:3d} frames x {seconds:4.0f} s | {label:8s} | "
        f"median of {repeat} runs | "
        f"C++ {c50:7.1f} / {c99:7.1f} us | {side} {t50:7.1f} / {t99:7.1f} us | "
        f"ratio {ratio:4.2f} / {ratio99:4.2f} (median of per-run ratios) | "
        f"runs with every transform received: {sum(r[4] for r in runs)}/{repeat}",
        flush=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs")
    parser.add_argument("--repeat", type=int, default=1, help="runs per scenario (default 1)")
    parser.add_argument(
        "--modes",
        default=",".join(MODES),
        help="how the 50-frame scenario is received, comma separated (default: all; "
        "queue = the receive-latency target's row; the 1-frame scenario is always queue)",
    )
    parser.add_argument("--baseline", metavar="TREE", default=None,
                        help="alternate each run with one whose tfbus side imports the tfbus "
                             "of another checkout (e.g. a scratch worktree of an earlier "
                             "commit, its .so files built); prints both CPU medians")  # fmt: skip
    parser.add_argument("--uvloop", action="store_true",
                        help="run the tfbus side's asyncio loop on uvloop (anyio's use_uvloop; "
                             "pip install uvloop)")  # fmt: skip
    parser.add_argument("--skip-one-frame", action="store_true",
                        help="only the 50-frame scenarios")
    parser.add_argument("--tfbus-sub", choices=MODES, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.tfbus_sub == "floor":
        floor_subscriber()
        return
    if args.tfbus_sub:
        tfbus_subscriber(args.tfbus_sub)
        return
    modes = [m for m in args.modes.split(",") if m]
    bad = [m for m in modes if m not in MODES]
    if bad or not modes:
        parser.error(f"--modes: {bad or modes!r}: choose from {', '.join(MODES)}")
    why = ros1_missing(BENCH_PACKAGES)
    if why is not None:
        sys.exit(f"ROS 1 unavailable: {why}")
    with tempfile.TemporaryDirectory() as tmp:
        bins = Path(tmp)
        build(bins)
        master = start_master(bins / "ros_home")
        if args.uvloop:
            master.env[UVLOOP_ENV] = "1"
        try:
            print("latency median / p99, one-way, receive time - header.stamp (same run)")
            base = None if args.baseline is None else Path(args.baseline).resolve()
            if not args.skip_one_frame:
                repeated(master, bins, 100.0, 1, 5.0 if args.quick else 10.0, args.repeat,
                         baseline=base)  # fmt: skip
            for mode in modes:
                repeated(master, bins, 100.0, 50, 10.0 if args.quick else 60.0, args.repeat,
                         mode, baseline=base)  # fmt: skip
            if "queue" in modes:  # the same, every value changing in every message
                repeated(master, bins, 100.0, 50, 10.0 if args.quick else 60.0, args.repeat,
                         "queue", moving=True, baseline=base)  # fmt: skip
        finally:
            master.stop()


if __name__ == "__main__":
    main()
