"""Cross-process latency at robot rates: tfbus over Zenoh beside raw zenoh-python.

Two processes on 127.0.0.1 (Zenoh peers, explicit tcp/127.0.0.1 endpoints, multicast
scouting off: :func:`tfbus.transports.zenoh.config.zenoh_config`, the configuration
``ZenohTransport`` itself uses). This process receives; a child it starts sends probes at
each rate in turn (10, 50, 100 and 1 000 Hz by default), paced on absolute deadlines.
Each probe carries the sender's ``time.monotonic_ns()`` (CLOCK_MONOTONIC is system-wide
on Linux), so one-way latency is the receiver's clock minus it.

Paths measured, each with Zenoh's default batching and with ``express`` publishers:

* ``raw``: zenoh-python ``Publisher.put`` of 8 bytes -> subscriber callback (on Zenoh's
  thread): the floor any Python program on Zenoh pays;
* ``raw+loop``: the same callback handing the sample to the event loop of ``--backend``
  (asyncio: ``loop.call_soon_threadsafe`` into an ``asyncio.Queue``; trio:
  ``TrioToken.run_sync_soon`` into a memory channel) and the latency taken when the task
  awaiting it resumes: the thread hop and task wake-up any awaiting Python program on
  Zenoh pays;
* ``raw+loops``: ``raw+loop`` whose sender also runs an event loop of ``--backend``: its
  ``put`` made by a task paced with ``anyio.sleep`` (:func:`raw_loop_sender`), as an
  async program's are: what the sender's loop does after each ``put`` (the task's next
  sleep, the loop's timer and poll) runs while Zenoh sends the sample;
* ``bus``: ``TransformBroadcaster.send_transform`` on a ``Bus(ZenohTransport)`` ->
  a lookup awaiting that stamp (``Buffer.wait_for_transform``) on the receiver's bus.

Usage: ``python benchmarks/bench_latency.py [--seconds 2] [--rates 10,50,100,1000]
[--paths raw,raw+loop,bus] [--backend asyncio] [--rounds 1] [--breakdown]
[--zenoh-config PATH=JSON ...]``. Prints a table
of medians and p90 per rate and path (microseconds) and the ratio of ``bus`` to
``raw+loop`` and to ``raw``, and the load average at the start and the end. On a shared,
loaded machine the paths, measured one after the other, see different spells of load:
``--rounds N`` runs the whole sequence N times and pools each path's probes.

``--zenoh-config PATH=JSON`` (repeatable) sets a Zenoh configuration value in both
processes of every path, raw and bus alike (the same configuration), e.g.
``--zenoh-config transport/link/tx/queue/batching/enabled=false``; the values are
printed in the header.

``--breakdown`` also times the stages of the ``bus`` path, per probe (medians per rate,
microseconds): on the sender, the stamp to ``send_nowait``, the encode and the ``put``; on
the receiver, the stamp to Zenoh's callback, the callback to the transport's reader
waking, the decode (with the transport's counters and sequence numbers), the decode to
the bus delivery, the delivery to the buffer insert (the listener's callback, which also
re-checks and wakes the pending lookup), and the insert to the lookup's resumption. The
stages are timed by wrapping the transport's and buffer's methods on their instances (a
few hundred nanoseconds each), so the ``bus`` figures of a ``--breakdown`` run are
slightly higher.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import json
import math
import os
import socket
import statistics
import struct
import subprocess
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

import anyio

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import zenoh

from tfbus.broadcaster import TransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.listener import TransformListener
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Time
from tfbus.transports.zenoh import ZenohTransport
from tfbus.transports.zenoh.config import zenoh_config

RAW_KEY = "bench/latency"
PROBE = struct.Struct("<qq")  # (rate, sent monotonic ns)
START_DELAY = 1.0  # seconds the sender waits after it sees the receiver, before probing


def _schedule(rates: list[float], seconds: float) -> list[tuple[float, int]]:
    """(rate, probes) per rate: ``seconds`` worth, at least 20, at most 2000."""
    return [(rate, max(20, min(2000, int(rate * seconds)))) for rate in rates]


def _pace(rates: list[float], seconds: float) -> list[tuple[int, float]]:
    """(rate, offset from the start in seconds) of every probe, in order."""
    out: list[tuple[int, float]] = []
    t = 0.0
    for rate, count in _schedule(rates, seconds):
        for _ in range(count):
            out.append((int(rate), t))
            t += 1.0 / rate
        t += 0.2  # a gap between rates
    return out


# -- sender (child process) -------------------------------------------------------------


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The ``--zenoh-config PATH=JSON`` values, as a mapping for ``zenoh_config``."""
    out: dict[str, Any] = {}
    for item in args.zenoh_config:
        path, sep, value = item.partition("=")
        if not sep or not path:
            raise SystemExit(f"--zenoh-config wants PATH=JSON, got {item!r}")
        try:
            out[path] = json.loads(value)
        except ValueError:
            raise SystemExit(f"--zenoh-config {path}: not a JSON value: {value!r}") from None
    return out


