"""The checks of ``tfbus doctor`` and the one-pass state they run on: :class:`Doctor` is fed
one tf message at a time (:meth:`Doctor.add`, from a bag or a live bus) and keeps per-link
state only (O(frames + broadcasters), never O(messages)); :meth:`Doctor.report` turns that
state into :class:`~tfbus.doctor.report.Finding` s.

Each check's rule and reference is in :data:`CHECKS` (and ``docs/doctor.md``); the numbers
it uses are the fields of :class:`Thresholds`.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Final

from tfbus.core import frame_path
from tfbus.core.kernels import compiled_extension
from tfbus.doctor.report import BroadcasterDelay, Finding, Level, Report
from tfbus.messages import TransformStamped
from tfbus.monitor import SIM_TIME_GAP
from tfbus.time import NSEC_PER_SEC, Time

__all__ = ["CHECKS", "PLACEHOLDER_AUTHORITIES", "Check", "Doctor", "Thresholds"]

PLACEHOLDER_AUTHORITIES: Final = frozenset({
    "Authority undetectable", "default_authority", "unknown", "unattributed",
    "unknown_publisher",
})
"""Authorities that do not name a sender (tf2_ros's ROS 2 listener's, a live bus's before
the sender is known): never counted as a second broadcaster of a frame."""

REP105_ORDER: Final = ("earth", "map", "odom", "base_link")
"""REP 105's chain, top first: each present frame must be an ancestor of those after it."""
ROBOT_FRAMES: Final = ("base_link", "base_footprint")
"""The robot's own frames: REP 105's world frames (earth, map, odom) are never below them."""


@dataclass(frozen=True)
class Check:
    """A check's name, rule and the source of the rule."""

    name: str
    rule: str
    reference: str


CHECKS: Final[dict[str, Check]] = {c.name: c for c in (
    Check("damaged_recording", "the recording could not be read to its end: everything "
          "before the damage is diagnosed", "tfbus.bag.read_messages (BagReadError)"),
    Check("several_authorities", "a child frame is sent by more than one broadcaster: "
          "error when their sending overlaps in time, info when one followed the other; "
          "a static frame sent with different values by several is a warning",
          "tf2 BufferCore::setTransform (authority); tf2 FAQ, 'TF_REPEATED_DATA' and "
          "'multiple publishers'; ros2/geometry2 #798"),
    Check("static_and_dynamic", "a child frame is sent on /tf_static and on /tf",
          "tf2 BufferCore::setTransformImpl (a frame's cache is static or dynamic; ROS 2 "
          "geometry2 replaces it when that changes)"),
    Check("parent_change", "a child frame's parent (header.frame_id) changes over time",
          "tf2 TimeCache (each sample keeps its parent: lookups before and after the "
          "change walk different trees); REP 105"),
    Check("loop", "following parents from a frame comes back to it (a transform whose "
          "frame_id equals its child_frame_id included)",
          "tf2 BufferCore::walkToTopParent ('the tf tree is invalid because it contains a "
          "loop'), setTransformImpl (TF_SELF_TRANSFORM)"),
    Check("rep105", "earth -> map -> odom -> base_link: each present frame is an ancestor "
          "of those after it when they are in one tree, and earth, map, odom are never "
          "below base_link or base_footprint", "REP 105 'Coordinate Frames for Mobile "
          "Platforms', Relationship between Frames"),
    Check("base_footprint", "base_footprint and base_link, when both are in one tree, "
          "are parent and child of each other", "REP 120 base_footprint; REP 105"),
    Check("leading_slash", "a frame id starts with '/'", "tf2 BufferCore::validateFrameId "
          "(ROS 2 refuses such ids in lookups; ROS 1 tf2 strips the slash when storing)"),
    Check("stopped", "a dynamic frame received nothing for more than stale_periods of its "
          "own periods (and at least stale_after seconds) before the end",
          "tf_monitor (tfbus.monitor STALE_PERIODS); tf2 ExtrapolationException"),
    Check("gap", "an interval between consecutive header stamps of a dynamic frame longer "
          "than gap_periods of its period (and gap_min seconds)",
          "tf2 TimeCache::getData (interpolation spans the gap; ExtrapolationException "
          "past it)"),
    Check("rate_drop", "a dynamic frame's rate (moving average over rate_window intervals) "
          "falls below rate_drop of its steady rate", "tf_monitor rates (tfbus.monitor)"),
    Check("repeated_stamps", "a dynamic transform repeats a header stamp its frame already "
          "has (counted by sender)", "tf2 TimeCache::insertData (TF_REPEATED_DATA: "
          "ignored)"),
    Check("out_of_order", "a sender's header stamp for a frame goes back; an error when it "
          "is older than cache_time before the frame's newest stamp", "tf2 "
          "TimeCache::insertData (TF_OLD_DATA: dropped)"),
    Check("clock_offset", "a sender's median delay (receive time - header stamp) is below "
          "-ahead seconds: its stamps are in the receiver's future",
          "tf2 FAQ (ExtrapolationException 'into the future': clocks not synchronised); "
          "tf_monitor delays"),
    Check("post_dated", "some of a sender's frames have a mean delay below -ahead seconds "
          "while its other frames do not: those frames are stamped in the future on purpose",
          "ROS 1 robot_state_publisher publishFixedTransforms (now + 0.5 s); amcl "
          "transform_tolerance"),
    Check("latency", "a sender's median delay exceeds the smallest median delay of the "
          "senders by more than lag seconds", "tf_monitor per-broadcaster delays; tf2 "
          "ExtrapolationException 'into the past'"),
    Check("disconnected", "the frames form more than one tree (a loop, which has no root, "
          "is left to the loop check): a lookup between frames of two trees raises "
          "ConnectivityException", "tf2 BufferCore::lookupTransform "
          "(ConnectivityException), tf2 FAQ"),
    Check("too_many_frames", "more child frames than max_frames (or more than MAX_LOOPS "
          "distinct loops): the rest are counted, not checked", "tfbus doctor's memory bound"),
)}
"""Every check by name: its rule and reference (``docs/doctor.md`` lists the same)."""


