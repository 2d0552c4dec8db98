"""tf2 lookups over a Ray Dataset: rows grouped by recording, each group answered by one
task that opens only its recording (whole, or only the windows its rows need).

::

    import ray
    from tfbus.table import ray as tfray
    ds = ray.data.from_arrow(queries)      # recording, target_frame, source_frame, stamp
    poses = tfray.lookup(ds, window=60.0)  # a Dataset with the result columns
    poses.write_parquet("poses/")

Needs the ``ray`` extra (``ray[data]``).
"""

from __future__ import annotations

from typing import Any

from tfbus._extras import require

require(__name__, "pyarrow", "ray", extra="ray")

from tfbus.table.recordings import DEFAULT_MARGIN, lookup_by_recording  # noqa: E402

__all__ = ["lookup"]


def lookup(
    dataset: Any,
    *,
    recording: str = "recording",
    window: float | None = None,
    margin: float = DEFAULT_MARGIN,
    num_cpus: float = 1.0,
) -> Any:
    """Answer a Ray Dataset of queries that name their recording.

    Args:
        dataset: a ``ray.data.Dataset`` with ``recording`` (path or fsspec URL every
            worker can open), ``target_frame``, ``source_frame``, ``stamp`` (and optional
            ``fixed_frame`` / ``source_stamp``, see :func:`tfbus.table.lookup`).
        recording: the name of the recording column.
        window, margin: as :func:`tfbus.table.lookup_recording` (None: each group reads
            its recording whole; seconds: only the windows its rows need).
        num_cpus: CPUs per task (Ray's ``map_groups`` resources).

    Returns:
        A lazy ``ray.data.Dataset``: the query rows with
        :data:`tfbus.table.RESULT_COLUMNS`, grouped by recording (Ray's ``groupby``
        sorts by it; the rows of one recording keep their order).

    A recording that cannot be read makes its rows fail with the error's class and
    message (:func:`tfbus.table.lookup_by_recording`); the others are answered.
    """

    def answer(group: Any) -> Any:
        return lookup_by_recording(group, recording=recording, window=window, margin=margin)

    return dataset.groupby(recording).map_groups(
        answer, batch_format="pyarrow", num_cpus=num_cpus)
