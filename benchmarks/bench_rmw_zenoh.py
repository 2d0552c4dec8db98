"""rmw_zenoh's wire against tfbus's own Zenoh wire, same router, same process (prints
figures, asserts nothing).

A Zenoh router on 127.0.0.1 (``tfbus router``'s) and two client buses of one transport
kind in this process: ``rmw_zenoh`` (:class:`RmwZenohTransport`: CDR payload + 33-byte
attachment) or ``zenoh`` (:class:`ZenohTransport` in client mode: tfbus's msgspec wire).

1. Latency: probe ``i`` (one transform, translation.x = ``time.monotonic_ns()`` at
   publish) is published on ``/tf`` and awaited on the other bus before probe ``i+1``
   (ping-pong, one way measured): median, p90, p99 in microseconds.
2. Throughput: TFMessages of ``--batch`` transforms published as fast as the event loop
   allows for ``--seconds``, then a bounded wait for the tail; transforms per second
   delivered into the receiving bus.
3. Per-message cost without the network: encode + decode of one TFMessage of ``--batch``
   transforms on each wire, and of one rmw_zenoh attachment, microseconds.

Both buses share this process's event loop and CPU, so the figures compare the wires;
they are not the cross-process figures of ``bench_zenoh.py``.

Usage: ``python benchmarks/bench_rmw_zenoh.py [--probes 1000] [--batch 100] [--seconds 3]``.
"""

from __future__ import annotations

import argparse
import socket
import statistics
import sys
import time
import timeit
from collections.abc import Callable
from pathlib import Path

import anyio

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tfbus.bus import Bus, Transport
from tfbus.codecs.cdr import decode_tf, encode_tf
from tfbus.codecs.native import WireCodec, new_sender_id
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Time
from tfbus.transports.rmw_zenoh import RmwZenohTransport
from tfbus.transports.rmw_zenoh.wire import Attachment, decode_attachment, encode_attachment
from tfbus.transports.zenoh import ZenohTransport
from tfbus.transports.zenoh.router import ZenohRouter


def _ts(child: str, ns: int, x: float) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(ns), "world"), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion()))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _make(kind: str, endpoint: str, name: str) -> Transport:
    if kind == "rmw_zenoh":
        return RmwZenohTransport(connect=endpoint, name=name, connect_timeout=20.0)
    return ZenohTransport(connect=endpoint, config={"mode": "client"}, name=name,
                          connect_timeout=20.0)


async def _warm_up(a: Bus, sub: object) -> None:
    """Publish until the route is up (one message arrives), bounded."""
    with anyio.fail_after(20):
        while True:
            a.publish_nowait("/tf", TFMessage((_ts("warm", 1, 0.0),)))
            with anyio.move_on_after(0.2):
                await sub.receive()  # type: ignore[attr-defined]
                return


async def _run(kind: str, args: argparse.Namespace) -> dict[str, float]:
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    out: dict[str, float] = {}
    async with ZenohRouter(listen=endpoint):
        a, b = Bus(transport=_make(kind, endpoint, "sender")), Bus(
            transport=_make(kind, endpoint, "receiver"), queue_size=100_000)
        async with a, b, b.subscribe("/tf", queue_size=100_000) as sub:
            await _warm_up(a, sub)
            while True:  # drain the warm-up copies
                with anyio.move_on_after(0.3):
                    await sub.receive()
                    continue
                break
            lat: list[float] = []
            with anyio.fail_after(60):
                for i in range(args.probes):
                    a.publish_nowait("/tf", TFMessage((_ts("probe", i + 2, time.monotonic_ns()),)))
                    msg = await sub.receive()
                    lat.append((time.monotonic_ns() - msg.transforms[0].transform.translation.x)
                               / 1e3)
            q = statistics.quantiles(lat, n=100)
            out.update(median_us=statistics.median(lat), p90_us=q[89], p99_us=q[98])
            batch = TFMessage(tuple(_ts(f"f{j}", 10**9, float(j)) for j in range(args.batch)))
            got = 0

            async def count() -> None:
                nonlocal got
                while True:
                    m = await sub.receive()
                    got += len(m.transforms)

            async with anyio.create_task_group() as tg:
                tg.start_soon(count)
                start = time.perf_counter()
                sent = 0
                while time.perf_counter() - start < args.seconds:
                    a.publish_nowait("/tf", batch)
                    sent += 1
                    if sent % 16 == 0:
                        await anyio.sleep(0)
                with anyio.move_on_after(2.0):  # the tail in flight
                    while got < sent * args.batch:
                        await anyio.sleep(0.01)
                elapsed = time.perf_counter() - start
                tg.cancel_scope.cancel()
            out.update(sent_tf_s=sent * args.batch / args.seconds, got_tf_s=got / elapsed)
    return out


def _per_call_us(fn: Callable[[], object], number: int = 2000) -> float:
    return min(timeit.repeat(fn, number=number, repeat=3)) / number * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--probes", type=int, default=1000)
    parser.add_argument("--batch", type=int, default=100)
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    batch = TFMessage(tuple(_ts(f"f{j}", 10**9, float(j)) for j in range(args.batch)))
    codec, sender = WireCodec(), new_sender_id()
    native = codec.encode(batch, sender=sender, seq=1)
    cdr = encode_tf(batch)
    att = Attachment(1, time.time_ns(), bytes(16))
    native_us = _per_call_us(
        lambda: codec.decode(codec.encode(batch, sender=sender, seq=1)), 200)
    cdr_us = _per_call_us(lambda: decode_tf(encode_tf(batch)), 200)
    att_us = _per_call_us(lambda: decode_attachment(encode_attachment(att)))
    print(f"encode+decode one TFMessage of {args.batch} transforms: zenoh wire "
          f"{native_us:.1f} us ({len(native)} B), rmw_zenoh CDR {cdr_us:.1f} us "
          f"({len(cdr)} B); rmw_zenoh attachment encode+decode {att_us:.2f} us")
    for kind in ("zenoh", "rmw_zenoh"):
        r = anyio.run(_run, kind, args)
        print(f"{kind:>9}: latency median {r['median_us']:.0f} us, p90 {r['p90_us']:.0f} us, "
              f"p99 {r['p99_us']:.0f} us ({args.probes} probes); throughput "
              f"{r['got_tf_s']:,.0f} transforms/s delivered of {r['sent_tf_s']:,.0f}/s "
              f"published (batches of {args.batch})")


if __name__ == "__main__":
    main()
