"""tf2 lookups as a table operator: an Arrow table of queries in, an Arrow table of poses
out, row for row.

:func:`lookup` groups the rows by frame pair, hands each group's ``stamp`` column to the
core's batch kernel (``batch_lookup``: the path is resolved once per pair, every row is
the single lookup's walk, bit for bit ``BufferCore.lookup_transform``) and answers each
row it cannot with the single lookup itself, so a failed row carries tf2's exception
class and text (``status``, ``message``). One bad row never raises.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import numpy.typing as npt

from tfbus.core import BufferCore, _pybatch, _pycore
from tfbus.core.batch import TransformArray, compose_rows, single_lookups
from tfbus.core.kernels import CoreBase, batch_lookup
from tfbus.errors import TransformException
from tfbus.time import Time

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = [
    "OK",
    "QUERY_COLUMNS",
    "RESULT_COLUMNS",
    "as_arrow",
    "lookup",
    "result_schema",
]

OK: Final = "ok"
"""The ``status`` of a row that was answered."""

QUERY_COLUMNS: Final = ("target_frame", "source_frame", "stamp")
"""The columns every query table has: two frame ids (strings) and ``stamp`` (int64 ns or
an Arrow timestamp; 0 means the latest common time, as in tf2). Optional:
``fixed_frame`` and ``source_stamp`` (a full lookup, tf2's time travel)."""

RESULT_COLUMNS: Final = (
    "x", "y", "z", "qx", "qy", "qz", "qw", "transform_stamp", "status", "message",
)
"""The columns :func:`lookup` adds: translation (m) and rotation (x, y, z, w) as float64,
``transform_stamp`` (int64 ns, the time used: the latest common time for a stamp of 0),
``status`` (``"ok"`` or tf2's exception class name) and ``message`` (tf2's text; null for
an answered row)."""

_INVALID: Final = "InvalidArgumentException"

_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]
_Batch = Callable[[Any, str, str, _I64, _F64, _I64, npt.NDArray[np.int8]], int]


def result_schema() -> pa.Schema:
    """The Arrow schema of the columns :func:`lookup` adds (:data:`RESULT_COLUMNS`)."""
    import pyarrow as pa

    return pa.schema(
        [(name, pa.float64()) for name in RESULT_COLUMNS[:7]]
        + [("transform_stamp", pa.int64()), ("status", pa.string()), ("message", pa.string())]
    )


def as_arrow(queries: object) -> pa.Table:
    """``queries`` as a :class:`pyarrow.Table`: an Arrow table or record batch as it is,
    a Polars DataFrame through ``to_arrow()``, a pandas DataFrame through
    ``Table.from_pandas``, anything with ``__arrow_c_stream__`` (Arrow's PyCapsule
    interface) through ``pa.table``.

    Raises:
        TypeError: none of those.
    """
    import pyarrow as pa

    if isinstance(queries, pa.Table):
        return queries
    if isinstance(queries, pa.RecordBatch):
        return pa.Table.from_batches([queries])
    module = type(queries).__module__.split(".")[0]
    if module == "polars" and hasattr(queries, "to_arrow"):
        table = queries.to_arrow()
        assert isinstance(table, pa.Table)
        return table
    if module == "pandas":
        return pa.Table.from_pandas(queries, preserve_index=False)
    if hasattr(queries, "__arrow_c_stream__"):
        return pa.table(queries)
    raise TypeError(
        "queries must be a pyarrow Table or RecordBatch, a polars or pandas DataFrame, "
        f"got {type(queries).__name__}"
    )


def _batch_for(core: BufferCore) -> _Batch:
    """The batch kernel of the core ``core`` is built on (a buffer over the pure-Python
    core's CoreBase in a process whose selected core is the compiled one, as the twin
    tests build, takes the pure kernel)."""
    if isinstance(core, CoreBase):
        return batch_lookup
    if isinstance(core, _pycore.CoreBase):
        return _pybatch.batch_lookup
    raise TypeError(f"buffer must be a tfbus BufferCore, got {type(core).__name__}")


def _column(table: pa.Table, name: str, required: bool) -> pa.ChunkedArray | None:
    """Column ``name`` of ``table``; None when it is absent and optional.

    Raises:
        ValueError: a required column is absent (the message names it and the columns).
    """
    if name not in table.column_names:
        if required:
            raise ValueError(
                f"queries has no column {name!r} (needs {', '.join(QUERY_COLUMNS)}; "
                f"got {', '.join(table.column_names) or 'no columns'})"
            )
        return None
    return table.column(name)


