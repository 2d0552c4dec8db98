"""Servers soak: a Zenoh graph at ``--rate`` Hz x ``--frames`` transforms for ``--seconds``
s with ``tfbus monitor``, ``tfbus view --bus`` and ``tfbus serve-buffer`` attached, and
lookup clients coming and going, some of them badly behaved.

Everything runs on 127.0.0.1 through one ``tfbus router`` (multicast scouting off), with
``congestion_control=block`` (Zenoh never drops ``/tf``; a drop would be tfbus's own,
counted):

* a broadcaster process (this file, ``--role pub``) sends ``--frames`` dynamic transforms
  at ``--rate`` Hz on an absolute schedule, plus one static, and prints how many it sent;
* a counting listener (``--role sub``) counts the distinct transforms it received on /tf
  (per child frame, each stamp newer than the last) and prints how many;
* ``tfbus monitor``, ``tfbus view --bus`` (its page served, no browser) and
  ``tfbus serve-buffer`` run the whole time;
* every ``--client-period`` s a new client process (``--role client``) opens a session,
  asks serve-buffer a lookup that is answered, one for a frame that never comes with no
  timeout (cancelled after 1 s by the client), one with a 2 KB frame name, then leaves;
* ``tfbus web --bus`` serves rosbridge clients: one well-behaved client stays subscribed
  to ``/tf`` the whole time (it must get messages in every 10 s window), while short
  clients join, subscribe and leave at random: a close handshake, an aborted connection,
  a half-open one, one that never reads, garbage (bad JSON, a binary frame, unknown ops),
  a service call left behind;
* ``tfbus view``'s page is fetched every 5 s by a well-behaved client, while others ask
  unknown paths, send half a request and hold it, or open a websocket and abort it;
* a fleet listener (``--role fleet``: a FleetBuffer on ``namespace=*``, ``max_robots``
  20) follows a robot that stays (``keeper``, asked a lookup every 2 s) while robots
  with ever new names come (``--role robot``, each its own namespace and process), send
  for a moment and leave, by SIGINT or SIGKILL: the fleet fills and makes room.

The resident memory (VmRSS) of every long-lived process is read after ``--warmup`` s and
at the end; the soak passes when none grew by more than ``--max-growth-mb`` MB, no valid
transform was lost, every answered lookup was right, and every process was still alive.
Prints one line per process and a verdict; exits 1 on a failure. Not a test (it runs for
minutes): ``benchmarks/results/soak_servers.txt`` keeps the last full run's output.

    .venv/bin/python benchmarks/soak_servers.py                      # 30 min, as measured
    .venv/bin/python benchmarks/soak_servers.py --seconds 600 --warmup 300 --max-growth-mb 5
    .venv/bin/python benchmarks/soak_servers.py --seconds 60 --warmup 20
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
TFBUS = [sys.executable, "-m", "tfbus.cli"]
_T0 = 1_000_000_000


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _client_spec(port: int) -> str:
    # congestion_control=block: Zenoh never drops /tf (tfbus's send queue would count it).
    return f"zenoh:mode=client&connect=tcp/127.0.0.1:{port}&congestion_control=block"


async def _until_signal() -> None:
    """Return at the first SIGINT or SIGTERM."""
    import anyio

    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for _ in signals:
            return


async def _cancel_on_signal(scope: Any) -> None:
    """Cancel ``scope`` (a task group's cancel scope) at the first SIGINT or SIGTERM."""
    await _until_signal()
    scope.cancel()


def publisher(args: argparse.Namespace) -> None:
    """Send on an absolute schedule until SIGINT; print SENT <transforms>."""
    import anyio

    from tfbus import (
        Header,
        Quaternion,
        StaticTransformBroadcaster,
        Time,
        Transform,
        TransformBroadcaster,
        TransformStamped,
        Vector3,
    )
    from tfbus.transports.spec import open_bus

    async def main() -> None:
        sent = 0
        async with open_bus(args.bus) as bus:
            await StaticTransformBroadcaster(bus).send_transform(TransformStamped(
                Header(Time.from_ns(_T0), "base_link"), "base_laser",
                Transform(Vector3(0.1, 0.0, 0.2), Quaternion())))
            tf = TransformBroadcaster(bus)
            period = 1.0 / args.rate
            start = time.monotonic()
            print("READY", flush=True)
            async with anyio.create_task_group() as tg:
                tg.start_soon(_cancel_on_signal, tg.cancel_scope)
                tick = 0
                while True:
                    stamp = Time.from_ns(_T0 + tick * int(period * 1e9))
                    batch = [TransformStamped(Header(stamp, "odom"), f"frame_{i}",
                                              Transform(Vector3(tick * 1e-3, i, 0.0),
                                                        Quaternion()))
                             for i in range(args.frames)]
                    await tf.send_transform(batch)
                    sent += len(batch)
                    tick += 1
                    await anyio.sleep(max(0.0, start + tick * period - time.monotonic()))
            await anyio.sleep(0.5)  # let the last messages leave
        print(f"SENT {sent}", flush=True)

    anyio.run(main)


def subscriber(args: argparse.Namespace) -> None:
    """Count the distinct transforms of /tf until SIGINT; print RECEIVED <n>."""
    import anyio

    from tfbus.transports.spec import open_bus

    async def main() -> None:
        # Per frame: the newest stamp and how many newer stamps came (one publisher, in
        # order): distinct transforms counted in constant memory; older or equal ones are
        # repeats.
        newest: dict[str, int] = {}
        counted = {"new": 0, "repeats": 0}

        def count(message: Any) -> None:  # called in every delivery: no queue to overflow
            for t in message.transforms:
                if t.child_frame_id.startswith("frame_"):
                    ns = t.header.stamp.ns
                    if ns > newest.get(t.child_frame_id, -1):
                        newest[t.child_frame_id] = ns
                        counted["new"] += 1
                    else:
                        counted["repeats"] += 1

        async with open_bus(args.bus) as bus:
            bus.subscribe_callback("/tf", count)
            print("READY", flush=True)
            await _until_signal()
        print(f"RECEIVED {counted['new']} {counted['repeats']}", flush=True)

    anyio.run(main)


def client(args: argparse.Namespace) -> None:
    """One short-lived lookup client; prints OK or BAD <why>."""
    import anyio

    from tfbus import Time
    from tfbus.remote import BufferClient
    from tfbus.transports.spec import open_bus

    async def main() -> None:
        async with open_bus(args.bus) as bus:
            c = BufferClient(bus)
            t = await c.lookup_transform("base_link", "base_laser", Time(0), timeout=5.0)
            good = abs(t.transform.translation.x - 0.1) < 1e-12
            with anyio.move_on_after(1.0):  # a frame that never comes, no timeout
                await c.lookup_transform("base_link", "never", Time(0), timeout=None)
            try:
                await c.lookup_transform("base_link", "x" * 2048, Time(0), timeout=0.5)
            except Exception as exc:  # refused or timed out: either is an answer
                good = good and type(exc).__name__ != "ExceptionGroup"
        print("OK" if good else f"BAD {t}", flush=True)

    anyio.run(main)


def robot(args: argparse.Namespace) -> None:
    """A robot in its own namespace: map -> base_link at 20 Hz until SIGINT."""
    import anyio

    from tfbus import Header, Quaternion, Time, Transform, TransformBroadcaster, TransformStamped
    from tfbus import Vector3 as V3
    from tfbus.transports.spec import open_bus

    async def main() -> None:
        async with open_bus(f"{args.bus}&namespace={args.name}") as bus:
            tf = TransformBroadcaster(bus)
            print("READY", flush=True)
            async with anyio.create_task_group() as tg:
                tg.start_soon(_cancel_on_signal, tg.cancel_scope)
                while True:
                    now = Time.from_ns(time.time_ns())
                    await tf.send_transform(TransformStamped(
                        Header(now, "map"), "base_link",
                        Transform(V3(1.0, 2.0, 0.0), Quaternion())))
                    await anyio.sleep(0.05)

    anyio.run(main)


def fleet(args: argparse.Namespace) -> None:
    """A fleet listener (max_robots 20); every 2 s a lookup of the keeper robot; at
    SIGINT prints FLEET <answered> <missed> <robots kept> <gone> <evicted> <refused>."""
    import anyio

    from tfbus import Time
    from tfbus.fleet import FleetBuffer
    from tfbus.transports.spec import open_bus

    async def main() -> None:
        answered = missed = 0
        async with open_bus(f"{args.bus}&namespace=*") as bus, \
                FleetBuffer(bus, max_robots=20, forget_after=300.0) as robots:
            await robots.wait_for_robot("keeper", timeout=60)
            print("READY", flush=True)
            async with anyio.create_task_group() as tg:
                tg.start_soon(_cancel_on_signal, tg.cancel_scope)
                while True:
                    await anyio.sleep(2.0)
                    try:
                        t = await robots["keeper"].lookup_transform_async(
                            "map", "base_link", Time(0), timeout=1.0)
                        answered += t.transform.translation.x == 1.0
                    except Exception:
                        missed += 1
            st = robots.statistics()
            print(f"FLEET {answered} {missed} {len(robots)} {st.gone} {st.evicted} "
                  f"{st.robots_refused}", flush=True)

    anyio.run(main)


class WebClient:
    """A blocking rosbridge (websocket) client on 127.0.0.1 (wsproto over a socket)."""

    def __init__(self, port: int, timeout: float = 10.0) -> None:
        from wsproto import ConnectionType, WSConnection
        from wsproto.events import AcceptConnection, Request

        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
        self.ws = WSConnection(ConnectionType.CLIENT)
        self.sock.sendall(self.ws.send(Request(host=f"127.0.0.1:{port}", target="/")))
        self.pending: list[Any] = []
        while not any(isinstance(e, AcceptConnection) for e in self.pending):
            self._read()
        self.pending.clear()

    def _read(self) -> None:
        data = self.sock.recv(65536)
        if not data:
            raise ConnectionError("closed by the server")
        self.ws.receive_data(data)
        self.pending.extend(self.ws.events())

    def send(self, message: dict[str, Any]) -> None:
        import json

        from wsproto.events import TextMessage

        self.sock.sendall(self.ws.send(TextMessage(json.dumps(message))))

    def send_raw(self, event: Any) -> None:
        self.sock.sendall(self.ws.send(event))

    def messages(self, n: int) -> int:
        """Read until ``n`` text messages came (or the socket's timeout); how many."""
        from wsproto.events import TextMessage

        got = 0
        while got < n:
            while self.pending:
                if isinstance(self.pending.pop(0), TextMessage):
                    got += 1
            if got < n:
                self._read()
        return got

    def close_handshake(self) -> None:
        from wsproto.events import CloseConnection

        self.send_raw(CloseConnection(code=1000))
        with contextlib.suppress(OSError, ConnectionError):
            while not any(isinstance(e, CloseConnection) for e in self.pending):
                self._read()
        self.sock.close()

    def abort(self) -> None:
        import struct

        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        self.sock.close()


def web_churn_once(port: int, kind: int) -> None:
    """One short rosbridge client: join, subscribe /tf, read a little, leave in the way
    ``kind`` names (mod 6)."""
    from wsproto.events import BytesMessage, TextMessage

    c = WebClient(port)
    try:
        c.send({"op": "subscribe", "topic": "/tf", "type": "tf2_msgs/TFMessage"})
        c.messages(2)
        way = kind % 6
        if way == 0:
            c.close_handshake()
        elif way == 1:
            c.abort()
        elif way == 2:  # half-open: no more from us, then gone
            c.sock.shutdown(socket.SHUT_WR)
            time.sleep(0.5)
            c.sock.close()
        elif way == 3:  # never reads while /tf flows, then aborts
            time.sleep(2.0)
            c.abort()
        elif way == 4:  # garbage
            c.send_raw(TextMessage("{not json"))
            c.send_raw(BytesMessage(b"\x00\xff" * 100))
            c.send({"op": "no_such_op", "id": 7})
            c.send({"op": "subscribe"})
            c.send({"op": "subscribe", "topic": 5, "throttle_rate": "x"})
            c.messages(1)
            c.close_handshake()
        else:  # a service call, left behind
            c.send({"op": "call_service", "service": "/rosapi/topics", "id": "s1"})
            c.abort()
    except (OSError, ConnectionError):
        c.sock.close()


def view_churn_once(port: int, kind: int) -> bool:
    """One view client: ``kind`` (mod 4) a page fetch, an unknown path, half a request
    held 2 s, a websocket opened then aborted. True when the page answered as it should."""
    import struct

    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        way = kind % 4
        if way == 0:
            sock.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                         "Connection: close\r\n\r\n".encode())
            return sock.recv(64).startswith(b"HTTP/1.1 200")
        if way == 1:
            sock.sendall(f"GET /{'x' * 3000} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                         "Connection: close\r\n\r\n".encode())
            return sock.recv(64).startswith(b"HTTP/1.1 ")
        if way == 2:
            sock.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n".encode())
            time.sleep(2.0)
            return True
        sock.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                     "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                     "Sec-WebSocket-Version: 13\r\n\r\n".encode())
        sock.recv(64)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        return True


class Proc:
    """A child process whose stdout lines are collected by a thread."""

    def __init__(self, name: str, argv: list[str]) -> None:
        self.name = name
        self.lines: list[str] = []
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, cwd=ROOT)
        self.err: list[str] = []
        threading.Thread(target=self._read, args=(self.proc.stdout, self.lines),
                         daemon=True).start()
        threading.Thread(target=self._read, args=(self.proc.stderr, self.err),
                         daemon=True).start()

    @staticmethod
    def _read(stream: object, into: list[str]) -> None:
        for line in stream:  # type: ignore[attr-defined]
            into.append(line.rstrip("\n"))

    def wait_line(self, prefix: str, timeout: float) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in self.lines:
                if line.startswith(prefix):
                    return line
            if self.proc.poll() is not None and not any(
                ln.startswith(prefix) for ln in self.lines
            ):
                break
            time.sleep(0.05)
        raise RuntimeError(f"{self.name}: no '{prefix}' line in {timeout} s; "
                           f"stderr: {self.err[-5:]}")

    def rss_mb(self) -> float:
        for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
        return float("nan")

    def stop(self, sig: int = signal.SIGINT, timeout: float = 30.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        return int(self.proc.returncode)


def run(args: argparse.Namespace) -> int:
    port = _free_port()
    bus = _client_spec(port)
    me = [sys.executable, __file__, "--bus", bus]
    router = Proc("router", [*TFBUS, "router", "--listen", f"tcp/127.0.0.1:{port}"])
    time.sleep(1.0)  # the router binds its port (its clients retry their connection)
    sub = Proc("listener", [*me, "--role", "sub"])
    sub.wait_line("READY", 60)
    view_port = _free_port()
    web_port = _free_port()
    servers = [
        Proc("monitor", [*TFBUS, "monitor", "--bus", bus, "--interval", "10"]),
        Proc("view", [*TFBUS, "view", "--bus", bus, "--port", str(view_port)]),
        Proc("serve-buffer", [*TFBUS, "serve-buffer", "--bus", bus]),
        Proc("web", [*TFBUS, "web", "--bus", bus, "--port", str(web_port)]),
    ]
    keeper = Proc("robot keeper", [*me, "--role", "robot", "--name", "keeper"])
    keeper.wait_line("READY", 60)
    fleet_listener = Proc("fleet", [*me, "--role", "fleet"])
    fleet_listener.wait_line("READY", 60)
    servers.append(fleet_listener)
    pub = Proc("broadcaster", [*me, "--role", "pub", "--rate", str(args.rate),
                               "--frames", str(args.frames)])
    pub.wait_line("READY", 60)
    watched = [router, sub, *servers, pub, keeper]
    stop = threading.Event()
    churn = {"web": 0, "web_failed": 0, "view": 0, "view_bad": 0, "robots": 0}
    windows: list[int] = []  # /tf messages the subscribed web client got per 10 s

    def web_keeper() -> None:
        c = WebClient(web_port, timeout=10.0)
        c.send({"op": "subscribe", "topic": "/tf", "type": "tf2_msgs/TFMessage"})
        while not stop.is_set():  # messages in each 10 s window (0: starved)
            end, got = time.monotonic() + 10.0, 0
            while time.monotonic() < end:
                try:
                    got += c.messages(1)
                except (OSError, ConnectionError):
                    break
            windows.append(got)
        c.close_handshake()

    def web_churner() -> None:
        k = 0
        while not stop.wait(0.5):
            try:
                web_churn_once(web_port, k)
                churn["web"] += 1
            except (OSError, ConnectionError):
                churn["web_failed"] += 1
            k += 1

    def view_churner() -> None:
        k = 0
        while not stop.wait(1.0):
            try:
                good = view_churn_once(view_port, k)
            except OSError:
                good = False
            churn["view"] += 1
            churn["view_bad"] += not good
            k += 1

    def robot_churner() -> None:
        k = 0
        while not stop.wait(3.0):
            r = Proc("robot", [*me, "--role", "robot", "--name", f"churn{k}"])
            with contextlib.suppress(RuntimeError):
                r.wait_line("READY", 60)
            time.sleep(1.0)
            r.stop(signal.SIGINT if k % 2 else signal.SIGKILL)
            churn["robots"] += 1
            k += 1

    threads = [threading.Thread(target=f, daemon=True)
               for f in (web_keeper, web_churner, view_churner, robot_churner)]
    for t in threads:
        t.start()
    start = time.monotonic()
    clients_ok = clients_bad = 0
    rss0: dict[str, float] = {}
    next_client = start + 5.0
    while (now := time.monotonic()) < start + args.seconds:
        if not rss0 and now >= start + args.warmup:
            rss0 = {p.name: p.rss_mb() for p in watched}
        if now >= next_client:
            c = Proc("client", [*me, "--role", "client"])
            with contextlib.suppress(subprocess.TimeoutExpired):
                c.proc.wait(60)
            c.stop()
            time.sleep(0.2)  # its reader threads take the last lines
            if c.lines == ["OK"] and c.proc.returncode == 0:
                clients_ok += 1
            else:
                clients_bad += 1
                print(f"client: {c.lines[-3:]} {c.err[-3:]}", flush=True)
            next_client = time.monotonic() + args.client_period
        dead = [p.name for p in watched if p.proc.poll() is not None]
        if dead:
            print(f"died: {dead}", flush=True)
            break
        time.sleep(0.5)
    rss1 = {p.name: p.rss_mb() for p in watched}
    alive = all(p.proc.poll() is None for p in watched)
    stop.set()
    for t in threads:
        t.join(60)
    pub.stop()
    sent = int(pub.wait_line("SENT", 30).split()[1])
    time.sleep(2.0)  # the listener drains what is in flight
    sub.stop()
    received, repeats = map(int, sub.wait_line("RECEIVED", 30).split()[1:])
    for p in servers:
        p.stop()
    answered_fleet, missed_fleet, kept, gone, evicted, refused = map(
        int, fleet_listener.wait_line("FLEET", 30).split()[1:])
    keeper.stop()
    router.stop()
    traces = [p.name for p in [*servers, router, keeper]
              if any("Traceback" in ln for ln in p.err)]
    print(f"soak: {args.seconds:.0f} s at {args.rate:g} Hz x {args.frames} frames over "
          f"a Zenoh router; {clients_ok + clients_bad} lookup clients")
    growth_ok = True
    for name in rss1:
        before = rss0.get(name, float("nan"))
        grew = rss1[name] - before
        growth_ok &= grew <= args.max_growth_mb
        print(f"  {name:13s} RSS {before:7.1f} MB after {args.warmup:.0f} s -> "
              f"{rss1[name]:7.1f} MB at the end ({grew:+.1f} MB)")
    lost = sent - received
    print(f"  transforms sent {sent}, received {received}, lost {lost} "
          f"(received again or out of order: {repeats})")
    print(f"  lookup clients answered right {clients_ok}, wrong or unanswered {clients_bad}")
    starved = sum(1 for n in windows[:-1] if n == 0)  # the last window is cut short
    print(f"  tfbus web: {churn['web']} short clients came and went ({churn['web_failed']} "
          f"could not connect); the subscribed client got /tf in {len(windows) - starved} "
          f"of {len(windows)} 10 s windows (min {min(windows[:-1] or [0])} messages)")
    print(f"  tfbus view: {churn['view']} clients, {churn['view_bad']} answered wrong")
    print(f"  fleet: {churn['robots']} robots came and went (gone {gone}, evicted {evicted}, "
          f"refused {refused}, kept {kept}); the keeper's lookups answered {answered_fleet}, "
          f"missed {missed_fleet}")
    print(f"  tracebacks on stderr: {traces or 'none'}")
    ok = (alive and growth_ok and lost == 0 and clients_bad == 0 and not traces
          and starved == 0 and churn["web_failed"] == 0 and churn["view_bad"] == 0
          and missed_fleet == 0 and answered_fleet > 0 and refused == 0)
    print("verdict:", "PASS" if ok else "FAIL")
    return 0 if ok else 1


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=1800.0)
    p.add_argument("--warmup", type=float, default=120.0)
    p.add_argument("--rate", type=float, default=100.0)
    p.add_argument("--frames", type=int, default=50)
    p.add_argument("--client-period", type=float, default=10.0)
    p.add_argument("--max-growth-mb", type=float, default=10.0)
    p.add_argument("--role", choices=["run", "pub", "sub", "client", "robot", "fleet"],
                   default="run", help=argparse.SUPPRESS)
    p.add_argument("--bus", help=argparse.SUPPRESS)
    p.add_argument("--name", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.role == "pub":
        publisher(args)
    elif args.role == "sub":
        subscriber(args)
    elif args.role == "client":
        client(args)
    elif args.role == "robot":
        robot(args)
    elif args.role == "fleet":
        fleet(args)
    else:
        sys.exit(run(args))


if __name__ == "__main__":
    main()
