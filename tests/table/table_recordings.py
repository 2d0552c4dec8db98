"""Generated tf recordings for the table tests: gaps, statics only at the start, frames
that appear late, several authorities; written with :func:`tfbus.bag.write_bag`."""

from __future__ import annotations

import math
import random
from pathlib import Path
from typing import Any

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.bag import TF_STATIC_TOPIC, TF_TOPIC, BagMessage, write_bag
from tfbus.messages import TFMessage

SEC = 1_000_000_000
START = 1_700_000_000 * SEC
"""Bag time of every recording's first message (a realistic epoch stamp)."""

SUFFIX = {"ros1": ".bag", "mcap": ".mcap", "sqlite3": ".db3"}


def ts(parent: str, child: str, ns: int, xyz: tuple[float, float, float],
       yaw: float) -> TransformStamped:
    """A transform rotating by ``yaw`` about z (unit quaternion)."""
    return TransformStamped(
        Header(Time.from_ns(ns), parent), child,
        Transform(Vector3(*xyz), Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))),
    )


def messages(seed: int, seconds: float = 20.0, rate_hz: float = 20.0) -> list[BagMessage]:
    """One robot's tf: statics (``base_link -> laser``, ``base_link -> imu``) only at the
    start; ``map -> odom`` at 2 Hz with a gap from 40 % to 55 % of the span;
    ``odom -> base_link`` at ``rate_hz`` with a gap from 70 % to 75 %; ``base_link ->
    arm`` appearing at 50 % of the span. Header stamps lag bag time by 1-3 ms."""
    rng = random.Random(seed)
    out = [BagMessage(Time.from_ns(START), TF_STATIC_TOPIC, TFMessage([
        ts("base_link", "laser", START, (0.2, 0.0, 0.3), 0.0),
        ts("base_link", "imu", START, (0.0, 0.1, 0.1), math.pi / 2),
    ]), "/static_publisher")]
    span = int(seconds * SEC)
    step = int(SEC / rate_hz)
    phase = rng.uniform(0, 6.0)
    for k in range(1, span // step):
        bag_ns = START + k * step
        frac = k * step / span
        stamp = bag_ns - rng.randrange(1_000_000, 3_000_000)
        t = (stamp - START) / SEC
        tfs = []
        if not 0.70 <= frac < 0.75:
            tfs.append(ts("odom", "base_link", stamp, (math.cos(t + phase), math.sin(t), 0.0),
                          0.3 * t + phase))
        if frac >= 0.5 and k % 2 == 0:
            tfs.append(ts("base_link", "arm", stamp, (0.1, 0.0, 0.5 + 0.1 * math.sin(3 * t)),
                          math.sin(2 * t)))
        if tfs:
            out.append(BagMessage(Time.from_ns(bag_ns), TF_TOPIC, TFMessage(tfs), "/robot"))
        if k % max(1, int(rate_hz / 2)) == 0 and not 0.40 <= frac < 0.55:
            out.append(BagMessage(Time.from_ns(bag_ns + 1), TF_TOPIC, TFMessage([
                ts("map", "odom", stamp, (0.01 * t, -0.02 * t, 0.0), 0.001 * t + seed)
            ]), "/localizer"))
    return out


def write(directory: Path, name: str, fmt: str, seed: int, **kw: float) -> Path:
    """Write :func:`messages` to ``directory/name`` in ``fmt`` (``ros1``, ``mcap``,
    ``sqlite3``); the path of the bag (a ROS 2 bag folder for mcap and sqlite3)."""
    path = directory / (name + (".bag" if fmt == "ros1" else ""))
    write_bag(path, messages(seed, **kw), format=fmt)
    return path


def write_mcap(path: Path, seed: int, chunk_size: int = 4096, **kw: float) -> Path:
    """:func:`messages` as a bare ``.mcap`` file with small chunks (``chunk_size`` bytes,
    zstd), so that a window is a few of many chunks: written by rosbags' writer (the ROS 2
    way) and re-chunked record for record with the ``mcap`` package's own Writer."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    folder = write(path.parent, path.stem + "_ros2", "mcap", seed, **kw)
    source = next(folder.glob("*.mcap"))
    with source.open("rb") as f_in, path.open("wb") as f_out:
        reader = make_reader(f_in)
        writer = Writer(f_out, chunk_size=chunk_size)
        writer.start(profile="ros2", library="tfbus tests")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert schema is not None
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding,
                                                            schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id],
                    dict(channel.metadata))
            writer.add_message(channels[channel.id], message.log_time, message.data,
                               message.publish_time, message.sequence)
        writer.finish()
    return path


def same_table(a: object, b: object) -> bool:
    """Two lookup results equal column for column, floats by their IEEE bits (a NaN row
    equals a NaN row, ``-0.0`` differs from ``0.0``)."""
    import numpy as np
    import pyarrow as pa

    assert isinstance(a, pa.Table) and isinstance(b, pa.Table)
    if a.column_names != b.column_names or a.num_rows != b.num_rows:
        return False
    for name in a.column_names:
        x, y = a.column(name), b.column(name)
        if pa.types.is_floating(x.type):
            if not np.array_equal(x.to_numpy().view(np.int64), y.to_numpy().view(np.int64)):
                return False
        elif not x.equals(y):
            return False
    return True


N_RECORDINGS = 20
ROWS_PER_RECORDING = 60
PAIRS = [("map", "laser"), ("odom", "base_link"), ("map", "arm"), ("base_link", "imu"),
         ("odom", "nowhere"), ("laser", "arm")]


def fleet(directory: Path) -> list[Path]:
    """20 recordings of 12 s, the three formats in turn, each robot its own seed."""
    paths = []
    for i in range(N_RECORDINGS):
        kind = ("ros1", "sqlite3", "mcap")[i % 3]
        if kind == "mcap":
            paths.append(write_mcap(directory / f"robot{i:02d}.mcap", seed=100 + i, seconds=12))
        else:
            paths.append(write(directory, f"robot{i:02d}", kind, seed=100 + i, seconds=12))
    return paths


def fleet_queries(paths: list[Path], seed: int = 0) -> Any:
    """Rows naming their recording, recordings interleaved, stamps from before to after
    each recording (0 included)."""
    import numpy as np
    import pyarrow as pa

    rng = np.random.default_rng(seed)
    n = len(paths) * ROWS_PER_RECORDING
    which = rng.integers(0, len(paths), n)
    pair = rng.integers(0, len(PAIRS), n)
    stamps = START + rng.integers(-SEC, 13 * SEC, n)
    stamps[rng.random(n) < 0.03] = 0
    return pa.table({
        "recording": [str(paths[k]) for k in which],
        "target_frame": [PAIRS[k][0] for k in pair],
        "source_frame": [PAIRS[k][1] for k in pair],
        "stamp": pa.array(stamps, pa.int64()),
    })


def plain(queries: Any) -> Any:
    """The plain path: per recording, ``lookup(rows, load_buffer(path))``, back in order."""
    import numpy as np
    import pyarrow as pa

    from tfbus.bag import load_buffer
    from tfbus.table import lookup

    names = queries.column("recording").to_pylist()
    parts, order = [], []
    for name in sorted(set(names)):
        rows = np.flatnonzero(np.array(names) == name)
        parts.append(lookup(queries.take(pa.array(rows)), load_buffer(name)))
        order.append(rows)
    merged = pa.concat_tables(parts)
    inverse = np.empty(queries.num_rows, dtype=np.int64)
    inverse[np.concatenate(order)] = np.arange(queries.num_rows)
    return merged.take(pa.array(inverse))
