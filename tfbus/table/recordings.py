"""Lookups against recordings: a file's rows answered from that file, whole or window by
window (:func:`tfbus.bag.load_buffer`'s ``start`` / ``end``, :func:`tfbus.bag.iter_windows`).

A window is bag (receive) time ``[start, end)``; its buffer holds every static transform
of the file and the ``/tf`` messages received from ``margin`` before to ``margin`` after
it. A row answered from a window equals the whole file's answer when every link on its
path has a sample within ``margin`` on each side of the row's stamp (the margin must be
more than the links' longest gap plus the header-stamp-to-receive delay); a row the
window cannot answer fails with tf2's exception for that window's data.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterator
from os import PathLike
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from tfbus.core import BufferCore
from tfbus.table.lookups import RESULT_COLUMNS, as_arrow, lookup, result_schema
from tfbus.time import NSEC_PER_SEC, Time

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = [
    "DEFAULT_LOAD_COST",
    "DEFAULT_MARGIN",
    "MAX_ROWS_PER_TABLE",
    "RecordingBuffers",
    "balanced_blocks",
    "lookup_by_recording",
    "lookup_recording",
    "output_schema",
    "poses_every",
]

DEFAULT_MARGIN = 5.0
"""Seconds each window's buffer reaches beyond the window on both sides."""

DEFAULT_LOAD_COST = 100_000.0
"""What reading one recording whole costs, in rows answered: on a 60 s recording of
3,600 ``/tf`` messages (``benchmarks/bench_table.py``'s fleet) ``load_buffer`` takes
about 50 ms and a row about 0.4 us, so one read weighs as much as about 10^5 rows."""


def _seconds_ns(value: float, name: str, *, positive: bool) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
        raise ValueError(f"{name} must be a number of seconds, got {value!r}")
    if value in (float("inf"), float("-inf")) or (value <= 0 if positive else value < 0):
        raise ValueError(f"{name} must be {'> 0' if positive else '>= 0'} s, got {value!r}")
    return round(value * NSEC_PER_SEC)


