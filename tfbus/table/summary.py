"""Recordings summarised as Arrow tables: one row per (file, link) (:func:`summary`) and
one row per ``tfbus doctor`` finding (:func:`findings`), for the engines that query a
fleet of recordings (DuckDB, Polars, Ray Data) to filter and join like any other table.
"""

from __future__ import annotations

from array import array
from collections.abc import Iterable
from os import PathLike
from typing import TYPE_CHECKING, Final

import numpy as np

if TYPE_CHECKING:
    import pyarrow as pa

    from tfbus.doctor import Thresholds

__all__ = ["FINDING_COLUMNS", "SUMMARY_COLUMNS", "findings", "findings_schema", "summary",
           "summary_schema"]

SUMMARY_COLUMNS: Final = (
    "file", "parent", "child", "static", "first_stamp", "last_stamp", "count", "rate",
    "largest_gap", "authorities",
)
"""The columns of :func:`summary`: ``file`` (the path as given), ``parent`` (the header's
``frame_id``), ``child`` (``child_frame_id``), ``static`` (read on ``/tf_static``),
``first_stamp`` / ``last_stamp`` (header stamps, int64 ns), ``count`` (transforms),
``rate`` (Hz, float64), ``largest_gap`` (int64 ns), ``authorities`` (list of strings)."""

FINDING_COLUMNS: Final = (
    "file", "check", "level", "message", "frames", "senders", "start_ns", "end_ns",
    "advice", "counts", "lookups", "reference",
)
"""The columns of :func:`findings`: ``file`` and the fields of
:class:`tfbus.doctor.Finding` (``counts`` a map of string to float64, ``lookups`` a list
of ``{target_frame, source_frame}``)."""

_Path = str | PathLike[str]


def summary_schema() -> pa.Schema:
    """The Arrow schema of :func:`summary` (:data:`SUMMARY_COLUMNS`)."""
    import pyarrow as pa

    return pa.schema([
        ("file", pa.string()), ("parent", pa.string()), ("child", pa.string()),
        ("static", pa.bool_()), ("first_stamp", pa.int64()), ("last_stamp", pa.int64()),
        ("count", pa.int64()), ("rate", pa.float64()), ("largest_gap", pa.int64()),
        ("authorities", pa.list_(pa.string())),
    ])


def findings_schema() -> pa.Schema:
    """The Arrow schema of :func:`findings` (:data:`FINDING_COLUMNS`)."""
    import pyarrow as pa

    return pa.schema([
        ("file", pa.string()), ("check", pa.string()), ("level", pa.string()),
        ("message", pa.string()), ("frames", pa.list_(pa.string())),
        ("senders", pa.list_(pa.string())), ("start_ns", pa.int64()), ("end_ns", pa.int64()),
        ("advice", pa.string()), ("counts", pa.map_(pa.string(), pa.float64())),
        ("lookups", pa.list_(pa.struct([("target_frame", pa.string()),
                                        ("source_frame", pa.string())]))),
        ("reference", pa.string()),
    ])


def _paths(paths: _Path | Iterable[_Path]) -> list[str]:
    if isinstance(paths, (str, PathLike)):
        return [str(paths)]
    out = []
    for p in paths:
        if not isinstance(p, (str, PathLike)):
            raise TypeError(f"paths must be paths or strings, got {type(p).__name__}: {p!r}")
        out.append(str(p))
    return out


class _Link:
    """One (parent, child, static) link of one file: its stamps (int64 ns, 8 bytes each)
    and authorities."""

    __slots__ = ("authorities", "stamps")

    def __init__(self) -> None:
        self.stamps = array("q")
        self.authorities: set[str] = set()


