"""tf2 lookups over a Dask DataFrame: the rows shuffled so that each recording's rows are
in one partition, each partition answered by :func:`tfbus.table.lookup_by_recording`
(each recording opened once per partition, whole or only the windows its rows need).

::

    import dask.dataframe as dd
    from tfbus.table import dask as tfdask
    ddf = dd.from_pandas(queries, npartitions=8)
    poses = tfdask.lookup(ddf).compute()

Needs the ``dask`` extra (``dask[dataframe]``; ``distributed`` for a cluster).
"""

from __future__ import annotations

from typing import Any

from tfbus._extras import require

require(__name__, "pyarrow", "dask", extra="dask")

from tfbus.table.lookups import RESULT_COLUMNS  # noqa: E402
from tfbus.table.recordings import DEFAULT_MARGIN, lookup_by_recording  # noqa: E402

__all__ = ["lookup"]


def lookup(
    frame: Any,
    *,
    recording: str = "recording",
    window: float | None = None,
    margin: float = DEFAULT_MARGIN,
) -> Any:
    """Answer a Dask DataFrame of queries that name their recording.

    Args:
        frame: a ``dask.dataframe.DataFrame`` with ``recording``, ``target_frame``,
            ``source_frame``, ``stamp`` (int64 ns) columns.
        recording: the name of the recording column.
        window, margin: as :func:`tfbus.table.lookup_recording`.

    Returns:
        A lazy Dask DataFrame: the query columns and :data:`tfbus.table.RESULT_COLUMNS`
        (``status`` and ``message`` as strings; ``message`` None for answered rows). The
        rows are shuffled by recording: keep an id column to join them back.
    """
    import pandas as pd

    def answer(part: Any) -> Any:
        if len(part) == 0:
            return meta
        out = lookup_by_recording(part.reset_index(drop=True), recording=recording,
                                  window=window, margin=margin)
        return out.to_pandas().set_axis(part.index)

    head = frame._meta
    meta = head.assign(**{
        name: pd.Series(dtype="float64") for name in RESULT_COLUMNS[:7]
    }).assign(transform_stamp=pd.Series(dtype="int64"),
              status=pd.Series(dtype="object"), message=pd.Series(dtype="object"))
    return frame.shuffle(on=recording).map_partitions(answer, meta=meta)
