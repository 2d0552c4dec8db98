"""The trail of a frame in ``tfbus view``: where its origin was in the fixed frame over the
last N seconds, looked up in the buffer at sampled stamps.

The trail ends at the latest time the fixed frame and the frame have in common (the
stamp ``lookup_transform(fixed_frame, frame_id, Time(0))`` answers, tf2's
``BufferCore::lookupTransform`` with time 0, the pose the page draws) and reaches back
``seconds`` from there. Stamps are taken on a grid of multiples of ``seconds /
(max_points - 1)`` (so that a stamp looked up once is the same stamp on the next redraw)
plus the end itself: at most ``max_points`` lookups for a new trail, then only the grid
stamps time has added. A stamp the buffer cannot answer (older than its data:
``ExtrapolationException``, or a chain not connected then) gives no point. Each point is
``lookup_transform(fixed_frame, frame_id, stamp)``'s translation: the origin at that
stamp in the fixed frame at that stamp (the fixed frame is the one taken not to move,
as rviz's TF display takes it).

Points already looked up are kept while the frame, the fixed frame, the duration and the
buffer object stay the same (a bag's buffer is a new object after a jump back), and
those older than the trail's start are dropped: a trail holds at most ``max_points``
points whatever the rate or the duration. A point is looked up once: data that arrives
later with an older stamp than the trail's end does not move it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tfbus.core import BufferCore
from tfbus.messages import TransformStamped
from tfbus.time import Time

__all__ = ["DEFAULT_TRAIL_SECONDS", "MAX_TRAIL_POINTS", "MAX_TRAIL_SECONDS",
           "MIN_TRAIL_SECONDS", "Trail", "TrailSampler"]

MIN_TRAIL_SECONDS = 0.5
"""Shortest trail, seconds."""
MAX_TRAIL_SECONDS = 600.0
"""Longest trail, seconds."""
DEFAULT_TRAIL_SECONDS = 10.0
"""The duration the page's trail control starts at, seconds."""
MAX_TRAIL_POINTS = 2000
"""Points of one trail at most (lookups of a new trail at most)."""


@dataclass(frozen=True)
class Trail:
    """A frame's origin in the fixed frame over a span of time.

    ``stamps`` are ``(K,)`` int64 nanoseconds, ascending; ``points`` the ``(K, 3)``
    float64 positions in metres at those stamps; ``error`` says why there is no trail
    (tf2's message for the latest lookup), else None."""

    frame_id: str
    fixed_frame: str
    seconds: float
    stamps: npt.NDArray[np.int64]
    points: npt.NDArray[np.float64]
    error: str | None = None

    def segments(self) -> npt.NDArray[np.float64]:
        """The trail as ``(K - 1, 2, 3)`` line segments, point k to point k + 1."""
        if len(self.points) < 2:
            return np.zeros((0, 2, 3))
        return np.stack([self.points[:-1], self.points[1:]], axis=1)


def check_seconds(seconds: float) -> float:
    """``seconds`` as a float when it is a trail duration (:data:`MIN_TRAIL_SECONDS` to
    :data:`MAX_TRAIL_SECONDS`).

    Raises:
        ValueError: naming the field and the value, otherwise (NaN too).
    """
    value = float(seconds)
    if not MIN_TRAIL_SECONDS <= value <= MAX_TRAIL_SECONDS:  # (False for NaN)
        raise ValueError(f"trail seconds must be between {MIN_TRAIL_SECONDS:g} and "
                         f"{MAX_TRAIL_SECONDS:g}, got {seconds!r}")
    return value


class TrailSampler:
    """Looks up trails, keeping the points of the last one (see the module's docstring).

    Args:
        max_points: points of one trail at most, 2 to :data:`MAX_TRAIL_POINTS`.

    Raises:
        ValueError: ``max_points`` out of that range.
    """

    def __init__(self, max_points: int = MAX_TRAIL_POINTS) -> None:
        if not 2 <= max_points <= MAX_TRAIL_POINTS:
            raise ValueError(f"max_points must be between 2 and {MAX_TRAIL_POINTS}, got "
                             f"{max_points!r}")
        self.max_points = max_points
        self.lookups = 0
        """Lookups made so far (for the cost: a redraw adds only the new stamps')."""
        self._key: tuple[str, str, float] | None = None
        self._core: BufferCore | None = None  # held: its id cannot be reused meanwhile
        self._points: dict[int, tuple[float, float, float] | None] = {}

    def sample(self, core: BufferCore, fixed_frame: str, frame_id: str,
               seconds: float) -> Trail:
        """The trail of ``frame_id`` in ``fixed_frame`` over the last ``seconds`` of
        ``core``'s data.

        Raises:
            ValueError: ``seconds`` out of :data:`MIN_TRAIL_SECONDS` ..
                :data:`MAX_TRAIL_SECONDS`.
        """
        seconds = check_seconds(seconds)
        key = (fixed_frame, frame_id, seconds)
        if key != self._key or core is not self._core:
            self._key, self._core = key, core
            self._points = {}
        empty = Trail(frame_id, fixed_frame, seconds, np.zeros(0, dtype=np.int64),
                      np.zeros((0, 3)))
        latest = core.try_lookup_transform(fixed_frame, frame_id, Time(0))
        self.lookups += 1
        if not isinstance(latest, TransformStamped):
            return Trail(frame_id, fixed_frame, seconds, empty.stamps, empty.points,
                         str(latest))
        end = latest.header.stamp.ns
        v = latest.transform.translation
        if end == 0:  # a static chain (or the frame itself): one place at every time
            return Trail(frame_id, fixed_frame, seconds, np.array([0], dtype=np.int64),
                         np.array([[v.x, v.y, v.z]]))
        step = math.ceil(seconds * 1e9 / (self.max_points - 1))
        start = end - round(seconds * 1e9)
        last = end // step
        if last * step == end:
            last -= 1  # the end itself is added below
        # at most max_points - 1 grid stamps (stamp 0 would mean "the latest" to a
        # lookup: the grid starts at k = 1)
        first = max(-(-start // step), last - (self.max_points - 2), 1)
        for k in [k for k in self._points if k < first or k > last]:
            del self._points[k]
        for k in range(first, last + 1):
            if k not in self._points:
                out = core.try_lookup_transform(fixed_frame, frame_id, Time.from_ns(k * step))
                self.lookups += 1
                t = out.transform.translation if isinstance(out, TransformStamped) else None
                self._points[k] = None if t is None else (t.x, t.y, t.z)
        ks = [k for k in range(first, last + 1) if self._points.get(k) is not None]
        stamps = np.array([k * step for k in ks] + [end], dtype=np.int64)
        points = np.array([self._points[k] for k in ks] + [(v.x, v.y, v.z)],
                          dtype=np.float64).reshape(-1, 3)
        return Trail(frame_id, fixed_frame, seconds, stamps, points)
