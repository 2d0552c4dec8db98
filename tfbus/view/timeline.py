"""A bag as a timeline for ``tfbus view``: the buffer as ``tfbus replay`` would have
filled it by bag time ``t``, and when each frame was last updated (no web library)."""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from pathlib import Path

from tfbus.bag import BagReadError, read_messages
from tfbus.core import BufferCore
from tfbus.messages import TransformStamped
from tfbus.time import Time
from tfbus.topics import TF_STATIC_TOPIC

__all__ = ["BagTimeline"]


@dataclass
class BagTimeline:
    """Every ``/tf`` and ``/tf_static`` message of a bag, in bag-time order.

    :meth:`buffer_at` returns a :class:`BufferCore` holding exactly the messages with bag
    time ``<= t`` (what a listener of ``tfbus replay`` holds at that moment), filled
    incrementally while ``t`` moves forward and rebuilt when it moves back.
    ``problem`` is the one-line reason a damaged bag was read only in part.
    """

    times: list[int] = field(default_factory=list)
    messages: list[tuple[tuple[TransformStamped, ...], str, bool]] = field(default_factory=list)
    problem: str | None = None
    cache_time: float = 10.0
    _core: BufferCore | None = None
    _upto: int = 0
    _frame_times: dict[str, list[int]] = field(default_factory=dict)

    @classmethod
    def read(cls, path: Path, *, cache_time: float = 10.0) -> BagTimeline:
        """Load the bag's tf messages (``tfbus.bag.read_messages``); a damaged bag keeps
        what was readable and says why in ``problem``."""
        tl = cls(cache_time=cache_time)
        try:
            for rec in read_messages(path):
                static = rec.topic == TF_STATIC_TOPIC
                tl.times.append(rec.time.ns)
                tl.messages.append((tuple(rec.message.transforms), rec.authority, static))
                if not static:
                    for t in rec.message.transforms:
                        tl._frame_times.setdefault(t.child_frame_id, []).append(rec.time.ns)
        except BagReadError as err:
            tl.problem = " ".join(str(err).split())
        return tl

    @property
    def start(self) -> Time:
        """Bag time of the first message (``Time(0)`` for an empty bag)."""
        return Time.from_ns(self.times[0] if self.times else 0)

    @property
    def end(self) -> Time:
        """Bag time of the last message."""
        return Time.from_ns(self.times[-1] if self.times else 0)

    def buffer_at(self, t: Time) -> BufferCore:
        """The buffer holding every message with bag time ``<= t`` (returned object is
        reused while ``t`` does not go back: treat it as read-only)."""
        n = bisect.bisect_right(self.times, t.ns)
        if self._core is None or n < self._upto:
            self._core = BufferCore(cache_time=self.cache_time)
            self._upto = 0
        core = self._core
        for transforms, authority, static in self.messages[self._upto:n]:
            for tr in transforms:
                # an invalid transform (NaN, bad ids) is refused by the core, as tf2 does
                if static:
                    core.set_transform_static(tr, authority)
                else:
                    core.set_transform(tr, authority)
        self._upto = n
        return core

    def last_update(self, t: Time) -> dict[str, Time]:
        """For each dynamic frame sent at or before ``t``: the bag time it was last sent."""
        out: dict[str, Time] = {}
        for frame, times in self._frame_times.items():
            i = bisect.bisect_right(times, t.ns)
            if i:
                out[frame] = Time.from_ns(times[i - 1])
        return out
