"""tf_monitor-style statistics of a recording: per frame, per authority, and the extent.

The statistics classes serve bags (:func:`summarize`) and live buses alike
(:meth:`BagSummary.add` takes one message at a time).
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path

from tfbus.bag.formats import (
    DEFAULT_TOPICS,
    TF_STATIC_TOPIC,
    BagFormat,
    BagMessage,
    detect_format,
)
from tfbus.bag.reader import read_messages
from tfbus.errors import BagReadError
from tfbus.time import NSEC_PER_SEC, Time

__all__ = ["AuthoritySummary", "BagSummary", "FrameSummary", "summarize"]

@dataclass
class FrameSummary:
    """Statistics of one child frame over a recording (or a live session).

    Stamps are header stamps in ns; ``delays`` are receive (bag) time minus header stamp
    in seconds, as tf_monitor measures them.
    """

    child: str
    parent: str
    static: bool
    authorities: dict[str, int] = field(default_factory=dict)
    count: int = 0
    first_stamp: int | None = None
    last_stamp: int | None = None
    delay_sum: float = 0.0
    delay_max: float = -math.inf

    @property
    def rate(self) -> float:
        """Average rate in Hz over the sample stamps (0.0 for static / single samples)."""
        if self.static or self.count < 2 or self.first_stamp is None or self.last_stamp is None:
            return 0.0
        span = (self.last_stamp - self.first_stamp) / NSEC_PER_SEC
        return (self.count - 1) / span if span > 0 else 0.0

    @property
    def authority(self) -> str:
        """The broadcaster that sent most of this frame's transforms."""
        return max(self.authorities, key=lambda a: self.authorities[a]) if self.authorities else ""

    @property
    def delay_avg(self) -> float:
        """Average receive delay, seconds (0.0 when nothing was counted)."""
        return self.delay_sum / self.count if self.count else 0.0

    @property
    def buffer_length(self) -> float:
        """Seconds between the oldest and the most recent sample."""
        if self.first_stamp is None or self.last_stamp is None:
            return 0.0
        return (self.last_stamp - self.first_stamp) / NSEC_PER_SEC


@dataclass
class AuthoritySummary:
    """Per broadcaster (authority): messages sent and their receive delays (seconds)."""

    authority: str
    messages: int = 0
    first: int | None = None
    last: int | None = None
    delay_sum: float = 0.0
    delay_count: int = 0
    delay_max: float = -math.inf

    @property
    def rate(self) -> float:
        """Messages per second of bag time (0.0 with fewer than two messages)."""
        if self.messages < 2 or self.first is None or self.last is None:
            return 0.0
        span = (self.last - self.first) / NSEC_PER_SEC
        return (self.messages - 1) / span if span > 0 else 0.0

    @property
    def delay_avg(self) -> float:
        """Average receive delay of its dynamic transforms, seconds."""
        return self.delay_sum / self.delay_count if self.delay_count else 0.0


@dataclass
class BagSummary:
    """What :func:`summarize` found: per-frame statistics and the recording's extent.

    ``start`` / ``end`` are bag times of the first and last tf message (``None`` if none),
    ``messages`` counts them per topic, ``frames`` maps child frame id to its summary.
    ``error`` is set when the bag was damaged (everything before it was summarised).
    """

    path: Path | None = None
    format: BagFormat | None = None
    start: Time | None = None
    end: Time | None = None
    messages: dict[str, int] = field(default_factory=dict)
    frames: dict[str, FrameSummary] = field(default_factory=dict)
    authorities: dict[str, AuthoritySummary] = field(default_factory=dict)
    error: BagReadError | None = None

    def add(self, rec: BagMessage) -> None:
        """Account for one message (from a bag or, later, a live bus)."""
        t = rec.time.ns
        if self.start is None or t < self.start.ns:
            self.start = rec.time
        if self.end is None or t > self.end.ns:
            self.end = rec.time
        self.messages[rec.topic] = self.messages.get(rec.topic, 0) + 1
        static = rec.topic == TF_STATIC_TOPIC
        auth = self.authorities.get(rec.authority)
        if auth is None:
            auth = self.authorities[rec.authority] = AuthoritySummary(rec.authority)
        auth.messages += 1
        if auth.first is None:
            auth.first = t
        auth.last = t
        frames = self.frames
        for ts in rec.message.transforms:
            child = ts.child_frame_id
            fs = frames.get(child)
            if fs is None or fs.static != static:
                fs = frames[child] = FrameSummary(child, ts.header.frame_id, static)
            fs.parent = ts.header.frame_id
            fs.count += 1
            fs.authorities[rec.authority] = fs.authorities.get(rec.authority, 0) + 1
            ns = ts.header.stamp.ns
            if fs.first_stamp is None or ns < fs.first_stamp:
                fs.first_stamp = ns
            if fs.last_stamp is None or ns > fs.last_stamp:
                fs.last_stamp = ns
            if not static:
                d = (t - ns) / NSEC_PER_SEC
                fs.delay_sum += d
                fs.delay_max = max(fs.delay_max, d)
                auth.delay_sum += d
                auth.delay_count += 1
                auth.delay_max = max(auth.delay_max, d)

    @property
    def duration(self) -> float:
        """Seconds between the first and last tf message (bag time)."""
        if self.start is None or self.end is None:
            return 0.0
        return (self.end.ns - self.start.ns) / NSEC_PER_SEC

    @property
    def transform_count(self) -> int:
        """Total number of transforms (every sample of every frame)."""
        return sum(f.count for f in self.frames.values())


def summarize(
    path: str | PathLike[str], *, topics: Collection[str] = DEFAULT_TOPICS
) -> BagSummary:
    """Summarise a bag's tf data: frames, parents, rates, delays, span, static vs dynamic.

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

