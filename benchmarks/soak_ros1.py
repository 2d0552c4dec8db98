"""ROS 1 soak under attack: a tfbus publisher process sends ``--rate`` Hz x
``--frames`` transforms for ``--seconds`` s through a real roscore to a tfbus subscriber
node that is attacked meanwhile, and every transform must arrive.

The attacks, all from this process on 127.0.0.1: three hostile "publishers" registered
with the master on ``/tf`` (one answers ``requestTopic`` with port 70000, one with
non-XML, one offers a TCPROS server that sends a valid header then a garbage frame), and
``--idle`` idle connections held open against the subscriber's TCPROS port and slave API
(re-opened whenever the node drops them after its header/request deadline).

Prints sent / received / lost transforms, the subscriber's counters and the reconnects
of the idle connections; exits 1 if anything was lost or the node died. Needs Debian's
ROS 1 (``scripts/install/install_ros1.sh``).

    .venv/bin/python benchmarks/soak_ros1.py                       # 60 s, asyncio
    .venv/bin/python benchmarks/soak_ros1.py --backend trio --seconds 10
"""

from __future__ import annotations

import argparse
import os
import selectors
import socket
import struct
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "peers" / "ros1"))  # the ROS 1 peers (no pytest)

from ros1_hostile import HostilePeer, http_answer, send_raw, tcpros_answer  # noqa: E402
from ros1_peers import Master, Proc, ros1_missing, start_master  # noqa: E402

_T0 = 1_000_000_000


def publisher(args: argparse.Namespace) -> None:
    """The sending side (a child process): wait for one subscriber connection on /tf,
    print READY, send on an absolute schedule, let queues drain, print SENT."""
    import anyio

    from tfbus import (
        Bus,
        Header,
        Quaternion,
        Time,
        Transform,
        TransformBroadcaster,
        TransformStamped,
        Vector3,
    )
    from tfbus.transports.ros1 import Ros1Transport

    async def main() -> None:
        t = Ros1Transport(master_uri=args.master, node_name="/soak_pub")
        async with Bus(transport=t) as bus:
            bc = TransformBroadcaster(bus)  # advertises /tf now
            with anyio.fail_after(60):
                while not any(c[2] == "o" and c[4] == "/tf" for c in t.bus_info()):
                    await anyio.sleep(0.02)
            print("READY", flush=True)
            period = 1.0 / args.rate
            n = int(args.seconds * args.rate)
            start = anyio.current_time()
            for k in range(n):
                stamp = Time.from_ns(_T0 + k * 1_000_000)
                bc.send_transform_nowait(
                    [
                        TransformStamped(
                            Header(stamp, "map"),
                            f"f{j}",
                            Transform(Vector3(k, j, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)),
                        )
                        for j in range(args.frames)
                    ]
                )
                await anyio.sleep_until(start + (k + 1) * period)
            await anyio.sleep(1.0)
            s = t.statistics()
            print(f"SENT {n} {n * args.frames} {s.sent} {s.send_dropped}", flush=True)

    anyio.run(main, backend=args.backend)


class _Idle(threading.Thread):
    """``count`` idle connections to the given ports, re-opened when dropped."""

    def __init__(self, ports: list[int], count: int) -> None:
        super().__init__(daemon=True)
        self.ports = ports
        self.count = count
        self.stop = threading.Event()
        self.reopened = 0
        self.failed = 0

    def _open(self, sel: selectors.BaseSelector, port: int) -> None:
        s = socket.socket()
        try:
            s.connect(("127.0.0.1", port))
        except OSError:
            self.failed += 1
            s.close()
            return
        sel.register(s, selectors.EVENT_READ, port)

    def run(self) -> None:
        sel = selectors.DefaultSelector()
        for i in range(self.count):
            self._open(sel, self.ports[i % len(self.ports)])
        deadline = time.monotonic() + 3600
        while not self.stop.is_set() and time.monotonic() < deadline:
            for key, _ in sel.select(timeout=0.1):
                sock: socket.socket = key.fileobj  # type: ignore[assignment]
                try:
                    data = sock.recv(65536)
                except OSError:
                    data = b""
                if not data:  # dropped by the node: attach again
                    sel.unregister(sock)
                    sock.close()
                    self.reopened += 1
                    self._open(sel, key.data)
        for key in list(sel.get_map().values()):
            key.fileobj.close()  # type: ignore[union-attr]


