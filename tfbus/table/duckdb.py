"""tf2 lookups in DuckDB SQL: a vectorised UDF (``type="arrow"``: one call of the core's
batch kernel per DuckDB vector) returning a struct of the lookup's result.

::

    import duckdb
    from tfbus.table.duckdb import register, register_recordings
    con = duckdb.connect()
    register(con, buffer)                  # tf_lookup(target_frame, source_frame, stamp)
    con.sql("SELECT q.*, unnest(tf_lookup(target_frame, source_frame, stamp)) FROM q")
    register_recordings(con)               # tf_lookup_recording(path, target, source, stamp)

Needs the ``table`` extra (pyarrow, duckdb).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from tfbus._extras import require

require(__name__, "pyarrow", "duckdb", extra="table")

import duckdb  # noqa: E402
import pyarrow as pa  # noqa: E402

from tfbus.table import lookups as _lookups  # noqa: E402
from tfbus.table import recordings as _recordings  # noqa: E402

if TYPE_CHECKING:
    from tfbus.core import BufferCore

__all__ = ["lookup_relation", "register", "register_recordings", "result_type"]


def result_type() -> Any:
    """DuckDB's ``STRUCT(x DOUBLE, ..., transform_stamp BIGINT, status VARCHAR,
    message VARCHAR)``: the UDFs' return type (:data:`tfbus.table.RESULT_COLUMNS`)."""
    fields = {
        name: duckdb.sqltype("BIGINT" if name == "transform_stamp" else
                             "VARCHAR" if name in ("status", "message") else "DOUBLE")
        for name in _lookups.RESULT_COLUMNS
    }
    return duckdb.struct_type(fields)


def _struct(result: pa.Table) -> pa.StructArray:
    return pa.StructArray.from_arrays(
        [result.column(name).combine_chunks() for name in _lookups.RESULT_COLUMNS],
        names=list(_lookups.RESULT_COLUMNS),
    )


def register(con: duckdb.DuckDBPyConnection, buffer: BufferCore, *,
             name: str = "tf_lookup") -> None:
    """Register ``name(target_frame VARCHAR, source_frame VARCHAR, stamp BIGINT)`` on
    ``con``, answering against ``buffer`` (:func:`tfbus.table.lookup` per vector).

    A NULL argument is a row error (``InvalidArgumentException``), not a NULL result.
    """

    def answer(targets: Any, sources: Any, stamps: Any) -> pa.StructArray:
        table = pa.table({"target_frame": targets, "source_frame": sources, "stamp": stamps})
        return _struct(_lookups.lookup(table, buffer, keep_columns=False))

    connection: Any = con  # (duckdb's stubs take the UDF kinds as its own enum values)
    connection.create_function(name, answer, ["VARCHAR", "VARCHAR", "BIGINT"], result_type(),
                               type="arrow", null_handling="special", side_effects=False)


def register_recordings(
    con: duckdb.DuckDBPyConnection,
    *,
    name: str = "tf_lookup_recording",
    buffers: _recordings.RecordingBuffers | None = None,
) -> _recordings.RecordingBuffers:
    """Register ``name(recording VARCHAR, target_frame VARCHAR, source_frame VARCHAR,
    stamp BIGINT)``: each row against its recording, read whole and kept in ``buffers``
    (default: the 2 most recently used recordings), so sort the rows by recording.

    Returns:
        The :class:`~tfbus.table.RecordingBuffers` in use (its ``loads`` counts reads).
    """
    cache = buffers if buffers is not None else _recordings.RecordingBuffers()

    def answer(paths: Any, targets: Any, sources: Any, stamps: Any) -> pa.StructArray:
        table = pa.table({"recording": paths, "target_frame": targets,
                          "source_frame": sources, "stamp": stamps})
        return _struct(_recordings.lookup_by_recording(table, buffers=cache,
                                                       keep_columns=False))

    connection: Any = con
    connection.create_function(name, answer, ["VARCHAR", "VARCHAR", "VARCHAR", "BIGINT"],
                               result_type(), type="arrow", null_handling="special",
                               side_effects=False)
    return cache


def lookup_relation(con: duckdb.DuckDBPyConnection, relation: Any,
                    buffer: BufferCore) -> Any:
    """A DuckDB relation (or SQL text) of queries answered whole through
    :func:`tfbus.table.lookup`: the relation of its rows with the result columns."""
    rel = con.sql(relation) if isinstance(relation, str) else relation
    return con.from_arrow(_lookups.lookup(rel.arrow(), buffer))