@dataclass(frozen=True)
class Thresholds:
    """The numbers the checks use (every field finite and > 0).

    Attributes:
        stale_periods: a frame silent for this many of its periods has stopped (5, as
            :data:`tfbus.monitor.STALE_PERIODS`).
        stale_after: ... and silent for at least this many seconds (1.0).
        gap_periods: a stamp interval this many periods long is a gap (5.0).
        gap_min: ... and at least this many seconds (0.5).
        rate_drop: a rate below this fraction of the steady rate has dropped (0.5).
        rate_window: intervals the moving-average period is taken over (20); no gap
            or rate drop is judged before this many intervals.
        ahead: a sender whose median delay is below ``-ahead`` seconds is ahead (0.01).
        lag: a sender whose median delay exceeds the smallest by this many seconds lags
            (0.25).
        min_samples: delays needed before a sender's clock is judged (10).
        cache_time: seconds of history tf2 keeps (10.0, tf2's default): older data is
            dropped (TF_OLD_DATA).
        max_frames: child frames tracked at most (10000); the rest are counted.
        max_senders: broadcasters tracked per frame and in all (256); the rest are counted
            under ``"..."``.
        delay_samples: delays kept per broadcaster for its median (1024).
    """

    stale_periods: float = 5.0
    stale_after: float = 1.0
    gap_periods: float = 5.0
    gap_min: float = 0.5
    rate_drop: float = 0.5
    rate_window: int = 20
    ahead: float = 0.01
    lag: float = 0.25
    min_samples: int = 10
    cache_time: float = 10.0
    max_frames: int = 10_000
    max_senders: int = 256
    delay_samples: int = 1024

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            ok = (isinstance(value, (int, float)) and not isinstance(value, bool)
                  and math.isfinite(value) and value > 0)
            if ok and f.type == "int" and not isinstance(value, int):
                ok = False
            if not ok:
                raise ValueError(f"Thresholds.{f.name} must be a finite number > 0, got {value!r}")
        if not 0 < self.rate_drop < 1:
            raise ValueError("Thresholds.rate_drop must be between 0 and 1, "
                             f"got {self.rate_drop!r}")
        if self.delay_samples < 4:
            raise ValueError(f"Thresholds.delay_samples must be >= 4, got {self.delay_samples!r}")


OVERFLOW: Final = "..."
"""The sender name under which broadcasters beyond :attr:`Thresholds.max_senders` count."""


class _SpanFields:
    """The fields of :class:`_Span` (the pure twin of ``_cchecks.SpanFields``)."""

    __slots__ = ("count", "first", "last")
    count: int
    first: int
    last: int


class _SampleFields:
    """The fields of :class:`_Sample` (the pure twin of ``_cchecks.SampleFields``)."""

    __slots__ = ("cap", "n", "stride", "values")
    cap: int
    n: int
    stride: int
    values: list[float]


class _MeanFields:
    """The fields of :class:`_Mean` (the pure twin of ``_cchecks.MeanFields``)."""

    __slots__ = ("count", "total")
    total: float
    count: int


class _LinkFields:
    """The fields of :class:`_Link` (the pure twin of ``_cchecks.LinkFields``)."""

    __slots__ = (
        "baseline", "child", "consecutive_gaps", "delay", "drop_first", "drop_last",
        "drop_worst", "dynamic", "first_gap", "gap_count", "gap_largest", "gap_senders", "hot",
        "intervals",
        "last_gap", "last_received", "newest", "old_data", "order_span", "out_of_order",
        "parent", "parents", "period", "recent", "repeat_span", "repeated",
        "sender_stamp", "static", "static_values",
    )


_COMPILED_MAX_WINDOW: Final = 2**61
"""``Thresholds.rate_window`` below which the compiled loop runs (its interval counts are
C 64-bit ints)."""

_Account = Callable[["Doctor", int, Iterable[TransformStamped], str, bool, float], None]


def _compiled_accounting() -> tuple[type, type, type, type, _Account | None]:
    """The per-link field classes and :meth:`Doctor.add`'s compiled loop
    (:mod:`tfbus.doctor._cchecks`, where :func:`~tfbus.core.kernels.compiled_extension`
    finds it); else the pure field classes and None (``Doctor.add``'s own loop)."""
    module = compiled_extension("tfbus.doctor._cchecks")
    if module is None:
        return _SpanFields, _SampleFields, _MeanFields, _LinkFields, None
    return (module.SpanFields, module.SampleFields, module.MeanFields, module.LinkFields,
            module.account)


if TYPE_CHECKING:
    _SpanBase = _SpanFields
    _SampleBase = _SampleFields
    _MeanBase = _MeanFields
    _LinkBase = _LinkFields
    _ACCOUNT: _Account | None
else:
    _SpanBase, _SampleBase, _MeanBase, _LinkBase, _ACCOUNT = _compiled_accounting()


class _Span(_SpanBase):
    """Messages counted over a receive-time span."""

    __slots__ = ()

    def __init__(self, t: int) -> None:
        self.count = 0
        self.first = t
        self.last = t

    def add(self, t: int) -> None:
        self.count += 1
        if t > self.last:
            self.last = t
        elif t < self.first:
            self.first = t

    def merge(self, other: _Span) -> None:
        self.count += other.count
        self.first = min(self.first, other.first)
        self.last = max(self.last, other.last)


class _Sample(_SampleBase):
    """A bounded, deterministic sample of a stream of numbers: every value until
    ``cap``, then every other one kept and the stride doubled (the sample stays spread
    over the whole run)."""

    __slots__ = ()

    def __init__(self, cap: int) -> None:
        self.cap = cap
        self.values: list[float] = []
        self.stride = 1
        self.n = 0

    def add(self, x: float) -> None:
        if self.n % self.stride == 0:
            self.keep(x)
        self.n += 1

    def keep(self, x: float) -> None:
        """Keep ``x`` (a value :meth:`add` samples), thinning the sample at ``cap``."""
        self.values.append(x)
        if len(self.values) >= self.cap:
            self.values = self.values[::2]
            self.stride *= 2

    def quantile(self, q: float) -> float:
        v = sorted(self.values)
        if not v:
            return 0.0
        pos = q * (len(v) - 1)
        lo = math.floor(pos)
        hi = min(lo + 1, len(v) - 1)
        return v[lo] + (v[hi] - v[lo]) * (pos - lo)