def lookup_recording(
    path: str | PathLike[str],
    queries: object,
    *,
    window: float | None = None,
    margin: float = DEFAULT_MARGIN,
    keep_columns: bool = True,
) -> pa.Table:
    """Answer ``queries`` (see :func:`~tfbus.table.lookup`) against one recording.

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder, or a ``.db3`` / ``.mcap`` file.
        queries: the rows (Arrow table or Polars / pandas DataFrame).
        window: None: load the whole file once (every row exactly as
            ``load_buffer(path).lookup_transform``). Seconds: group the rows by window of
            that width on ``stamp`` and load each window that has rows (plus ``margin``
            on each side, and the file's statics) through the format's index; rows at
            stamp 0 (the latest data) and tables with ``source_stamp`` (full lookups)
            are answered from the whole file.
        margin: seconds each window's buffer reaches beyond the window.
        keep_columns: as in :func:`~tfbus.table.lookup`.

    Returns:
        The rows, in the order of ``queries``, with :data:`~tfbus.table.RESULT_COLUMNS`.

    Raises:
        ValueError: ``window`` is not positive or ``margin`` negative; as
            :func:`~tfbus.table.lookup`.
        BagNotFoundError, BagFormatError, BagReadError: see :func:`tfbus.bag.read_messages`.
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    from tfbus.bag import load_buffer

    table = as_arrow(queries)
    margin_ns = _seconds_ns(margin, "margin", positive=False)
    if window is None:
        return lookup(table, load_buffer(path), keep_columns=keep_columns)
    width = _seconds_ns(window, "window", positive=True)
    if "stamp" not in table.column_names:
        return lookup(table, load_buffer(path), keep_columns=keep_columns)  # names it
    stamps = table.column("stamp")
    if pa.types.is_timestamp(stamps.type):
        stamps = stamps.cast(pa.timestamp("ns", stamps.type.tz)).cast(pa.int64())
    if not pa.types.is_integer(stamps.type) or table.num_rows == 0:
        return lookup(table, load_buffer(path), keep_columns=keep_columns)
    if "source_stamp" in table.column_names:
        # A full lookup's two times need not fall in one window: use the whole file.
        return lookup(table, load_buffer(path), keep_columns=keep_columns)
    ns = np.asarray(pc.fill_null(stamps.cast(pa.int64()), -1).to_numpy(zero_copy_only=False))
    # Slots: -2 stamp 0 (the latest data: the whole file), -1 a null or negative stamp
    # (a row error: no data needed), k >= 0 the window of the stamp.
    slot = np.where(ns > 0, ns // width, np.where(ns == 0, -2, -1))
    parts: list[pa.Table] = []
    order: list[npt.NDArray[np.int64]] = []
    for k in np.unique(slot).tolist():
        rows = np.flatnonzero(slot == k)
        part = table.take(pa.array(rows))
        if k == -2:
            buffer = load_buffer(path)
        elif k == -1:
            buffer = BufferCore()
        else:
            lo = max(0, k * width - margin_ns)
            hi = min(2**63 - 1, (k + 1) * width + margin_ns)
            buffer = load_buffer(path, start=Time.from_ns(lo), end=Time.from_ns(hi))
        parts.append(lookup(part, buffer, keep_columns=keep_columns))
        order.append(rows)
    merged = pa.concat_tables(parts)
    placed = np.concatenate(order)
    if np.array_equal(placed, np.arange(table.num_rows)):  # already in the input's order
        return merged
    inverse = np.empty(table.num_rows, dtype=np.int64)
    inverse[placed] = np.arange(table.num_rows)
    return merged.take(pa.array(inverse))


MAX_ROWS_PER_TABLE = 1 << 20
"""Rows in one table :func:`poses_every` yields at most (a window whose stamps span more
is answered in several tables from the same buffer: memory bounded by this, not by the
span)."""


def poses_every(
    path: str | PathLike[str],
    target_frame: str,
    source_frame: str,
    every: float,
    *,
    window: float = 60.0,
    margin: float = DEFAULT_MARGIN,
) -> Iterator[pa.Table]:
    """The pose of ``source_frame`` in ``target_frame`` every ``every`` seconds over a
    recording, read window by window (:func:`tfbus.bag.iter_windows`: one pass, no more
    than a window and two margins of messages held).

    The stamps follow the data's clock, the transforms' header stamps (simulated time
    when the recording's is), as ``lookup_transform`` is asked by any tf2 program; not
    the bag (receive) time, which the windows use to read the file. They are
    ``t0 + k * every`` (``t0``: the earliest header stamp of the first window's ``/tf``
    transforms), each once, over the header stamps of the ``/tf`` transforms
    (:attr:`tfbus.bag.Window.stamps`): from the first to the last of every run of
    stamps in which no two consecutive ones are more than ``window`` seconds apart, so
    one stray stamp (a clock jump, a bogus header) adds at most one row, not a span.
    Each stamp is looked up in the buffer of the window whose transforms reach it (a
    stamp between two windows' transforms: the later window, which holds ``margin``
    seconds of the data before it);
    a stamp at or before one already written is not asked again (stamps that go back,
    a simulation restarted in the recording, give rows only once they pass the latest).
    ``/tf_static`` transforms do not place the grid.

    Args:
        path: the recording.
        target_frame, source_frame: the frames (as in ``lookup_transform``).
        every: seconds between stamps (> 0).
        window: seconds per window (> 0).
        margin: seconds each window's buffer reaches beyond it (>= 0).

    Yields:
        Arrow tables, one or more per window (at most :data:`MAX_ROWS_PER_TABLE` rows
        each): ``target_frame``, ``source_frame``, ``stamp`` (ns, the data's clock) and
        :data:`~tfbus.table.RESULT_COLUMNS`.

    Raises:
        ValueError: ``every`` or ``window`` not positive, ``margin`` negative.
        BagNotFoundError, BagFormatError, BagReadError: see :func:`tfbus.bag.read_messages`.
    """
    import pyarrow as pa

    from tfbus.bag import iter_windows

    step = _seconds_ns(every, "every", positive=True)
    gap = _seconds_ns(window, "window", positive=True)
    _seconds_ns(margin, "margin", positive=False)
    t0: int | None = None
    next_k = 0  # the grid's next index not yet written: each stamp once
    latest = 0  # the latest stamp of the windows so far
    for w in iter_windows(path, window, margin=margin):
        if not w.stamps.size:
            continue
        if t0 is None:
            t0 = latest = int(w.stamps[0])
        for lo, hi in _runs(w.stamps, gap):
            # A run that goes on from the stamps before it (across a window's edge too)
            # continues the grid from where it stopped; one after a longer gap starts at
            # its own first stamp.
            k_lo = next_k if lo - latest <= gap else max(next_k, -(-(lo - t0) // step))
            latest = max(latest, hi)
            k_hi = (hi - t0) // step
            while k_lo <= k_hi:
                k_end = min(k_hi, k_lo + MAX_ROWS_PER_TABLE - 1)
                stamps = t0 + np.arange(k_lo, k_end + 1, dtype=np.int64) * step
                n = stamps.shape[0]
                queries = pa.table({
                    "target_frame": pa.array([target_frame] * n, pa.string()),
                    "source_frame": pa.array([source_frame] * n, pa.string()),
                    "stamp": pa.array(stamps),
                })
                yield lookup(queries, w.buffer)
                k_lo = next_k = k_end + 1


def _runs(stamps: npt.NDArray[np.int64], gap: int) -> list[tuple[int, int]]:
    """``(first, last)`` of each run of sorted ``stamps`` whose consecutive stamps are
    at most ``gap`` ns apart."""
    breaks = np.flatnonzero(np.diff(stamps) > gap)
    firsts = np.concatenate(([0], breaks + 1))
    lasts = np.concatenate((breaks, [stamps.shape[0] - 1]))
    return [(int(stamps[a]), int(stamps[b])) for a, b in zip(firsts, lasts, strict=True)]


def output_schema() -> pa.Schema:
    """The schema of :func:`poses_every`'s tables (query columns, then results)."""
    import pyarrow as pa

    head = pa.schema([("target_frame", pa.string()), ("source_frame", pa.string()),
                      ("stamp", pa.int64())])
    return pa.schema(list(head) + list(result_schema()))





class RecordingBuffers:
    """Whole-recording buffers by path, the ``maxsize`` most recently used kept (memory
    bounded by ``maxsize`` recordings): what the engines' per-batch functions share
    when the same recording's rows come in several batches.

    Args:
        maxsize: recordings kept loaded (>= 1).

    Raises:
        ValueError: ``maxsize`` < 1.
    """

    def __init__(self, maxsize: int = 2) -> None:
        if isinstance(maxsize, bool) or not isinstance(maxsize, int) or maxsize < 1:
            raise ValueError(f"maxsize must be an int >= 1, got {maxsize!r}")
        self.maxsize = maxsize
        self._kept: OrderedDict[str, BufferCore] = OrderedDict()
        self.loads = 0
        """How many times a recording was read (a measure of the cache's use)."""

    def get(self, path: str) -> BufferCore:
        """The buffer of the whole recording at ``path`` (``load_buffer(path)``).

        Raises:
            BagNotFoundError, BagFormatError, BagReadError: see
                :func:`tfbus.bag.load_buffer`.
        """
        from tfbus.bag import load_buffer

        core = self._kept.pop(path, None)
        if core is None:
            core = load_buffer(path)
            self.loads += 1
        self._kept[path] = core
        while len(self._kept) > self.maxsize:
            self._kept.popitem(last=False)
        return core


def balanced_blocks(
    queries: object,
    blocks: int,
    *,
    recording: str = "recording",
    load_cost: float | dict[str, float] = DEFAULT_LOAD_COST,
) -> list[pa.Table]:
    """Split rows that name their recording into ``blocks`` tables of about equal cost,
    each recording's rows in one table (so each recording is read by one task, once).

    The cost of a recording is ``load_cost`` (its read, in rows) plus its row count;
    the recordings are placed by longest processing time first (LPT, Graham 1969: the
    costliest first, each into the block of least cost so far; ties to the lower
    block, recordings of equal cost in order of first appearance), which keeps the
    costliest block within 4/3 of the best split. Within a block the rows are grouped
    by recording (recordings in order of first appearance in ``queries``), each
    recording's rows in their order in ``queries``.

    Args:
        queries: an Arrow table (or pandas / Polars DataFrame) with a string column
            ``recording``.
        blocks: how many tables (>= 1); fewer recordings than ``blocks`` leave the
            last ones empty (every table has ``queries``' schema).
        recording: the name of the recording column.
        load_cost: rows one read of a recording weighs (>= 0), one number for all or a
            mapping from recording to its cost (e.g. its file size times rows per
            byte; recordings it does not name cost :data:`DEFAULT_LOAD_COST`).

    Returns:
        ``blocks`` Arrow tables; together they hold every row of ``queries`` once.

    Raises:
        ValueError: ``blocks`` < 1, a negative ``load_cost``, no ``recording`` column.
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    if isinstance(blocks, bool) or not isinstance(blocks, int) or blocks < 1:
        raise ValueError(f"blocks must be an int >= 1, got {blocks!r}")
    costs = load_cost if isinstance(load_cost, dict) else {}
    default = DEFAULT_LOAD_COST if isinstance(load_cost, dict) else float(load_cost)
    for name, value in [("load_cost", default), *costs.items()]:
        if not float(value) >= 0.0:
            raise ValueError(f"load_cost must be >= 0, got {value!r} for {name!r}")
    table = as_arrow(queries)
    if recording not in table.column_names:
        raise ValueError(f"queries has no column {recording!r} (the recording of each row)")
    column = table.column(recording)
    encoded = pc.dictionary_encode(pc.fill_null(column.cast(pa.string()), "")).combine_chunks()
    codes = np.asarray(encoded.indices.to_numpy(zero_copy_only=False), dtype=np.int64)
    names = encoded.dictionary.to_pylist()
    counts = np.bincount(codes, minlength=len(names))
    cost = [float(costs.get(name, default)) + float(counts[code])
            for code, name in enumerate(names)]
    # LPT: costliest first (stable: equal costs keep their order of first appearance).
    placed: list[list[int]] = [[] for _ in range(blocks)]
    totals = [0.0] * blocks
    for code in sorted(range(len(names)), key=lambda c: -cost[c]):
        least = min(range(blocks), key=lambda b: totals[b])
        placed[least].append(code)
        totals[least] += cost[code]
    # Each recording's row indices, in order (a stable sort by code).
    order = np.argsort(codes, kind="stable")
    starts = np.concatenate(([0], np.cumsum(counts)))
    out = []
    for members in placed:
        rows = [order[starts[c]:starts[c + 1]] for c in sorted(members)]
        take = np.concatenate(rows) if rows else np.empty(0, dtype=np.int64)
        out.append(table.take(pa.array(take, pa.int64())))
    return out


def lookup_by_recording(
    queries: object,
    *,
    recording: str = "recording",
    window: float | None = None,
    margin: float = DEFAULT_MARGIN,
    buffers: RecordingBuffers | None = None,
    keep_columns: bool = True,
) -> pa.Table:
    """Answer rows that name their recording: each recording's rows against that file.

    Args:
        queries: rows with the query columns of :func:`~tfbus.table.lookup` and a
            string column ``recording`` (a path or fsspec URL of each row's file).
        recording: the name of that column.
        window, margin: as :func:`lookup_recording` (None: whole files).
        buffers: whole-file buffers to reuse across calls (window None); default a new
            :class:`RecordingBuffers` for this call.
        keep_columns: as in :func:`~tfbus.table.lookup`.

    Returns:
        The rows in the order of ``queries`` with :data:`~tfbus.table.RESULT_COLUMNS`.
        A row whose recording cannot be read fails with ``status`` the error's class
        (``BagNotFoundError``, ``BagFormatError``, ``BagReadError``) and its message;
        the other recordings' rows are answered.

    Raises:
        ValueError, TypeError: as :func:`~tfbus.table.lookup`; no ``recording`` column.
    """
    import pyarrow as pa

    from tfbus.errors import BagError

    table = as_arrow(queries)
    if recording not in table.column_names:
        raise ValueError(f"queries has no column {recording!r} (the recording of each row)")
    column = table.column(recording)
    if not (pa.types.is_string(column.type) or pa.types.is_large_string(column.type)
            or pa.types.is_dictionary(column.type)):
        raise TypeError(f"queries column {recording!r} must hold paths, got {column.type}")
    cache = buffers if buffers is not None else RecordingBuffers()
    import pyarrow.compute as pc

    encoded = pc.dictionary_encode(pc.fill_null(column.cast(pa.string()), "")).combine_chunks()
    codes = encoded.indices.to_numpy(zero_copy_only=False)
    names = encoded.dictionary.to_pylist()
    parts: list[pa.Table] = []
    order: list[npt.NDArray[np.int64]] = []
    # Each recording's row indices (a stable sort by code); a recording whose rows are
    # consecutive (rows grouped by recording, as balanced_blocks makes them) is a slice,
    # not a copy.
    by_code = np.argsort(codes, kind="stable")
    bounds = np.concatenate(([0], np.cumsum(np.bincount(codes, minlength=len(names)))))
    for code, name in enumerate(names):
        rows = by_code[bounds[code]:bounds[code + 1]]
        if rows.size and int(rows[-1]) - int(rows[0]) + 1 == rows.size:
            part = table.slice(int(rows[0]), rows.size)
        else:
            part = table.take(pa.array(rows))
        try:
            if window is None:
                answered = lookup(part, cache.get(name), keep_columns=keep_columns)
            else:
                answered = lookup_recording(name, part, window=window, margin=margin,
                                            keep_columns=keep_columns)
        except BagError as err:
            answered = _failed(part, type(err).__name__, str(err), keep_columns)
        parts.append(answered)
        order.append(rows)
    if not parts:
        return lookup(table, BufferCore(), keep_columns=keep_columns)
    merged = pa.concat_tables(parts)
    placed = np.concatenate(order)
    if np.array_equal(placed, np.arange(table.num_rows)):  # already in the input's order
        return merged
    inverse = np.empty(table.num_rows, dtype=np.int64)
    inverse[placed] = np.arange(table.num_rows)
    return merged.take(pa.array(inverse))


def _failed(part: pa.Table, status: str, message: str, keep_columns: bool) -> pa.Table:
    """Every row of ``part`` failed with ``status`` and ``message`` (NaN values)."""
    import pyarrow as pa

    n = part.num_rows
    columns: dict[str, pa.Array] = {
        name: pa.array(np.full(n, np.nan)) for name in RESULT_COLUMNS[:7]
    }
    stamps = part.column("stamp") if "stamp" in part.column_names else None
    columns["transform_stamp"] = (
        pa.array(np.zeros(n, dtype=np.int64)) if stamps is None or stamps.type != pa.int64()
        else stamps.combine_chunks()
    )
    columns["status"] = pa.array([status] * n, pa.string())
    columns["message"] = pa.array([message] * n, pa.string())
    if not keep_columns:
        return pa.table(columns)
    out = part
    for name, column in columns.items():
        out = out.append_column(name, column)
    return out
