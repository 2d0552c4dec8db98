"""tf_monitor's summaries: per-frame rate and delay, per-broadcaster rate and delay, and
the net delay of a chain, for bags and live buses alike.

Words: in tfbus *statistics* are counters (``Bus.statistics()``,
``TransformListener.statistics()``, ``transport.statistics()``); the tables kept here are
*summaries* (:class:`TfSummary`, :class:`FrameSummary`, :class:`AuthoritySummary`), as
:func:`tfbus.bag.summarize` returns for a recording.

::

    stats = TfSummary()
    for rec in read_messages("turtle.bag"):               # a recording ...
        stats.add(rec.time, rec.message.transforms, rec.authority, static=rec.is_static)
    stats.frames["turtle1"].rate                          # Hz

    sink = MonitoredSink(buffer, stats, clock)            # ... or a live bus:
    async with TransformListener(sink, bus):              # the listener feeds the buffer
        ...                                               # and the summary at once

Definitions (one for every tool: ``tfbus frames``, ``monitor`` and ``bag-info``):

* **rate** of a frame: ``(distinct header stamps - 1) / (newest stamp - oldest stamp)``
  in Hz. A repeated stamp counts once, as tf2 keeps it once (``TF_REPEATED_DATA``);
  static frames and frames with a single stamp have no rate (0.0).
* **delay** of a transform: receive time minus header stamp, in seconds, as
  tf_monitor's ``callback`` measures it (``ros::Time::now() - stamp``); bag time is
  the receive time of a recorded message. When the stamps are more than
  :data:`SIM_TIME_GAP` seconds away from the receive clock (a bag recorded with
  simulated time, stamps near 0 while the recorder's clock is near 1.7e9), delays are
  measured against the newest stamp seen so far instead and :attr:`TfSummary.sim_time`
  is set, so that tools can say so.
* **rate** of a broadcaster: ``(messages - 1) / (last - first receive time)``.
* **net delay** of a chain (tf_monitor ``A B``): receive time minus the latest common
  stamp of the chain's dynamic links (what ``lookupTransform(A, B, Time())`` returns),
  sampled at every message that updates one of them.
* **recent rate** (live tables): the same rates over the samples received in the last
  :data:`RATE_WINDOW` seconds before now, and at most the last :data:`RECENT_SAMPLES`
  of them (:meth:`FrameSummary.recent_rate`, :meth:`AuthoritySummary.recent_rate`), as
  tf_monitor keeps only its last 1000 samples per frame and per broadcaster. The window
  is a :class:`RateWindow`: memory is bounded whatever the run time, and a rate costs
  O(1) amortized per call while the stamps held arrived in order (samples leave the
  window once).
* **stale**: a frame or broadcaster silent for more than :data:`STALE_PERIODS` of its
  own periods (and at least :data:`STALE_AFTER` seconds) has stopped: its recent rate is
  0.0 and :meth:`RateWindow.stale` says so.
* **distinct stamps** (the whole-run rate): a stamp counts once when it repeats one of
  the last :data:`RECENT_SAMPLES` distinct stamps of the frame (tf2 likewise only finds a
  repeated stamp among the data its cache still holds).

Source: ros/geometry ``tf/src/tf_monitor.cpp`` (TFMonitor::callback, outputFrameInfo,
spin), tf2 ``BufferCore::_chainAsVector`` for the chain's order.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Protocol, TypeVar, cast

from tfbus.clock import Clock
from tfbus.core import BatchResult, frame_path
from tfbus.core.kernels import compiled_extension
from tfbus.core.policy import ExpireAfter
from tfbus.core.results import BufferStatistics
from tfbus.messages import TransformStamped
from tfbus.time import NSEC_PER_SEC, Time
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC

__all__ = [
    "RATE_WINDOW",
    "RECENT_SAMPLES",
    "SIM_TIME_GAP",
    "STALE_AFTER",
    "STALE_PERIODS",
    "AuthoritySummary",
    "ChainDelay",
    "FrameSummary",
    "MonitoredSink",
    "RateWindow",
    "TfSummary",
    "expiry_line",
    "frame_chain",
    "link_rate",
]

SIM_TIME_GAP = 86_400.0
"""Seconds between a header stamp and its receive time beyond which the stamps are taken
to be simulated time (see the module docstring)."""

RATE_WINDOW = 10.0
"""Seconds of receive time the live tables' rates are measured over (module docstring)."""

