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
  timeout (cancelled after 1 s by the client), one with a 2 KB frame name, then leaves.

The resident memory (VmRSS) of every long-lived process is read after ``--warmup`` s and
at the end; the soak passes when none grew by more than ``--max-growth-mb`` MB, no valid
transform was lost, every answered lookup was right, and every process was still alive.
Prints one line per process and a verdict; exits 1 on a failure. Not a test (it runs for
minutes): ``benchmarks/results/soak_servers.txt`` keeps the last full run's output.

    .venv/bin/python benchmarks/soak_servers.py                      # 30 min, as measured
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

                async def stop() -> None:
                    await _until_signal()
                    tg.cancel_scope.cancel()

                tg.start_soon(stop)
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
    servers = [
        Proc("monitor", [*TFBUS, "monitor", "--bus", bus, "--interval", "10"]),
        Proc("view", [*TFBUS, "view", "--bus", bus, "--port", str(view_port)]),
        Proc("serve-buffer", [*TFBUS, "serve-buffer", "--bus", bus]),
    ]
    pub = Proc("broadcaster", [*me, "--role", "pub", "--rate", str(args.rate),
                               "--frames", str(args.frames)])
    pub.wait_line("READY", 60)
    watched = [router, sub, *servers, pub]
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
    pub.stop()
    sent = int(pub.wait_line("SENT", 30).split()[1])
    time.sleep(2.0)  # the listener drains what is in flight
    sub.stop()
    received, repeats = map(int, sub.wait_line("RECEIVED", 30).split()[1:])
    for p in servers:
        p.stop()
    router.stop()
    traces = [p.name for p in [*servers, router] if any("Traceback" in ln for ln in p.err)]
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
    print(f"  tracebacks on stderr: {traces or 'none'}")
    ok = alive and growth_ok and lost == 0 and clients_bad == 0 and not traces
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
    p.add_argument("--role", choices=["run", "pub", "sub", "client"], default="run",
                   help=argparse.SUPPRESS)
    p.add_argument("--bus", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.role == "pub":
        publisher(args)
    elif args.role == "sub":
        subscriber(args)
    elif args.role == "client":
        client(args)
    else:
        sys.exit(run(args))


if __name__ == "__main__":
    main()
