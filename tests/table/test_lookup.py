"""``tfbus.table.lookup``: every row against ``BufferCore.lookup_transform`` on the same
buffer, bit for bit, on the compiled and the pure-Python core side by side; failed rows
carry the exact tf2 exception class and text; input forms and bad input."""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
pytest.importorskip("rosbags")

from table_recordings import SEC, START, write  # noqa: E402

from tfbus import Time, TransformException  # noqa: E402
from tfbus.bag import TF_STATIC_TOPIC, read_messages  # noqa: E402
from tfbus.core import BufferCore, _pycore  # noqa: E402
from tfbus.table import RESULT_COLUMNS, lookup  # noqa: E402
from tfbus.table import lookups as table_lookups  # noqa: E402

FRAMES = ["map", "odom", "base_link", "laser", "imu", "arm", "nowhere", ""]


def _buffer_class(base: type) -> type[BufferCore]:
    """``BufferCore``'s own methods over another core's ``CoreBase`` (the twin tests'
    construction, tests/core/test_pycore.py)."""
    body = {k: v for k, v in vars(BufferCore).items() if k not in {"__dict__", "__weakref__"}}
    return type("BufferCore", (base,), body)


CORES = {"compiled": BufferCore, "pure": _buffer_class(_pycore.CoreBase)}


def fill(cls: type[BufferCore], path: Path) -> BufferCore:
    """A buffer of ``cls`` holding every transform of ``path`` (statics first)."""
    core = cls(cache_time=3600.0)
    recs = list(read_messages(path))
    for rec in recs:
        if rec.topic == TF_STATIC_TOPIC:
            for t in rec.message.transforms:
                core.set_transform_static(t, rec.authority)
    for rec in recs:
        if rec.topic != TF_STATIC_TOPIC:
            for t in rec.message.transforms:
                core.set_transform(t, rec.authority)
    return core


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write(tmp_path_factory.mktemp("rec"), "robot", "ros1", seed=3)


def _queries(seed: int, n: int) -> Any:
    """Random rows: every frame pair (unknown and empty ids included), stamps inside the
    recording, in its gaps, before and after it, and 0 (latest)."""
    rng = np.random.default_rng(seed)
    targets = rng.choice(FRAMES, n)
    sources = rng.choice(FRAMES, n)
    stamps = START + rng.integers(-2 * SEC, 23 * SEC, n)
    stamps[rng.random(n) < 0.05] = 0
    return pa.table({"target_frame": targets, "source_frame": sources,
                     "stamp": pa.array(stamps, pa.int64())})


def _bits(values: tuple[float, ...]) -> tuple[int, ...]:
    return tuple(struct.unpack("<q", struct.pack("<d", v))[0] for v in values)


def _expect(core: BufferCore, target: str, source: str, ns: int) -> tuple[Any, ...]:
    try:
        out = core.lookup_transform(target, source, Time.from_ns(ns))
    except TransformException as exc:
        return ("err", type(exc).__name__, str(exc))
    (x, y, z), (qx, qy, qz, qw) = out.transform
    return ("ok", _bits((x, y, z, qx, qy, qz, qw)), out.header.stamp.ns)


def _got(row: dict[str, Any]) -> tuple[Any, ...]:
    if row["status"] != "ok":
        assert all(math.isnan(row[k]) for k in RESULT_COLUMNS[:7])
        return ("err", row["status"], row["message"])
    assert row["message"] is None
    return ("ok", _bits(tuple(row[k] for k in RESULT_COLUMNS[:7])), row["transform_stamp"])


@pytest.mark.parametrize("core_kind", sorted(CORES))
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_every_row_is_the_single_lookup_bit_for_bit(
    recording: Path, core_kind: str, seed: int
) -> None:
    core = fill(CORES[core_kind], recording)
    queries = _queries(seed, 3000)
    result = lookup(queries, core)
    assert result.num_rows == 3000
    assert result.column_names == [*queries.column_names, *RESULT_COLUMNS]
    statuses = set()
    for q, row in zip(queries.to_pylist(), result.to_pylist(), strict=True):
        want = _expect(core, q["target_frame"], q["source_frame"], q["stamp"])
        assert _got(row) == want, q
        statuses.add(row["status"])
    # The rows cover answers and every kind of failure the recording can give.
    assert {"ok", "LookupException", "InvalidArgumentException",
            "BackwardExtrapolationException", "ForwardExtrapolationException"} <= statuses