def _frame_codes(table: pa.Table, name: str, required: bool) -> tuple[_I64, list[str]] | None:
    """A string column as (int64 codes, the distinct ids); a null id is the empty
    string (tf2: "frame_ids cannot be empty")."""
    import pyarrow as pa
    import pyarrow.compute as pc

    col = _column(table, name, required)
    if col is None:
        return None
    kind = col.type.value_type if pa.types.is_dictionary(col.type) else col.type
    if not (pa.types.is_string(kind) or pa.types.is_large_string(kind)
            or pa.types.is_null(kind) or getattr(pa.types, "is_string_view", bool)(kind)):
        raise TypeError(f"queries column {name!r} must hold strings, got {col.type}")
    if pa.types.is_null(kind):
        col = pa.chunked_array([pa.array([""] * len(col), pa.string())])
    if col.null_count:
        col = pc.fill_null(col.cast(pa.string()), "")
    if not pa.types.is_dictionary(col.type):
        col = pc.dictionary_encode(col)
    encoded = col.combine_chunks() if col.num_chunks != 1 else col.chunk(0)
    if encoded.dictionary.type != pa.string():
        # (large_string or string_view values: the same ids as Python strings)
        encoded = pa.DictionaryArray.from_arrays(encoded.indices,
                                                 encoded.dictionary.cast(pa.string()))
    codes = encoded.indices.to_numpy(zero_copy_only=False).astype(np.int64, copy=False)
    return codes, encoded.dictionary.to_pylist()


def _stamps(
    table: pa.Table, name: str, required: bool
) -> tuple[_I64, npt.NDArray[np.bool_]] | None:
    """A stamp column as (int64 ns, valid-row mask): int64 viewed without a copy when it
    has one chunk and no nulls; unsigned and timestamp types converted to ns."""
    import pyarrow as pa
    import pyarrow.compute as pc

    col = _column(table, name, required)
    if col is None:
        return None
    if pa.types.is_timestamp(col.type):
        col = col.cast(pa.timestamp("ns", col.type.tz)).cast(pa.int64())
    elif pa.types.is_integer(col.type) and col.type != pa.int64():
        try:
            col = col.cast(pa.int64())
        except pa.ArrowInvalid:
            raise ValueError(
                f"queries column {name!r} has stamps beyond int64 nanoseconds"
            ) from None
    elif not pa.types.is_null(col.type) and col.type != pa.int64():
        raise TypeError(
            f"queries column {name!r} must be int64 nanoseconds or an Arrow timestamp, "
            f"got {col.type}"
        )
    if pa.types.is_null(col.type):
        n = len(col)
        return np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool)
    arr = col.combine_chunks() if col.num_chunks != 1 else col.chunk(0)
    if arr.null_count == 0:
        values = arr.to_numpy(zero_copy_only=True)  # a view of the Arrow buffer
        return values, np.ones(len(arr), dtype=bool)
    valid = arr.is_valid().to_numpy(zero_copy_only=False)
    values = pc.fill_null(arr, 0).to_numpy(zero_copy_only=False)
    return values, valid


class _Rows:
    """The output columns being filled: (7, N) values (one contiguous row per output
    column, handed to Arrow without a copy), stamps, status codes, messages."""

    def __init__(self, n: int) -> None:
        self.values = np.full((7, n), np.nan)
        self.stamps = np.zeros(n, dtype=np.int64)
        self.status = np.zeros(n, dtype=np.int32)  # index into self.names; 0 = ok
        self.message = np.full(n, -1, dtype=np.int32)  # index into self.texts; -1 = null
        self.names: dict[str, int] = {OK: 0}
        self.texts: dict[str, int] = {}

    def fail(self, rows: _I64 | int, name: str, text: str) -> None:
        self.status[rows] = self.names.setdefault(name, len(self.names))
        self.message[rows] = self.texts.setdefault(text, len(self.texts))
        self.values[:, rows] = np.nan

    def fail_with(self, rows: _I64 | int, exc: TransformException) -> None:
        self.fail(rows, type(exc).__name__, str(exc))

    def columns(self) -> dict[str, pa.Array]:
        import pyarrow as pa

        n = self.stamps.shape[0]
        out: dict[str, pa.Array] = {
            name: pa.array(self.values[k])  # (a contiguous float64 row: no copy)
            for k, name in enumerate(RESULT_COLUMNS[:7])
        }
        out["transform_stamp"] = pa.array(self.stamps)
        if len(self.names) == 1:
            # Every row answered: "ok" n times built from its buffers, no null messages.
            offsets = np.arange(0, 2 * n + 1, 2, dtype=np.int32)
            out["status"] = pa.StringArray.from_buffers(
                n, pa.py_buffer(offsets), pa.py_buffer(OK.encode() * n))
            out["message"] = pa.nulls(n, pa.string())
            return out
        out["status"] = pa.DictionaryArray.from_arrays(
            pa.array(self.status), pa.array(list(self.names), pa.string())
        ).cast(pa.string())
        mask = self.message < 0
        out["message"] = pa.DictionaryArray.from_arrays(
            pa.array(np.where(mask, 0, self.message), mask=mask),
            pa.array(list(self.texts) or [""], pa.string()),
        ).cast(pa.string())
        return out


