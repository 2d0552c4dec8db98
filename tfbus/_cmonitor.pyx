# cython: language_level=3, boundscheck=False
"""The compiled accounting of tf_monitor's tables: :func:`account` runs the loop of
:meth:`tfbus.monitor.TfSummary.add` over a message's transforms, on the fields declared
here (:class:`RateWindowFields`, :class:`FrameFields`, :class:`AuthorityFields`: the bases
of :class:`~tfbus.monitor.RateWindow`, :class:`~tfbus.monitor.FrameSummary` and
:class:`~tfbus.monitor.AuthoritySummary`, whose methods stay in ``monitor.py``), with the
typed fields read and written in C and no Python frame per transform. A new frame, a
stamp that is not newer than every one its window holds, and everything once per message
stay in ``TfSummary.add`` and ``RateWindow.add``; the values are computed with the same
operations in the same order (IEEE doubles, no fused multiply-add), so both give the same
tables, which ``tests/monitor/test_compiled_tables.py`` checks on the same streams. Used
with the compiled core (``tfbus.core.COMPILED``), ``TfSummary.add``'s own loop otherwise.
"""

from tfbus._cdelay cimport delay_seconds
from tfbus.messages import Header, TransformStamped
from tfbus.time import NSEC_PER_SEC, Time


cdef class RateWindowFields:
    """The fields of a :class:`~tfbus.monitor.RateWindow` (its docstring says what each
    holds)."""

    cdef public object window_ns, maxlen, distinct, last_received
    cdef public object _received, _values, _out_of_order, _held
    cdef public long long _seq


cdef class FrameFields:
    """The fields of a :class:`~tfbus.monitor.FrameSummary`. ``authorities`` (broadcaster
    -> transforms) is a dict whose newest broadcaster's count grows in a C counter, added
    to the dict when another broadcaster sends the frame or anyone reads ``authorities``:
    a stream from one broadcaster makes no int and writes no dict entry per transform."""

    cdef public object child, parent, static, first_stamp, last_stamp, received
    cdef public long long count, distinct_stamps, delay_count
    cdef public double delay_sum, delay_max
    cdef dict _authorities
    cdef object _counting  # the broadcaster _uncounted counts for (a key of _authorities)
    cdef long long _uncounted

    @property
    def authorities(self):
        """Transforms received by broadcaster (a dict; its counts are current)."""
        _settle_count(self)
        return self._authorities

    @authorities.setter
    def authorities(self, value):
        _settle_count(self)
        self._authorities = value
        self._counting = None


cdef inline void _settle_count(FrameFields fs) except *:
    """Add the counted transforms of ``fs``'s current broadcaster to its dict entry."""
    if fs._uncounted:
        if fs._counting in fs._authorities:
            fs._authorities[fs._counting] = fs._authorities[fs._counting] + fs._uncounted
        else:  # the entry was taken out (a rename): the count goes to a new one
            fs._authorities[fs._counting] = fs._uncounted
        fs._uncounted = 0


cdef class AuthorityFields:
    """The fields of an :class:`~tfbus.monitor.AuthoritySummary`."""

    cdef public object authority, first, last, received
    cdef public long long messages, delay_count
    cdef public double delay_sum, delay_max


def account(summary, frame_summary, object t, transforms, object authority, bint static,
            AuthorityFields auth, object sim_time_gap):
    """Account the transforms of one message received at ``t`` (int ns) from
    ``authority`` into ``summary`` (a ``TfSummary``): ``TfSummary.add``'s loop and its
    ``finally`` (the newest stamp and ``auth``'s delay figures written back). A new frame
    is a ``frame_summary(child, parent, static)``. ``sim_time_gap``:
    :data:`tfbus.monitor.SIM_TIME_GAP` (seconds). Returns whether a dynamic transform
    was accounted.

    Raises:
        Exception: whatever ``TfSummary.add``'s own loop raises on the same input (a
            header without ``frame_id`` or ``stamp``), after writing back what was
            accounted.
    """
    cdef dict frames = summary.frames
    cdef object sim_time = summary.sim_time
    cdef object newest = summary._newest_stamp
    cdef bint touched = False
    # the broadcaster's delay figures, held over the message and written back once
    cdef double a_sum = auth.delay_sum, a_max = auth.delay_max, d
    cdef long long a_count = auth.delay_count
    cdef FrameFields fs
    cdef RateWindowFields window
    cdef object ts, child, header, parent, stamp, ns, found, senders, values, received
    cdef object first, last
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
            else:
                parent = header.frame_id
            if not isinstance(parent, str):
                continue
            if type(header) is Header:
                stamp = (<tuple>header)[0]
            else:
                stamp = header.stamp
            if not isinstance(stamp, Time):
                continue
            found = frames.get(child)
            if found is None or (<FrameFields>found).static != static:
                found = frame_summary(child, parent, static)
                frames[child] = found
            fs = <FrameFields>found
            fs.parent = parent
            fs.count += 1
            if fs._counting is not authority and (fs._counting is None
                                                  or fs._counting != authority):
                # another broadcaster: its entry made now, where the pure loop makes it
                # (the dict's order kept), its count added when it is settled
                _settle_count(fs)
                senders = fs._authorities
                if authority not in <dict>senders:
                    (<dict>senders)[authority] = 0
                fs._counting = authority
            fs._uncounted += 1
            ns = stamp._ns
            if static:  # no rate: a stamp other than the last one counts as new
                fs.distinct_stamps += ns != fs.last_stamp
            else:
                window = <RateWindowFields>fs.received
                values = window._values
                if (values and ns > values[-1] and window._held is None
                        and not window._out_of_order):
                    # RateWindow.add's common case: a stamp newer than every one held,
                    # all held in order (then also _pop's)
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
                sim_time = abs(t - ns) / NSEC_PER_SEC > sim_time_gap
                summary.sim_time = sim_time
            if ns > newest:
                newest = ns
            d = delay_seconds((newest if sim_time else t) - ns)
            fs.delay_sum += d
            fs.delay_count += 1
            if d > fs.delay_max:
                fs.delay_max = d
            a_sum += d
            a_count += 1
            if d > a_max:
                a_max = d
    finally:
        summary._newest_stamp = newest
        auth.delay_sum = a_sum
        auth.delay_count = a_count
        auth.delay_max = a_max
    return touched