RECENT_SAMPLES = 1000
"""Samples kept per frame and per broadcaster for the recent rates: the bound on memory
(tf_monitor keeps its last 1000; above 100 Hz the window is the last 1000 samples)."""

STALE_PERIODS = 5.0
"""A frame or broadcaster silent for this many of its own periods has stopped."""
STALE_AFTER = 1.0
"""... and silent for at least this many seconds (a stale verdict is never quicker)."""


class _RateWindowFields:
    """The fields of :class:`RateWindow` (the pure twin of ``_cmonitor.RateWindowFields``)."""

    __slots__ = ("_held", "_out_of_order", "_received", "_seq", "_values", "distinct",
                 "last_received", "maxlen", "window_ns")


class _FrameFields:
    """The fields of :class:`FrameSummary` (the pure twin of ``_cmonitor.FrameFields``)."""

    __slots__ = ("authorities", "child", "count", "delay_count", "delay_max", "delay_sum",
                 "distinct_stamps", "first_stamp", "last_stamp", "parent", "received", "static")


class _AuthorityFields:
    """The fields of :class:`AuthoritySummary` (the pure twin of
    ``_cmonitor.AuthorityFields``)."""

    __slots__ = ("authority", "delay_count", "delay_max", "delay_sum", "first", "last",
                 "messages", "received")


_Account = Callable[..., bool]


def _compiled_tables() -> tuple[type, type, type, _Account | None]:
    """The field classes of the tables and :meth:`TfSummary.add`'s compiled loop
    (:mod:`tfbus._cmonitor`, where :func:`~tfbus.core.kernels.compiled_extension` finds
    it); else the pure field classes and None (``TfSummary.add``'s own loop)."""
    module = compiled_extension("tfbus._cmonitor")
    if module is None:
        return _RateWindowFields, _FrameFields, _AuthorityFields, None
    return module.RateWindowFields, module.FrameFields, module.AuthorityFields, module.account


if TYPE_CHECKING:
    _RateWindowBase = _RateWindowFields
    _FrameBase = _FrameFields
    _AuthorityBase = _AuthorityFields
    _ACCOUNT: _Account | None
else:
    _RateWindowBase, _FrameBase, _AuthorityBase, _ACCOUNT = _compiled_tables()

_T = TypeVar("_T")


def _fields_on_base(cls: type[_T]) -> type[_T]:
    """A dataclass whose fields live on its base (the field classes above): the class
    attributes ``@dataclass`` leaves for defaults would hide them, so they go (its
    ``__init__`` keeps its own copy of each default)."""
    for f in fields(cls):  # type: ignore[arg-type]
        if f.name in cls.__dict__:
            delattr(cls, f.name)
    return cls