def raw_sender(args: argparse.Namespace) -> None:
    cfg, _ = zenoh_config(connect=args.endpoint, config=_overrides(args))
    with zenoh.open(cfg) as session:
        publisher = session.declare_publisher(RAW_KEY, express=args.express)
        deadline = time.monotonic() + 30
        while not publisher.matching_status.matching:
            if time.monotonic() > deadline:
                raise SystemExit("raw sender: no subscriber within 30 s")
            time.sleep(0.01)
        time.sleep(START_DELAY)
        start = time.monotonic()
        for rate, offset in _pace(args.rate_list, args.seconds):
            delay = start + offset - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            publisher.put(PROBE.pack(rate, time.monotonic_ns()))
        time.sleep(0.5)


async def raw_loop_sender(args: argparse.Namespace) -> None:
    """:func:`raw_sender`'s puts made by a task of an event loop, paced with
    ``anyio.sleep`` (the ``raw+loops`` path's sender)."""
    cfg, _ = zenoh_config(connect=args.endpoint, config=_overrides(args))
    with zenoh.open(cfg) as session:
        publisher = session.declare_publisher(RAW_KEY, express=args.express)
        with anyio.fail_after(30):
            while not publisher.matching_status.matching:
                await anyio.sleep(0.01)
        await anyio.sleep(START_DELAY)
        start = time.monotonic()
        for rate, offset in _pace(args.rate_list, args.seconds):
            delay = start + offset - time.monotonic()
            if delay > 0:
                await anyio.sleep(delay)
            publisher.put(PROBE.pack(rate, time.monotonic_ns()))
        await anyio.sleep(0.5)


async def bus_sender(args: argparse.Namespace) -> None:
    transport = ZenohTransport(connect=args.endpoint, name="latency-sender", express=args.express,
                               config=_overrides(args))
    async with Bus(transport=transport) as bus:
        with anyio.fail_after(30):
            while not transport.alive():
                await anyio.sleep(0.01)
        await anyio.sleep(START_DELAY)
        tf = TransformBroadcaster(bus)
        stages: dict[int, list[list[float]]] = {}
        if args.breakdown:
            send_nowait, encode = transport.send_nowait, transport._codec.encode
            encoded = [0]

            def timed_encode(message: object, *, sender: int, seq: int) -> bytes:
                payload = encode(message, sender=sender, seq=seq)
                encoded[0] = time.monotonic_ns()
                return payload

            def timed_send(topic: str, message: object) -> None:
                entry = time.monotonic_ns()
                send_nowait(topic, message)
                v = message.transforms[0].transform.translation  # type: ignore[attr-defined]
                done = time.monotonic_ns()
                rate = int(v.y)
                if stages and rate not in stages:  # the previous rate is over: its line
                    _print_sender_stages(stages)
                stages.setdefault(rate, []).append(
                    [(entry - v.x) / 1e3, (encoded[0] - entry) / 1e3, (done - encoded[0]) / 1e3]
                )

            transport._codec.encode = timed_encode  # type: ignore[method-assign]
            transport.send_nowait = timed_send  # type: ignore[method-assign]
        start = time.monotonic()
        for i, (rate, offset) in enumerate(_pace(args.rate_list, args.seconds), 1):
            delay = start + offset - time.monotonic()
            if delay > 0:
                await anyio.sleep(delay)
            await tf.send_transform(
                TransformStamped(
                    Header(Time.from_ns(i), "world"),
                    "probe",
                    Transform(Vector3(float(time.monotonic_ns()), float(rate), 0.0), Quaternion()),
                )
            )
        _print_sender_stages(stages)  # before the receiver, done, ends this process
        await anyio.sleep(0.5)


