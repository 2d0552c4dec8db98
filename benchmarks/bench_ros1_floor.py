"""ROS 1 receive floor: the CPU per TCPROS ``TFMessage`` of bare receivers of one live
stream, beside a C++ roscpp subscriber of the same stream, same run.

A C++ roscpp publisher (``peers/ros1/bench_pub.cpp``) sends ``/tf`` (50 transforms, about
5 kB a message, 100 Hz by default). Every receiver below runs at once, in its own process,
connected to that publisher; the CPU time of each (its threads' scheduler run time in ns,
``/proc/PID/task/*/schedstat``: ``benchmarks/proc_cpu.py``) is read over the same windows
(``--rounds`` windows of ``--seconds``) and divided by the messages sent in the window.
Each window also gives each receiver's ratio to roscpp in that window (the machine's load
moves all of them together); min / median / max are printed.

Receivers (``--receivers``, comma separated; roscpp always runs):

* ``asyncio`` -- an :class:`asyncio.BufferedProtocol`: the loop's read callback splits
  frames (:class:`~tfbus.transports.ros1.tcpros.FrameSplitter`) and decodes each with the
  codec's compiled decoder: the floor of tfbus's receive design on asyncio.
* ``thread`` -- the same split and decode in a thread blocked in ``socket.recv_into``
  (roscpp's design: a poll thread reads, ``Connection::readTransport``); the event loop
  beside it idles.
* ``thread+wake`` -- ``thread``, plus one ``loop.call_soon_threadsafe`` a message: what a
  reader thread pays to run anything on the event loop (a callback subscription's thread).
* ``asyncio+store``, ``thread+store`` -- ``asyncio`` / ``thread`` with each message's
  transforms stored in a :class:`~tfbus.Buffer` (``set_transforms``), no loop wake-up;
  ``asyncio+core`` the same into a :class:`~tfbus.BufferCore`.
* ``callback`` -- a tfbus node (``Bus(transport=Ros1Transport())``) with one callback
  subscription on ``/tf`` (``bench_ros1.py``'s ``callback`` row).
* ``listener`` -- a tfbus node with a :class:`~tfbus.TransformListener` into a ``Buffer``.

A receiver's name followed by ``@uvloop`` (e.g. ``callback@uvloop``) runs its event loop
on uvloop (``pip install uvloop``; anyio's ``use_uvloop``) instead of asyncio's own;
``callback@trio`` and ``listener@trio`` run the tfbus node on trio. A tfbus node's name
followed by ``#S`` (e.g. ``listener#30``) checks the master every S seconds
(``Ros1Transport(master_check_period=S)``; default the transport's 5 s: one ``lookupNode``
call to the master, whose CPU is part of each message's share at 100 Hz).
``tf2_ros`` (the C++ ``tf2_ros::TransformListener`` into a ``tf2_ros::Buffer``,
``peers/ros1/bench_listener.cpp``) is printed beside roscpp, the ``listener`` row's peer.

Every Python receiver imports tfbus, its ROS 1 transport and ``Buffer`` first (a
tfbus-sized process: cache misses per wake-up grow with the process, not with the work).
Figures only; nothing is asserted. Needs Debian's ROS 1 (``scripts/install/install_ros1.sh``)
and g++. Everything on 127.0.0.1.

    .venv/bin/python benchmarks/bench_ros1_floor.py                  # 3 windows of 12 s
    .venv/bin/python benchmarks/bench_ros1_floor.py --receivers asyncio,thread,thread+wake
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import dataclasses
import os
import socket
import statistics
import sys
import tempfile
import threading
import time
import xmlrpc.client
from collections.abc import Callable
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "peers" / "ros1"))

from proc_cpu import cpu_seconds  # noqa: E402
from ros1_peers import Proc, ros1_missing, start_master  # noqa: E402

RECEIVERS = (
    "asyncio", "thread", "thread+wake", "asyncio+store", "asyncio+core", "thread+store",
    "callback", "listener",
)  # fmt: skip
"""Every receiver this benchmark runs (see the module docstring)."""

FRAMES = 50
"""Transforms a message (``bench_pub``'s second argument): about 5 kB a message."""


def _connect(store: bool, core: bool = False) -> tuple[str, int, bytes, Any, Callable[[Any], None]]:
    """Ask ``/bench_pub`` for its TCPROS endpoint (polling the master, bounded); returns
    host, port, our connection header, a frame splitter and its message sink."""
    import tfbus.transports.ros1.transport  # noqa: F401  (a tfbus-sized process)
    from tfbus import Buffer, BufferCore
    from tfbus.codecs import ros1 as ros1_codec
    from tfbus.transports.ros1.tcpros import FrameSplitter, encode_header

    master = xmlrpc.client.ServerProxy(os.environ["ROS_MASTER_URI"])
    for _ in range(1200):  # 60 s
        code, _, uri = master.lookupNode("/floor", "/bench_pub")
        if code == 1:
            break
        time.sleep(0.05)
    else:
        raise SystemExit("no /bench_pub within 60 s")
    _, _, (_, host, port) = xmlrpc.client.ServerProxy(uri).requestTopic(
        "/floor", "/tf", [["TCPROS"]]
    )
    hello = encode_header({
        "callerid": f"/floor_{os.getpid()}", "topic": "/tf", "md5sum": ros1_codec.TF_MD5SUM,
        "type": "tf2_msgs/TFMessage", "tcp_nodelay": "1",
    })  # fmt: skip
    decode = ros1_codec._compiled_ros1 or ros1_codec.TFCodec().decode
    store_into = (BufferCore() if core else Buffer()).set_transforms
    header_seen = [False]

    def sink(raw: Any) -> None:
        if not header_seen[0]:  # the publisher's connection header
            header_seen[0] = True
            return
        RECEIVED[0] += 1
        transforms = decode(raw)
        if store:
            store_into(iter(transforms), "/bench_pub", False)

    splitter = FrameSplitter(sink, 1 << 20, 1 << 24)
    return host, port, hello, splitter, sink


class SplitReader(asyncio.BufferedProtocol):
    """asyncio's read callback feeding a TCPROS ``FrameSplitter``: each read lands in one
    64 KiB buffer and is fed as a view of it (a frame inside one read is not copied);
    ``ended``, when given, is done once the connection is lost."""

    def __init__(self, splitter: Any, ended: asyncio.Future[None] | None = None) -> None:
        self.view = memoryview(bytearray(65536))
        self.splitter = splitter
        self.ended = ended

    def get_buffer(self, sizehint: int) -> memoryview:
        return self.view

    def buffer_updated(self, nbytes: int) -> None:
        self.splitter.feed(self.view[:nbytes])

    def connection_lost(self, exc: Exception | None) -> None:
        if self.ended is not None and not self.ended.done():
            self.ended.set_result(None)


def bare_asyncio(store: bool, core: bool = False) -> None:
    """The ``asyncio``, ``asyncio+store`` and ``asyncio+core`` receivers (a child process)."""
    host, port, hello, splitter, _ = _connect(store or core, core)

    async def main() -> None:
        loop = asyncio.get_running_loop()
        ended: asyncio.Future[None] = loop.create_future()
        transport, _ = await loop.create_connection(
            lambda: SplitReader(splitter, ended), host, port)
        transport.get_extra_info("socket").setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        transport.write(hello)
        print("READY", flush=True)
        await ended

    run_loop(main())


def run_loop(main: Any) -> None:
    """``asyncio.run(main)``, on uvloop in a child whose receiver name ends ``@uvloop``."""
    if UVLOOP:
        import uvloop

        uvloop.run(main)
    else:
        asyncio.run(main)


RECEIVED = [0]
"""Messages a child received (its sink or callback counts them)."""

COUNT: list[Callable[[], int]] = [lambda: RECEIVED[0]]
"""What a child's reporter thread prints every 0.5 s (``COUNT n``): messages received."""


def report_count() -> None:
    """Start the child's reporter thread (``COUNT n`` lines, read by the parent)."""

    def run() -> None:
        while True:
            print(f"COUNT {COUNT[0]()}", flush=True)
            time.sleep(0.5)

    threading.Thread(target=run, daemon=True).start()


UVLOOP = False
"""Set in a child whose receiver ends ``@uvloop``."""

CHECK_PERIOD: float | None = None
"""``Ros1Transport(master_check_period=...)`` of a tfbus-node receiver: a name ending
``#S`` (e.g. ``callback#30``) sets S seconds; None (no ``#S``) keeps the transport's
default (one ``lookupNode`` call to the master every 5 s)."""

TRIO = False
"""Set in a child whose receiver ends ``@trio`` (``callback`` and ``listener`` only)."""


def bare_thread(store: bool, wake: bool) -> None:
    """The ``thread``, ``thread+store`` and ``thread+wake`` receivers (a child process)."""
    host, port, hello, splitter, sink = _connect(store)
    sock = socket.create_connection((host, port), timeout=30)
    sock.settimeout(None)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    sock.sendall(hello)

    def read() -> None:
        buf = bytearray(65536)
        view = memoryview(buf)
        while n := sock.recv_into(buf):
            splitter.feed(view[:n])

    async def main() -> None:
        if wake:
            call = asyncio.get_running_loop().call_soon_threadsafe

            def nothing() -> None:
                return None

            def sink_and_wake(raw: Any) -> None:
                sink(raw)
                call(nothing)

            splitter.sink = sink_and_wake
        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        print("READY", flush=True)
        while reader.is_alive():  # the loop idles beside the reader
            await asyncio.sleep(0.5)

    asyncio.run(main())


def tfbus_node(receiver: str) -> None:
    """The ``callback`` and ``listener`` receivers: a tfbus node (a child process)."""
    import anyio

    from tfbus import Buffer, Bus, TransformListener
    from tfbus.transports.ros1 import Ros1Transport

    def record(msg: object) -> None:
        RECEIVED[0] += 1

    async def main() -> None:
        node = (Ros1Transport(node_name=f"/floor_{os.getpid()}") if CHECK_PERIOD is None
                else Ros1Transport(node_name=f"/floor_{os.getpid()}",
                                   master_check_period=CHECK_PERIOD))
        async with Bus(transport=node) as bus, contextlib.AsyncExitStack() as stack:
            if receiver == "listener":
                listener = TransformListener(Buffer(), bus)
                await stack.enter_async_context(listener)
                COUNT[0] = lambda: listener.statistics().stored // FRAMES
            else:
                stack.enter_context(bus.subscribe_callback("/tf", record))
            print("READY", flush=True)
            await anyio.sleep(3600)

    if TRIO:
        anyio.run(main, backend="trio")
    else:
        anyio.run(main, backend_options={"use_uvloop": UVLOOP})


def last_count(proc: Proc, before: int) -> int:
    """The last ``COUNT n`` a child printed (``before`` if none since the last call)."""
    counts = [line for line in proc.drain() if line.startswith("COUNT ")]
    proc.seen.clear()
    return int(counts[-1].split()[1]) if counts else before


def child(receiver: str) -> None:
    global UVLOOP, TRIO, CHECK_PERIOD
    receiver, _, period = receiver.partition("#")
    CHECK_PERIOD = float(period) if period else None
    receiver, _, loop = receiver.partition("@")
    UVLOOP, TRIO = loop == "uvloop", loop == "trio"
    report_count()
    if receiver in ("asyncio", "asyncio+store", "asyncio+core"):
        bare_asyncio(receiver.endswith("+store"), receiver.endswith("+core"))
    elif receiver in ("thread", "thread+store", "thread+wake"):
        bare_thread(receiver.endswith("+store"), receiver.endswith("+wake"))
    else:
        tfbus_node(receiver)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--receivers",
        default=",".join(RECEIVERS),
        help=f"comma separated, from {', '.join(RECEIVERS)} (default: all)",
    )
    parser.add_argument("--rounds", type=int, default=3, help="windows (default 3)")
    parser.add_argument(
        "--seconds",
        type=float,
        default=12.0,
        help="seconds a window (default 12; /proc counts 10 ms ticks)",
    )
    parser.add_argument("--rate", type=float, default=100.0, help="messages/s (default 100)")
    parser.add_argument("--baseline", metavar="TREE", default=None,
                        help="also run each callback/listener receiver on the tfbus of another "
                             "checkout (its .so files built), labelled '@ baseline'")  # fmt: skip
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child)
        return
    receivers = [r for r in args.receivers.split(",") if r]
    bad = [
        r for r in receivers
        if r.partition("#")[0].removesuffix("@uvloop") not in RECEIVERS
        and r.partition("#")[0] not in ("callback@trio", "listener@trio")
    ]  # fmt: skip
    if bad or not receivers:
        parser.error(f"--receivers: {bad or receivers!r}: choose from {', '.join(RECEIVERS)}")
    why = ros1_missing(("roscpp", "tf2_msgs"))
    if why is not None:
        sys.exit(f"ROS 1 unavailable: {why}")
    result = measure(receivers, args.rounds, args.seconds, args.rate, args.baseline)
    per_msg = result.per_msg
    print(f"{args.rate:.0f} Hz x {FRAMES} transforms, {args.rounds} windows of "
          f"{args.seconds:.0f} s, load {result.load:.2f} (1 min)")  # fmt: skip
    print("receiver                   | CPU/msg us min / median / max | ratio to roscpp, "
          "to tf2_ros min / median / max")  # fmt: skip

    def ratios(values: list[float], ref: str) -> str:
        r = result.ratios(values, ref)
        return f"{min(r):4.2f} / {statistics.median(r):4.2f} / {max(r):4.2f}"

    for name, values in per_msg.items():
        print(f"{name:26s} | {min(values):6.1f} / {statistics.median(values):6.1f} / "
              f"{max(values):6.1f} | {ratios(values, 'roscpp')} | "
              f"{ratios(values, 'tf2_ros')}", flush=True)  # fmt: skip
    received = ", ".join(f"{r} {n}" for r, n in result.received.items())
    print(f"messages received in the windows (0.5 s steps) of ~{result.sent:.0f} sent: "
          f"{received}")