class RateWindow(_RateWindowBase):
    """The samples of one frame (or broadcaster) received in the last ``window`` seconds,
    at most ``maxlen`` of them: ``(receive time, value)`` in ns, value the header stamp
    (``distinct``: a repeated stamp is kept once, as tf2 keeps it) or the receive time.

    Memory is ``O(maxlen)``: two queues of plain ints, no object per sample. While the
    values held arrived in order (each newer than the one before it: the common case),
    :meth:`add` and :meth:`rate` are O(1) amortized (each sample enters and leaves once;
    the oldest value held is the smallest, the newest the largest; a repeated stamp is
    found by bisection). A value that arrives out of order is remembered until it leaves
    the window; meanwhile the values held are also kept in a set (built once, O(held),
    then updated with each sample) and a rate reads the smallest and largest by a scan.

    Args:
        window: seconds of receive time (> 0).
        maxlen: samples kept at most (>= 2).
        distinct: keep one sample per value (header stamps), else every sample.

    Raises:
        ValueError: ``window`` not finite and > 0, or ``maxlen`` < 2.
    """

    __slots__ = ()

    def __init__(self, window: float = RATE_WINDOW, maxlen: int = RECENT_SAMPLES, *,
                 distinct: bool = True) -> None:
        if not (0.0 < window < math.inf):
            raise ValueError(f"window must be finite and > 0 seconds, got {window!r}")
        if maxlen < 2:
            raise ValueError(f"maxlen must be >= 2, got {maxlen!r}")
        self.window_ns = round(window * NSEC_PER_SEC)
        self.maxlen = maxlen
        self.distinct = distinct
        self.last_received: int | None = None
        """Receive time (ns) of the newest sample added, repeated ones included."""
        self._received: deque[int] = deque()  # receive times, oldest sample first
        self._values: deque[int] = deque()  # the samples' values, in the same order
        # Sequence numbers of the samples held that were added out of order (a value
        # below the one added before it): while there are none, the values held do not
        # decrease from the oldest sample to the newest (with ``distinct``, increase).
        self._out_of_order: deque[int] = deque()
        self._seq = 0  # sequence number of the next sample kept
        self._held: set[int] | None = None  # distinct: the values held, while out of order

    def __len__(self) -> int:
        """Samples held now (at most :attr:`maxlen`)."""
        return len(self._values)

    def __eq__(self, other: object) -> bool:
        """Same settings and the same samples held (receive time, value)."""
        if not isinstance(other, RateWindow):
            return NotImplemented
        return ((self.window_ns, self.maxlen, self.distinct, self.last_received)
                == (other.window_ns, other.maxlen, other.distinct, other.last_received)
                and self._received == other._received and self._values == other._values)

    __hash__ = None  # type: ignore[assignment]

    def values(self) -> set[int]:
        """The values held now (distinct header stamps for a frame)."""
        return set(self._values)

    def values_by_time(self) -> list[int]:
        """The receive times (ns) of the samples held now, oldest first."""
        return list(self._received)

    def add(self, received: int, value: int) -> bool:
        """Account one sample (ns); False when ``distinct`` and ``value`` is held already
        (a repeated stamp: not kept again)."""
        self.last_received = received
        values = self._values
        if values:
            last = values[-1]
            if self.distinct:
                held = self._held
                if held is not None:  # out of order: the set answers
                    if value in held:
                        return False
                    held.add(value)
                    if value < last:
                        self._out_of_order.append(self._seq)
                elif value <= last:  # in order so far: the values held increase
                    at = bisect_left(values, value)
                    if values[at] == value:
                        return False
                    self._out_of_order.append(self._seq)
                    held = self._held = set(values)
                    held.add(value)
            elif value < last:
                self._out_of_order.append(self._seq)
        self._seq += 1
        values.append(value)
        self._received.append(received)
        if len(values) > self.maxlen:
            self._pop()
        return True

    def _pop(self) -> None:
        value = self._values.popleft()
        self._received.popleft()
        out = self._out_of_order
        if out:
            if out[0] == self._seq - len(self._values) - 1:  # the oldest sample's number
                out.popleft()
            held = self._held
            if held is not None:
                if out:
                    held.discard(value)
                else:  # in order again
                    self._held = None

    def age(self, now: Time) -> None:
        """Let go of the samples received more than ``window`` seconds before ``now``."""
        start = now.ns - self.window_ns
        received = self._received
        while received and received[0] < start:
            self._pop()

    def stale(self, now: Time) -> bool:
        """Whether the source stopped: nothing received for :data:`STALE_PERIODS` of
        its periods in the window and at least :data:`STALE_AFTER` seconds (or ever)."""
        if self.last_received is None:
            return True
        silent = (now.ns - self.last_received) / NSEC_PER_SEC
        rate = self._span_rate()
        period = 1.0 / rate if rate > 0 else 0.0
        return silent > max(STALE_AFTER, STALE_PERIODS * period)

    def _span_rate(self) -> float:
        values = self._values
        if len(values) < 2:
            return 0.0
        if self._out_of_order:
            return link_rate(len(values), min(values), max(values))
        return link_rate(len(values), values[0], values[-1])

    def rate(self, now: Time) -> float:
        """``(samples - 1) / (newest - oldest value)`` in Hz over the window ending at
        ``now`` (:func:`link_rate`); 0.0 with fewer than two samples or when
        :meth:`stale`. Samples received after ``now`` (a clock that went back) are
        not counted."""
        self.age(now)
        received = self._received
        now_ns = now.ns
        if received and received[-1] > now_ns:
            vals = [v for r, v in zip(received, self._values, strict=True) if r <= now_ns]
            if len(vals) < 2:
                return 0.0
            return link_rate(len(vals), min(vals), max(vals))
        return 0.0 if self.stale(now) else self._span_rate()