def test_the_two_cores_agree_row_for_row(recording: Path) -> None:
    queries = _queries(7, 4000)
    a = lookup(queries, fill(CORES["compiled"], recording))
    b = lookup(queries, fill(CORES["pure"], recording))
    for name in RESULT_COLUMNS[:7]:
        x = a.column(name).to_numpy()
        y = b.column(name).to_numpy()
        assert np.array_equal(x.view(np.int64), y.view(np.int64)) or (np.array_equal(
            np.isnan(x), np.isnan(y)) and np.array_equal(
            x[~np.isnan(x)].view(np.int64), y[~np.isnan(y)].view(np.int64)))
    for name in ("transform_stamp", "status", "message"):
        assert a.column(name).equals(b.column(name))


def test_rows_in_a_gap_interpolate_across_it_and_a_late_frame_extrapolates(
    recording: Path,
) -> None:
    core = fill(BufferCore, recording)
    in_gap = START + 9 * SEC  # map -> odom has no sample from 8 s to 11 s
    before_arm = START + 5 * SEC  # base_link -> arm appears at 10 s
    q = pa.table({"target_frame": ["map", "base_link"], "source_frame": ["laser", "arm"],
                  "stamp": pa.array([in_gap, before_arm], pa.int64())})
    rows = lookup(q, core).to_pylist()
    single = core.lookup_transform("map", "laser", Time.from_ns(in_gap))
    assert rows[0]["status"] == "ok"
    assert rows[0]["x"] == single.transform.translation.x
    assert rows[1]["status"] == "BackwardExtrapolationException"
    assert rows[1]["message"].startswith("Lookup would require extrapolation ")
    assert rows[1]["message"].endswith(
        "when looking up transform from frame [arm] to frame [base_link]")


@pytest.mark.parametrize("core_kind", sorted(CORES))
def test_full_lookups_are_lookup_transform_full_bit_for_bit(
    recording: Path, core_kind: str
) -> None:
    core = fill(CORES[core_kind], recording)
    rng = np.random.default_rng(5)
    n = 1500
    fixed = rng.choice(["map", "odom", "nowhere"], n).astype(object)
    fixed[rng.random(n) < 0.2] = None  # a plain lookup in the same table
    q = pa.table({
        "target_frame": rng.choice(["base_link", "laser", "map"], n),
        "source_frame": rng.choice(["laser", "arm", "imu"], n),
        "fixed_frame": pa.array(fixed, pa.string()),
        "stamp": pa.array(START + rng.integers(0, 21 * SEC, n), pa.int64()),
        "source_stamp": pa.array(START + rng.integers(0, 21 * SEC, n), pa.int64()),
    })
    result = lookup(q, core).to_pylist()
    kinds = set()
    for row in result:
        t, s, f = row["target_frame"], row["source_frame"], row["fixed_frame"]
        try:
            if f is None:
                out = core.lookup_transform(t, s, Time.from_ns(row["stamp"]))
            else:
                out = core.lookup_transform_full(t, Time.from_ns(row["stamp"]), s,
                                                 Time.from_ns(row["source_stamp"]), f)
        except TransformException as exc:
            want: tuple[Any, ...] = ("err", type(exc).__name__, str(exc))
        else:
            (x, y, z), (qx, qy, qz, qw) = out.transform
            want = ("ok", _bits((x, y, z, qx, qy, qz, qw)), out.header.stamp.ns)
        assert _got(row) == want, row
        kinds.add((f is None, want[0]))
    assert kinds == {(True, "ok"), (True, "err"), (False, "ok"), (False, "err")}