def _answer_pair(
    core: BufferCore,
    batch: _Batch,
    rows: _Rows,
    idx: _I64,
    target: str,
    source: str,
    times: _I64,
) -> None:
    """Rows ``idx`` (times ``times``) of one frame pair: the batch kernel, then the single
    lookup for each row it did not answer (tf2's exception and text by construction)."""
    n = times.shape[0]
    out = np.empty((n, 7))
    stamps = np.array(times, dtype=np.int64, copy=True)
    ok = np.empty(n, dtype=np.int8)
    if target == source:
        # The identity for any string (time 0: the frame's latest stamp); no kernel call.
        try:
            array = core.lookup_transforms(target, source, times, errors="mask")
        except TransformException as exc:
            rows.fail_with(idx, exc)
            return
        _store(core, rows, idx, target, source, times, array)
        return
    answered = batch(core, target, source, times, out, stamps, ok)
    if answered < 0:
        # An invalid or unknown id: tf2 validates the ids before it looks at the time,
        # so the single lookup's exception at the first time holds for every row.
        try:
            core.lookup_transform(target, source, Time.from_ns(int(times[0])))
        except TransformException as exc:
            rows.fail_with(idx, exc)
            return
        _fail_rows(core, rows, idx, target, source, times, np.ones(n, dtype=bool))
        return
    rows.values[:, idx] = out.T
    rows.stamps[idx] = stamps
    if answered != n:
        _fail_rows(core, rows, idx, target, source, times, ok == 0)


def _store(
    core: BufferCore,
    rows: _Rows,
    idx: _I64,
    target: str,
    source: str,
    times: _I64,
    array: TransformArray,
) -> None:
    rows.values[:3, idx] = array.translations.T
    rows.values[3:, idx] = array.rotations.T
    rows.stamps[idx] = array.stamps
    if not array.valid.all():
        _fail_rows(core, rows, idx, target, source, times, ~array.valid)


def _fail_rows(
    core: BufferCore,
    rows: _Rows,
    idx: _I64,
    target: str,
    source: str,
    times: _I64,
    bad: npt.NDArray[np.bool_],
) -> None:
    """Each failed row's exception from the single lookup (one call per distinct time)."""
    for i, found in single_lookups(
        core.lookup_transform, target, source, times, np.flatnonzero(bad).tolist()
    ):
        if isinstance(found, TransformException):
            rows.fail_with(int(idx[i]), found)
        else:  # (the kernel and the single walk agree: not reached)
            (x, y, z), (qx, qy, qz, qw) = found.transform
            rows.values[:, int(idx[i])] = (x, y, z, qx, qy, qz, qw)
            rows.stamps[int(idx[i])] = found.header.stamp.ns


def _answer_full(
    core: BufferCore,
    batch: _Batch,
    rows: _Rows,
    idx: _I64,
    target: str,
    source: str,
    fixed: str,
    times: _I64,
    source_times: _I64,
) -> None:
    """Rows of one (target, source, fixed) triple: ``lookup_transform_full``'s two legs
    through the batch kernel, composed as the single call composes them
    (:func:`~tfbus.core.batch.compose_rows`); failed rows from the single call."""
    frames = (target, source, fixed)
    if not all(core.invalid_frame_id(f) is None and core.frame_exists(f) for f in frames):
        try:
            core.lookup_transform_full(target, Time(), source, Time(), fixed)
        except TransformException as exc:
            rows.fail_with(idx, exc)
            return
    leg1 = _leg(core, batch, fixed, source, source_times)
    leg2 = _leg(core, batch, target, fixed, times)
    composed = compose_rows(leg2, leg1)
    rows.values[:3, idx] = composed.translations.T
    rows.values[3:, idx] = composed.rotations.T
    rows.stamps[idx] = composed.stamps
    bad = ~composed.valid
    for i in np.flatnonzero(bad).tolist():
        try:
            core.lookup_transform_full(
                target, Time.from_ns(int(times[i])), source, Time.from_ns(int(source_times[i])),
                fixed,
            )
        except TransformException as exc:
            rows.fail_with(int(idx[i]), exc)


