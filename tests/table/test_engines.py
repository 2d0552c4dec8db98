"""The engines (Polars, DuckDB; Ray and Dask in their own files) on 20 generated
recordings agree with the plain path: each recording's rows looked up with
``tfbus.table.lookup`` against ``load_buffer`` of that recording."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
pytest.importorskip("rosbags")

from table_recordings import (  # noqa: E402
    N_RECORDINGS,
    SEC,
    START,
    fleet,
    fleet_queries,
    plain,
    same_table,
)

from tfbus.bag import load_buffer  # noqa: E402
from tfbus.table import (  # noqa: E402
    RESULT_COLUMNS,
    RecordingBuffers,
    lookup,
    lookup_by_recording,
    lookup_recording,
)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    return fleet(tmp_path_factory.mktemp("fleet20"))


@pytest.fixture(scope="module")
def expected(recordings: list[Path]) -> tuple[Any, Any]:
    queries = fleet_queries(recordings)
    return queries, plain(queries)


def test_lookup_by_recording_is_the_plain_path(expected: tuple[Any, Any]) -> None:
    queries, want = expected
    buffers = RecordingBuffers(maxsize=3)
    got = lookup_by_recording(queries, buffers=buffers)
    assert same_table(got, want)
    assert buffers.loads == N_RECORDINGS  # each recording read once
    statuses = set(want.column("status").to_pylist())
    assert {"ok", "LookupException", "ForwardExtrapolationException"} <= statuses


def test_windowed_rows_are_the_whole_file_rows_where_it_answers(
    expected: tuple[Any, Any],
) -> None:
    queries, want = expected
    got = lookup_by_recording(queries, window=3.0, margin=4.0).to_pylist()
    for g, w in zip(got, want.to_pylist(), strict=True):
        if w["status"] == "ok":
            assert g == w
        else:
            assert g["status"] != "ok"


def test_lookup_recording_by_window_reads_windows_not_the_file(
    recordings: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    import tfbus.bag

    path = recordings[0]
    seen: list[tuple[Any, Any]] = []
    original = tfbus.bag.load_buffer

    def spy(p: Any, **kw: Any) -> Any:
        seen.append((kw.get("start"), kw.get("end")))
        return original(p, **kw)

    monkeypatch.setattr(tfbus.bag, "load_buffer", spy)
    q = pa.table({"target_frame": ["map"] * 3, "source_frame": ["laser"] * 3,
                  "stamp": pa.array([START + 2 * SEC, START + 2 * SEC + 5, START + 9 * SEC],
                                    pa.int64())})
    got = lookup_recording(path, q, window=1.0, margin=2.0)
    assert [(s.ns, e.ns) for s, e in seen] == [
        (START, START + 5 * SEC), (START + 7 * SEC, START + 12 * SEC)]
    whole = lookup(q, original(path))
    assert same_table(got, whole)


def test_a_recording_that_cannot_be_read_fails_its_rows_only(
    recordings: list[Path], tmp_path: Path
) -> None:
    q = pa.table({"recording": [str(recordings[1]), str(tmp_path / "missing.mcap")],
                  "target_frame": ["map", "map"], "source_frame": ["laser", "laser"],
                  "stamp": pa.array([START + 3 * SEC] * 2, pa.int64())})
    rows = lookup_by_recording(q).to_pylist()
    assert rows[0]["status"] == "ok"
    assert rows[1]["status"] == "BagNotFoundError"
    assert "missing.mcap: no such file or directory" in rows[1]["message"]
    with pytest.raises(ValueError, match="no column 'recording'"):
        lookup_by_recording(q.drop_columns(["recording"]))


def test_polars(expected: tuple[Any, Any], recordings: list[Path]) -> None:
    pl = pytest.importorskip("polars")
    from tfbus.table import polars as tpl

    queries, want = expected
    got = tpl.lookup_by_recording(pl.from_arrow(queries)).to_arrow().cast(want.schema)
    assert same_table(got, want)
    # The expression form, against one recording's buffer.
    path = str(recordings[2])
    mine = queries.filter(pa.compute.equal(queries.column("recording"), path))
    buffer = load_buffer(path)
    frame = pl.from_arrow(mine).lazy().with_columns(pose=tpl.tf_lookup(buffer)).unnest(
        "pose").collect()
    assert same_table(frame.to_arrow().cast(want.schema), lookup(mine, buffer))
    assert same_table(tpl.lookup(pl.from_arrow(mine), buffer).to_arrow().cast(want.schema),
                      lookup(mine, buffer))


def test_duckdb(expected: tuple[Any, Any], recordings: list[Path]) -> None:
    duckdb = pytest.importorskip("duckdb")
    from tfbus.table import duckdb as tdb

    queries, want = expected
    con = duckdb.connect()
    try:
        buffers = tdb.register_recordings(con)
        q = queries.append_column("i", pa.array(np.arange(queries.num_rows)))
        con.register("q", q)
        got = con.sql(
            "SELECT recording, target_frame, source_frame, stamp, "
            "unnest(tf_lookup_recording(recording, target_frame, source_frame, stamp)) "
            "FROM (SELECT * FROM q ORDER BY recording, i) ORDER BY i").arrow()
        got = got.read_all() if hasattr(got, "read_all") else got
        assert same_table(got.cast(want.schema), want)
        assert buffers.loads == N_RECORDINGS
        path = str(recordings[4])
        buffer = load_buffer(path)
        tdb.register(con, buffer)
        mine = queries.filter(pa.compute.equal(queries.column("recording"), path))
        con.register("mine", mine.drop_columns(["recording"]))
        one = con.sql("SELECT target_frame, source_frame, stamp, "
                      "unnest(tf_lookup(target_frame, source_frame, stamp)) FROM mine").arrow()
        one = one.read_all() if hasattr(one, "read_all") else one
        ref = lookup(mine.drop_columns(["recording"]), buffer)
        assert same_table(one.cast(ref.schema), ref)
        rel = tdb.lookup_relation(con, "SELECT * FROM mine", buffer).arrow()
        rel = rel.read_all() if hasattr(rel, "read_all") else rel
        assert same_table(rel.cast(ref.schema), ref)
        assert list(RESULT_COLUMNS) == rel.column_names[-len(RESULT_COLUMNS):]
    finally:
        con.close()


def test_duckdb_table_macros_select_from_tf_lookup(
    expected: tuple[Any, Any], recordings: list[Path]
) -> None:
    duckdb = pytest.importorskip("duckdb")
    from tfbus.table import duckdb as tdb

    queries, want = expected
    con = duckdb.connect()
    try:
        buffers = tdb.register_recordings(con)
        con.register("q", queries.append_column("i", pa.array(np.arange(queries.num_rows))))
        got = con.sql("SELECT * FROM tf_lookup_recording(q) ORDER BY i").arrow()
        got = got.read_all() if hasattr(got, "read_all") else got
        assert got.column_names == [*queries.column_names, "i", *RESULT_COLUMNS]
        assert same_table(got.drop_columns(["i"]).cast(want.schema), want)
        assert buffers.loads == N_RECORDINGS  # the macro orders the rows by recording
        path = str(recordings[7])
        buffer = load_buffer(path)
        tdb.register(con, buffer)
        mine = queries.filter(pa.compute.equal(queries.column("recording"), path))
        mine = mine.drop_columns(["recording"])
        con.register("mine", mine)
        con.execute("CREATE TEMP VIEW late AS SELECT * FROM mine WHERE stamp > "
                    f"{START + 10 * SEC}")
        one = con.sql("SELECT * FROM tf_lookup(mine)").arrow()
        one = one.read_all() if hasattr(one, "read_all") else one
        ref = lookup(mine, buffer)
        assert same_table(one.cast(ref.schema), ref)
        assert set(one.column("status").to_pylist()) >= {"ok", "LookupException"}
        # The scalar UDF of the same name is still there, and a view is a table.
        late = con.sql("SELECT count(*), count(*) FILTER (WHERE (r).status = 'ok') FROM "
                       "(SELECT tf_lookup(target_frame, source_frame, stamp) AS r FROM late)"
                       ).fetchall()[0]
        n_late = sum(1 for s in mine.column("stamp").to_pylist() if s > START + 10 * SEC)
        ok_late = sum(1 for s, st in zip(mine.column("stamp").to_pylist(),
                                         ref.column("status").to_pylist(), strict=True)
                      if s > START + 10 * SEC and st == "ok")
        assert late == (n_late, ok_late)
        assert con.sql("SELECT count(*) FROM tf_lookup(late)").fetchall() == [(n_late,)]
        with pytest.raises(duckdb.CatalogException, match="nowhere"):
            con.sql("SELECT * FROM tf_lookup(nowhere)").fetchall()
        with pytest.raises(ValueError, match=r"name must be an SQL identifier.*'tf; DROP'"):
            tdb.register(con, buffer, name="tf; DROP")
    finally:
        con.close()
