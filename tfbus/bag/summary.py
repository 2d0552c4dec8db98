"""tf_monitor's summary of a recording: :func:`summarize` a bag with
:class:`tfbus.monitor.TfSummary`, the same accounting that serves live buses.

The definitions (a frame's rate, delays, sim-time stamps) are :mod:`tfbus.monitor`'s, so
``summarize``, ``tfbus bag-info``, ``tfbus monitor`` and ``tfbus frames`` agree:

* rate of a frame = ``(distinct header stamps - 1) / (newest - oldest stamp)`` in Hz
  (:func:`tfbus.monitor.link_rate`; one definition for every tool);
* delay = bag (receive) time minus header stamp, or against the newest stamp when the
  bag was recorded with simulated time (:attr:`~tfbus.monitor.TfSummary.sim_time`).
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

from tfbus.bag.formats import DEFAULT_TOPICS, BagFormat, BagMessage, detect_format
from tfbus.bag.reader import read_messages
from tfbus.errors import BagReadError
from tfbus.messages import TransformStamped
from tfbus.monitor import AuthoritySummary, FrameSummary, TfSummary
from tfbus.time import Time

__all__ = ["AuthoritySummary", "BagSummary", "FrameSummary", "summarize"]

@dataclass
class BagSummary(TfSummary):
    """What :func:`summarize` found: tf_monitor's tables (:class:`TfSummary`: ``start``
    / ``end`` bag times of the first and last tf message, ``messages`` per topic,
    ``frames``, ``authorities``) plus the bag's ``path`` and ``format``, and ``error``
    when the bag was damaged (everything before the damage was accounted)."""

    path: Path | None = None
    format: BagFormat | None = None
    error: BagReadError | None = None

    def add(self, time: Time | BagMessage, transforms: Iterable[TransformStamped] = (),
            authority: str = "", *, static: bool = False, topic: str | None = None) -> None:
        """Account for one message: ``add(rec)`` with a :class:`BagMessage` (at bag time,
        counted under its own topic, static when it is ``/tf_static``), or the arguments
        of :meth:`TfSummary.add`."""
        if isinstance(time, BagMessage):
            rec = time
            super().add(rec.time, rec.message.transforms, rec.authority,
                        static=rec.is_static, topic=rec.topic)
        else:
            super().add(time, transforms, authority, static=static, topic=topic)


def summarize(
    path: str | PathLike[str], *, topics: Collection[str] = DEFAULT_TOPICS
) -> BagSummary:
    """Summarise a bag's tf data: frames, parents, rates, delays, span, static vs dynamic
    (tf_monitor's statistics, :mod:`tfbus.monitor`).

    A damaged bag is summarised up to the damage and the error stored in ``error``.

    Raises:
        BagNotFoundError, BagFormatError: see :func:`read_messages`.
    """
    summary = BagSummary(path=Path(path), format=detect_format(path))
    try:
        for rec in read_messages(path, topics=topics):
            summary.add(rec)
    except BagReadError as err:
        summary.error = err
    return summary