def link_rate(distinct_stamps: int, oldest_ns: int, newest_ns: int) -> float:
    """The rate of a link in Hz: ``(distinct_stamps - 1) / (newest - oldest)`` seconds;
    0.0 with fewer than two stamps or a zero span. The one definition used by
    ``tfbus frames``, ``monitor`` and ``bag-info``."""
    span = (newest_ns - oldest_ns) / NSEC_PER_SEC
    if distinct_stamps < 2 or span <= 0:
        return 0.0
    return (distinct_stamps - 1) / span


@_fields_on_base
@dataclass
class FrameSummary(_FrameBase):
    """The summary of one child frame: its parent, who sends it, its stamps and delays.

    Stamps are header stamps in ns; delays are seconds (see the module docstring).
    ``count`` counts every transform received, ``distinct_stamps`` the distinct stamps
    (module docstring); memory is bounded (:class:`RateWindow`).
    """

    __slots__ = ()
    child: str
    parent: str
    static: bool
    authorities: dict[str, int] = field(default_factory=dict)
    count: int = 0
    distinct_stamps: int = 0
    first_stamp: int | None = None
    last_stamp: int | None = None
    delay_sum: float = 0.0
    delay_count: int = 0
    delay_max: float = -math.inf
    received: RateWindow = field(default_factory=RateWindow, repr=False)
    """(receive time, header stamp) in ns of the distinct stamps received in the last
    :data:`RATE_WINDOW` seconds, at most :data:`RECENT_SAMPLES` of them."""

    @property
    def stamps(self) -> set[int]:
        """The distinct header stamps (ns) held in :attr:`received` (the recent ones)."""
        return self.received.values()

    @property
    def last_received(self) -> int | None:
        """Receive time (ns) of the newest transform of this frame."""
        return self.received.last_received

    @property
    def rate(self) -> float:
        """Average rate in Hz (:func:`link_rate` of :attr:`distinct_stamps`; 0.0 for a
        static frame)."""
        if self.static or self.first_stamp is None or self.last_stamp is None:
            return 0.0
        return link_rate(self.distinct_stamps, self.first_stamp, self.last_stamp)

    def recent_rate(self, now: Time) -> float:
        """The rate in Hz (:func:`link_rate` of the distinct stamps) of the samples
        received in the :data:`RATE_WINDOW` seconds before ``now``
        (:meth:`RateWindow.rate`): 0.0 for a static frame, or one that is stale (its
        broadcaster stopped)."""
        return 0.0 if self.static else self.received.rate(now)

    def stale(self, now: Time) -> bool:
        """Whether this dynamic frame stopped arriving (:meth:`RateWindow.stale`)."""
        return not self.static and self.received.stale(now)

    @property
    def authority(self) -> str:
        """The broadcaster that sent most of this frame's transforms ("" if none)."""
        return max(self.authorities, key=lambda a: self.authorities[a]) if self.authorities else ""

    @property
    def delay_avg(self) -> float:
        """Average delay, seconds (0.0 when none was measured)."""
        return self.delay_sum / self.delay_count if self.delay_count else 0.0

    @property
    def buffer_length(self) -> float:
        """Seconds between the oldest and the most recent stamp."""
        if self.first_stamp is None or self.last_stamp is None:
            return 0.0
        return (self.last_stamp - self.first_stamp) / NSEC_PER_SEC