def _leg(core: BufferCore, batch: _Batch, target: str, source: str, times: _I64) -> TransformArray:
    """One leg of a full lookup for every time, masked rows invalid (the batch kernel;
    equal ids through ``lookup_transforms``)."""
    n = times.shape[0]
    if target == source:
        return core.lookup_transforms(target, source, times, errors="mask")
    out = np.full((n, 7), np.nan)
    stamps = np.array(times, dtype=np.int64, copy=True)
    ok = np.zeros(n, dtype=np.int8)
    batch(core, target, source, times, out, stamps, ok)
    valid = ok.astype(bool)
    out[~valid] = np.nan
    return TransformArray(stamps, out[:, :3], out[:, 3:], target, source, valid)



def _pair_groups(key: _I64, good: npt.NDArray[np.bool_], stamps: _I64) -> list[_I64 | None]:
    """The rows of each pair key (``good`` rows only), each group in time order; ``[None]``
    when every row is good, of one key and already in time order (no index needed).

    O(N) apart from the sort of each group's stamps: the keys are compacted through a
    count of each key (not ``np.unique``'s sort), grouped by a stable radix argsort of
    the compact keys, then each group's stamps are sorted on their own (the groups'
    sorts together cost less than one sort of every stamp), skipped when in order."""
    n = key.shape[0]
    if n == 0:
        return []
    lo, hi = int(key.min()), int(key.max())
    all_good = bool(good.all())
    if all_good and lo == hi:
        if bool(np.all(stamps[1:] >= stamps[:-1])):
            return [None]
        return [np.argsort(stamps).astype(np.int64, copy=False)]
    if hi - lo < 1 << 22:
        counts = np.bincount(key - lo, minlength=hi - lo + 1)
        present = np.flatnonzero(counts)
        table = np.zeros(hi - lo + 1, dtype=np.int64)
        table[present] = np.arange(present.size, dtype=np.int64)
        compact = table[key - lo]
    else:
        _, compact = np.unique(key, return_inverse=True)
        compact = compact.reshape(-1).astype(np.int64, copy=False)
    n_keys = int(compact.max()) + 1
    if not all_good:
        compact = np.where(good, compact, n_keys)  # (the rows already failed: last, dropped)
    small = compact.astype(np.uint16) if n_keys < 2**16 - 1 else compact
    order = np.argsort(small, kind="stable").astype(np.int64, copy=False)
    sizes = np.bincount(compact, minlength=n_keys + 1)[:n_keys]
    ends = np.cumsum(sizes)
    groups: list[_I64 | None] = []
    start = 0
    for end in ends.tolist():
        if end > start:
            idx = order[start:end]
            times = stamps[idx]
            if not bool(np.all(times[1:] >= times[:-1])):
                idx = idx[np.argsort(times)]
            groups.append(idx)
        start = end
    return groups


