"""ROS 1 receive path in one process: CPU per TCPROS frame of a 50-transform ``TFMessage``,
from the bytes a read returned to the end of the bus's callbacks, hot and cache-cold.

A connection to a publisher is made of a ``FrameSplitter`` feeding the transport's frame
handler, which decodes and delivers to the bus (``tfbus/transports/ros1/transport.py``).
Here that handler is fed real frames (the publisher's connection header, then messages
encoded by :class:`tfbus.codecs.ros1.TFCodec`, as ``peers/ros1/bench_pub.cpp`` sends them),
with no socket and no event loop wake-up, on an open in-process :class:`tfbus.Bus`:

* ``callback``: a :meth:`tfbus.Bus.subscribe_callback` callback receives each message (the
  counterpart of a roscpp subscription callback);
* ``listener``: a :class:`tfbus.TransformListener` stores each message into a
  :class:`tfbus.Buffer` (50 frames, one transform each per message).

Each figure is the thread CPU time (``time.thread_time_ns``) per frame: ``hot`` is the
median over batches of frames fed back to back; ``cold`` feeds one frame after touching
32 MiB of other memory (what another process does to the caches between two messages
at 100 Hz on a loaded machine), timing only the frame. ``--baseline TREE`` runs the same
in a child process importing another checkout's tfbus, alternated round by round
(min / median / max of the rounds printed for each). Figures only; nothing is asserted.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_ros1_receive.py
    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_ros1_receive.py --rounds 5 \
        --baseline /tmp/old-tree
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

FRAMES = 50
"""Transforms per message (the 50-frame rows of ``bench_ros1.py``)."""


def measure(mode: str, hot_frames: int, cold_frames: int, n: int = FRAMES) -> dict[str, float]:
    """Feed frames of ``n`` transforms to one connection's handler; returns ``hot`` and
    ``cold`` us/frame."""
    import anyio
    import numpy as np

    from tfbus import Buffer, Bus, TransformListener
    from tfbus.codecs.ros1 import TF_MD5SUM, TFCodec
    from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
    from tfbus.time import Time
    from tfbus.transports.ros1 import Ros1Transport
    from tfbus.transports.ros1 import transport as ros1_transport
    from tfbus.transports.ros1.tcpros import encode_header, frame

    codec = TFCodec()
    t0 = time.time_ns()
    messages = [
        frame(codec.encode(
            TransformStamped(Header(Time.from_ns(t0 + k * 10_000_000), "base_link"),
                             f"bench_{i}", Transform(Vector3(float(i), 0.0, 0.0),
                                                     Quaternion(0.0, 0.0, 0.0, 1.0)))
            for i in range(n)
        ))
        for k in range(hot_frames + cold_frames + 1)
    ]  # fmt: skip
    header = encode_header({"callerid": "/bench_pub", "md5sum": TF_MD5SUM,
                            "type": "tf2_msgs/TFMessage", "topic": "/tf"})  # fmt: skip
    other = np.ones(32 * 1024 * 1024 // 8)
    out: dict[str, float] = {}

    async def main() -> None:
        node = Ros1Transport("http://127.0.0.1:9", node_name="/bench_receive")
        async with Bus() as bus:
            seen = [0]

            def record(msg: Any) -> None:
                seen[0] += len(msg.transforms)

            buffer = Buffer(cache_time=3600.0)
            listener = TransformListener(buffer, bus) if mode == "listener" else None
            if listener is not None:
                await listener.__aenter__()
            cb = bus.subscribe_callback("/tf", record)
            try:
                link = ros1_transport._Inbound(node, bus, "/tf", "http://127.0.0.1:1/")
                feed = link.splitter.feed
                feed(memoryview(header))
                msgs = iter(messages)
                feed(memoryview(next(msgs)))  # the first message: one-time set-up
                per: list[float] = []
                batch = 20
                for _ in range(hot_frames // batch):
                    views = [memoryview(next(msgs)) for _ in range(batch)]
                    start = time.thread_time_ns()
                    for v in views:
                        feed(v)
                    per.append((time.thread_time_ns() - start) / batch / 1e3)
                out["hot"] = statistics.median(per)
                cold: list[float] = []
                for _ in range(cold_frames):
                    v = memoryview(next(msgs))
                    other.sum()  # evict: the caches hold 32 MiB of something else
                    start = time.thread_time_ns()
                    feed(v)
                    cold.append((time.thread_time_ns() - start) / 1e3)
                out["cold"] = statistics.median(cold)
                expected = (1 + hot_frames // batch * batch + cold_frames) * n
                if seen[0] != expected:  # every frame must have been delivered whole
                    raise RuntimeError(f"delivered {seen[0]} transforms, expected {expected}")
                if listener is not None and listener.statistics().stored != expected:
                    raise RuntimeError(f"stored {listener.statistics().stored} of {expected}")
            finally:
                cb.close()
                if listener is not None:
                    await listener.__aexit__(None, None, None)

    anyio.run(main)
    return out


def child(tree: Path, mode: str, hot: int, cold: int, n: int) -> dict[str, float]:
    """:func:`measure` in a fresh process importing ``tree``'s tfbus."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    got = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--child", mode, "--hot", str(hot),
         "--cold", str(cold), "--transforms", str(n)],
        env=env, capture_output=True, text=True, check=True, timeout=600,
    )  # fmt: skip
    result: dict[str, float] = json.loads(got.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=3, help="alternated rounds (default 3)")
    parser.add_argument("--hot", type=int, default=2000, help="frames fed back to back")
    parser.add_argument("--cold", type=int, default=300, help="frames fed cache-cold")
    parser.add_argument("--modes", default="callback,listener")
    parser.add_argument(
        "--transforms", type=int, default=FRAMES, help=f"per message (default {FRAMES})"
    )
    parser.add_argument(
        "--baseline",
        metavar="TREE",
        default=None,
        help="alternate with a child importing another checkout's tfbus",
    )
    parser.add_argument("--child", choices=("callback", "listener"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.child, args.hot, args.cold, args.transforms)))
        return
    here = Path(__file__).resolve().parent.parent
    trees = {"tfbus": here}
    if args.baseline:
        trees["baseline"] = Path(args.baseline).resolve()
    print(f"ROS 1 receive, in process, {args.transforms} transforms a frame: thread CPU us "
          f"per frame; {args.rounds} alternated rounds, load {os.getloadavg()[0]:.1f}")  # fmt: skip
    for mode in args.modes.split(","):
        got: dict[str, list[dict[str, float]]] = {name: [] for name in trees}
        for _ in range(args.rounds):
            for name, tree in trees.items():
                got[name].append(child(tree, mode, args.hot, args.cold, args.transforms))
        for name, runs in got.items():
            cells = []
            for key in ("hot", "cold"):
                v = [r[key] for r in runs]
                cells.append(f"{key} min {min(v):6.2f} median {statistics.median(v):6.2f} "
                             f"max {max(v):6.2f}")  # fmt: skip
            print(f"  {mode:8s} {name:8s} | " + " | ".join(cells), flush=True)
    print(f"  load after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