@_fields_on_base
@dataclass
class AuthoritySummary(_AuthorityBase):
    """Per broadcaster (authority): messages received and their transforms' delays."""

    __slots__ = ()
    authority: str
    messages: int = 0
    first: int | None = None
    last: int | None = None
    delay_sum: float = 0.0
    delay_count: int = 0
    delay_max: float = -math.inf
    received: RateWindow = field(default_factory=lambda: RateWindow(distinct=False),
                                 repr=False)
    """Receive times (ns) of the messages of the last :data:`RATE_WINDOW` seconds, at
    most :data:`RECENT_SAMPLES` of them."""

    @property
    def rate(self) -> float:
        """Messages per second of receive time (0.0 with fewer than two messages)."""
        if self.messages < 2 or self.first is None or self.last is None:
            return 0.0
        span = (self.last - self.first) / NSEC_PER_SEC
        return (self.messages - 1) / span if span > 0 else 0.0

    def recent_rate(self, now: Time) -> float:
        """Messages per second among those received in the :data:`RATE_WINDOW` seconds
        before ``now`` (:meth:`RateWindow.rate`; 0.0 for a stale broadcaster)."""
        return self.received.rate(now)

    def stale(self, now: Time) -> bool:
        """Whether this broadcaster stopped sending (:meth:`RateWindow.stale`)."""
        return self.received.stale(now)

    @property
    def delay_avg(self) -> float:
        """Average delay of its dynamic transforms, seconds."""
        return self.delay_sum / self.delay_count if self.delay_count else 0.0


frame_chain = frame_path
"""The frames from a source up to the lowest common ancestor and down to a target, given
each child frame's parent: :func:`tfbus.core.frame_path` (this module's name for it)."""


@dataclass
class ChainDelay:
    """Net delay of the chain between ``source`` and ``target`` (tf_monitor ``A B``):
    receive time minus the latest common stamp of the chain's dynamic links, in seconds.
    The chain is found again at every sample, so it may appear while a bus is heard."""

    source: str
    target: str
    frames: tuple[str, ...] | None = None
    """The chain at the last sample (:func:`tfbus.core.frame_path`), None while not connected."""
    delay_sum: float = 0.0
    delay_count: int = 0
    delay_max: float = 0.0

    @property
    def delay_avg(self) -> float:
        """Average net delay, seconds (0.0 before any sample)."""
        return self.delay_sum / self.delay_count if self.delay_count else 0.0


