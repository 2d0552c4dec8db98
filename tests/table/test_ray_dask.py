"""Ray Data (a local cluster of num_cpus=2) and Dask (a local cluster of two worker
processes) on 20 generated recordings agree with the plain path row for row."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
pytest.importorskip("rosbags")

from table_recordings import fleet, fleet_queries, plain, same_table  # noqa: E402

# Ray Data warns about its own deprecated settings when its context is first read.
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning:ray.data.context")


@pytest.fixture(scope="module")
def expected(tmp_path_factory: pytest.TempPathFactory) -> tuple[Any, Any]:
    paths = fleet(tmp_path_factory.mktemp("fleet20"))
    queries = fleet_queries(paths, seed=4)
    queries = queries.append_column("row", pa.array(np.arange(queries.num_rows)))
    return queries, plain(queries)


def _by_row(table: Any, schema: Any) -> Any:
    """The rows ordered by their ``row`` id, in ``schema``'s column order and types."""
    table = table.select(schema.names).cast(schema)
    return table.take(pa.compute.sort_indices(table.column("row")))


@pytest.fixture(scope="module")
def ray_cluster() -> Iterator[Any]:
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             configure_logging=False, ignore_reinit_error=True)
    try:
        from ray.data.context import ShuffleStrategy

        context = ray.data.DataContext.get_current()
        context.enable_progress_bars = False
        # The groupby by recording through Ray's sort-based pull shuffle (tasks): on these
        # 1,200 rows about 4 s, against 11-15 s for the default hash shuffle's actors.
        context.shuffle_strategy = ShuffleStrategy.SORT_SHUFFLE_PULL_BASED
        yield ray
    finally:
        ray.shutdown()


def _blocks(table: Any, n: int) -> list[Any]:
    """``table`` as ``n`` slices: a Dataset of ``n`` blocks without Ray's repartition
    (an all-to-all shuffle of its own, seconds on a loaded machine)."""
    step = -(-table.num_rows // n)
    return [table.slice(k * step, step) for k in range(n)]


# The shuffled path (groupby by recording: Ray's hash shuffle, the slow part) runs once,
# whole files; windows go through the unshuffled path (map_batches per block, counted in
# test_each_ray_task_opens_only_the_windows_of_its_rows).
@pytest.mark.parametrize(("window", "shuffle"), [(None, True), (None, False)])
def test_ray_data_agrees_with_the_plain_path(
    ray_cluster: Any, expected: tuple[Any, Any], window: float | None, shuffle: bool
) -> None:
    from tfbus.table import ray as tfray

    queries, want = expected
    if not shuffle:  # rows ordered by recording, as read from per-recording files
        queries = queries.sort_by("recording")
    ds = ray_cluster.data.from_arrow(_blocks(queries, 4))
    assert ds.num_blocks() == 4
    got = tfray.lookup(ds, window=window, margin=5.0, shuffle=shuffle)
    table = pa.concat_tables(list(got.iter_batches(batch_format="pyarrow",
                                                   batch_size=None)))
    result = _by_row(table, want.schema)
    if window is None:
        assert same_table(result, want)
    else:
        for g, w in zip(result.to_pylist(), want.to_pylist(), strict=True):
            assert g == w if w["status"] == "ok" else g["status"] != "ok"


def test_dask_agrees_with_the_plain_path(expected: tuple[Any, Any], tmp_path: Path) -> None:
    dd = pytest.importorskip("dask.dataframe")
    distributed = pytest.importorskip("distributed")
    from tfbus.table import dask as tfdask

    queries, want = expected
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, host="127.0.0.1",
                                  local_directory=str(tmp_path)) as cluster, \
            distributed.Client(cluster):
        frame = dd.from_pandas(queries.to_pandas(), npartitions=4)
        got = tfdask.lookup(frame).compute()
    table = pa.Table.from_pandas(got, preserve_index=False)
    assert same_table(_by_row(table, want.schema), want)


def test_each_ray_task_opens_only_the_windows_of_its_rows(
    ray_cluster: Any, expected: tuple[Any, Any]
) -> None:
    """The unshuffled path's task (``tfbus.table.ray._answer_batch``) run in the Ray
    workers with ``tfbus.bag.load_buffer`` counted there: per batch, each recording's
    windows that hold rows (and the whole file for rows at stamp 0), each once; its rows
    are the whole file's where it answers (a window may refuse a row the file answers)."""
    width, margin = 6.0, 5.0
    queries, want = expected
    queries = queries.sort_by("recording")

    def counted(batch: Any) -> Any:
        import os
        import uuid

        import tfbus.bag
        from tfbus.table import ray as tfray

        original = tfbus.bag.load_buffer
        loads: list[tuple[str, int, int]] = []

        def spy(path: Any, **kw: Any) -> Any:
            start, end = kw.get("start"), kw.get("end")
            loads.append((str(path), -1 if start is None else start.ns,
                          -1 if end is None else end.ns))
            return original(path, **kw)

        tfbus.bag.load_buffer = spy
        try:
            answered = tfray._answer_batch(batch, "recording", width, margin, 2)
        finally:
            tfbus.bag.load_buffer = original
        assert answered.num_rows == batch.num_rows
        tag = uuid.uuid4().hex
        n = batch.num_rows
        nothing = [None] * len(loads)
        return pa.table({
            "kind": ["row"] * n + ["load"] * len(loads),
            "batch": [tag] * (n + len(loads)),
            "pid": [os.getpid()] * (n + len(loads)),
            "recording": batch.column("recording").to_pylist() + [p for p, _, _ in loads],
            "a": batch.column("stamp").to_pylist() + [a for _, a, _ in loads],
            "b": [0] * n + [b for _, _, b in loads],
            "row": answered.column("row").to_pylist() + nothing,
            "status": answered.column("status").to_pylist() + nothing,
            "pose": [[r[c] for c in ("x", "y", "z", "qx", "qy", "qz", "qw")]
                     for r in answered.to_pylist()] + nothing,
        })

    ds = ray_cluster.data.from_arrow(_blocks(queries, 4))
    out = pa.concat_tables(list(ds.map_batches(counted, batch_format="pyarrow",
                                               batch_size=None).iter_batches(
        batch_format="pyarrow", batch_size=None))).to_pylist()
    w, m = round(width * 1e9), round(margin * 1e9)
    batches = {r["batch"] for r in out}
    assert len(batches) == 4
    windows = 0
    for tag in batches:
        rows = [r for r in out if r["batch"] == tag and r["kind"] == "row"]
        loads = sorted((r["recording"], r["a"], r["b"]) for r in out
                       if r["batch"] == tag and r["kind"] == "load")
        needed = set()
        for r in rows:
            if r["a"] == 0:
                needed.add((r["recording"], -1, -1))
            elif r["a"] > 0:
                k = r["a"] // w
                needed.add((r["recording"], max(0, k * w - m), (k + 1) * w + m))
        assert loads == sorted(needed)  # each window of its rows, once; no other read
        windows += sum(1 for _, a, _ in loads if a >= 0)
    assert windows >= 2 * 20  # twenty recordings of 12 s: at least two 6 s windows each
    got = {r["row"]: r for r in out if r["kind"] == "row"}
    assert len(got) == queries.num_rows
    answered = 0
    for w_row in want.to_pylist():
        g = got[w_row["row"]]
        if w_row["status"] == "ok":
            assert g["status"] == "ok"
            assert g["pose"] == [w_row[c] for c in ("x", "y", "z", "qx", "qy", "qz", "qw")]
            answered += 1
        else:
            assert g["status"] != "ok"
    assert answered > queries.num_rows // 2