def test_dataframes_and_timestamps_in(recording: Path) -> None:
    pl = pytest.importorskip("polars")
    pd = pytest.importorskip("pandas")
    core = fill(BufferCore, recording)
    stamps = [START + 3 * SEC, START + 12 * SEC + 5]
    base = {"target_frame": ["map", "odom"], "source_frame": ["laser", "arm"]}
    expected = lookup(pa.table({**base, "stamp": pa.array(stamps, pa.int64())}), core,
                      keep_columns=False)
    forms = [
        pl.DataFrame({**base, "stamp": stamps}),
        pd.DataFrame({**base, "stamp": stamps}),
        pa.table({**base, "stamp": pa.array(stamps, pa.timestamp("ns"))}),
        pa.table({**base, "stamp": pa.array([s // 1000 for s in stamps], pa.timestamp("us"))}),
        pa.table({**base, "stamp": pa.array(stamps, pa.uint64())}),
        pa.table({**base, "stamp": pa.chunked_array([[stamps[0]], [stamps[1]]], pa.int64())}),
        pa.table({"target_frame": pa.array(base["target_frame"]).dictionary_encode(),
                  "source_frame": pa.array(base["source_frame"], pa.large_string()),
                  "stamp": pa.array(stamps, pa.int64())}),
    ]
    for i, form in enumerate(forms):
        got = lookup(form, core, keep_columns=False)
        if i == 3:  # microseconds: the second stamp loses its 5 ns
            assert got.column("x")[0].as_py() == expected.column("x")[0].as_py()
            continue
        assert got.equals(expected), i
    assert expected.column("status").to_pylist() == ["ok", "ok"]


def test_bad_rows_are_rows_and_bad_tables_are_errors(recording: Path) -> None:
    core = fill(BufferCore, recording)
    q = pa.table({"target_frame": pa.array(["map", None, "map", "map"]),
                  "source_frame": ["laser", "laser", "laser", "laser"],
                  "stamp": pa.array([START + SEC, START + SEC, None, -5], pa.int64())})
    rows = lookup(q, core).to_pylist()
    assert rows[0]["status"] == "ok"
    assert (rows[1]["status"], rows[1]["message"]) == (
        "InvalidArgumentException",
        "Invalid argument passed to lookupTransform argument target_frame in tf2 "
        "frame_ids cannot be empty")
    assert (rows[2]["status"], rows[2]["message"]) == (
        "InvalidArgumentException", "queries row 2: stamp must be >= 0 ns, got null")
    assert (rows[3]["status"], rows[3]["message"]) == (
        "InvalidArgumentException", "queries row 3: stamp must be >= 0 ns, got -5")
    with pytest.raises(ValueError, match="queries has no column 'stamp'"):
        lookup(pa.table({"target_frame": ["a"], "source_frame": ["b"]}), core)
    with pytest.raises(TypeError, match="column 'stamp' must be int64 nanoseconds"):
        lookup(pa.table({"target_frame": ["a"], "source_frame": ["b"], "stamp": [1.5]}), core)
    with pytest.raises(TypeError, match="column 'source_frame' must hold strings"):
        lookup(pa.table({"target_frame": ["a"], "source_frame": [1], "stamp": [1]}), core)
    with pytest.raises(ValueError, match="result column"):
        lookup(pa.table({"target_frame": ["a"], "source_frame": ["b"], "stamp": [1],
                         "x": [1.0]}), core)
    with pytest.raises(ValueError, match="stamps beyond int64"):
        lookup(pa.table({"target_frame": ["a"], "source_frame": ["b"],
                         "stamp": pa.array([2**64 - 1], pa.uint64())}), core)
    with pytest.raises(TypeError, match="queries must be a pyarrow Table"):
        lookup([("a", "b", 1)], core)
    empty = lookup(pa.table({"target_frame": pa.array([], pa.string()),
                             "source_frame": pa.array([], pa.string()),
                             "stamp": pa.array([], pa.int64())}), core)
    assert empty.num_rows == 0 and empty.column_names[-1] == "message"


def test_one_pair_hands_the_stamp_column_to_the_kernel_without_a_copy(
    recording: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    core = fill(BufferCore, recording)
    stamps = pa.array(START + SEC + np.arange(1000, dtype=np.int64) * 10_000_000, pa.int64())
    q = pa.table({"target_frame": ["map"] * 1000, "source_frame": ["laser"] * 1000,
                  "stamp": stamps})
    seen: list[int] = []
    kernel = table_lookups._batch_for(core)

    def spy(c: Any, t: str, s: str, times: Any, *rest: Any) -> int:
        seen.append(times.ctypes.data)
        return kernel(c, t, s, times, *rest)

    monkeypatch.setattr(table_lookups, "_batch_for", lambda _core: spy)
    result = lookup(q, core)
    assert seen == [stamps.buffers()[1].address]
    assert result.column("status").to_pylist() == ["ok"] * 1000
