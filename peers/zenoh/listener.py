"""Test peer: a listener process over Zenoh (for tests/transports/test_zenoh.py).

Feeds a Buffer through a TransformListener and prints one line per event, flushed:
``READY <node_id>``, ``TF <child> <stamp_ns>`` (/tf), ``STATIC <child>`` (/tf_static),
``PEER <alive 0|1> <name> <topic>`` (liveliness) and, with ``--lookup FRAME``, ``LOOKUP
<frame> <x>`` once ``world -> FRAME`` can be looked up. Runs until killed or ``--duration``.
"""

from __future__ import annotations

import argparse
from typing import Any

import anyio

from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.listener import TransformListener
from tfbus.messages import TFMessage
from tfbus.time import Time
from tfbus.transports.zenoh import PEERS_TOPIC, PeerEvent, ZenohTransport


async def _print_tf(sub: Any, tag: str) -> None:
    async for msg in sub:
        assert isinstance(msg, TFMessage)
        for ts in msg.transforms:
            if tag == "TF":
                print("TF", ts.child_frame_id, ts.header.stamp.ns, flush=True)
            else:
                print("STATIC", ts.child_frame_id, flush=True)


async def _print_peers(sub: Any, transport: ZenohTransport) -> None:
    # The nodes already alive first: their liveliness may have been delivered before this
    # subscription existed (the transport's history query runs as the bus starts).
    for info in transport.alive().values():
        print("PEER", 1, info.name, "-", flush=True)
    async for ev in sub:
        assert isinstance(ev, PeerEvent)
        print("PEER", int(ev.alive), ev.name, ev.topic or "-", flush=True)


async def _lookup(buffer: Buffer, frame: str) -> None:
    ts = await buffer.lookup_transform_async("world", frame, Time(0), timeout=30.0)
    print("LOOKUP", frame, ts.transform.translation.x, flush=True)


async def main(args: argparse.Namespace) -> None:
    transport = ZenohTransport(
        connect=args.connect, listen=args.listen, prefix=args.prefix, name=args.name
    )
    buffer = Buffer()
    async with Bus(transport=transport) as bus, TransformListener(buffer, bus):
        with anyio.move_on_after(args.duration):
            async with anyio.create_task_group() as tg:
                tg.start_soon(_print_tf, bus.subscribe("/tf", queue_size=10_000), "TF")
                tg.start_soon(_print_tf, bus.subscribe("/tf_static"), "STATIC")
                tg.start_soon(_print_peers, bus.subscribe(PEERS_TOPIC), transport)
                if args.lookup:
                    tg.start_soon(_lookup, buffer, args.lookup)
                print("READY", transport.node_id, flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--connect", action="append")
    parser.add_argument("--listen", action="append")
    parser.add_argument("--prefix", default="tfbus")
    parser.add_argument("--name", default="listener")
    parser.add_argument("--lookup", default="")
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--backend", default="asyncio")
    ns = parser.parse_args()
    anyio.run(main, ns, backend=ns.backend)
