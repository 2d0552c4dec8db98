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
        ray.data.DataContext.get_current().enable_progress_bars = False
        yield ray
    finally:
        ray.shutdown()


def _blocks(table: Any, n: int) -> list[Any]:
    """``table`` as ``n`` slices: a Dataset of ``n`` blocks without Ray's repartition
    (an all-to-all shuffle of its own, seconds on a loaded machine)."""
    step = -(-table.num_rows // n)
    return [table.slice(k * step, step) for k in range(n)]


# The shuffled path (groupby by recording: Ray's hash shuffle, the slow part) runs once,
# whole files; windows go through the unshuffled path (map_batches per block).
@pytest.mark.parametrize(("window", "shuffle"), [(None, True), (6.0, False), (None, False)])
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
