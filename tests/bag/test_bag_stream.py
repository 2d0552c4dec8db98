"""The chunk-by-chunk ROS 1 read (tfbus.bag.stream): the same messages in the same order as
rosbags' indexed read, in memory that does not grow with the message count."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import pytest

pytest.importorskip("rosbags")
hypothesis = pytest.importorskip("hypothesis")

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from tfbus.bag import read_messages  # noqa: E402
from tfbus.bag.formats import BagFormat  # noqa: E402
from tfbus.bag.reader import _raw_rosbags  # noqa: E402
from tfbus.bag.stream import read_ros1_chunks  # noqa: E402
from tfbus.messages import Header, Transform, TransformStamped, Vector3  # noqa: E402
from tfbus.time import Time  # noqa: E402

T0 = 1_700_000_000 * 10**9
TOPICS = frozenset({"/tf", "/tf_static"})


def _raw(store: object, k: int) -> bytes:
    from tfbus.codecs.ros1 import ROSBAGS_TF_TYPE, to_rosbags

    tfs = [TransformStamped(Header(Time.from_ns(T0 + k), "odom"), f"link{k % 7}",
                            Transform(Vector3(0.001 * k, 0.0, 0.0)))]
    return bytes(store.serialize_ros1(  # type: ignore[attr-defined]
        to_rosbags(store, tfs, ros1=True), ROSBAGS_TF_TYPE))


def write_ros1(path: Path, rows: list[tuple[int, int]], *, compression: str | None,
               chunk_threshold: int) -> Path:
    """A ROS 1 bag through rosbags' writer: ``rows`` of (bag time offset ns, connection
    0-3) in write order; connections /tf by two callers, /tf_static, and /odom (not tf:
    the same payload type, another topic)."""
    from rosbags.rosbag1 import Writer

    from tfbus.codecs.ros1 import ROSBAGS_TF_TYPE, tf_typestore

    store = tf_typestore(ros1=True)
    path.unlink(missing_ok=True)
    writer = Writer(path)
    if compression is not None:
        writer.set_compression(Writer.CompressionFormat[compression.upper()])
    writer.chunk_threshold = chunk_threshold
    with writer:
        conns = [writer.add_connection(topic, ROSBAGS_TF_TYPE, typestore=store,
                                       callerid=caller, latching=int(topic == "/tf_static"))
                 for topic, caller in (("/tf", "/a"), ("/tf", "/b"), ("/tf_static", "/c"),
                                       ("/odom", "/a"))]
        for k, (dt, c) in enumerate(rows):
            writer.write(conns[c], T0 + dt, _raw(store, k))
    return path


def _full(p: Path, lo: int | None, hi: int | None) -> list[tuple[int, str, str, bytes]]:
    return [(t, s.topic, s.authority, bytes(raw))
            for t, s, raw, _ in _raw_rosbags(p, BagFormat.ROS1, TOPICS, lo, hi)]


def _streamed(p: Path, lo: int | None, hi: int | None) -> list[tuple[int, str, str, bytes]]:
    return [(t, s.topic, s.authority, bytes(raw))
            for t, s, raw, _ in read_ros1_chunks(p, TOPICS, lo, hi)]


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    rows=st.lists(st.tuples(st.integers(0, 40), st.integers(0, 3)), max_size=120),
    compression=st.sampled_from([None, "bz2", "lz4"]),
    chunk_threshold=st.sampled_from([1, 300, 2000, 1 << 20]),
    window=st.tuples(st.none() | st.integers(0, 40), st.none() | st.integers(0, 41)),
)
def test_chunk_read_yields_exactly_the_full_read(
    tmp_path: Path, rows: list[tuple[int, int]], compression: str | None,
    chunk_threshold: int, window: tuple[int | None, int | None],
) -> None:
    """Generated bags (times out of order and repeated, so chunks overlap in time and
    ties cross connections; none / bz2 / lz4 chunks of 1 to many messages): the
    chunk-by-chunk read gives the same (bag time, topic, caller id, payload) list, in the
    same order, as rosbags' read of the whole index, with and without a time window."""
    p = write_ros1(tmp_path / "gen.bag", rows, compression=compression,
                   chunk_threshold=chunk_threshold)
    lo = None if window[0] is None else T0 + window[0]
    hi = None if window[1] is None else T0 + window[1]
    want = _full(p, lo, hi)
    assert _streamed(p, lo, hi) == want
    assert len(want) == sum(c != 3 and (lo is None or T0 + dt >= lo)
                            and (hi is None or T0 + dt < hi) for dt, c in rows)


def test_chunk_read_merges_overlapping_chunks_by_time(tmp_path: Path) -> None:
    """Chunks of one message each written at times 30, 10, 20, 10 (ns after T0): read in
    time order, the tie at 10 by connection (/tf of /a before /tf_static of /c)."""
    p = write_ros1(tmp_path / "o.bag", [(30, 0), (10, 2), (20, 1), (10, 0)],
                   compression="lz4", chunk_threshold=1)
    got = [(t - T0, topic, who) for t, topic, who, _ in _streamed(p, None, None)]
    assert got == [(10, "/tf", "/a"), (10, "/tf_static", "/c"), (20, "/tf", "/b"),
                   (30, "/tf", "/a")]


def _peak_bytes(p: Path) -> tuple[int, int]:
    tracemalloc.start()
    try:
        n = sum(1 for _ in read_messages(p))
        return n, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("compression", [None, "bz2"])
def test_read_messages_memory_does_not_grow_with_message_count(
    tmp_path: Path, compression: str | None
) -> None:
    """``read_messages`` of a ROS 1 bag of 50 000 messages peaks (tracemalloc) within
    1.5x + 256 kB of the same bag's 10 000-message prefix: what it holds is bounded by a
    chunk (1 MiB, rosbags' default threshold), not by an index entry per message (rosbags'
    reader: about 150 B each, 6 MB more at 50 000)."""
    rows = [(k * 1000, k % 2) for k in range(50_000)]
    small = write_ros1(tmp_path / "s.bag", rows[:10_000], compression=compression,
                       chunk_threshold=1 << 20)
    large = write_ros1(tmp_path / "l.bag", rows, compression=compression,
                       chunk_threshold=1 << 20)
    n_small, peak_small = _peak_bytes(small)
    n_large, peak_large = _peak_bytes(large)
    assert (n_small, n_large) == (10_000, 50_000)
    assert peak_large < 1.5 * peak_small + 256 * 1024, (peak_small, peak_large)