def _garbage_tcpros(stop: threading.Event) -> int:
    """A TCPROS server: a valid /tf header, then a frame claiming 2**32-1 transforms."""
    from tfbus.transports.ros1 import TF_MD5SUM, encode_header

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(16)
    srv.settimeout(0.2)

    def serve() -> None:
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except OSError:
                continue
            with conn:
                try:
                    conn.settimeout(2.0)
                    conn.recv(65536)
                    conn.sendall(
                        encode_header({"callerid": "/garbage", "md5sum": TF_MD5SUM, "topic": "/tf"})
                        + struct.pack("<I", 7)
                        + b"\xff" * 7
                    )
                except OSError:
                    pass
        srv.close()

    threading.Thread(target=serve, daemon=True).start()
    return int(srv.getsockname()[1])


def subscriber(args: argparse.Namespace, master: Master) -> int:
    import anyio

    from tfbus import Bus, TFMessage
    from tfbus.transports.ros1 import Ros1Transport

    stop = threading.Event()
    garbage_port = _garbage_tcpros(stop)
    peers = [
        HostilePeer(send_raw(http_answer(tcpros_answer("<int>70000</int>")))),
        HostilePeer(send_raw(http_answer(b"<<<not xml"))),
        HostilePeer(send_raw(http_answer(tcpros_answer(f"<int>{garbage_port}</int>")))),
    ]
    for i, peer in enumerate(peers):
        peer.start()
        master.call("registerPublisher", f"/hostile{i}", "/tf", "tf2_msgs/TFMessage", peer.uri)

    seen: set[int] = set()
    counts = {"messages": 0, "transforms": 0, "duplicates": 0}

    def on_tf(message: TFMessage) -> None:
        counts["messages"] += 1
        counts["transforms"] += len(message.transforms)
        k = message.transforms[0].header.stamp.ns if message.transforms else -1
        if k in seen:
            counts["duplicates"] += 1
        seen.add(k)

    result: dict[str, object] = {}

    async def main() -> None:
        t = Ros1Transport(master_uri=master.uri, node_name="/soak_sub")
        async with Bus(transport=t) as bus:
            bus.subscribe_callback("/tf", on_tf)
            api_port = int(t.uri.rsplit(":", 1)[1].strip("/"))
            idle = _Idle([t._tcp_port, api_port], args.idle)
            idle.start()
            env = dict(master.env)
            env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
            cmd = [sys.executable, str(Path(__file__).resolve()), "--role", "pub"]
            cmd += ["--master", master.uri, "--seconds", str(args.seconds)]
            cmd += ["--rate", str(args.rate), "--frames", str(args.frames)]
            pub = Proc([*cmd, "--backend", args.backend], env)
            try:
                await anyio.to_thread.run_sync(lambda: pub.wait_for("^READY$", 90.0))
                m = await anyio.to_thread.run_sync(
                    lambda: pub.wait_for(r"^SENT (\d+) (\d+) (\d+) (\d+)$", args.seconds + 120)
                )
                sent_msgs, sent_tf = int(m[1]), int(m[2])
                with anyio.move_on_after(10):
                    while counts["transforms"] < sent_tf:
                        await anyio.sleep(0.05)
                result.update(sent=sent_tf, sent_msgs=sent_msgs, stats=t.statistics())
                result.update(pub_sent=int(m[3]), pub_dropped=int(m[4]))
            finally:
                pub.stop()
                idle.stop.set()
                idle.join(5)
            result.update(reopened=idle.reopened, idle_failed=idle.failed)

    try:
        anyio.run(main, backend=args.backend)
    finally:
        stop.set()
        for peer in peers:
            peer.close()
    sent = int(result["sent"])  # type: ignore[call-overload]
    got = counts["transforms"]
    print(
        f"backend {args.backend}: {args.rate} Hz x {args.frames} transforms x {args.seconds} s"
        f" with 3 hostile publishers and {args.idle} idle connections"
    )
    print(
        f"  sent {sent} transforms ({result['sent_msgs']} messages), received {got}, "
        f"lost {sent - got}, duplicates {counts['duplicates']}; publisher queue drops "
        f"{result['pub_dropped']}"
    )
    print(f"  idle connections dropped by the node and re-attached: {result['reopened']}")
    print(f"  subscriber counters: {result['stats']}")
    return 0 if got == sent and counts["duplicates"] == 0 else 1


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--rate", type=float, default=100.0)
    p.add_argument("--frames", type=int, default=50)
    p.add_argument("--idle", type=int, default=50)
    p.add_argument("--backend", choices=["asyncio", "trio"], default="asyncio")
    p.add_argument("--role", choices=["sub", "pub"], default="sub", help=argparse.SUPPRESS)
    p.add_argument("--master", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.role == "pub":
        publisher(args)
        return
    why = ros1_missing()
    if why is not None:
        sys.exit(f"ROS 1 is needed: {why}")
    with tempfile.TemporaryDirectory() as tmp:
        master = start_master(Path(tmp) / "ros_home")
        try:
            code = subscriber(args, master)
        finally:
            master.stop()
    sys.exit(code)


if __name__ == "__main__":
    main()