def _print_sender_stages(stages: dict[int, list[list[float]]]) -> None:
    """Print the sender's stage medians of the last rate in ``stages``."""
    rate, rows = list(stages.items())[-1]
    meds = [statistics.median(col) for col in zip(*rows, strict=True)]
    print(f"breakdown sender   {rate:5d} Hz (median of {len(rows)}): stamp->send_nowait "
          f"{meds[0]:.1f}, encode {meds[1]:.1f}, put {meds[2]:.1f} us", flush=True)


# -- receiver (this process) ------------------------------------------------------------


def _child(args: argparse.Namespace, path: str, endpoint: str) -> subprocess.Popen[bytes]:
    cmd = [sys.executable, __file__, "--role", "sender", "--path", path, "--endpoint", endpoint,
           "--seconds", str(args.seconds), "--rates", args.rates, "--backend", args.backend]
    if args.express:
        cmd.append("--express")
    for item in args.zenoh_config:
        cmd += ["--zenoh-config", item]
    if args.breakdown and path == "bus":
        cmd.append("--breakdown")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)}
    return subprocess.Popen(cmd, env=env)


def _total(args: argparse.Namespace) -> int:
    return len(_pace(args.rate_list, args.seconds))


def raw_receiver(args: argparse.Namespace, endpoint: str, loop_hop: bool,
                 sender: str = "raw") -> dict[int, list[float]]:
    lat: dict[int, list[float]] = {}
    total = _total(args)
    done = threading.Event()
    count = [0]

    def record(rate: int, sent: int, now: int) -> None:
        lat.setdefault(rate, []).append((now - sent) / 1e3)
        count[0] += 1
        if count[0] >= total:
            done.set()

    async def run_loop() -> None:
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[tuple[int, int]] = asyncio.Queue()

        def callback(sample: zenoh.Sample) -> None:
            loop.call_soon_threadsafe(queue.put_nowait, PROBE.unpack(sample.payload.to_bytes()))

        cfg, _ = zenoh_config(listen=endpoint, config=_overrides(args))
        with zenoh.open(cfg) as session:
            session.declare_subscriber(RAW_KEY, callback)
            child = _child(args, sender, endpoint)
            try:
                limit = 60 + 2 * args.seconds * len(args.rate_list)
                with anyio.move_on_after(limit):
                    while count[0] < total:
                        if child.poll() is not None and queue.empty():
                            await asyncio.sleep(0.5)  # the last samples in flight
                            if queue.empty():
                                break
                        try:
                            rate, sent = await asyncio.wait_for(queue.get(), 1.0)
                        except TimeoutError:
                            continue
                        record(rate, sent, time.monotonic_ns())  # the awaiting task resumed
            finally:
                child.kill()
                child.wait(timeout=10)

    async def run_trio() -> None:
        import trio

        token = trio.lowlevel.current_trio_token()
        send, receive = trio.open_memory_channel[tuple[int, int]](math.inf)

        def callback(sample: zenoh.Sample) -> None:
            item = PROBE.unpack(sample.payload.to_bytes())
            with contextlib.suppress(trio.RunFinishedError):
                token.run_sync_soon(send.send_nowait, item)

        def empty() -> bool:
            return receive.statistics().current_buffer_used == 0

        cfg, _ = zenoh_config(listen=endpoint, config=_overrides(args))
        with zenoh.open(cfg) as session:
            session.declare_subscriber(RAW_KEY, callback)
            child = _child(args, sender, endpoint)
            try:
                with trio.move_on_after(60 + 2 * args.seconds * len(args.rate_list)):
                    while count[0] < total:
                        if child.poll() is not None and empty():
                            await trio.sleep(0.5)  # the last samples in flight
                            if empty():
                                break
                        with trio.move_on_after(1.0):
                            rate, sent = await receive.receive()
                            record(rate, sent, time.monotonic_ns())  # the task resumed
            finally:
                child.kill()
                child.wait(timeout=10)

    if loop_hop:
        if args.backend == "trio":
            import trio

            trio.run(run_trio)
        else:
            asyncio.run(run_loop())
        return lat

    def callback(sample: zenoh.Sample) -> None:
        rate, sent = PROBE.unpack(sample.payload.to_bytes())
        record(rate, sent, time.monotonic_ns())

    cfg, _ = zenoh_config(listen=endpoint, config=_overrides(args))
    with zenoh.open(cfg) as session:
        session.declare_subscriber(RAW_KEY, callback)
        child = _child(args, sender, endpoint)
        try:
            deadline = time.monotonic() + 60 + 2 * args.seconds * len(args.rate_list)
            while not done.wait(0.05) and time.monotonic() < deadline:
                if child.poll() is not None:
                    done.wait(0.5)
                    break
        finally:
            child.kill()
            child.wait(timeout=10)
    return lat