def summary(paths: _Path | Iterable[_Path]) -> pa.Table:
    """One row per (file, link) of the recordings ``paths``, in file order, then by
    parent, child, static.

    Args:
        paths: one recording or several (every format :func:`tfbus.bag.read_messages`
            reads, fsspec URLs of MCAP files included).

    Returns:
        An Arrow table of :data:`SUMMARY_COLUMNS`. A link is a (``frame_id``,
        ``child_frame_id``) pair as broadcast, dynamic (``/tf``) and static
        (``/tf_static``) apart: a child whose parent changes has one row per parent.
        ``first_stamp`` / ``last_stamp`` are the smallest and largest header stamps;
        ``count`` the transforms read; ``rate`` ``(count - 1)`` over the span in
        seconds (null for one transform or a zero span); ``largest_gap`` the largest
        difference between consecutive distinct header stamps, in stamp order (null for
        fewer than two) — the span tf2's interpolation bridges silently
        (``TimeCache::interpolate``); ``authorities`` the sorted broadcasters
        (ROS 1 caller ids; ROS 2 recordings carry none: tf2_ros's
        ``"Authority undetectable"``). A damaged recording is summarised up to the
        damage (:func:`findings` reports it as ``damaged_recording``).

    Raises:
        TypeError: an element of ``paths`` is not a path.
        BagNotFoundError: a path does not exist.
        BagFormatError: a path is not a bag format tfbus reads.

    Memory: 8 bytes a transform of the largest file, plus its links.
    """
    import pyarrow as pa

    from tfbus.bag import read_messages
    from tfbus.errors import BagReadError

    cols: dict[str, list[object]] = {name: [] for name in SUMMARY_COLUMNS}
    for path in _paths(paths):
        links: dict[tuple[str, str, bool], _Link] = {}
        try:
            for rec in read_messages(path):
                static = rec.is_static
                for t in rec.message.transforms:
                    key = (t.header.frame_id, t.child_frame_id, static)
                    link = links.get(key)
                    if link is None:
                        link = links[key] = _Link()
                    link.stamps.append(t.header.stamp.ns)
                    link.authorities.add(rec.authority)
        except BagReadError:
            pass  # (read up to the damage; findings() names it)
        for (parent, child, static), link in sorted(links.items()):
            stamps = np.sort(np.frombuffer(link.stamps, dtype=np.int64))
            count = int(stamps.size)
            first, last = int(stamps[0]), int(stamps[-1])
            distinct = np.unique(stamps)
            gap = int(np.diff(distinct).max()) if distinct.size > 1 else None
            cols["file"].append(path)
            cols["parent"].append(parent)
            cols["child"].append(child)
            cols["static"].append(static)
            cols["first_stamp"].append(first)
            cols["last_stamp"].append(last)
            cols["count"].append(count)
            cols["rate"].append((count - 1) / ((last - first) / 1e9) if last > first else None)
            cols["largest_gap"].append(gap)
            cols["authorities"].append(sorted(link.authorities))
    return pa.table(cols, schema=summary_schema())


def findings(paths: _Path | Iterable[_Path], *,
             thresholds: Thresholds | None = None) -> pa.Table:
    """One row per ``tfbus doctor`` finding of the recordings ``paths``
    (:func:`tfbus.doctor.diagnose` on each, in file order, each file's findings most
    severe first).

    Args:
        paths: one recording or several (as :func:`summary`).
        thresholds: the checks' numbers (:class:`tfbus.doctor.Thresholds`; default
            its defaults).

    Returns:
        An Arrow table of :data:`FINDING_COLUMNS`: ``file`` and each
        :class:`~tfbus.doctor.Finding` field (``level`` as ``"error"``, ``"warning"``
        or ``"info"``; ``start_ns`` / ``end_ns`` receive times in ns, null for a
        property of the whole tree). A file with no finding has no row.

    Raises:
        TypeError: an element of ``paths`` is not a path.
        BagNotFoundError: a path does not exist.
        BagFormatError: a path is not a bag format tfbus reads.
    """
    import pyarrow as pa

    from tfbus.doctor import diagnose

    cols: dict[str, list[object]] = {name: [] for name in FINDING_COLUMNS}
    for path in _paths(paths):
        for f in diagnose(path, thresholds=thresholds, label=path).findings:
            cols["file"].append(path)
            cols["check"].append(f.check)
            cols["level"].append(f.level.value)
            cols["message"].append(f.message)
            cols["frames"].append(list(f.frames))
            cols["senders"].append(list(f.senders))
            cols["start_ns"].append(f.start_ns)
            cols["end_ns"].append(f.end_ns)
            cols["advice"].append(f.advice)
            cols["counts"].append([(k, float(v)) for k, v in f.counts.items()])
            cols["lookups"].append([{"target_frame": a, "source_frame": b}
                                    for a, b in f.lookups])
            cols["reference"].append(f.reference)
    return pa.table(cols, schema=findings_schema())