@dataclass
class TfSummary:
    """tf_monitor's tables, fed one message at a time by :meth:`add`.

    ``start`` / ``end`` are the first and last receive times, ``messages`` counts
    messages per topic, ``frames`` maps a child frame id to its summary and
    ``authorities`` a broadcaster to its own.
    """

    start: Time | None = None
    end: Time | None = None
    messages: dict[str, int] = field(default_factory=dict)
    frames: dict[str, FrameSummary] = field(default_factory=dict)
    authorities: dict[str, AuthoritySummary] = field(default_factory=dict)
    sim_time: bool | None = None
    """None before the first dynamic transform; True when delays are measured against
    the newest stamp because the stamps are simulated time (module docstring)."""
    chains: list[ChainDelay] = field(default_factory=list)
    _newest_stamp: int = 0

    def watch_chain(self, source: str, target: str) -> ChainDelay:
        """Start measuring the net delay of the chain between two frames."""
        chain = ChainDelay(source, target)
        chain.frames = self.chain(source, target)
        self.chains.append(chain)
        return chain

    def chain(self, source: str, target: str) -> tuple[str, ...] | None:
        """The chain between two frames now (:func:`tfbus.core.frame_path`), None if unconnected."""
        found = frame_chain(self.parents(), source, target)
        return tuple(found) if found is not None else None

    def parents(self) -> dict[str, str]:
        """Each child frame's latest parent."""
        return {child: f.parent for child, f in self.frames.items()}

    def add(
        self,
        time: Time,
        transforms: Iterable[TransformStamped],
        authority: str,
        *,
        static: bool,
        topic: str | None = None,
    ) -> None:
        """Account for one message received at ``time`` (bag time or clock time) from
        ``authority``, counted in :attr:`messages` under ``topic`` (default ``/tf`` or
        ``/tf_static``); items that are not ``TransformStamped`` with string frame ids
        are skipped."""
        t = time.ns
        if self.start is None or t < self.start.ns:
            self.start = time
        if self.end is None or t > self.end.ns:
            self.end = time
        if topic is None:
            topic = TF_STATIC_TOPIC if static else TF_TOPIC
        self.messages[topic] = self.messages.get(topic, 0) + 1
        auth = self.authorities.get(authority)
        if auth is None:
            auth = self.authorities[authority] = AuthoritySummary(authority)
        auth.messages += 1
        if auth.first is None:
            auth.first = t
        auth.last = t
        auth.received.add(t, t)
        if _ACCOUNT is not None:  # _account, compiled
            touched = _ACCOUNT(self, FrameSummary, t, transforms, authority, static, auth,
                              SIM_TIME_GAP)
        else:
            touched = self._account(t, transforms, authority, static, auth)
        if touched:
            reference = self._newest_stamp if self.sim_time else t
            for chain in self.chains:
                self._sample_chain(chain, reference)

    def _account(self, t: int, transforms: Iterable[TransformStamped], authority: str,
                 static: bool, auth: AuthoritySummary) -> bool:
        """:meth:`add`'s loop over the message's transforms; whether one was dynamic."""
        touched = False
        frames = self.frames
        sim_time = self.sim_time
        newest = self._newest_stamp
        # The broadcaster's delay figures, kept in locals over the message and written
        # back once (the same additions in the same order as one attribute at a time).
        a_sum, a_count, a_max = auth.delay_sum, auth.delay_count, auth.delay_max
        try:
            for ts in transforms:
                if not isinstance(ts, TransformStamped):
                    continue
                child = ts.child_frame_id
                if not isinstance(child, str):
                    continue
                header = ts.header
                parent = header.frame_id
                if not isinstance(parent, str):
                    continue
                stamp = header.stamp
                if not isinstance(stamp, Time):
                    continue
                fs = frames.get(child)
                if fs is None or fs.static != static:
                    fs = frames[child] = FrameSummary(child, parent, static)
                fs.parent = parent
                fs.count += 1
                senders = fs.authorities
                senders[authority] = senders.get(authority, 0) + 1
                ns = stamp._ns
                if static:  # no rate: a stamp other than the last one counts as new
                    fs.distinct_stamps += ns != fs.last_stamp
                else:
                    window = fs.received
                    values = window._values
                    if (values and ns > values[-1] and window._held is None
                            and not window._out_of_order):
                        # RateWindow.add's common case, inline: a stamp newer than every
                        # one held, all held in order (then also _pop's)
                        window.last_received = t
                        window._seq += 1
                        values.append(ns)
                        received = window._received
                        received.append(t)
                        if len(values) > window.maxlen:
                            values.popleft()
                            received.popleft()
                        fs.distinct_stamps += 1
                    elif window.add(t, ns):
                        fs.distinct_stamps += 1
                first = fs.first_stamp
                if first is None or ns < first:
                    fs.first_stamp = ns
                last = fs.last_stamp
                if last is None or ns > last:
                    fs.last_stamp = ns
                if static:
                    continue
                touched = True
                if sim_time is None:
                    sim_time = self.sim_time = abs(t - ns) / NSEC_PER_SEC > SIM_TIME_GAP
                if ns > newest:
                    newest = ns
                d = ((newest if sim_time else t) - ns) / NSEC_PER_SEC
                fs.delay_sum += d
                fs.delay_count += 1
                if d > fs.delay_max:
                    fs.delay_max = d
                a_sum += d
                a_count += 1
                if d > a_max:
                    a_max = d
        finally:
            self._newest_stamp = newest
            auth.delay_sum, auth.delay_count, auth.delay_max = a_sum, a_count, a_max
        return touched

    def _sample_chain(self, chain: ChainDelay, reference: int) -> None:
        chain.frames = self.chain(chain.source, chain.target)
        if chain.frames is None:
            return
        common: int | None = None
        for frame in chain.frames:
            fs = self.frames.get(frame)
            # The chain's top frame: its own link is not on the way between the two.
            if fs is None or fs.static or fs.last_stamp is None or fs.parent not in chain.frames:
                continue
            common = fs.last_stamp if common is None else min(common, fs.last_stamp)
        if common is None:
            return
        d = (reference - common) / NSEC_PER_SEC
        chain.delay_sum += d
        chain.delay_count += 1
        chain.delay_max = max(chain.delay_max, d)

    def rename_authority(self, old: str, new: str) -> None:
        """Account everything received from ``old`` to ``new`` instead (merged with what
        ``new`` already has): a live bus names a message's broadcaster only once it is
        known, so what came first under a placeholder moves to it."""
        src = self.authorities.pop(old, None)
        if src is None or old == new:
            if src is not None:
                self.authorities[old] = src
            return
        dst = self.authorities.get(new)
        if dst is None:
            src.authority = new
            self.authorities[new] = src
        else:
            dst.messages += src.messages
            firsts = [x for x in (dst.first, src.first) if x is not None]
            lasts = [x for x in (dst.last, src.last) if x is not None]
            dst.first = min(firsts) if firsts else None
            dst.last = max(lasts) if lasts else None
            dst.delay_sum += src.delay_sum
            dst.delay_count += src.delay_count
            dst.delay_max = max(dst.delay_max, src.delay_max)
            merged = RateWindow(distinct=False)
            for t in sorted([*src.received.values_by_time(), *dst.received.values_by_time()]):
                merged.add(t, t)
            dst.received = merged
        for fs in self.frames.values():
            if old in fs.authorities:
                fs.authorities[new] = fs.authorities.get(new, 0) + fs.authorities.pop(old)

    def forget(self, children: Iterable[str]) -> int:
        """Drop the summaries of these child frames (a buffer with
        ``cache_policy=expire_after(...)`` removed their links: ``BufferCore.forget``),
        so that the tables and their memory follow what the buffer holds; a frame sent
        again later starts a new summary. Broadcasters and chains keep what they
        measured. Returns how many frames were dropped."""
        dropped = 0
        for child in children:
            if self.frames.pop(child, None) is not None:
                dropped += 1
        return dropped

    @property
    def duration(self) -> float:
        """Seconds between the first and the last message received."""
        if self.start is None or self.end is None:
            return 0.0
        return (self.end.ns - self.start.ns) / NSEC_PER_SEC

    @property
    def transform_count(self) -> int:
        """Total number of transforms (every sample of every frame)."""
        return sum(f.count for f in self.frames.values())