BREAKDOWN_STAGES = ("stamp->callback", "callback->reader", "decode", "decode->deliver",
                    "deliver->insert", "insert->resume")


def _instrument(transport: ZenohTransport, buffer: Buffer) -> dict[int, list[int]]:
    """Wrap the receiver's methods to time each probe's stages: {probe: [callback entry,
    reader woke, decoded, delivery entry, inserted]} (monotonic ns)."""
    stamps: dict[int, list[int]] = {}
    callbacks: deque[int] = deque()
    woke = [0]
    on_sample, drain, receive = transport._on_sample, transport._drain, transport._receive
    deliver, set_transform = transport._deliver, buffer.set_transform

    def timed_on_sample(sample: zenoh.Sample) -> None:
        callbacks.append(time.monotonic_ns())
        on_sample(sample)

    def timed_drain(bus: object) -> bool:
        woke[0] = time.monotonic_ns()
        return drain(bus)  # type: ignore[arg-type]

    def timed_receive(kind: int, topic: str | None, payload: bytes, bus: object = None) -> object:
        entry = callbacks.popleft() if kind == 0 and callbacks else 0
        message = receive(kind, topic, payload, bus)  # type: ignore[arg-type]
        if isinstance(message, TFMessage) and message.transforms:
            stamps[message.transforms[0].header.stamp.ns] = [entry, woke[0], time.monotonic_ns()]
        return message

    def timed_deliver(bus: object, topic: str | None, run: list[object]) -> None:
        now = time.monotonic_ns()
        for message in run:
            if isinstance(message, TFMessage) and message.transforms:
                stamps.get(message.transforms[0].header.stamp.ns, []).append(now)
        deliver(bus, topic, run)  # type: ignore[arg-type]

    def timed_set_transform(transform: TransformStamped, authority: str = "default") -> bool:
        stored = set_transform(transform, authority)
        stamps.get(transform.header.stamp.ns, []).append(time.monotonic_ns())
        return stored

    transport._on_sample = timed_on_sample  # type: ignore[method-assign]
    transport._drain = timed_drain  # type: ignore[method-assign]
    transport._receive = timed_receive  # type: ignore[method-assign]
    transport._deliver = timed_deliver  # type: ignore[method-assign]
    # the one-transform store: the listener's compiled handler calls it for a probe, as
    # it calls the buffer's own (a wrapped set_transforms would send every message to
    # the listener's Python path instead: the buffer no longer has the batch store)
    buffer.set_transform = timed_set_transform  # type: ignore[method-assign]
    return stamps


async def bus_receiver(args: argparse.Namespace, endpoint: str) -> dict[int, list[float]]:
    lat: dict[int, list[float]] = {}
    transport = ZenohTransport(listen=endpoint, name="latency-receiver", express=args.express,
                               config=_overrides(args))
    buffer = Buffer(cache_time=3600.0)
    stamps = _instrument(transport, buffer) if args.breakdown else {}
    stages: dict[int, list[list[float]]] = {}
    async with Bus(transport=transport) as bus, TransformListener(buffer, bus):
        child = _child(args, "bus", endpoint)
        try:
            with anyio.fail_after(60):
                await buffer.wait_for_transform("world", "probe", Time.from_ns(1))
            for i in range(1, _total(args) + 1):
                try:
                    ts = await buffer.wait_for_transform(
                        "world", "probe", Time.from_ns(i), timeout=2.0
                    )
                except Exception:
                    continue
                now = time.monotonic_ns()
                if ts.header.stamp.ns == i:
                    v = ts.transform.translation
                    lat.setdefault(int(v.y), []).append((now - v.x) / 1e3)
                    times = stamps.pop(i, [])
                    if len(times) == 5 and times[0]:
                        marks = [v.x, *times, now]
                        stages.setdefault(int(v.y), []).append(
                            [(b - a) / 1e3 for a, b in itertools.pairwise(marks)]
                        )
        finally:
            child.kill()
            child.wait(timeout=10)
    for rate, rows in sorted(stages.items()):
        meds = [statistics.median(col) for col in zip(*rows, strict=True)]
        print(f"breakdown receiver {rate:5d} Hz (median of {len(rows)}): " + ", ".join(
            f"{name} {med:.1f}" for name, med in zip(BREAKDOWN_STAGES, meds, strict=True)
        ) + " us")
    return lat


