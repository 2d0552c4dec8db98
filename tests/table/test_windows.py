"""Windowed reads (``read_window``, ``load_buffer(start=, end=)``, ``iter_windows``) against a
full read of the same recording, for ROS 1 .bag, ROS 2 .db3 and a many-chunk .mcap."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pa = pytest.importorskip("pyarrow")
pytest.importorskip("rosbags")

from table_recordings import SEC, START, same_table, write, write_mcap  # noqa: E402

from tfbus import Time  # noqa: E402
from tfbus.bag import (  # noqa: E402
    TF_STATIC_TOPIC,
    iter_windows,
    load_buffer,
    read_messages,
    read_window,
)
from tfbus.core import BufferCore  # noqa: E402
from tfbus.table import lookup  # noqa: E402

SPAN = 30  # seconds of each recording
FORMATS = ["ros1", "sqlite3", "mcap"]


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("windows")
    return {
        "ros1": write(d, "r1", "ros1", seed=11, seconds=SPAN),
        "sqlite3": write(d, "r2", "sqlite3", seed=11, seconds=SPAN),
        "mcap": write_mcap(d / "r3.mcap", seed=11, seconds=SPAN),
    }


@pytest.fixture(scope="module")
def full(bags: dict[str, Path]) -> dict[str, list[Any]]:
    return {fmt: list(read_messages(path)) for fmt, path in bags.items()}


def _expected(messages: list[Any], lo: int | None, hi: int | None) -> list[Any]:
    statics = [m for m in messages if m.topic == TF_STATIC_TOPIC]
    window = [m for m in messages if m.topic != TF_STATIC_TOPIC
              and (lo is None or m.time.ns >= lo) and (hi is None or m.time.ns < hi)]
    return statics + window


bounds = st.one_of(st.none(), st.integers(-2 * SEC, (SPAN + 2) * SEC).map(lambda x: START + x))


@pytest.mark.parametrize("fmt", FORMATS)
@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(lo=bounds, hi=bounds)
def test_a_window_is_every_static_and_exactly_the_messages_received_in_it(
    bags: dict[str, Path], full: dict[str, list[Any]], fmt: str, lo: int | None, hi: int | None
) -> None:
    if lo is not None and hi is not None and hi < lo:
        lo, hi = hi, lo
    got = list(read_window(bags[fmt], start=None if lo is None else Time.from_ns(lo),
                           end=None if hi is None else Time.from_ns(hi)))
    assert got == _expected(full[fmt], lo, hi)


def _fill(messages: list[Any]) -> BufferCore:
    core = BufferCore(cache_time=3600.0)
    for m in messages:
        for t in m.message.transforms:
            if m.topic == TF_STATIC_TOPIC:
                core.set_transform_static(t, m.authority)
            else:
                core.set_transform(t, m.authority)
    return core


def _grid(lo: int, hi: int, n: int = 400) -> Any:
    rng = np.random.default_rng(lo % 1000)
    pairs = [("map", "laser"), ("odom", "imu"), ("map", "arm"), ("base_link", "imu")]
    k = rng.integers(0, len(pairs), n)
    return pa.table({"target_frame": [pairs[i][0] for i in k],
                     "source_frame": [pairs[i][1] for i in k],
                     "stamp": pa.array(rng.integers(lo, hi, n), pa.int64())})


@pytest.mark.parametrize("fmt", FORMATS)
def test_load_buffer_of_a_window_answers_as_a_buffer_of_its_messages(
    bags: dict[str, Path], full: dict[str, list[Any]], fmt: str
) -> None:
    lo, hi = START + 12 * SEC, START + 17 * SEC
    windowed = load_buffer(bags[fmt], start=Time.from_ns(lo), end=Time.from_ns(hi))
    reference = _fill(_expected(full[fmt], lo, hi))
    queries = _grid(lo - SEC, hi + SEC)
    got, want = lookup(queries, windowed), lookup(queries, reference)
    assert same_table(got, want)
    # The statics recorded once at the start are there in a window in the middle.
    assert windowed.lookup_transform("base_link", "laser", Time()).transform.translation.x == 0.2
    # Frames of the window only: map -> odom's samples before the window are not loaded.
    whole = lookup(queries, load_buffer(bags[fmt]))
    assert not same_table(got, whole)


def test_a_window_of_a_many_chunk_mcap_reads_only_its_chunks(
    bags: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    from mcap.records import Chunk

    read: list[int] = []
    original = Chunk.read

    def counting(stream: Any) -> Chunk:
        chunk = original(stream)
        read.append(chunk.message_start_time)
        return chunk

    monkeypatch.setattr(Chunk, "read", staticmethod(counting))
    list(read_messages(bags["mcap"]))
    every = len(read)
    read.clear()
    msgs = list(read_window(bags["mcap"], start=Time.from_ns(START + 14 * SEC),
                            end=Time.from_ns(START + 15 * SEC)))
    assert every >= 10
    # The chunk with the statics and the one or two that overlap the second: not all.
    assert 1 <= len(read) <= 4 < every
    assert sum(1 for m in msgs if m.topic != TF_STATIC_TOPIC) >= 20


@pytest.mark.parametrize("fmt", FORMATS)
def test_iter_windows_walks_the_file_once_with_carry_over(
    bags: dict[str, Path], full: dict[str, list[Any]], fmt: str
) -> None:
    dynamic = [m for m in full[fmt] if m.topic != TF_STATIC_TOPIC]
    whole = _fill(full[fmt])
    # margin: more than the longest gap (map -> odom: 4.5 s from 12 s to 16.5 s).
    windows = list(iter_windows(bags[fmt], 4.0, margin=6.0))
    assert [w.start.ns for w in windows] == [START + SEC // 20 + k * 4 * SEC for k in range(8)]
    assert sum(w.messages for w in windows) == len(dynamic)
    # Each window's stamps: the header stamps of its own messages' transforms, sorted,
    # once each; together every /tf stamp of the file.
    for w in windows:
        own = {ts.header.stamp.ns for m in dynamic if w.start.ns <= m.time.ns < w.end.ns
               for ts in m.message.transforms}
        assert w.stamps.tolist() == sorted(own)
    assert sorted(s for w in windows for s in w.stamps.tolist()) == sorted(
        {ts.header.stamp.ns for m in dynamic for ts in m.message.transforms})
    for w in windows:
        queries = _grid(w.start.ns, w.end.ns, 200)
        got = lookup(queries, w.buffer).to_pylist()
        want = lookup(queries, whole).to_pylist()
        for g, r in zip(got, want, strict=True):
            if r["status"] == "ok":
                # Every row the whole file answers is answered bit for bit the same.
                assert g == r
            else:
                assert g["status"] != "ok"


def test_empty_windows_are_skipped_and_bad_arguments_named(bags: dict[str, Path]) -> None:
    starts = [w.start.ns for w in iter_windows(
        bags["ros1"], 1.0, margin=0.0, start=Time.from_ns(START - 100 * SEC),
        end=Time.from_ns(START + 3 * SEC))]
    assert starts == [START - 100 * SEC + k * SEC for k in (100, 101, 102)]
    with pytest.raises(ValueError, match="width must be > 0 s, got 0"):
        next(iter_windows(bags["ros1"], 0))
    with pytest.raises(ValueError, match="margin must be >= 0 s, got -1"):
        next(iter_windows(bags["ros1"], 1.0, margin=-1))
    with pytest.raises(ValueError, match=r"end .* is before start"):
        load_buffer(bags["ros1"], start=Time.from_ns(START + SEC), end=Time.from_ns(START))
