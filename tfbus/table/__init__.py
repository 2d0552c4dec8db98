"""tf over fleets of recordings: lookups as a table operator (Apache Arrow in and out).

* :func:`lookup`: an Arrow table (or Polars / pandas DataFrame) of ``target_frame``,
  ``source_frame``, ``stamp`` rows answered against a :class:`~tfbus.core.BufferCore`, row
  for row, each row bit for bit ``lookup_transform`` or tf2's exception class and text;
* :func:`lookup_recording`: the same against a recording, whole or read only over the
  windows its rows need (:func:`tfbus.bag.load_buffer`'s ``start`` / ``end``);
  :func:`lookup_by_recording`: rows that name their recording (a ``recording`` column);
* :func:`poses_every`: the queries for one frame pair every ``every`` seconds over a
  recording;
* :func:`summary`: one row per (file, link) of recordings (span, count, rate, largest
  gap, authorities); :func:`findings`: one row per ``tfbus doctor`` finding;
* engines: :mod:`tfbus.table.polars`, :mod:`tfbus.table.duckdb`, :mod:`tfbus.table.ray`,
  :mod:`tfbus.table.dask`.

Needs the ``table`` extra (pyarrow): ``pip install 'tfbus[table]'``.
"""

from __future__ import annotations

from tfbus._extras import require

require(__name__, "pyarrow", extra="table")

from tfbus.table.lookups import (  # noqa: E402  (after the extra check)
    OK,
    QUERY_COLUMNS,
    RESULT_COLUMNS,
    as_arrow,
    lookup,
    result_schema,
)
from tfbus.table.recordings import (  # noqa: E402
    DEFAULT_MARGIN,
    RecordingBuffers,
    lookup_by_recording,
    lookup_recording,
    output_schema,
    poses_every,
)
from tfbus.table.summary import (  # noqa: E402
    FINDING_COLUMNS,
    SUMMARY_COLUMNS,
    findings,
    findings_schema,
    summary,
    summary_schema,
)

__all__ = [
    "DEFAULT_MARGIN",
    "FINDING_COLUMNS",
    "OK",
    "QUERY_COLUMNS",
    "RESULT_COLUMNS",
    "SUMMARY_COLUMNS",
    "RecordingBuffers",
    "as_arrow",
    "findings",
    "findings_schema",
    "lookup",
    "lookup_by_recording",
    "lookup_recording",
    "output_schema",
    "poses_every",
    "result_schema",
    "summary",
    "summary_schema",
]
