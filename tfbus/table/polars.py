"""tf2 lookups in Polars: a DataFrame in, a DataFrame out, or an expression on a struct
of columns (``map_batches``: one call of the core's batch kernel per batch).

::

    from tfbus.table.polars import lookup, tf_lookup
    poses = lookup(df, buffer)                                   # df: target_frame, ...
    df.with_columns(pose=tf_lookup(buffer)).unnest("pose")       # the same, as a column

Needs the ``table`` extra (pyarrow, polars).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from tfbus._extras import require

require(__name__, "pyarrow", "polars", extra="table")

import polars as pl  # noqa: E402

from tfbus.table import lookups as _lookups  # noqa: E402
from tfbus.table import recordings as _recordings  # noqa: E402

if TYPE_CHECKING:
    from tfbus.core import BufferCore

__all__ = ["lookup", "lookup_by_recording", "result_dtype", "tf_lookup"]


def result_dtype() -> pl.Struct:
    """The Polars struct type of :func:`tf_lookup`'s column: the fields of
    :data:`tfbus.table.RESULT_COLUMNS`."""
    empty = pl.from_arrow(_lookups.result_schema().empty_table())
    assert isinstance(empty, pl.DataFrame)
    return pl.Struct(empty.schema)


def lookup(df: pl.DataFrame | pl.LazyFrame, buffer: BufferCore, *,
           keep_columns: bool = True) -> pl.DataFrame:
    """:func:`tfbus.table.lookup` on a Polars DataFrame (a LazyFrame is collected):
    the query columns (``target_frame``, ``source_frame``, ``stamp``, optional
    ``fixed_frame`` / ``source_stamp``) in, the same rows with the result columns out.

    Raises:
        ValueError, TypeError: as :func:`tfbus.table.lookup`.
    """
    frame = df.collect() if isinstance(df, pl.LazyFrame) else df
    out = pl.from_arrow(_lookups.lookup(frame.to_arrow(), buffer, keep_columns=keep_columns))
    assert isinstance(out, pl.DataFrame)
    return out


def lookup_by_recording(df: pl.DataFrame | pl.LazyFrame, **options: Any) -> pl.DataFrame:
    """:func:`tfbus.table.lookup_by_recording` on a Polars DataFrame (rows with a
    ``recording`` column); ``options`` as that function's."""
    frame = df.collect() if isinstance(df, pl.LazyFrame) else df
    out = pl.from_arrow(_recordings.lookup_by_recording(frame.to_arrow(), **options))
    assert isinstance(out, pl.DataFrame)
    return out


def tf_lookup(
    buffer: BufferCore,
    target_frame: str | pl.Expr = "target_frame",
    source_frame: str | pl.Expr = "source_frame",
    stamp: str | pl.Expr = "stamp",
) -> pl.Expr:
    """An expression whose value is a struct column of the lookup's result per row
    (:func:`result_dtype`: ``x .. qw``, ``transform_stamp``, ``status``, ``message``).

    Args:
        buffer: the BufferCore to ask.
        target_frame, source_frame, stamp: column names or expressions (strings, strings,
            int64 ns or a Datetime).

    Each batch Polars hands to ``map_batches`` is one :func:`tfbus.table.lookup` call.
    """

    def answer(batch: pl.Series) -> pl.Series:
        frame = batch.struct.unnest()
        frame.columns = ["target_frame", "source_frame", "stamp"]
        result = _lookups.lookup(frame.to_arrow(), buffer, keep_columns=False)
        answered = pl.from_arrow(result)
        assert isinstance(answered, pl.DataFrame)
        return answered.to_struct(batch.name)

    return pl.struct(
        pl.col(target_frame) if isinstance(target_frame, str) else target_frame,
        pl.col(source_frame) if isinstance(source_frame, str) else source_frame,
        pl.col(stamp) if isinstance(stamp, str) else stamp,
    ).map_batches(answer, return_dtype=result_dtype())