class _Mean(_MeanBase):
    """A running mean of a sender's delays on one link: ``total`` (seconds) over
    ``count`` values, updated in place."""

    __slots__ = ()

    def __init__(self) -> None:
        self.total = 0.0
        self.count = 0

    def add(self, other: _Mean) -> None:
        """Count ``other``'s values too (a sender renamed into another)."""
        self.total += other.total
        self.count += other.count

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, _Mean):
            return NotImplemented
        return (self.total, self.count) == (other.total, other.count)

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"_Mean(total={self.total!r}, count={self.count!r})"


_RECENT_STAMPS = 32  # stamps per frame kept to tell a repeated one (tf2's cache holds more)
MAX_LOOPS: Final = 100
"""Distinct loops remembered (a peer re-parenting frames at random cannot grow memory);
further ones are counted in the report's ``too_many_frames``-style ``loops_untracked``."""


class _Link(_LinkBase):
    """Everything the checks keep about one child frame."""

    __slots__ = ()

    def __init__(self, child: str) -> None:
        self.child = child
        self.parent = ""
        self.parents: dict[str, _Span] = {}
        self.static: dict[str, _Span] = {}
        self.dynamic: dict[str, _Span] = {}
        self.static_values: dict[str, tuple[object, ...]] = {}
        self.sender_stamp: dict[str, int] = {}
        self.delay: dict[str, _Mean] = {}  # sender -> the mean of its delays (s)
        # the last message's (parent, sender, static) and its spans and delay tables
        self.hot: tuple[str, str, bool, _Span, _Span, _Mean | None,
                        _Sample | None] | None = None
        self.newest: int | None = None
        # the last stamps kept (a repeated one is looked for here only when a stamp is
        # not newer than the newest: 32 ints scanned, no set to keep on the common path)
        self.recent: deque[int] = deque(maxlen=_RECENT_STAMPS)
        self.repeated: dict[str, int] = {}
        self.repeat_span: _Span | None = None
        self.out_of_order: dict[str, int] = {}
        self.old_data = 0
        self.order_span: _Span | None = None
        self.last_received: int | None = None
        self.period: float | None = None  # ns, moving average of stamp intervals
        self.intervals = 0
        self.consecutive_gaps = 0
        self.gap_count = 0
        self.gap_largest = (0, 0)  # (from stamp, to stamp)
        self.gap_senders: set[str] = set()
        self.first_gap: int | None = None  # receive times
        self.last_gap: int | None = None
        self.baseline: float | None = None  # ns, shortest settled period
        self.drop_first: int | None = None
        self.drop_last: int | None = None
        self.drop_worst = 0.0


def _sec(ns: float) -> float:
    return ns / NSEC_PER_SEC


def _fmt(s: float) -> str:
    return f"{s:.3f}"


