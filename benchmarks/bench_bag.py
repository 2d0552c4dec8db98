"""Bag loading speed: transforms/s into a BufferCore vs a bare rosbags read.

For each format (ROS 1 .bag, ROS 2 sqlite3, MCAP) a synthetic recording is written with
tfbus's own writer (a robot-like mix: several dynamic frames per /tf message at 100 Hz,
plus one /tf_static), then timed:

* ``rosbags``: rosbags' AnyReader + typestore ``deserialize`` of every /tf message (the
  "bare read" the read-speed target is stated against);
* ``read_messages``: tfbus.bag.read_messages (decoded to tfbus values);
* ``load_buffer``: tfbus.bag.load_buffer (read + BufferCore.set_transform).

A bare ``.mcap`` file is read by tfbus through the ``mcap`` package; its row shows that
reader against rosbags' own MCAP reader on the same file.

The recordings in tests/data (tests/data/SOURCES.md) are timed too. Prints figures only.

    .venv/bin/python benchmarks/bench_bag.py [--transforms N]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from tfbus import Header, Quaternion, TFMessage, Time, Transform, TransformStamped, Vector3
from tfbus.bag import BagMessage, load_buffer, read_messages, write_bag

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"


def synthetic(n_transforms: int, per_msg: int = 10) -> list[BagMessage]:
    t0 = 1_700_000_000 * 10**9
    msgs = [
        BagMessage(
            Time.from_ns(t0),
            "/tf_static",
            TFMessage(
                [
                    TransformStamped(
                        Header(Time.from_ns(t0), "base_link"),
                        "laser",
                        Transform(Vector3(0.1, 0.0, 0.2)),
                    )
                ]
            ),
            "/bench",
        )
    ]
    for i in range(n_transforms // per_msg):
        stamp = Time.from_ns(t0 + i * 10_000_000)
        tss = []
        for k in range(per_msg):
            parent = "odom" if k == 0 else f"link{k - 1}"
            tss.append(
                TransformStamped(
                    Header(stamp, parent),
                    f"link{k}",
                    Transform(Vector3(0.001 * i, 0.1 * k, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)),
                )
            )
        msgs.append(BagMessage(stamp, "/tf", TFMessage(tss), "/bench"))
    return msgs


def bare_rosbags(path: Path) -> int:
    from rosbags.highlevel import AnyReader

    n = 0
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic in ("/tf", "/tf_static")]
        for conn, _t, raw in reader.messages(connections=conns):
            n += len(reader.deserialize(raw, conn.msgtype).transforms)  # type: ignore[attr-defined]
    return n


def tfbus_read(path: Path) -> int:
    return sum(len(r.message.transforms) for r in read_messages(path))


def tfbus_load(path: Path) -> int:
    core = load_buffer(path)
    return sum(info[4] for info in core.frame_info())


def report(label: str, path: Path, repeat: int) -> None:
    """Best of ``repeat`` rounds; the three readers take turns inside each round so that
    load from other processes affects them alike."""
    fns = {"bare": bare_rosbags, "read": tfbus_read, "load": tfbus_load}
    best = dict.fromkeys(fns, float("inf"))
    count = dict.fromkeys(fns, 0)
    for _ in range(repeat):
        for key, fn in fns.items():
            t = time.perf_counter()
            count[key] = fn(path)
            best[key] = min(best[key], time.perf_counter() - t)
    rate = {k: count[k] / best[k] / 1e3 for k in fns}
    print(
        f"{label:<28} {count['bare']:>8} tf | rosbags {rate['bare']:8.1f} k/s"
        f" | read_messages {rate['read']:8.1f} k/s"
        f" | load_buffer {rate['load']:8.1f} k/s"
        f" | load/bare time {best['load'] / best['bare']:5.2f}x"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--transforms", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    msgs = synthetic(args.transforms)
    tmp = Path(tempfile.mkdtemp(prefix="tfbus-bench-"))
    try:
        targets = {
            "ROS 1 .bag": (tmp / "s.bag", "ros1"),
            "ROS 2 sqlite3": (tmp / "s_db3", "sqlite3"),
            "ROS 2 mcap": (tmp / "s_mcap", "mcap"),
        }
        print(f"synthetic: {args.transforms} transforms, 10 per /tf message, 100 Hz")
        for label, (path, fmt) in targets.items():
            write_bag(path, msgs, format=fmt)
            report(label, path, args.repeat)
        # A bare .mcap file is read by the mcap package (a bag folder by rosbags).
        report("ROS 2 .mcap file (mcap pkg)", next((tmp / "s_mcap").glob("*.mcap")), args.repeat)
        print("recordings (tests/data):")
        for name in ("webviz_turtle_tf_example.bag", "laser/drl_guardian_3.bag",
                     "nav2_like.mcap", "tf_example"):
            report(name, DATA / name, args.repeat)
    finally:
        shutil.rmtree(tmp)


if __name__ == "__main__":
    main()