def lookup(queries: object, buffer: BufferCore, *, keep_columns: bool = True) -> pa.Table:
    """Answer a table of lookups against ``buffer``, row for row.

    Args:
        queries: a :class:`pyarrow.Table` (or RecordBatch, Polars or pandas DataFrame)
            with ``target_frame`` and ``source_frame`` (strings) and ``stamp`` (int64
            nanoseconds or an Arrow timestamp; 0 means the latest common time). Optional
            ``fixed_frame`` (string) and ``source_stamp`` (ns): a row whose
            ``fixed_frame`` is not null is ``lookup_transform_full(target_frame, stamp,
            source_frame, source_stamp, fixed_frame)`` (a null ``source_stamp``: ``stamp``).
        buffer: the :class:`~tfbus.core.BufferCore` (or Buffer) to ask.
        keep_columns: return the query's columns (as they are, not copied) followed by
            the result's; False: the result's alone.

    Returns:
        An Arrow table with one row per query row, in order, with
        :data:`RESULT_COLUMNS`: ``x, y, z`` (m), ``qx, qy, qz, qw`` (float64),
        ``transform_stamp`` (int64 ns), ``status`` (``"ok"`` or the tf2 exception class
        the single lookup raises for that row, e.g. ``LookupException``,
        ``ForwardExtrapolationException``) and ``message`` (its text, tf2 0.7.6's; null
        when ok). A failed row's values are NaN. A row with a null or negative stamp is
        ``InvalidArgumentException`` naming the column and value.

    Raises:
        ValueError: a required column is missing, a result column name is already a
            query column (with ``keep_columns``), or stamps exceed int64 ns.
        TypeError: ``queries`` is not a table, a column has the wrong type, or
            ``buffer`` is not a BufferCore.

    Each answered row is bit for bit ``buffer.lookup_transform(target_frame,
    source_frame, Time.from_ns(stamp))`` (``lookup_transform_full`` for full rows): the
    rows of a frame pair go through the core's ``batch_lookup`` (tf2
    ``BufferCore::lookupTransform`` / ``walkToTopParent`` per time, the path resolved
    once, the rows of a pair in time order); a ``stamp`` column of int64 without nulls
    in one chunk, already in time order, is handed to it without a copy when the table
    has one frame pair.
    """
    import pyarrow as pa

    batch = _batch_for(buffer)
    table = as_arrow(queries)
    if keep_columns:
        clash = sorted(set(RESULT_COLUMNS) & set(table.column_names))
        if clash:
            raise ValueError(
                f"queries already has result column(s) {', '.join(clash)}: rename them or "
                "pass keep_columns=False"
            )
    targets = _frame_codes(table, "target_frame", True)
    sources = _frame_codes(table, "source_frame", True)
    stamped = _stamps(table, "stamp", True)
    assert targets is not None and sources is not None and stamped is not None
    fixed = _frame_codes(table, "fixed_frame", False)
    source_stamped = _stamps(table, "source_stamp", False)
    n = table.num_rows
    rows = _Rows(n)
    t_codes, t_names = targets
    s_codes, s_names = sources
    stamps, stamp_ok = stamped
    rows.stamps[:] = np.where(stamp_ok, stamps, 0)
    good = stamp_ok & (stamps >= 0)
    for i in np.flatnonzero(~good).tolist():
        value = "null" if not stamp_ok[i] else str(int(stamps[i]))
        rows.fail(i, _INVALID, f"queries row {i}: stamp must be >= 0 ns, got {value}")
    if source_stamped is not None:
        src_stamps, src_ok = source_stamped
        src_stamps = np.where(src_ok, src_stamps, stamps)
    else:
        src_stamps = stamps
    key = t_codes * len(s_names) + s_codes
    if fixed is not None:
        f_codes, f_names = fixed
        # A null fixed_frame (code of "" only when it was null or empty) is a plain lookup.
        has_fixed = np.asarray(
            table.column("fixed_frame").is_valid().to_numpy(zero_copy_only=False), dtype=bool
        )
        f_key = np.where(has_fixed, f_codes + 1, 0)
        key = key * (len(f_names) + 1) + f_key
        bad_src = has_fixed & good & (src_stamps < 0)
        for i in np.flatnonzero(bad_src).tolist():
            rows.fail(i, _INVALID, f"queries row {i}: source_stamp must be >= 0 ns, "
                                   f"got {int(src_stamps[i])}")
        good = good & ~bad_src
    else:
        f_key = None
        f_names = []
    # Each frame pair's rows go to the kernel in time order (its walk then moves forward
    # through each link's samples: about twice as fast as random order).
    groups = _pair_groups(key, good, stamps)
    in_place = len(groups) == 1 and groups[0] is None
    if in_place:
        groups = [np.arange(n, dtype=np.int64)]  # the stamp column itself goes to the kernel
    for idx in groups:
        assert idx is not None
        first = int(idx[0])
        target = t_names[int(t_codes[first])]
        source = s_names[int(s_codes[first])]
        times = stamps if in_place else stamps[idx]
        if f_key is not None and f_key[first]:
            fixed_id = f_names[int(f_key[first]) - 1]
            src_times = src_stamps if in_place else src_stamps[idx]
            _answer_full(buffer, batch, rows, idx, target, source, fixed_id,
                         np.ascontiguousarray(times), np.ascontiguousarray(src_times))
        else:
            _answer_pair(buffer, batch, rows, idx, target, source, np.ascontiguousarray(times))
    result = rows.columns()
    if not keep_columns:
        return pa.table(result)
    out = table
    for name, column in result.items():
        out = out.append_column(name, column)
    return out