def _loadavg() -> str:
    """The system's load averages: the figures are only comparable at similar loads."""
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _free_endpoint() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def options(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line (``argv``, default ``sys.argv[1:]``) parsed, ``rate_list`` added.

    Raises:
        SystemExit: a malformed option or ``--zenoh-config`` value."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--role", default="receiver", choices=["receiver", "sender"])
    parser.add_argument("--path", default="", help="sender: raw, raw-loop or bus")
    parser.add_argument("--endpoint", default="")
    parser.add_argument("--seconds", type=float, default=2.0, help="seconds per rate")
    parser.add_argument("--rates", default="10,50,100,1000")
    parser.add_argument("--paths", default="raw,raw+loop,bus")
    parser.add_argument("--express", action="store_true", help="sender: express publisher")
    parser.add_argument("--modes", default="batched,express", help="receiver: which to run")
    parser.add_argument("--rounds", type=int, default=1,
                        help="run every path this many times, alternately; pool the probes")
    parser.add_argument("--backend", default="asyncio")
    parser.add_argument("--breakdown", action="store_true", help="time the bus path's stages")
    parser.add_argument("--zenoh-config", action="append", default=[], metavar="PATH=JSON",
                        help="a Zenoh config value for every path's both processes (repeatable)")
    args = parser.parse_args(argv)
    args.rate_list = [float(r) for r in args.rates.split(",")]
    _overrides(args)  # a malformed --zenoh-config ends the run before anything starts
    return args


def receive(args: argparse.Namespace, mode: str, path: str) -> dict[int, list[float]]:
    """One run of ``path`` (``raw``, ``raw+loop``, ``raw+loops`` or ``bus``) with
    ``mode``'s publishers (``batched`` or ``express``): a sender child on a free 127.0.0.1
    port, this process receiving; the one-way latencies in microseconds by rate."""
    args.express = mode == "express"
    endpoint = _free_endpoint()
    if path == "bus":
        got: dict[int, list[float]] = anyio.run(bus_receiver, args, endpoint, backend=args.backend)
        return got
    if path == "raw+loops":
        return raw_receiver(args, endpoint, loop_hop=True, sender="raw-loop")
    return raw_receiver(args, endpoint, loop_hop=path == "raw+loop")


def main() -> None:
    args = options()
    if args.role == "sender":
        if args.path == "raw":
            raw_sender(args)
        elif args.path == "raw-loop":
            anyio.run(raw_loop_sender, args, backend=args.backend)
        else:
            anyio.run(bus_sender, args, backend=args.backend)
        return
    paths = args.paths.split(",")
    modes = args.modes.split(",")
    print(f"bench_latency: one-way latency, 2 processes on 127.0.0.1, backend={args.backend}, "
          f"{args.seconds:g} s per rate (20..2000 probes) x {args.rounds} round(s), microseconds")
    if args.zenoh_config:
        print("zenoh config, every path: " + " ".join(args.zenoh_config))
    print("load average (1, 5, 15 min) at the start: " + _loadavg())
    results: dict[tuple[str, str], dict[int, list[float]]] = {}
    for _ in range(args.rounds):  # paths alternate: each sees the same spells of load
        for mode in modes:
            for path in paths:
                got = receive(args, mode, path)
                pooled = results.setdefault((mode, path), {})
                for rate, lat in got.items():
                    pooled.setdefault(rate, []).extend(lat)
    print("load average (1, 5, 15 min) at the end: " + _loadavg())
    header = f"{'publisher':9} {'rate':>6} " + " ".join(
        f"{p + ' med':>13} {'p90':>7}" for p in paths
    )
    print(header)
    for mode in modes:
        for rate in (int(r) for r in args.rate_list):
            cells = []
            meds: dict[str, float] = {}
            for path in paths:
                lat = sorted(results[(mode, path)].get(rate, []))
                if not lat:
                    cells.append(f"{'-':>13} {'-':>7}")
                    continue
                meds[path] = statistics.median(lat)
                p90 = lat[min(len(lat) - 1, int(len(lat) * 0.9))]
                cells.append(f"{meds[path]:13.0f} {p90:7.0f}")
            ratio = "".join(
                f" bus/{p}={meds['bus'] / meds[p]:.2f}"
                for p in paths if p != "bus" and p in meds and "bus" in meds
            )
            ratio = f" {ratio}" if ratio else ""
            print(f"{mode:9} {rate:6d} " + " ".join(cells) + ratio)


if __name__ == "__main__":
    main()