class Doctor:
    """One pass over tf messages, then :meth:`report`.

    ::

        doctor = Doctor()
        for rec in read_messages("run.bag"):
            doctor.add(rec.time, rec.message.transforms, rec.authority, static=rec.is_static)
        report = doctor.report()

    Memory is O(frames x broadcasters) (bounded by :attr:`Thresholds.max_frames` and
    :attr:`Thresholds.max_senders`), whatever the number of messages.

    Args:
        thresholds: the numbers the checks use.
        source: what is diagnosed (a path, a bus spec), copied into the report.
    """

    def __init__(self, thresholds: Thresholds | None = None, *, source: str = "") -> None:
        self.thresholds = thresholds if thresholds is not None else Thresholds()
        self.source = source
        self.messages = 0
        self.transforms = 0
        self.start: int | None = None
        self.end: int | None = None
        self.sim_time: bool | None = None
        self.damage: str | None = None
        self.untracked = 0
        self.loops_untracked = 0
        self._links: dict[str, _Link] = {}
        self._latest: dict[str, str] = {}  # child -> its latest parent
        self._loops: dict[frozenset[str], tuple[tuple[str, ...], str, int, int]] = {}
        self._delays: dict[str, _Sample] = {}
        self._newest_stamp = 0
        t = self.thresholds
        self._alpha = 2.0 / (t.rate_window + 1)
        self._cache_ns = round(t.cache_time * NSEC_PER_SEC)
        self._senders: set[str] = set()
        # the compiled loop of add, when built (its counters of intervals are C ints)
        self._account = _ACCOUNT if t.rate_window < _COMPILED_MAX_WINDOW else None
        self._slashed: dict[str, tuple[_Span, set[str], str]] = {}

    # ------------------------------------------------------------------ feeding

    def _sender(self, authority: str) -> str:
        if authority in self._senders:
            return authority
        if len(self._senders) >= self.thresholds.max_senders:
            return OVERFLOW
        self._senders.add(authority)
        return authority

    def add(self, time: Time | int, transforms: Iterable[TransformStamped], authority: str, *,
            static: bool) -> None:
        """Account one message received at ``time`` (bag time or clock time, a
        :class:`~tfbus.time.Time` or ns) from ``authority``, on ``/tf_static`` when
        ``static``. Items that are not ``TransformStamped`` with string frame ids and a
        :class:`~tfbus.time.Time` stamp are skipped (the listener counts them)."""
        t = time.ns if isinstance(time, Time) else int(time)
        sender = self._sender(authority if isinstance(authority, str) else str(authority))
        self.messages += 1
        if self.start is None or t < self.start:
            self.start = t
        if self.end is None or t > self.end:
            self.end = t
        account = self._account
        if account is not None:  # the loop below, compiled
            account(self, t, transforms, sender, static, SIM_TIME_GAP)
            return
        links = self._links
        # the newest stamp held over the message, written back once (a dynamic transform
        # reads it and may raise it; nothing else reads it meanwhile)
        newest_stamp = self._newest_stamp
        sim_time = self.sim_time
        counted = 0
        # _interval's thresholds, read once a message for its common case inline below
        th = self.thresholds
        rate_window, gap_periods, rate_drop = th.rate_window, th.gap_periods, th.rate_drop
        gap_min_ns = th.gap_min * NSEC_PER_SEC
        settled = 2 * rate_window
        alpha = self._alpha
        try:
            for ts in transforms:
                if not isinstance(ts, TransformStamped):
                    continue
                child = ts.child_frame_id
                if not isinstance(child, str):
                    continue
                header = ts.header
                parent = header.frame_id
                when = header.stamp
                if not (isinstance(parent, str) and isinstance(when, Time)):
                    continue
                counted += 1
                link = links.get(child)
                if (link is not None and (hot := link.hot) is not None and hot[0] == parent
                        and hot[1] == sender and hot[2] is static):
                    # the same parent, sender and topic as the link's last message: no
                    # lookups (and no slash to strip: links and parents are kept without);
                    # its two spans' add(t), inline
                    span = hot[3]
                    span.count += 1
                    if t > span.last:
                        span.last = t
                    elif t < span.first:
                        span.first = t
                    span = hot[4]
                    span.count += 1
                    if t > span.last:
                        span.last = t
                    elif t < span.first:
                        span.first = t
                    mean, sample = hot[5], hot[6]
                else:
                    found = self._find(child, parent, sender, static, t)
                    if found is None:
                        continue
                    link, parent, mean, sample = found
                link.last_received = t
                if static:
                    tr, rot = ts.transform.translation, ts.transform.rotation
                    link.static_values[sender] = (parent, tr.x, tr.y, tr.z,
                                                  rot.x, rot.y, rot.z, rot.w)
                    continue
                assert mean is not None and sample is not None
                stamp = when._ns
                # delay: receive time - stamp (against the newest stamp in simulated time)
                if sim_time is None:
                    sim_time = self.sim_time = abs(t - stamp) / NSEC_PER_SEC > SIM_TIME_GAP
                if stamp > newest_stamp:
                    newest_stamp = stamp
                d = ((newest_stamp if sim_time else t) - stamp) / NSEC_PER_SEC
                mean.total += d
                mean.count += 1
                if sample.n % sample.stride == 0:  # sample.add(d), inline
                    sample.keep(d)
                sample.n += 1
                newest = link.newest
                if newest is not None and stamp > newest:
                    # in order (the common case): newer than every stamp held, not repeated
                    link.recent.append(stamp)
                    link.sender_stamp[sender] = stamp
                    p = link.period
                    interval = float(stamp - newest)
                    if p is None or (link.intervals >= rate_window and interval > gap_periods * p
                                     and interval > gap_min_ns):
                        self._interval(link, t, stamp, newest, sender)  # the first, or a gap
                    else:  # _interval's common case, inline: the moving average moves
                        link.newest = stamp
                        intervals = link.intervals = link.intervals + 1
                        link.consecutive_gaps = 0
                        p = link.period = p + alpha * (interval - p)
                        if intervals > settled:
                            baseline = link.baseline
                            if baseline is None or p < baseline:
                                link.baseline = baseline = p
                            if p * rate_drop > baseline:
                                self._dropped(link, t, p)
                else:
                    self._stamps(link, t, stamp, sender)
        finally:
            self._newest_stamp = newest_stamp
            self.transforms += counted

    def _link(self, child: str) -> _Link | None:
        link = self._links.get(child)
        if link is None:
            if len(self._links) >= self.thresholds.max_frames:
                self.untracked += 1
                return None
            link = self._links[child] = _Link(child)
        return link

    def _find(self, child: str, parent: str, sender: str, static: bool, t: int
              ) -> tuple[_Link, str, _Mean | None, _Sample | None] | None:
        """A transform whose link has no hot entry for it (another parent, sender or
        topic than its last message, a new link, a slash to strip): its link, its parent
        without a leading slash and, for a dynamic one, its sender's delay tables
        (:meth:`_relook`); None when the link is untracked (:attr:`Thresholds.max_frames`)."""
        link = None
        if child.startswith("/"):  # tf2 (ROS 1, and tfbus) stores it without the slash
            self._slash(child, "child_frame_id", sender, t)
            child = child[1:]
        else:
            link = self._links.get(child)
        if parent.startswith("/"):
            self._slash(parent, "frame_id", sender, t)
            parent = parent[1:]
        link = link or self._link(child)
        if link is None:
            return None
        mean, sample = self._relook(link, t, parent, sender, static)
        return link, parent, mean, sample

    def _relook(self, link: _Link, t: int, parent: str, sender: str, static: bool
                ) -> tuple[_Mean | None, _Sample | None]:
        """Account a message whose parent, sender or topic differs from the link's last:
        the span tables looked up (and bounded), a new parent checked for a loop."""
        span = link.parents.get(parent)
        if span is None:
            if len(link.parents) >= self.thresholds.max_senders:
                parent = OVERFLOW
            span = link.parents.setdefault(parent, _Span(t))
        span.add(t)
        if parent != link.parent:
            link.parent = parent
            self._relink(link.child, parent, sender, t)
        senders = link.static if static else link.dynamic
        sspan = senders.get(sender)
        if sspan is None:
            if len(senders) >= self.thresholds.max_senders:
                sender = OVERFLOW
            sspan = senders.setdefault(sender, _Span(t))
        sspan.add(t)
        mean: _Mean | None = None
        sample: _Sample | None = None
        if not static:
            mean = link.delay.get(sender)
            if mean is None:
                mean = link.delay[sender] = _Mean()
            sample = self._delays.get(sender)
            if sample is None:
                sample = self._delays[sender] = _Sample(self.thresholds.delay_samples)
        # The hot entry lets a later message skip the slash checks (see _add_one): not
        # kept for an id that still starts with '/' once one was stripped ("//a").
        link.hot = (None if parent.startswith("/") or link.child.startswith("/")
                    else (parent, sender, static, span, sspan, mean, sample))
        return mean, sample

    def _slash(self, frame_id: str, role: str, sender: str, t: int) -> None:
        found = self._slashed.get(frame_id)
        if found is None:
            if len(self._slashed) >= self.thresholds.max_frames:
                return
            found = self._slashed[frame_id] = (_Span(t), set(), role)
        found[0].add(t)
        if len(found[1]) < self.thresholds.max_senders:
            found[1].add(sender)

    def _relink(self, child: str, parent: str, sender: str, t: int) -> None:
        """A new latest parent for ``child``: a loop when ``child`` is an ancestor of
        ``parent`` (:func:`tfbus.core.frame_path` from ``parent`` to ``child`` while
        ``child`` has no parent is the way up between them, None when there is none)."""
        latest = self._latest
        latest.pop(child, None)
        up = [child] if parent == child else frame_path(latest, parent, child)
        latest[child] = parent
        if up is None:
            return
        path = (child, *up[:-1]) if parent != child else (child,)
        key = frozenset(path)
        found = self._loops.get(key)
        if found is None and len(self._loops) >= MAX_LOOPS:
            self.loops_untracked += 1
            return
        self._loops[key] = (path, sender, found[2] if found else t, t)

    def _stamps(self, link: _Link, t: int, stamp: int, sender: str) -> None:
        # repeated stamps (TF_REPEATED_DATA) and out-of-order ones, by sender
        if stamp in link.recent:
            link.repeated[sender] = link.repeated.get(sender, 0) + 1
            link.repeat_span = link.repeat_span or _Span(t)
            link.repeat_span.add(t)
            return
        link.recent.append(stamp)
        before = link.sender_stamp.get(sender)
        link.sender_stamp[sender] = stamp if before is None else max(before, stamp)
        if before is not None and stamp < before:
            link.out_of_order[sender] = link.out_of_order.get(sender, 0) + 1
            if link.newest is not None and link.newest - stamp > self._cache_ns:
                link.old_data += 1
            link.order_span = link.order_span or _Span(t)
            link.order_span.add(t)
        newest = link.newest
        if newest is not None and stamp <= newest:
            return
        if newest is None:
            link.newest = stamp
            return
        self._interval(link, t, stamp, newest, sender)

    def _interval(self, link: _Link, t: int, stamp: int, newest: int, sender: str) -> None:
        """A stamp newer than the frame's newest: rates and gaps over the increasing
        stamps (:meth:`add` makes the common case, no gap after the first interval,
        itself)."""
        th = self.thresholds
        link.newest = stamp
        d = float(stamp - newest)
        link.intervals += 1
        p = link.period
        if p is None:
            link.period = d
            return
        if (link.intervals > th.rate_window and d > th.gap_periods * p
                and d > th.gap_min * NSEC_PER_SEC):
            link.gap_count += 1
            link.consecutive_gaps += 1
            link.gap_senders.add(sender)
            if d > link.gap_largest[1] - link.gap_largest[0]:
                link.gap_largest = (newest, stamp)
            link.first_gap = t if link.first_gap is None else link.first_gap
            link.last_gap = t
            if link.consecutive_gaps < 3:
                return
            p = link.period = d  # slow for three intervals: this is the rate now
        else:
            link.consecutive_gaps = 0
            p = link.period = p + self._alpha * (d - p)
        if link.intervals <= 2 * th.rate_window:
            return
        if link.baseline is None or p < link.baseline:
            link.baseline = p
        if p * th.rate_drop > link.baseline:
            self._dropped(link, t, p)

    @staticmethod
    def _dropped(link: _Link, t: int, p: float) -> None:
        """The link's moving-average period ``p`` (ns) is a dropped rate at receive time
        ``t``."""
        link.drop_first = t if link.drop_first is None else link.drop_first
        link.drop_last = t
        link.drop_worst = max(link.drop_worst, p)

    def note_damage(self, reason: str) -> None:
        """Record that the source was damaged (a :class:`~tfbus.errors.BagReadError`'s
        one-line reason): the report gets a ``damaged_recording`` finding."""
        self.damage = " ".join(reason.split())

    def rename_authority(self, old: str, new: str, *, static: bool | None = None) -> None:
        """Account what was received from ``old`` to ``new`` instead (a live bus names a
        sender only once its liveliness arrives, as
        :meth:`tfbus.monitor.TfSummary.rename_authority`): with ``static`` True only its
        ``/tf_static`` messages, False only its ``/tf`` ones, None both."""
        if old == new:
            return
        dynamic = static is not True
        for link in self._links.values():
            link.hot = None
            tables = [t for t, kind in ((link.static, True), (link.dynamic, False))
                      if static is None or kind is static]
            for table in tables:
                span = table.pop(old, None)
                if span is not None:
                    if new in table:
                        table[new].merge(span)
                    else:
                        table[new] = span
            if old in link.static_values and static is not False:
                link.static_values[new] = link.static_values.pop(old)
            if not dynamic:
                continue
            for counter in (link.repeated, link.out_of_order):
                if old in counter:
                    counter[new] = counter.get(new, 0) + counter.pop(old)
            if old in link.sender_stamp:
                stamp = link.sender_stamp.pop(old)
                link.sender_stamp[new] = max(stamp, link.sender_stamp.get(new, stamp))
            if old in link.delay:
                moved = link.delay.pop(old)
                mean = link.delay.get(new)
                if mean is None:
                    mean = link.delay[new] = _Mean()
                mean.add(moved)
            if old in link.gap_senders:
                link.gap_senders.discard(old)
                link.gap_senders.add(new)
        sample = self._delays.pop(old, None) if dynamic else None
        if sample is not None:
            into = self._delays.setdefault(new, _Sample(self.thresholds.delay_samples))
            for v in sample.values:
                into.add(v)
            into.n += sample.n - len(sample.values)
        self._senders.add(new)

    # ------------------------------------------------------------------ reporting

    def broadcasters(self) -> tuple[BroadcasterDelay, ...]:
        """Each broadcaster's delays (receive time - header stamp) so far."""
        out = []
        for sender, sample in sorted(self._delays.items()):
            out.append(BroadcasterDelay(
                sender, sample.n, sample.quantile(0.5),
                max(0.0, sample.quantile(0.9) - sample.quantile(0.1)), len(sample.values)))
        return tuple(out)

    def report(self, now: Time | int | None = None) -> Report:
        """The findings so far. ``now`` is the receive time the ``stopped`` check measures
        silence up to (live: the clock's now); by default the last message's time."""
        end = self.end if now is None else (now.ns if isinstance(now, Time) else int(now))
        findings: list[Finding] = []
        if self.damage is not None:
            findings.append(self._finding(
                "damaged_recording", Level.ERROR, f"the recording is damaged: {self.damage}",
                advice="everything before the damage was diagnosed; re-record or repair the "
                "file (rosbag reindex, ros2 bag reindex, mcap recover)",
                start=self.end, end=self.end))
        for link in self._links.values():
            findings += self._link_findings(link, end)
        for name, (span, senders, role) in self._slashed.items():
            findings.append(self._finding(
                "leading_slash", Level.ERROR,
                f"frame id {name} starts with '/' (as {role}, {span.count} times)",
                frames=(name,), senders=sorted(senders), start=span.first, end=span.last,
                advice=f"drop the leading '/': ROS 2's tf2 refuses {name} in lookups, ROS 1's "
                "strips it (the doctor checks the tree without it)",
                counts={"transforms": span.count}))
        findings += self._loop_findings()
        findings += self._tree_findings()
        findings += self._clock_findings()
        if self.untracked or self.loops_untracked:
            findings.append(self._finding(
                "too_many_frames", Level.INFO,
                f"more than {self.thresholds.max_frames} child frames or {MAX_LOOPS} loops: "
                f"{self.untracked} transforms of further frames and {self.loops_untracked} "
                "further loops were counted, not checked",
                advice="raise Thresholds.max_frames (memory grows with it)",
                counts={"untracked_transforms": self.untracked,
                        "untracked_loops": self.loops_untracked}))
        findings.sort(key=lambda f: (-f.level.rank, f.check, f.frames, f.senders))
        return Report(
            source=self.source, findings=tuple(findings), messages=self.messages,
            transforms=self.transforms, frames=self._frame_count(),
            links=len(self._links), start_ns=self.start,
            end_ns=self.end, sim_time=bool(self.sim_time), broadcasters=self.broadcasters())

    def _frame_count(self) -> int:
        """Frame ids of the tracked links, their parents (every parent seen) included."""
        ids = set(self._links)
        for link in self._links.values():
            ids.update(link.parents)
            if link.parent:
                ids.add(link.parent)
        return len(ids)

    @staticmethod
    def _finding(check: str, level: Level, message: str, *, frames: Sequence[str] = (),
                 senders: Sequence[str] = (), start: int | None = None,
                 end: int | None = None, advice: str = "",
                 counts: dict[str, int | float] | None = None,
                 lookups: Sequence[tuple[str, str]] = ()) -> Finding:
        return Finding(check, level, message, tuple(frames), tuple(senders), start, end,
                       advice, counts or {}, tuple(lookups), CHECKS[check].reference)

    def _link_findings(self, link: _Link, end: int | None) -> list[Finding]:
        out: list[Finding] = []
        child = link.child
        named_dyn = {s: v for s, v in link.dynamic.items() if s not in PLACEHOLDER_AUTHORITIES}
        if len(named_dyn) > 1:
            items = sorted(named_dyn.items(), key=lambda kv: (kv[1].first, kv[0]))
            overlap = any(
                a.first <= b.last and b.first <= a.last
                for i, (_, a) in enumerate(items) for (_, b) in items[i + 1:])
            names = [s for s, _ in items]
            who = ", ".join(f"{s} ({v.count})" for s, v in items)
            out.append(self._finding(
                "several_authorities", Level.ERROR if overlap else Level.INFO,
                f"{child} is sent by {len(items)} broadcasters"
                f"{' at the same time' if overlap else ' one after another'}: {who}",
                frames=(child, link.parent), senders=names,
                start=min(v.first for v in named_dyn.values()),
                end=max(v.last for v in named_dyn.values()),
                advice="make one node publish this frame (the others overwrite it; tf2 keeps "
                "whichever sample came last)" if overlap else "a broadcaster took over: "
                "fine after a restart, otherwise make one node publish this frame",
                counts={s: v.count for s, v in items}))
        named_static = {s: v for s, v in link.static.items()
                        if s not in PLACEHOLDER_AUTHORITIES}
        if len(named_static) > 1 and len({link.static_values.get(s) for s in named_static}) > 1:
            items = sorted(named_static.items())
            out.append(self._finding(
                "several_authorities", Level.WARNING,
                f"static {child} is sent with different values by {len(items)} broadcasters: "
                + ", ".join(f"{s} ({v.count})" for s, v in items),
                frames=(child, link.parent), senders=[s for s, _ in items],
                start=min(v.first for v in named_static.values()),
                end=max(v.last for v in named_static.values()),
                advice="keep one static publisher for this frame: the last one latched wins",
                counts={s: v.count for s, v in items}))
        if link.static and link.dynamic:
            st, dy = sorted(link.static), sorted(link.dynamic)
            spans = [*link.static.values(), *link.dynamic.values()]
            out.append(self._finding(
                "static_and_dynamic", Level.ERROR,
                f"{child} is sent both on /tf_static (by {', '.join(st)}) and on /tf "
                f"(by {', '.join(dy)})",
                frames=(child, link.parent), senders=sorted(set(st) | set(dy)),
                start=min(s.first for s in spans), end=max(s.last for s in spans),
                advice="send it on one topic: /tf_static for a fixed joint, /tf for a moving "
                "one (tf2 replaces the frame's history when it switches)",
                counts={"static": sum(s.count for s in link.static.values()),
                        "dynamic": sum(s.count for s in link.dynamic.values())}))
        if len(link.parents) > 1:
            items = sorted(link.parents.items(), key=lambda kv: (kv[1].first, kv[0]))
            out.append(self._finding(
                "parent_change", Level.WARNING,
                f"{child} changes parent: " + " -> ".join(p for p, _ in items),
                frames=(child, *(p for p, _ in items)), senders=self._all_senders(link),
                start=min(s.first for _, s in items), end=max(s.last for _, s in items),
                advice="give each frame one parent; a frame that is re-parented makes lookups "
                "before and after the change walk different trees",
                counts={p: s.count for p, s in items}))
        if link.dynamic:
            out += self._timing_findings(link, end)
        return out

    def _all_senders(self, link: _Link) -> list[str]:
        return sorted(set(link.static) | set(link.dynamic))

    def _timing_findings(self, link: _Link, end: int | None) -> list[Finding]:
        th = self.thresholds
        out: list[Finding] = []
        child = link.child
        dyn = sorted(link.dynamic)
        if link.repeated:
            total = sum(link.repeated.values())
            span = link.repeat_span
            out.append(self._finding(
                "repeated_stamps", Level.WARNING,
                f"{child}: {total} transforms repeat a stamp the frame already has "
                "(TF_REPEATED_DATA): " + ", ".join(f"{s} ({n})" for s, n in
                                                   sorted(link.repeated.items())),
                frames=(child, link.parent), senders=sorted(link.repeated),
                start=span.first if span else None, end=span.last if span else None,
                advice="publish each stamp once (tf2 ignores the repeats with a warning); two "
                "senders or a timer faster than the data repeat stamps",
                counts=dict(sorted(link.repeated.items()))))
        if link.out_of_order:
            total = sum(link.out_of_order.values())
            span = link.order_span
            old = link.old_data
            out.append(self._finding(
                "out_of_order", Level.ERROR if old else Level.WARNING,
                f"{child}: {total} stamps go back in time" + (
                    f", {old} older than cache_time ({_fmt(th.cache_time)} s: TF_OLD_DATA, "
                    "dropped)" if old else ""),
                frames=(child, link.parent), senders=sorted(link.out_of_order),
                start=span.first if span else None, end=span.last if span else None,
                advice="stamp with a clock that does not go back (a sim clock reset, two "
                "senders, or a reordering queue)",
                counts={**dict(sorted(link.out_of_order.items())), "old_data": old}))
        if link.period is None or link.period <= 0:
            return out
        period = _sec(link.period)
        if (end is not None and link.last_received is not None
                and link.intervals >= 2):
            silent = _sec(end - link.last_received)
            if silent > max(th.stale_after, th.stale_periods * period):
                out.append(self._finding(
                    "stopped", Level.WARNING,
                    f"{child} stopped: nothing for {_fmt(silent)} s at the end "
                    f"(it came every {_fmt(period)} s)",
                    frames=(child, link.parent), senders=dyn, start=link.last_received,
                    end=end,
                    advice="its broadcaster stopped or died: lookups after its last stamp "
                    "raise ExtrapolationException",
                    counts={"silent_s": silent, "period_s": period}))
        if link.gap_count:
            a, b = link.gap_largest
            out.append(self._finding(
                "gap", Level.WARNING,
                f"{child}: {link.gap_count} gap{'s' if link.gap_count > 1 else ''} in its "
                f"stamps, the longest "
                f"{_fmt(_sec(b - a))} s (it comes every {_fmt(period)} s)",
                frames=(child, link.parent), senders=sorted(link.gap_senders),
                start=link.first_gap, end=link.last_gap,
                advice="lookups inside a gap interpolate across it; look at what its "
                "broadcaster was doing (CPU, network, a blocked callback)",
                counts={"gaps": link.gap_count, "longest_s": _sec(b - a),
                        "longest_from_ns": a, "longest_to_ns": b}))
        if link.drop_first is not None and link.baseline:
            steady = NSEC_PER_SEC / link.baseline
            worst = NSEC_PER_SEC / link.drop_worst
            out.append(self._finding(
                "rate_drop", Level.WARNING,
                f"{child}: its rate fell from {steady:.1f} Hz to {worst:.1f} Hz",
                frames=(child, link.parent), senders=dyn, start=link.drop_first,
                end=link.drop_last,
                advice="its broadcaster slowed down (CPU, network, a slower input); "
                "lookups wait longer or extrapolate",
                counts={"steady_hz": steady, "lowest_hz": worst}))
        return out

    def _loop_findings(self) -> list[Finding]:
        out = []
        for path, sender, first, last in self._loops.values():
            cycle = " -> ".join((*path, path[0]))
            out.append(self._finding(
                "loop", Level.ERROR,
                f"{path[0]} is its own parent" if len(path) == 1 else f"loop: {cycle}",
                frames=path, senders=(sender,), start=first, end=last,
                advice="a frame must never be its own ancestor: find the broadcaster of the "
                "last link (tf2 refuses every lookup through a loop)"))
        return out

    def _tree_findings(self) -> list[Finding]:
        parents = dict(self._latest)
        frames = set(parents) | set(parents.values())
        children: dict[str, list[str]] = {}
        for c, p in parents.items():
            children.setdefault(p, []).append(c)
        # each tree from its root down (frames in a loop have no root: none reaches them)
        tree_of: dict[str, str] = {}
        roots: dict[str, list[str]] = {}
        for top in sorted(frames - set(parents)):
            members, todo = [], [top]
            while todo:
                f = todo.pop()
                tree_of[f] = top
                members.append(f)
                todo += children.get(f, ())
            roots[top] = members
        out: list[Finding] = []

        def root(f: str) -> str | None:
            return tree_of.get(f)

        def ancestors(f: str) -> list[str]:
            top = tree_of.get(f)
            path = None if top is None else frame_path(parents, f, top)
            return [] if path is None else path[1:]

        present = [f for f in REP105_ORDER if f in frames]
        for i, a in enumerate(present):
            for b in present[i + 1:]:
                if root(a) is None or root(a) != root(b) or a in ancestors(b):
                    continue
                inverted = b in ancestors(a)
                out.append(self._finding(
                    "rep105", Level.ERROR,
                    f"REP 105 wants {a} above {b}, but "
                    + (f"{b} is an ancestor of {a}" if inverted else
                       f"{b} is not below {a} ({b} <- {' <- '.join(ancestors(b)) or '-'})"),
                    frames=(a, b), senders=self._senders_of((a, b)),
                    start=self._span((a, b))[0], end=self._span((a, b))[1],
                    advice=f"publish {' -> '.join(present)} as one chain, "
                    f"each frame the parent of the next"))
        for w in ("earth", "map", "odom"):
            if w not in frames:
                continue
            robot = next((r for r in ancestors(w) if r in ROBOT_FRAMES), None)
            if robot is not None and robot not in present:
                out.append(self._finding(
                    "rep105", Level.ERROR, f"{w} is below the robot frame {robot}",
                    frames=(w, robot), senders=self._senders_of((w,)),
                    start=self._span((w,))[0], end=self._span((w,))[1],
                    advice=f"{w} is a world frame (REP 105): publish {w} -> ... -> {robot}"))
        if ("base_footprint" in frames and "base_link" in frames
                and root("base_footprint") is not None
                and root("base_footprint") == root("base_link")
                and parents.get("base_footprint") != "base_link"
                and parents.get("base_link") != "base_footprint"):
            out.append(self._finding(
                "base_footprint", Level.WARNING,
                "base_footprint and base_link are not parent and child: base_footprint <- "
                + (" <- ".join(ancestors("base_footprint")) or "-") + "; base_link <- "
                + (" <- ".join(ancestors("base_link")) or "-"),
                frames=("base_footprint", "base_link"),
                senders=self._senders_of(("base_footprint", "base_link")),
                start=self._span(("base_footprint", "base_link"))[0],
                end=self._span(("base_footprint", "base_link"))[1],
                advice="publish base_link -> base_footprint (REP 120) or base_footprint -> "
                "base_link, one directly below the other"))
        # a component whose walk ends on a loop has no root: the loop check reports it
        trees = sorted(roots.items(), key=lambda kv: (-len(kv[1]), kv[0]))
        if len(trees) > 1:
            tops = [r for r, _ in trees]
            lookups = [(a, b) for i, a in enumerate(tops) for b in tops[i + 1:]][:10]
            known = [f for f in (*REP105_ORDER, "base_footprint") if f in frames]
            lookups += [(a, b) for i, a in enumerate(known) for b in known[i + 1:]
                        if root(a) != root(b) and (a, b) not in lookups]
            out.append(self._finding(
                "disconnected", Level.WARNING,
                f"{len(trees)} separate trees: " + "; ".join(
                    f"{r} ({len(fs)} frames)" for r, fs in trees[:10]),
                frames=tuple(tops), senders=self._senders_of(
                    [f for r, fs in trees[1:] for f in fs]),
                advice="publish the link between the trees (a /tf_static missing from the "
                "recording, a node not running); lookups across them raise "
                "ConnectivityException",
                counts={r: len(fs) for r, fs in trees[:50]},
                lookups=lookups))
        return out

    def _span(self, frames: Iterable[str], sender: str | None = None
              ) -> tuple[int | None, int | None]:
        """The receive-time span of ``frames``' messages (of ``sender``'s only, when given)."""
        spans = []
        for f in frames:
            link = self._links.get(f)
            if link is None:
                continue
            for table in (link.static, link.dynamic):
                spans += [s for name, s in table.items() if sender is None or name == sender]
        if not spans:
            return None, None
        return min(s.first for s in spans), max(s.last for s in spans)

    def _senders_of(self, frames: Iterable[str]) -> list[str]:
        out: set[str] = set()
        for f in frames:
            link = self._links.get(f)
            if link is not None:
                out |= set(link.static) | set(link.dynamic)
        return sorted(out)

    def _clock_findings(self) -> list[Finding]:
        th = self.thresholds
        out: list[Finding] = []
        judged = [b for b in self.broadcasters() if b.transforms >= th.min_samples]
        if not judged:
            return out
        on_time = [b.median for b in judged if self.sim_time or b.median >= -th.ahead]
        lowest = min(on_time) if on_time else 0.0
        for b in judged:
            frames = self._frames_of(b.sender)
            start, end = self._span(frames, b.sender)
            means = {c: m for c in frames
                     if (d := self._links[c].delay.get(b.sender)) and d.count >= th.min_samples
                     for m in (d.total / d.count,)}
            ahead = {c: m for c, m in means.items() if m < -th.ahead}
            if not self.sim_time and ahead and len(ahead) == len(means):
                out.append(self._finding(
                    "clock_offset", Level.ERROR,
                    f"{b.sender}'s stamps are {_fmt(-b.median)} s ahead of the receiver's "
                    f"clock (median of {b.samples}, spread {_fmt(b.spread)} s)",
                    frames=frames, senders=(b.sender,), start=start, end=end,
                    advice="synchronise its clock (chrony/NTP): lookups at now() with its "
                    "frames raise ExtrapolationException into the future",
                    counts={"median_delay_s": b.median, "spread_s": b.spread}))
            elif not self.sim_time and ahead:
                out.append(self._finding(
                    "post_dated", Level.INFO,
                    f"{b.sender} stamps {len(ahead)} of its {len(means)} frames ahead of "
                    "the receiver's clock (its other frames are not: its clock is right): "
                    + ", ".join(f"{c} {_fmt(-m)} s" for c, m in sorted(ahead.items())[:10]),
                    frames=tuple(sorted(ahead)), senders=(b.sender,), start=start, end=end,
                    advice="deliberate future-dating (ROS 1 robot_state_publisher's fixed "
                    "joints: +0.5 s; amcl's transform_tolerance): fine unless those frames "
                    "are meant to be measured; fixed joints belong on /tf_static",
                    counts={c: -m for c, m in sorted(ahead.items())}))
            elif on_time and b.median - lowest > th.lag:
                out.append(self._finding(
                    "latency", Level.WARNING,
                    f"{b.sender} lags the others by {_fmt(b.median - lowest)} s (median "
                    f"delay {_fmt(b.median)} s against {_fmt(lowest)} s)",
                    frames=frames, senders=(b.sender,), start=start, end=end,
                    advice="its clock is behind or it stamps late data: lookups joining its "
                    "frames with others wait or extrapolate into the past",
                    counts={"median_delay_s": b.median, "lowest_median_s": lowest,
                            "spread_s": b.spread}))
        return out

    def _frames_of(self, sender: str) -> tuple[str, ...]:
        return tuple(sorted(c for c, link in self._links.items() if sender in link.dynamic))
