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

from tfbus.table.recordings import (  # noqa: E402
    DEFAULT_LOAD_COST,
    DEFAULT_MARGIN,
    RecordingBuffers,
    balanced_blocks,
    lookup_by_recording,
)

__all__ = ["balanced_dataset", "lookup"]


_WORKER_BUFFERS: dict[int, RecordingBuffers] = {}
"""Each Ray worker process's most recently used whole recordings (by ``keep``): a
worker process runs many tasks, so a recording read by one batch's task is not read
again by the next batch's task on the same worker."""


def _answer_batch(batch: Any, recording: str, window: float | None, margin: float,
                  keep: int) -> Any:
    """One batch of the unshuffled path, against this worker's kept recordings."""
    buffers = _WORKER_BUFFERS.setdefault(keep, RecordingBuffers(keep))
    return lookup_by_recording(batch, recording=recording, window=window, margin=margin,
                               buffers=buffers)


def balanced_dataset(
    queries: Any,
    *,
    blocks: int | None = None,
    per_cpu: int = 2,
    recording: str = "recording",
    load_cost: float | dict[str, float] = DEFAULT_LOAD_COST,
) -> Any:
    """A Ray Dataset of ``queries`` in blocks of about equal cost, each recording's rows
    in one block (:func:`tfbus.table.recordings.balanced_blocks`): for
    ``lookup(..., shuffle=False)``, whose tasks then read each recording once and take
    about equal CPU time, so that no worker waits on another's last block.

    Args:
        queries: an Arrow table (or pandas / Polars DataFrame) with ``recording`` and
            the query columns of :func:`tfbus.table.lookup`, in the driver's memory.
        blocks: how many blocks; None: ``per_cpu`` times the cluster's CPUs
            (``ray.cluster_resources()``; Ray initialised).
        per_cpu: blocks per CPU when ``blocks`` is None (>= 1): one block per CPU has
            the fewest tasks; two let a worker that runs behind (a busy core) hand over
            part of its share.
        recording, load_cost: as :func:`~tfbus.table.recordings.balanced_blocks`.

    Returns:
        ``ray.data.from_arrow`` of the blocks (empty blocks left out). On a small
        cluster set ``ray.data.DataContext.get_current().op_resource_reservation_enabled
        = False`` too: Ray Data's per-operator reservation otherwise starts the second
        task a second or more after the first (docs/table.md).

    Raises:
        ValueError: ``blocks`` or ``per_cpu`` < 1; see ``balanced_blocks``.
    """
    import ray

    if blocks is None:
        if isinstance(per_cpu, bool) or not isinstance(per_cpu, int) or per_cpu < 1:
            raise ValueError(f"per_cpu must be an int >= 1, got {per_cpu!r}")
        resources: dict[str, float] = ray.cluster_resources()  # type: ignore[no-untyped-call]
        blocks = max(1, per_cpu * int(resources.get("CPU", 1)))
    parts = balanced_blocks(queries, blocks, recording=recording, load_cost=load_cost)
    kept = [part for part in parts if part.num_rows] or parts[:1]
    return ray.data.from_arrow(kept)


def lookup(
    dataset: Any,
    *,
    recording: str = "recording",
    window: float | None = None,
    margin: float = DEFAULT_MARGIN,
    num_cpus: float = 1.0,
    shuffle: bool = True,
    keep: int = 2,
) -> Any:
    """Answer a Ray Dataset of queries that name their recording.

    Args:
        dataset: a ``ray.data.Dataset`` with ``recording`` (path or fsspec URL every
            worker can open), ``target_frame``, ``source_frame``, ``stamp`` (and optional
            ``fixed_frame`` / ``source_stamp``, see :func:`tfbus.table.lookup`).
        recording: the name of the recording column.
        window, margin: as :func:`tfbus.table.lookup_recording` (None: each group reads
            its recording whole; seconds: only the windows its rows need).
        num_cpus: CPUs per task or worker.
        shuffle: True: ``groupby(recording).map_groups``, one task per recording
            (rows in any order; Ray shuffles them). False: no shuffle, for rows already
            ordered by recording (read from per-recording files, or sorted): ``map_batches``
            tasks, each worker process keeping its ``keep`` most recently used recordings
            loaded (a recording whose rows span several batches is read once per worker
            process that gets them); :func:`balanced_dataset` makes such blocks of
            equal cost, each recording in one block.
        keep: recordings each worker process keeps loaded (unshuffled path).

    Returns:
        A lazy ``ray.data.Dataset``: the query rows with
        :data:`tfbus.table.RESULT_COLUMNS` (shuffled: grouped by recording; keep an id
        column to join them back).

    A recording that cannot be read makes its rows fail with the error's class and
    message (:func:`tfbus.table.lookup_by_recording`); the others are answered.
    """

    if not shuffle:
        return dataset.map_batches(
            _answer_batch, fn_kwargs={"recording": recording, "window": window,
                                      "margin": margin, "keep": keep},
            batch_format="pyarrow", batch_size=None, num_cpus=num_cpus)

    def answer(group: Any) -> Any:
        return lookup_by_recording(group, recording=recording, window=window, margin=margin)

    return dataset.groupby(recording).map_groups(
        answer, batch_format="pyarrow", num_cpus=num_cpus)
