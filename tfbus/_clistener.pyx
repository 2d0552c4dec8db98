# cython: language_level=3, boundscheck=False, wraparound=False
"""The compiled message handler of :class:`tfbus.listener.TransformListener`: what the bus
calls, inside each publish or delivery on ``/tf`` or ``/tf_static``, to store a message.

A ``TFMessage`` whose ``transforms`` is a tuple (what a broadcaster sends, and what the
ROS 1 and Zenoh transports deliver) is stored here with no Python frame: the count of
messages, the listener's clock read (tf2_ros ``TransformListener::subscription_callback_impl``
reads the time on each message), the store and the count of what it did. A message of one
transform goes to the listener's one-transform store (``set_transform`` or
``set_transform_static`` of the buffer), any other tuple to the buffer's
``set_transforms`` (one call a message, as in ``_handle``). A subclass of ``TFMessage``
(the ROS 1 transport's per-publisher class) is stored under the authority its class
names (its ``authority``, a non-empty str), when the listener records publishers'
authorities. Anything else (another message type, a ``transforms`` that is not a tuple)
goes to the listener's own ``_handle``, which counts, checks and logs it; a transform
the buffer refuses by raising goes to the listener's ``_store_failed`` (counted as
invalid or malformed, and logged), and a ``set_transforms`` that raises to its
``_sink_failed``, as in ``_handle``. Same behaviour as ``_handle`` alone (the pure-Python
path, ``TFBUS_PURE_PYTHON``), which ``tests/test_listener_handler.py`` runs beside this
one.
"""

from cpython.time cimport time_ns as _time_ns

from tfbus.clock import SystemClock
from tfbus.messages import TFMessage
from tfbus.time import Time


cdef object _system_clock_of(object now_ns):
    """The clock ``now_ns`` reads when it is ``SystemClock.now_ns`` itself, bound to an
    instance of exactly :class:`~tfbus.clock.SystemClock` (read here by
    :func:`_system_now_ns`); else None (``now_ns`` is called)."""
    cdef object clock = getattr(now_ns, "__self__", None)
    if type(clock) is SystemClock and getattr(now_ns, "__func__", None) is SystemClock.now_ns:
        return clock
    return None


cdef object _system_now_ns(object clock):
    """``clock.now_ns()`` of a :class:`~tfbus.clock.SystemClock`, in C: the same wall
    clock (``time.time_ns``'s, CPython's own system clock read), the same record of the
    latest time read, the same jump callbacks fired when it went backwards, in the same
    order."""
    cdef object ns = _time_ns()
    cdef object latest = clock._latest_ns
    clock._latest_ns = ns
    if ns < latest:
        clock._jump.fire(Time.from_ns(latest), Time.from_ns(ns))
    return ns


cdef class InlineHandler:
    """``handler(message)``: store one ``/tf`` (``static`` False) or ``/tf_static``
    (``static`` True) message into ``listener``'s buffer: a message of one transform
    through ``store`` (the buffer's ``set_transform`` or ``set_transform_static``:
    ``store(transform, authority) -> bool``, True when stored), any other through
    ``store_many`` (the buffer's ``set_transforms``: ``store_many(transforms, authority,
    static)`` -> its result's ``stored``, ``refused`` and ``errors``). ``now_ns()`` is the
    listener's clock read (int nanoseconds; a :class:`~tfbus.clock.SystemClock`'s own
    ``now_ns`` is read in C, with the same effects); ``authority`` what the transforms are
    stored under, or, when ``publisher_authority``, the ``authority`` a ``TFMessage``
    subclass names.

    ``messages``, ``stored`` and ``refused`` count the messages this handler stored itself
    and what the buffer did with their transforms, which the listener adds to its own
    counters; every other message is counted by the listener.
    """

    cdef object _listener
    cdef object _store
    cdef object _store_many
    cdef object _now_ns
    cdef object _system_clock  # the SystemClock now_ns reads, read in C; or None
    cdef object _authority
    cdef bint _static
    cdef bint _publisher_authority
    cdef readonly long long messages
    """Messages handled here."""
    cdef readonly long long stored
    """Of their transforms, those the buffer stored."""
    cdef readonly long long refused
    """Of their transforms, those the buffer refused without raising (old or repeated
    data)."""

    def __cinit__(self, listener, bint static, store, store_many, now_ns, str authority,
                  bint publisher_authority):
        self._listener = listener
        self._static = static
        self._store = store
        self._store_many = store_many
        self._now_ns = now_ns
        self._system_clock = _system_clock_of(now_ns)
        self._authority = authority
        self._publisher_authority = publisher_authority
        self.messages = 0
        self.stored = 0
        self.refused = 0

    def __call__(self, message):
        cdef object transforms, now, stored, result, named
        cdef object authority = self._authority
        if type(message) is TFMessage:
            transforms = (<tuple>message)[0]
        elif isinstance(message, TFMessage):
            if self._publisher_authority:
                named = getattr(type(message), "authority", None)
                if isinstance(named, str) and named:
                    authority = named
            transforms = message.transforms  # as _handle reads it (a subclass may override)
        else:
            self._listener._handle(self._static, message)
            return
        if type(transforms) is not tuple:
            self._listener._handle(self._static, message)
            return
        self.messages += 1
        if self._system_clock is not None:
            now = _system_now_ns(self._system_clock)
        else:
            now = self._now_ns()
        if len(<tuple>transforms) == 1:
            try:
                stored = self._store((<tuple>transforms)[0], authority)
            except Exception as exc:
                self._listener._store_failed(self._static, now, exc)
                return
            if stored:
                self.stored += 1
            else:
                self.refused += 1
            return
        try:
            result = self._store_many(iter(transforms), authority, self._static)
        except Exception as exc:
            self._listener._sink_failed(self._static, now, exc)
            return
        self.stored += result.stored
        self.refused += result.refused
        for _, failed in result.errors:
            self._listener._store_failed(self._static, now, failed)
