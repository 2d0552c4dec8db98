"""Test peer: a broadcaster process over Zenoh (for tests/transports/test_zenoh.py).

Publishes the static transforms ``world -> <name>_static`` once at start, then
``world -> <name>_moving`` on /tf at ``--rate`` Hz with stamps 1 ns, 2 ns, ... (the
sequence number), and prints ``READY <node_id>`` once it is running. Runs until killed or
``--duration`` seconds have passed.
"""

from __future__ import annotations

import argparse
import sys

import anyio

from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
from tfbus.bus import Bus
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import Time
from tfbus.transports.zenoh import ZenohTransport


def _ts(parent: str, child: str, ns: int, x: float) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), parent), child, Transform(Vector3(x, 0.0, 0.0), Quaternion())
    )


async def main(args: argparse.Namespace) -> None:
    transport = ZenohTransport(
        connect=args.connect, listen=args.listen, prefix=args.prefix, name=args.name
    )
    async with Bus(transport=transport) as bus:
        StaticTransformBroadcaster(bus).send_transform_nowait(
            _ts("world", f"{args.name}_static", 1, 1.0)
        )
        print("READY", transport.node_id, flush=True)
        tf = TransformBroadcaster(bus)
        with anyio.move_on_after(args.duration):
            seq = 0
            while True:
                seq += 1
                await tf.send_transform(_ts("world", f"{args.name}_moving", seq, float(seq)))
                await anyio.sleep(1.0 / args.rate)


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--connect", action="append")
    parser.add_argument("--listen", action="append")
    parser.add_argument("--prefix", default="tfbus")
    parser.add_argument("--name", default="bcast")
    parser.add_argument("--rate", type=float, default=50.0)
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--backend", default="asyncio")
    ns = parser.parse_args()
    anyio.run(main, ns, backend=ns.backend)
    sys.exit(0)
