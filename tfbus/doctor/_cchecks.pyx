# cython: language_level=3, boundscheck=False, wraparound=False
"""The compiled accounting of ``tfbus doctor``'s checks: :func:`account` runs the loop of
:meth:`tfbus.doctor.checks.Doctor.add` over a message's transforms, on the fields of the
per-link state declared here (:class:`SpanFields`, :class:`SampleFields`,
:class:`LinkFields`: the bases of the doctor's ``_Span``, ``_Sample`` and ``_Link``,
whose methods stay in ``checks.py``), with the typed fields read and written in C and no
Python frame per transform. What is not the common case (a new link, another parent,
sender or topic, a stamp not newer than the newest, a gap, a rate drop) is handed to the
same methods of the doctor as in ``Doctor.add``; the values are computed with the same
operations in the same order (IEEE doubles, no fused multiply-add), so both give the
same report, which ``tests/doctor/test_compiled_accounting.py`` checks on the same
streams. Used with the compiled core (``tfbus.core.COMPILED``), ``Doctor.add``'s own
loop otherwise.
"""

from libc.stdint cimport int64_t

from tfbus._cdelay cimport delay_seconds
from tfbus.messages import Header, TransformStamped
from tfbus.time import NSEC_PER_SEC, Time


cdef class SpanFields:
    """The fields of a count over a receive-time span: ``count``, ``first`` and ``last``
    receive times (ns)."""

    cdef public long long count
    cdef public object first
    cdef public object last


cdef class SampleFields:
    """The fields of a bounded sample of numbers: ``cap``, ``n`` values offered,
    ``stride`` (every ``stride``-th kept), ``values`` kept."""

    cdef public object cap
    cdef public long long n
    cdef public long long stride
    cdef public list values


cdef class MeanFields:
    """The fields of a running mean: ``total`` (the sum of the values) and ``count``,
    updated in place (no new number object per value)."""

    cdef public double total
    cdef public long long count


cdef enum:
    RECENT_STAMPS_HELD = 32  # checks._RECENT_STAMPS: the stamps a link keeps to tell a repeat


RECENT_STAMPS = RECENT_STAMPS_HELD
"""The stamps :attr:`LinkFields.recent` holds (``checks._RECENT_STAMPS``)."""


cdef class LinkFields:
    """The fields of the doctor's state of one child frame (``checks._Link`` documents
    them). Held in C, so that a stamp in order makes no Python number: ``period`` (ns,
    or None before the second stamp) as a double and a flag; ``newest`` (ns, or None) as
    a 64-bit int and a flag (a :class:`~tfbus.time.Time`'s nanoseconds are in [0,
    2**63)); ``recent``, the last :data:`RECENT_STAMPS` stamps kept, as a ring of 64-bit
    ints (a :class:`RecentStamps` view reads and appends to it, as the pure twin's
    ``deque(maxlen=32)``); ``sender_stamp``, a dict whose current sender's newest stamp
    is held in C and written to the dict when another sender stamps the link or anyone
    reads ``sender_stamp``."""

    cdef public object baseline, child, delay, drop_first, drop_last, drop_worst, dynamic
    cdef public object first_gap, gap_largest, gap_senders, hot, last_gap, last_received
    cdef public object order_span, out_of_order, parent, parents
    cdef public object repeat_span, repeated, static, static_values
    cdef public long long consecutive_gaps, gap_count, intervals, old_data
    cdef double _period
    cdef bint _has_period
    cdef bint _has_newest
    cdef int64_t _newest
    cdef int _recent_oldest  # the ring's index of the oldest stamp held
    cdef int _recent_count
    cdef int64_t _recent[RECENT_STAMPS_HELD]
    cdef dict _sender_stamp
    cdef object _stamping  # the sender whose newest stamp _unwritten holds (a key)
    cdef int64_t _unwritten
    cdef bint _has_unwritten

    @property
    def sender_stamp(self):
        """Each sender's newest stamp (ns) on this link (a dict; its values are
        current)."""
        _write_stamp(self)
        return self._sender_stamp

    @sender_stamp.setter
    def sender_stamp(self, value):
        _write_stamp(self)
        self._sender_stamp = value
        self._stamping = None

    @property
    def newest(self):
        """The newest stamp (ns, int), or None."""
        return self._newest if self._has_newest else None

    @newest.setter
    def newest(self, value):
        if value is None:
            self._has_newest = False
        else:
            self._newest = value
            self._has_newest = True

    @property
    def recent(self):
        """The last stamps kept (ns, oldest first): a :class:`RecentStamps` view."""
        return RecentStamps(self)

    @recent.setter
    def recent(self, stamps):
        self._recent_oldest = 0
        self._recent_count = 0
        for stamp in stamps:
            _remember(self, stamp)

    @property
    def period(self):
        """The moving average of the stamp intervals, ns (float), or None."""
        return self._period if self._has_period else None

    @period.setter
    def period(self, value):
        if value is None:
            self._has_period = False
        else:
            self._period = value
            self._has_period = True