@dataclasses.dataclass
class Measured:
    """What :func:`measure` found: per receiver (``roscpp``, ``tf2_ros`` and each Python
    receiver), its CPU per message in each window (microseconds); messages received by
    each Python receiver in the windows, of ``sent``; the 1-minute load at the end."""

    per_msg: dict[str, list[float]]
    received: dict[str, int]
    sent: float
    load: float

    def ratios(self, values: list[float], ref: str) -> list[float]:
        """``values`` over receiver ``ref``'s, window by window."""
        return [v / max(c, 1e-9) for v, c in zip(values, self.per_msg[ref], strict=True)]


def measure(receivers: list[str], rounds: int, seconds: float, rate: float = 100.0,
            baseline: str | None = None) -> Measured:
    """Run roscpp, tf2_ros's C++ listener and every receiver of ``receivers`` (each in its
    own process) on one C++ publisher's ``/tf`` (``FRAMES`` transforms a message at
    ``rate``), wait 3 s (every receiver connected and past its first messages), then read
    each one's CPU over ``rounds`` windows of ``seconds``. ``baseline``: also run each
    callback/listener receiver on the tfbus of that checkout, labelled ``@ baseline``.
    Needs Debian's ROS 1 and g++."""
    import bench_ros1

    with tempfile.TemporaryDirectory() as tmp:
        bins = Path(tmp)
        bench_ros1.build(bins)
        master = start_master(bins / "ros_home")
        procs: list[Proc] = []
        try:
            path = [str(ROOT), *os.environ.get("PYTHONPATH", "").split(os.pathsep)]
            env = {**master.env, "PYTHONPATH": os.pathsep.join(p for p in path if p)}
            cpp = master.run(str(bins / "bench_sub"))
            procs.append(cpp)
            cpp.wait_for("READY", 30)
            tf2 = master.run(str(bins / "bench_listener"), str(FRAMES))
            procs.append(tf2)
            tf2.wait_for("READY", 30)
            total = rounds * seconds + 20
            procs.append(master.run(str(bins / "bench_pub"), str(rate), str(FRAMES),
                                    str(total)))  # fmt: skip
            pids = {"roscpp": cpp.proc.pid, "tf2_ros": tf2.proc.pid}
            children: dict[str, Proc] = {}
            runs = [(r, r, env) for r in receivers]
            if baseline is not None:
                base = str(Path(baseline).resolve())
                base_env = {**env, "PYTHONPATH": os.pathsep.join([base, *path[1:]])}
                runs += [(f"{r} @ baseline", r, base_env) for r in receivers
                         if r.partition("@")[0] in ("callback", "listener")]  # fmt: skip
            for r, what, run_env in runs:
                proc = Proc([sys.executable, __file__, "--child", what], run_env)
                procs.append(proc)
                proc.wait_for("READY", 60)
                pids[r] = proc.proc.pid
                children[r] = proc
            got = dict.fromkeys(children, 0)
            n1 = dict.fromkeys(children, 0)
            sent = 0.0
            time.sleep(3.0)  # every receiver connected and past its first messages
            per_msg: dict[str, list[float]] = {name: [] for name in pids}
            for _ in range(rounds):
                before = {name: cpu_seconds(pid) for name, pid in pids.items()}
                t0 = time.monotonic()
                n0 = {r: last_count(p, n1[r]) for r, p in children.items()}
                time.sleep(seconds)
                messages = (time.monotonic() - t0) * rate
                for r, p in children.items():
                    n1[r] = last_count(p, n0[r])
                    got[r] += n1[r] - n0[r]
                sent += messages
                for name, pid in pids.items():
                    per_msg[name].append((cpu_seconds(pid) - before[name]) / messages * 1e6)
            return Measured(per_msg, got, sent, os.getloadavg()[0])
        finally:
            for proc in reversed(procs):
                proc.stop()
            master.stop()

if __name__ == "__main__":
    main()
