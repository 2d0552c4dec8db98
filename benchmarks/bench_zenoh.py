"""Cross-process benchmark of the Zenoh transport (prints figures, asserts nothing).

Two processes on 127.0.0.1: this one (the receiver: Bus + TransformListener + Buffer)
and a child it starts (the sender: Bus + TransformBroadcaster).

1. One-way latency: the sender calls ``send_transform`` for probe ``i`` (stamp ``i`` ns,
   translation.x = its ``time.monotonic_ns()``) about every ms; the receiver has
   ``await buffer.wait_for_transform("world", "probe", Time.from_ns(i))`` pending and
   takes ``monotonic_ns()`` when it returns (CLOCK_MONOTONIC is system-wide on Linux).
2. Throughput: the sender publishes TFMessages of ``--batch`` transforms as fast as it
   can for ``--seconds``; the receiver counts transforms stored in its Buffer.
3. Wire encoding and decoding in this process (first, no network): microseconds per
   ``WireCodec.encode`` of a TFMessage of 1 and 100 transforms, beside msgspec writing the
   same envelope alone (what the codec does without the compiled writer); microseconds
   per payload decoded for valid TFMessages and for hostile payloads refused (1 000-deep
   nesting, stamps beyond int64, a flat 16 KB list walked by the nesting bound).

Under load (``--hogs N``: N busy-looping processes this benchmark starts before the run
and ends by PID after it), and with ``--statics N`` (N ``/tf_static`` transforms sent by a
``StaticTransformBroadcaster`` during the flood, one frame each), the throughput line also
gives ``/tf`` messages dropped as counted at each end (the sender's ``send_dropped``, the
receiver's sequence-number ``lost``), the messages neither end received and the
``/tf_static`` frames the receiver's Buffer holds of those sent.

Usage: ``python benchmarks/bench_zenoh.py [--probes 2000] [--batch 100] [--seconds 3]
[--statics 0] [--hogs 0] [--wire-only]``.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import itertools
import os
import socket
import statistics
import subprocess
import sys
import time
import timeit
from collections.abc import Callable, Iterator
from pathlib import Path

import anyio
import anyio.lowlevel
import msgspec

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.codecs import native
from tfbus.codecs.native import WireCodec, WireError
from tfbus.listener import TransformListener
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Time
from tfbus.transports.zenoh import ZenohTransport


def _ts(child: str, ns: int, x: float) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), "world"), child, Transform(Vector3(x, 0.0, 0.0), Quaternion())
    )


async def sender(args: argparse.Namespace) -> None:
    transport = ZenohTransport(
        connect=args.endpoint,
        name="bench-sender",
        express=args.express,
        congestion_control=args.congestion_control,
    )
    async with Bus(transport=transport) as bus:
        with anyio.fail_after(10):
            while not transport.alive():
                await anyio.sleep(0.01)
        await anyio.sleep(0.5)
        tf = TransformBroadcaster(bus)
        static = StaticTransformBroadcaster(bus)
        for i in range(1, args.probes + 1):
            await tf.send_transform(_ts("probe", i, float(time.monotonic_ns())))
            await anyio.sleep(0.001)
        await anyio.sleep(0.5)
        children = [f"f{k}" for k in range(args.batch)]
        stamp = 0
        end = time.monotonic() + args.seconds
        sent = 0
        statics = 0
        while time.monotonic() < end:
            for _ in range(10):
                stamp += 1
                tf.send_transform_nowait([_ts(c, stamp, 1.0) for c in children])
                sent += args.batch
            if statics < args.statics:
                await static.send_transform(_ts(f"static{statics}", 0, 1.0))
                statics += 1
            await anyio.lowlevel.checkpoint()
        await anyio.sleep(0.5)  # the flood's tail, before the totals
        bus.publish_nowait("/bench/done", [sent, transport.statistics().send_dropped, statics])
        await anyio.sleep(1.0)


async def receiver(args: argparse.Namespace, endpoint: str) -> dict[str, float]:
    """The receiving side (this process): prints the latency and throughput lines and
    returns their figures: ``latency_median_us``, ``timeouts``, ``transforms_per_s``,
    ``sent``/``received`` (transforms; ``received`` counts the ``/tf_static`` ones too),
    ``received_msgs`` (``/tf`` messages), ``batch``, ``send_dropped`` (counted
    by the sender), ``lost`` (counted by this receiver, during the flood),
    ``unaccounted`` (``/tf`` messages neither end counted),
    ``statics_sent``/``statics_held``."""
    transport = ZenohTransport(listen=endpoint, name="bench-receiver")
    buffer = Buffer(cache_time=3600.0)
    async with Bus(transport=transport, queue_size=10_000) as bus:
        done = bus.subscribe("/bench/done")
        listener = TransformListener(buffer, bus, queue_size=10_000)
        async with listener:
            child = subprocess.Popen(
                [
                    sys.executable,
                    __file__,
                    "--role",
                    "sender",
                    "--endpoint",
                    endpoint,
                    "--probes",
                    str(args.probes),
                    "--batch",
                    str(args.batch),
                    "--seconds",
                    str(args.seconds),
                    "--statics",
                    str(args.statics),
                ]
                + (["--express"] if args.express else [])
                + ["--congestion-control", args.congestion_control],
                env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)},
            )
            try:
                lat: list[float] = []
                timeouts = 0
                with anyio.fail_after(30):
                    await buffer.wait_for_transform("world", "probe", Time.from_ns(1))
                for i in range(1, args.probes + 1):
                    try:
                        ts = await buffer.wait_for_transform(
                            "world", "probe", Time.from_ns(i), timeout=1.0
                        )
                    except Exception:
                        timeouts += 1
                        continue
                    now = time.monotonic_ns()
                    if ts.header.stamp.ns == i:
                        lat.append((now - ts.transform.translation.x) / 1e3)
                lat.sort()
                print(
                    f"one-way latency send_transform -> awaiting wait_for_transform, "
                    f"{len(lat)} probes ({timeouts} timed out):"
                )
                print(
                    f"  median {statistics.median(lat):.1f} us   "
                    f"p99 {lat[int(len(lat) * 0.99) - 1]:.1f} us   max {lat[-1]:.1f} us"
                )
                # throughput
                lost0 = transport.statistics().lost
                t_first = None
                stored0 = listener.statistics().stored
                last_stored, t_last = stored0, time.perf_counter()
                sent = None
                with anyio.fail_after(args.seconds + 30):
                    while True:
                        await anyio.sleep(0.005)
                        s = listener.statistics().stored
                        now_p = time.perf_counter()
                        if s != last_stored:
                            if t_first is None:
                                t_first = now_p
                                stored0 = last_stored
                            last_stored, t_last = s, now_p
                        with contextlib.suppress(anyio.WouldBlock):
                            sent = done.receive_nowait()
                        if sent is not None and now_p - t_last > 0.3:
                            break
                got = last_stored - stored0
                span = t_last - (t_first or t_last)
                stats = transport.statistics()
                sent_tfs, send_dropped, statics = sent
                held = sum(
                    buffer.can_transform("world", f"static{k}", Time(0)) is True
                    for k in range(statics)
                )
                lost = stats.lost - lost0
                # Every /tf message of the flood holds frame f0 once, at its own stamp.
                tf_msgs = next(f.samples for f in buffer.frame_info() if f.child == "f0")
                unaccounted = sent_tfs // args.batch - tf_msgs - lost - send_dropped
                print(
                    f"throughput, batches of {args.batch} transforms into the Buffer: "
                    f"{got / max(span, 1e-9) / 1e6:.3f} M transforms/s "
                    f"({got} of {sent_tfs} sent in {span:.2f} s; lost {stats.lost} messages, "
                    f"{stats.batches} wake-ups for {stats.received} payloads)"
                )
                if args.statics or args.hogs:
                    print(
                        f"  /tf messages dropped: {send_dropped} counted by the sender, "
                        f"{lost} by the receiver, {unaccounted} by neither; /tf_static: "
                        f"{held} of {statics} frames held ({args.hogs} CPU hogs, load "
                        f"{os.getloadavg()[0]:.2f})"
                    )
                return {
                    "latency_median_us": statistics.median(lat),
                    "timeouts": timeouts,
                    "transforms_per_s": got / max(span, 1e-9),
                    "sent": sent_tfs,
                    "received": got,
                    "received_msgs": tf_msgs,
                    "batch": args.batch,
                    "send_dropped": send_dropped,
                    "lost": lost,
                    "unaccounted": unaccounted,
                    "statics_sent": statics,
                    "statics_held": held,
                }
            finally:
                child.kill()
                child.wait(timeout=10)


def _per_call_us(fn: Callable[[], object], number: int) -> float:
    return min(timeit.repeat(fn, number=number, repeat=5)) / number * 1e6


def _msgspec_payload(encoder: msgspec.msgpack.Encoder, message: TFMessage) -> bytes:
    """What ``WireCodec.encode`` has msgspec write with no compiled writer (the envelope
    built, then written)."""
    envelope = native._OutEnvelope(123456789, 5, native._TF_TAG, message.transforms)
    return native._HEADER + encoder.encode(envelope)


def wire_costs() -> None:
    codec = WireCodec()

    def decode_or_error(payload: bytes) -> None:
        with contextlib.suppress(WireError):
            codec.decode(payload)

    rows = []
    for n in (1, 100):
        msg = TFMessage(tuple(_ts(f"f{k}", 1_700_000_000_000_000_000 + k, 1.0) for k in range(n)))
        payload = codec.encode(msg, sender=123456789, seq=5)
        rows.append((f"valid TFMessage, {n} transform(s)", payload))
    # 100 moving transforms: 64 messages of other values, decoded in turn and dropped
    # (what a listener of a moving robot decodes: no value repeats at its position)
    moving = itertools.cycle([codec.encode(TFMessage(tuple(
        _ts(f"f{k}", 1_700_000_000_000_000_000 + j, 1.0 + j + 0.01 * k) for k in range(100))),
        sender=123456789, seq=5 + j) for j in range(64)])  # fmt: skip
    head = payload[:2] + b"\x94\x01\x01"
    rows += [
        ("1 000-deep nesting, tag tf (refused)", head + b"\xa2tf" + b"\x91" * 1000 + b"\xc0"),
        ("1 000-deep nesting, plain (refused)", head + b"\xa0" + b"\x91" * 1000 + b"\xc0"),
        ("flat list of 16 000 ints, plain (walked, decoded)", head + b"\xa0" + b"\xdc\x3e\x80"
         + b"\x01" * 16_000),
        ("stamp beyond int64 (refused)", rows[0][1].replace(
            rows[0][1][rows[0][1].index(b"\xcf", 10) : rows[0][1].index(b"\xcf", 10) + 9],
            b"\xcf" + b"\xff" * 8, 1)),
    ]  # fmt: skip
    print("wire encode, this process (min of 5 runs): WireCodec.encode, and msgspec alone")
    msgspec_encoder = msgspec.msgpack.Encoder(enc_hook=native._enc_hook)
    for n in (1, 100):
        msg = TFMessage(tuple(_ts(f"f{k}", 1_700_000_000_000_000_000 + k, 1.0) for k in range(n)))
        number = 200 if n > 10 else 5000
        us = _per_call_us(functools.partial(codec.encode, msg, sender=123456789, seq=5), number)
        alone = _per_call_us(functools.partial(_msgspec_payload, msgspec_encoder, msg), number)
        print(f"  {f'TFMessage, {n} transform(s)':52s} {us:9.2f} us   msgspec {alone:9.2f} us"
              f"   {'C writer' if native._compiled_tf_writer is not None else 'msgspec'}")
    print("wire decode, this process (min of 5 runs):")
    for label, payload in rows:
        number = 200 if len(payload) > 2000 else 5000
        us = _per_call_us(functools.partial(decode_or_error, payload), number)
        print(f"  {label:52s} {len(payload):6d} B  {us:9.2f} us")
        if label.startswith("valid TFMessage, 100"):
            us = _per_call_us(lambda: decode_or_error(next(moving)), 640)
            print(f"  {'valid TFMessage, 100 moving transforms':52s} {len(payload):6d} B  "
                  f"{us:9.2f} us")


@contextlib.contextmanager
def cpu_hogs(n: int) -> Iterator[list[int]]:
    """``n`` busy-looping Python processes for the duration of the block (their PIDs
    given); each is killed by its PID and waited for when the block ends."""
    procs: list[subprocess.Popen[bytes]] = []
    try:
        for _ in range(n):
            procs.append(subprocess.Popen([sys.executable, "-c", "while True: pass"]))
        yield [p.pid for p in procs]
    finally:
        for p in procs:
            p.kill()
            p.wait(timeout=10)


def run(args: argparse.Namespace) -> dict[str, float]:
    """The latency and throughput run of ``args`` (:func:`options`) on a free 127.0.0.1
    port, under ``args.hogs`` CPU hogs: prints its lines, returns :func:`receiver`'s
    figures."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    print(
        f"bench_zenoh: backend={args.backend} express={args.express} "
        f"congestion_control={args.congestion_control} (2 processes, "
        f"127.0.0.1:{port})"
    )
    with cpu_hogs(args.hogs):
        out: dict[str, float] = anyio.run(
            receiver, args, f"tcp/127.0.0.1:{port}", backend=args.backend
        )
    return out


def options(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line (``argv``, default ``sys.argv[1:]``) parsed."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--role", default="receiver", choices=["receiver", "sender"])
    parser.add_argument("--endpoint", default="")
    parser.add_argument("--probes", type=int, default=2000)
    parser.add_argument("--batch", type=int, default=100)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--express", action="store_true")
    parser.add_argument("--congestion-control", default="drop", choices=["drop", "block"])
    parser.add_argument("--backend", default="asyncio")
    parser.add_argument("--statics", type=int, default=0,
                        help="/tf_static frames sent during the flood")
    parser.add_argument("--hogs", type=int, default=0,
                        help="busy-looping processes started for the run (the load)")
    parser.add_argument("--wire-only", action="store_true")
    return parser.parse_args(argv)


def main() -> None:
    args = options()
    if args.role == "sender":
        anyio.run(sender, args, backend=args.backend)
        return
    wire_costs()
    if args.wire_only:
        return
    run(args)


if __name__ == "__main__":
    main()