cdef inline void _remember(LinkFields link, int64_t stamp) noexcept:
    """Keep ``stamp`` in ``link``'s ring, the oldest one let go when it is full
    (``deque.append`` with a ``maxlen``)."""
    cdef int at = link._recent_oldest + link._recent_count
    if link._recent_count < RECENT_STAMPS_HELD:
        link._recent_count += 1
    else:
        link._recent_oldest += 1
        if link._recent_oldest == RECENT_STAMPS_HELD:
            link._recent_oldest = 0
    if at >= RECENT_STAMPS_HELD:
        at -= RECENT_STAMPS_HELD
    link._recent[at] = stamp


cdef inline void _write_stamp(LinkFields link) except *:
    """Write the newest stamp held for ``link``'s current sender to its dict entry."""
    if link._has_unwritten:
        link._sender_stamp[link._stamping] = link._unwritten
        link._has_unwritten = False


cdef class RecentStamps:
    """A view of a :class:`LinkFields`'s ring of recent stamps (ns), with what the doctor
    asks of its pure twin's ``deque(maxlen=32)``: ``append``, ``in``, ``len`` and
    iteration, oldest first (``in`` compares as the deque does, on the stamps as ints;
    the doctor asks it only of a stamp not newer than the newest).

    Raises:
        OverflowError, TypeError: ``append`` of a value that is not an int in
            [-2**63, 2**63).
    """

    cdef LinkFields _link

    def __cinit__(self, LinkFields link):
        self._link = link

    def append(self, stamp):
        """Keep ``stamp`` (the oldest one let go once :data:`RECENT_STAMPS` are held)."""
        _remember(self._link, stamp)

    def __contains__(self, stamp):
        return stamp in self._stamps()

    def __len__(self):
        return self._link._recent_count

    def __iter__(self):
        return iter(self._stamps())

    cdef list _stamps(self):
        """The stamps held, oldest first."""
        cdef LinkFields link = self._link
        cdef int i, at
        out = []
        for i in range(link._recent_count):
            at = link._recent_oldest + i
            if at >= RECENT_STAMPS_HELD:
                at -= RECENT_STAMPS_HELD
            out.append(link._recent[at])
        return out


cdef inline void _count(SpanFields span, object t) except *:
    """``_Span.add(t)``: one more message, received at ``t``."""
    span.count += 1
    if t > span.last:
        span.last = t
    elif t < span.first:
        span.first = t


