"""tf2 lookups in DuckDB SQL: a vectorised UDF (``type="arrow"``: one call of the core's
batch kernel per DuckDB vector) returning a struct of the lookup's result, and a table
macro of the same name over a table of queries.

::

    import duckdb
    from tfbus.table.duckdb import register, register_recordings
    con = duckdb.connect()
    register(con, buffer)                  # tf_lookup(target_frame, source_frame, stamp)
    con.sql("SELECT q.*, unnest(tf_lookup(target_frame, source_frame, stamp)) FROM q")
    con.sql("SELECT * FROM tf_lookup(q)")  # the same rows: the table macro
    register_recordings(con)               # tf_lookup_recording(path, target, source, stamp)
    con.sql("SELECT * FROM tf_lookup_recording(q)")   # q with a recording column

DuckDB's Python API (1.x, 2.0) registers scalar functions only (``create_function``:
native or Arrow UDFs), not table functions; the ``FROM name(table)`` form is a
temporary table macro (``CREATE TEMP MACRO ... AS TABLE``, DuckDB's SQL) over the UDF
and ``query_table``, so it lives on the connection, as the UDF does.

Needs the ``table`` extra (pyarrow, duckdb).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from tfbus._extras import require

require(__name__, "pyarrow", "duckdb", extra="table")

import re  # noqa: E402

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


_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _checked_name(name: object) -> str:
    """``name`` when it is a plain SQL identifier (it is written into SQL text)."""
    if not isinstance(name, str) or not _IDENTIFIER.fullmatch(name):
        raise ValueError(f"name must be an SQL identifier ([A-Za-z_][A-Za-z0-9_]*), "
                         f"got {name!r}")
    return name


def _table_macro(con: duckdb.DuckDBPyConnection, name: str, body: str) -> None:
    """``CREATE OR REPLACE TEMP MACRO name(queries) AS TABLE body``: ``body`` reads
    ``query_table(queries)``, the table or view named by the macro's argument."""
    con.execute(f"CREATE OR REPLACE TEMP MACRO {name}(queries) AS TABLE {body}")


def register(con: duckdb.DuckDBPyConnection, buffer: BufferCore, *,
             name: str = "tf_lookup") -> None:
    """Register ``name(target_frame VARCHAR, source_frame VARCHAR, stamp BIGINT)`` on
    ``con``, answering against ``buffer`` (:func:`tfbus.table.lookup` per vector), and
    the table macro ``name(queries)``: ``SELECT * FROM name(q)`` is every row of the
    table or view ``q`` (columns ``target_frame``, ``source_frame``, ``stamp`` and any
    others) followed by :data:`tfbus.table.RESULT_COLUMNS`.

    A NULL argument is a row error (``InvalidArgumentException``), not a NULL result.

    Raises:
        ValueError: ``name`` is not an SQL identifier.
    """
    _checked_name(name)

    def answer(targets: Any, sources: Any, stamps: Any) -> pa.StructArray:
        table = pa.table({"target_frame": targets, "source_frame": sources, "stamp": stamps})
        return _struct(_lookups.lookup(table, buffer, keep_columns=False))

    connection: Any = con  # (duckdb's stubs take the UDF kinds as its own enum values)
    connection.create_function(name, answer, ["VARCHAR", "VARCHAR", "BIGINT"], result_type(),
                               type="arrow", null_handling="special", side_effects=False)
    _table_macro(con, name, "SELECT *, unnest("
                 f"{name}(target_frame, source_frame, stamp)) FROM query_table(queries)")


def register_recordings(
    con: duckdb.DuckDBPyConnection,
    *,
    name: str = "tf_lookup_recording",
    buffers: _recordings.RecordingBuffers | None = None,
) -> _recordings.RecordingBuffers:
    """Register ``name(recording VARCHAR, target_frame VARCHAR, source_frame VARCHAR,
    stamp BIGINT)``: each row against its recording, read whole and kept in ``buffers``
    (default: the 2 most recently used recordings), so sort the rows by recording; and
    the table macro ``name(queries)``: ``SELECT * FROM name(q)`` is every row of ``q``
    (``recording``, ``target_frame``, ``source_frame``, ``stamp`` and any others),
    ordered by ``recording``, followed by :data:`tfbus.table.RESULT_COLUMNS`.

    Returns:
        The :class:`~tfbus.table.RecordingBuffers` in use (its ``loads`` counts reads).

    Raises:
        ValueError: ``name`` is not an SQL identifier.
    """
    _checked_name(name)
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
    _table_macro(con, name, "SELECT *, unnest("
                 f"{name}(recording, target_frame, source_frame, stamp)) "
                 "FROM (SELECT * FROM query_table(queries) ORDER BY recording)")
    return cache


def lookup_relation(con: duckdb.DuckDBPyConnection, relation: Any,
                    buffer: BufferCore) -> Any:
    """A DuckDB relation (or SQL text) of queries answered whole through
    :func:`tfbus.table.lookup`: the relation of its rows with the result columns."""
    rel = con.sql(relation) if isinstance(relation, str) else relation
    return con.from_arrow(_lookups.lookup(rel.arrow(), buffer))