def expiry_line(stats: BufferStatistics, policy: ExpireAfter) -> str:
    """The monitor's line for a buffer with frame expiry
    (``cache_policy=expire_after(...)``): frames and links it holds now, and how many
    links it has removed since it started, e.g. ``"buffer: 3 frames, 2 links; 5 frames
    expired (no data for 2 s)"``."""
    return (
        f"buffer: {stats.frames} frames, {stats.links} links; {stats.frames_expired} "
        f"frames expired (no data for {policy.after_ns / NSEC_PER_SEC:g} s)"
    )


class _Store(Protocol):
    """The buffer methods :class:`MonitoredSink` forwards to (``BufferCore``'s)."""

    def set_transforms(
        self, transforms: Iterable[TransformStamped], authority: str, is_static: bool, /
    ) -> BatchResult: ...

    def set_transform(self, transform: TransformStamped, authority: str, /) -> bool: ...

    def set_transform_static(self, transform: TransformStamped, authority: str, /) -> bool: ...

    def clear(self) -> None: ...


class _Expiring(Protocol):
    """What :class:`MonitoredSink` reads of a buffer that expires frames
    (``BufferCore.frames_expired`` and ``get_parent``)."""

    @property
    def frames_expired(self) -> int: ...

    def get_parent(self, frame_id: str) -> str | None: ...