def account(doctor, object t, transforms, str sender, bint static, object sim_time_gap):
    """Account the transforms of one message received at ``t`` (int ns) from ``sender``
    (already bounded by the doctor) into ``doctor`` (a ``Doctor``): ``Doctor.add``'s loop
    and its ``finally`` (the newest stamp and the count of transforms written back).
    ``sim_time_gap``: :data:`tfbus.monitor.SIM_TIME_GAP` (seconds).

    Raises:
        Exception: whatever ``Doctor.add``'s own loop raises on the same input (a header
            without ``frame_id`` or ``stamp``), after writing back what was accounted.
    """
    cdef dict links = doctor._links
    cdef object newest_stamp = doctor._newest_stamp
    cdef object sim_time = doctor.sim_time
    cdef long long counted = 0
    th = doctor.thresholds
    cdef long long rate_window = th.rate_window
    cdef double gap_periods = th.gap_periods
    cdef double rate_drop = th.rate_drop
    gap_min_ns = th.gap_min * NSEC_PER_SEC  # compared as Python compares it (in a gap)
    cdef long long settled = 2 * rate_window
    cdef double alpha = doctor._alpha
    cdef LinkFields link
    cdef SampleFields sample
    cdef tuple hot
    cdef MeanFields mean
    cdef object ts, child, header, parent, when, stamp, baseline, found
    cdef double d, interval, pd, bd
    cdef int64_t s64
    cdef long long intervals
    try:
        for ts in transforms:
            if type(ts) is TransformStamped:
                header = (<tuple>ts)[0]
                child = (<tuple>ts)[1]
            elif isinstance(ts, TransformStamped):
                child = ts.child_frame_id
                header = None
            else:
                continue
            if not isinstance(child, str):
                continue
            if header is None:
                header = ts.header
            if type(header) is Header:
                parent = (<tuple>header)[1]
                when = (<tuple>header)[0]
            else:
                parent = header.frame_id
                when = header.stamp
            if not (isinstance(parent, str) and isinstance(when, Time)):
                continue
            counted += 1
            found_link = links.get(child)
            link = None
            if found_link is not None and isinstance(found_link, LinkFields):
                link = <LinkFields>found_link
                if link.hot is not None:
                    hot = <tuple>link.hot
                    if not (hot[0] == parent and hot[1] == sender and hot[2] is static):
                        link = None
                else:
                    link = None
            if link is not None:
                # the same parent, sender and topic as the link's last message: its two
                # spans counted here
                _count(<SpanFields>hot[3], t)
                _count(<SpanFields>hot[4], t)
                mean = <MeanFields?>hot[5] if not static else None
                sample_obj = hot[6]
            else:
                found = doctor._find(child, parent, sender, static, t)
                if found is None:
                    continue
                link = <LinkFields>(<tuple>found)[0]
                parent = (<tuple>found)[1]
                mean = <MeanFields?>(<tuple>found)[2] if not static else None
                sample_obj = (<tuple>found)[3]
            link.last_received = t
            if static:
                tr = ts.transform
                tt = tr.translation
                rot = tr.rotation
                link.static_values[sender] = (parent, tt.x, tt.y, tt.z,
                                              rot.x, rot.y, rot.z, rot.w)
                continue
            sample = <SampleFields?>sample_obj
            stamp = when._ns
            # delay: receive time - stamp (against the newest stamp in simulated time)
            if sim_time is None:
                sim_time = abs(t - stamp) / NSEC_PER_SEC > sim_time_gap
                doctor.sim_time = sim_time
            if stamp > newest_stamp:
                newest_stamp = stamp
            d = delay_seconds((newest_stamp if sim_time else t) - stamp)
            mean.total = mean.total + d
            mean.count += 1
            if sample.n % sample.stride == 0:
                sample_obj.keep(d)
            sample.n += 1
            s64 = stamp  # a Time's nanoseconds: in [0, 2**63)
            if link._has_newest and s64 > link._newest:
                # in order (the common case): newer than every stamp held, not repeated
                _remember(link, s64)
                if link._stamping is not sender and (link._stamping is None
                                                     or link._stamping != sender):
                    # another sender: its entry written now (the dict's order kept)
                    _write_stamp(link)
                    link._sender_stamp[sender] = stamp
                    link._stamping = sender
                else:
                    link._unwritten = s64
                    link._has_unwritten = True
                interval = <double>(s64 - link._newest)
                if not link._has_period:
                    doctor._interval(link, t, stamp, link._newest, sender)
                    continue
                pd = link._period
                if (link.intervals >= rate_window and interval > gap_periods * pd
                        and interval > gap_min_ns):
                    doctor._interval(link, t, stamp, link._newest, sender)  # a gap
                    continue
                # _interval's common case: the moving average moves
                link._newest = s64
                link.intervals += 1
                intervals = link.intervals
                link.consecutive_gaps = 0
                pd = pd + alpha * (interval - pd)
                link._period = pd
                if intervals > settled:
                    baseline = link.baseline
                    if baseline is None or pd < <double>baseline:
                        link.baseline = pd
                        bd = pd
                    else:
                        bd = baseline
                    if pd * rate_drop > bd:
                        doctor._dropped(link, t, pd)
            else:
                doctor._stamps(link, t, stamp, sender)
    finally:
        doctor._newest_stamp = newest_stamp
        doctor.transforms += counted
