"""Ray Data (a local cluster of num_cpus=2) and Dask (a local cluster of two worker
processes) on 20 generated recordings agree with the plain path row for row; the blocks
of equal cost (``balanced_blocks``, ``tfbus.table.ray.balanced_dataset``) place each
recording's rows in one block by longest processing time first."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

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


def _rows_of(blocks: list[Any]) -> list[list[int]]:
    return [block.column("row").to_pylist() for block in blocks]


def test_balanced_blocks_place_recordings_longest_first() -> None:
    """Costs A 4, B 3, C 3, D 2, E 1 (rows, reads free) into two blocks by LPT: A -> 0
    (4), B -> 1 (3), C -> 1 (6), D -> 0 (6), E -> 0 (7: a tie goes to the lower block);
    within a block the recordings in order of first appearance, each one's rows in
    their order."""
    from tfbus.table.recordings import balanced_blocks

    names = list("BACADBCEABCAD")
    queries = pa.table({"recording": names, "row": list(range(len(names)))})
    got = balanced_blocks(queries, 2, load_cost=0.0)
    assert _rows_of(got) == [[1, 3, 8, 11, 4, 12, 7], [0, 5, 9, 2, 6, 10]]
    assert [b.column("recording").to_pylist() for b in got] == [
        list("AAAADDE"), list("BBBCCC")]


def test_balanced_blocks_weigh_each_read() -> None:
    """One recording of 100 rows and four of 1 row: reads free, the big one fills a
    block alone; a read worth 50 rows (costs 150 and 51 each), the small ones split
    three to one: A -> 0, B, C, D -> 1 (153), E -> 0 (201)."""
    from tfbus.table.recordings import balanced_blocks

    names = ["A"] * 100 + ["B", "C", "D", "E"]
    queries = pa.table({"recording": names, "row": list(range(104))})
    free = balanced_blocks(queries, 2, load_cost=0.0)
    assert _rows_of(free) == [list(range(100)), [100, 101, 102, 103]]
    weighed = balanced_blocks(queries, 2, load_cost=50.0)
    assert _rows_of(weighed) == [[*range(100), 103], [100, 101, 102]]
    # per recording: E's read is dear, so E is placed right after A, alone.
    dear = balanced_blocks(queries, 2, load_cost={"E": 500.0, "A": 0.0, "B": 0.0,
                                                  "C": 0.0, "D": 0.0})
    assert _rows_of(dear) == [[103], [*range(100), 100, 101, 102]]


def test_balanced_blocks_even_a_sorted_fleet() -> None:
    """The benchmark's shape: 100 recordings, rows sorted by recording, 4 blocks: 25
    recordings each (a read costs 10^5 rows), blocks within 2 % of each other, where
    equal row slices cut recordings (read by two tasks) and differ in recordings."""
    from tfbus.table.recordings import balanced_blocks

    rng = np.random.default_rng(7)
    which = np.sort(rng.integers(0, 100, 200_000))
    queries = pa.table({"recording": [f"r{k:03d}" for k in which],
                        "row": np.arange(which.size)})
    blocks = balanced_blocks(queries, 4)
    recordings = [set(b.column("recording").to_pylist()) for b in blocks]
    assert [len(r) for r in recordings] == [25, 25, 25, 25]
    assert set().union(*recordings) == {f"r{k:03d}" for k in range(100)}
    costs = [len(r) * 100_000 + b.num_rows for r, b in zip(recordings, blocks, strict=True)]
    assert max(costs) / min(costs) < 1.02
    assert sorted(np.concatenate(_rows_of(blocks)).tolist()) == list(range(which.size))


@settings(max_examples=60, deadline=None)
@given(names=st.lists(st.sampled_from(["a", "b", "c", "d", "e", "f", "g"]), max_size=60),
       blocks=st.integers(1, 5), load_cost=st.floats(0.0, 20.0))
def test_balanced_blocks_hold_every_row_once(names: list[str], blocks: int,
                                             load_cost: float) -> None:
    """Every row in exactly one block, each recording in one block, its rows in their
    order; the costliest block within the bound of greedy placement (Graham 1966: the
    mean cost per block plus (1 - 1/m) times the costliest recording)."""
    from tfbus.table.recordings import balanced_blocks

    queries = pa.table({"recording": pa.array(names, pa.string()),
                        "row": pa.array(range(len(names)), pa.int64())})
    got = balanced_blocks(queries, blocks, load_cost=load_cost)
    assert len(got) == blocks
    assert all(b.schema == queries.schema for b in got)
    assert sorted(np.concatenate([*_rows_of(got), []]).tolist()) == list(range(len(names)))
    owner: dict[str, int] = {}
    for k, block in enumerate(got):
        for name in block.column("recording").to_pylist():
            assert owner.setdefault(name, k) == k
        rows = block.column("row").to_pylist()
        for name in set(block.column("recording").to_pylist()):
            mine = [r for r in rows if names[r] == name]
            assert mine == sorted(mine)
    cost = {n: load_cost + names.count(n) for n in set(names)}
    totals = [sum(cost[n] for n in set(b.column("recording").to_pylist())) for b in got]
    bound = sum(cost.values()) / blocks + (1 - 1 / blocks) * max([*cost.values(), 0.0])
    assert max(totals) <= bound + 1e-9


def test_balanced_blocks_name_bad_arguments() -> None:
    from tfbus.table.recordings import balanced_blocks

    queries = pa.table({"recording": ["a"], "row": [0]})
    with pytest.raises(ValueError, match="blocks must be an int >= 1, got 0"):
        balanced_blocks(queries, 0)
    with pytest.raises(ValueError, match=r"load_cost must be >= 0, got -1\.0 for 'load_cost'"):
        balanced_blocks(queries, 2, load_cost=-1.0)
    with pytest.raises(ValueError, match="load_cost must be >= 0, got nan for 'a'"):
        balanced_blocks(queries, 2, load_cost={"a": float("nan")})
    with pytest.raises(ValueError, match="no column 'robot'"):
        balanced_blocks(queries, 2, recording="robot")


def test_ray_balanced_dataset_reads_each_recording_once(
    ray_cluster: Any, expected: tuple[Any, Any]
) -> None:
    """``balanced_dataset`` (two blocks per CPU: 4) then the unshuffled path's task: bit
    for bit the plain path, and the tasks read the 20 recordings 20 times in all (each
    recording's rows in one block)."""
    from tfbus.table import ray as tfray

    queries, want = expected

    def counted(batch: Any) -> Any:
        before = tfray._WORKER_BUFFERS.get(2)
        start = 0 if before is None else before.loads
        out = tfray._answer_batch(batch, "recording", None, 5.0, 2)
        loads = tfray._WORKER_BUFFERS[2].loads - start
        return out.append_column("loads", pa.array(np.full(out.num_rows, loads)))

    ds = tfray.balanced_dataset(queries)
    assert ds.num_blocks() == 4
    batches = [b for b in ds.map_batches(counted, batch_format="pyarrow",
                                         batch_size=None).iter_batches(
        batch_format="pyarrow", batch_size=None) if b.num_rows]
    table = pa.concat_tables(batches)
    loads = sum(b.column("loads")[0].as_py() for b in batches)
    assert loads == 20
    assert same_table(_by_row(table, want.schema), want)


# The shuffled path (groupby by recording: Ray's hash shuffle, the slow part) runs once,
# whole files; windows go through the unshuffled path (map_batches per block, counted in
# test_each_ray_task_opens_only_the_windows_of_its_rows).
@pytest.mark.parametrize(("window", "shuffle"), [(None, True), (None, False)])
def test_ray_data_agrees_with_the_plain_path(
    ray_cluster: Any, expected: tuple[Any, Any], window: float | None, shuffle: bool
) -> None:
    from tfbus.table import ray as tfray
    from tfbus.table.recordings import balanced_blocks as tfbus_balanced_blocks

    queries, want = expected
    if shuffle:
        ds = ray_cluster.data.from_arrow(_blocks(queries, 4))
    else:  # blocks of equal cost, each recording's rows in one (3 blocks: 20 recordings
        # of about 60 rows, placed 7, 7, 6)
        ds = tfray.balanced_dataset(queries, blocks=3)
        assert [len(set(b.column("recording").to_pylist()))
                for b in tfbus_balanced_blocks(queries, 3)] == [7, 7, 6]
    assert ds.num_blocks() == (4 if shuffle else 3)
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