class MonitoredSink:
    """A :class:`~tfbus.listener.TransformSink` that stores into ``buffer`` and accounts
    every message in ``summary`` (receive time = ``clock.now()``): a
    ``TransformListener`` on it feeds the buffer and tf_monitor's tables at once.

    Args:
        buffer: the ``BufferCore`` or ``Buffer`` to store into.
        summary: where to account (the tables).
        clock: the receive clock.
        authority: ``authority(is_static) -> str`` names the sender of a message (the
            wire format carries none); by default the listener's authority is used.
        attribute: ``attribute(is_static, transforms) -> str`` names the sender from
            the message too (its frames); used instead of ``authority`` when given.

    :attr:`observers` are called with every message accounted, ``(receive time,
    transforms, authority as attributed, is_static)`` (``tfbus doctor`` watches a live bus
    through them).

    When the buffer expires frames (``cache_policy=expire_after(...)``), the dynamic
    frames whose link it removed leave ``summary`` as soon as it has removed them
    (:meth:`TfSummary.forget`; checked when ``frames_expired`` grows, O(frames in the
    summary) each time): the tables and the summary's memory follow the buffer.
    """

    def __init__(
        self,
        buffer: _Store,
        summary: TfSummary,
        clock: Clock,
        authority: Callable[[bool], str] | None = None,
        *,
        attribute: Callable[[bool, Sequence[TransformStamped]], str] | None = None,
    ) -> None:
        """Wrap ``buffer``."""
        self.buffer = buffer
        self.summary = summary
        self._clock = clock
        self._authority = authority
        self._attribute = attribute
        self.observers: list[Callable[[Time, Sequence[TransformStamped], str, bool], None]] = []
        """Called with each message accounted: (receive time, transforms, authority,
        is_static)."""
        expired = getattr(buffer, "frames_expired", None)
        self._expiring: _Expiring | None = (
            cast("_Expiring", buffer)
            if isinstance(expired, int) and hasattr(buffer, "get_parent") else None
        )
        self._expired_seen = expired if isinstance(expired, int) else 0

    def _follow_expiry(self) -> None:
        """Drop from the summary the dynamic frames whose link the buffer expired."""
        buffer = self._expiring
        if buffer is None or buffer.frames_expired == self._expired_seen:
            return
        self._expired_seen = buffer.frames_expired
        self.summary.forget([child for child, fs in self.summary.frames.items()
                             if not fs.static and buffer.get_parent(child) is None])

    def _account(self, transforms: Sequence[TransformStamped], authority: str,
                 static: bool) -> str:
        if self._attribute is not None:
            authority = self._attribute(static, transforms)
        elif self._authority is not None:
            authority = self._authority(static)
        now = self._clock.now()
        self.summary.add(now, transforms, authority, static=static)
        for observe in self.observers:
            observe(now, transforms, authority, static)
        return authority

    def set_transforms(
        self, transforms: Iterable[TransformStamped], authority: str = "default",
        is_static: bool = False,
    ) -> BatchResult:
        """Account for one message, then store it (``BufferCore.set_transforms``)."""
        items = list(transforms)
        authority = self._account(items, authority, is_static)
        result = self.buffer.set_transforms(items, authority, is_static)
        self._follow_expiry()
        return result

    def set_transform(self, transform: TransformStamped, authority: str, /) -> bool:
        """Account for and store one dynamic transform."""
        authority = self._account([transform], authority, False)
        stored = self.buffer.set_transform(transform, authority)
        self._follow_expiry()
        return stored

    def set_transform_static(self, transform: TransformStamped, authority: str, /) -> bool:
        """Account for and store one static transform."""
        authority = self._account([transform], authority, True)
        return self.buffer.set_transform_static(transform, authority)

    def clear(self) -> None:
        """The clock jumped back (the listener asks): clear the buffer's dynamic data,
        as tf2_ros does; the summary keeps what was seen."""
        self.buffer.clear()
