# cython: language_level=3, boundscheck=False, wraparound=False
"""The compiled message handler of :class:`tfbus.listener.TransformListener`: what the bus
calls, inside each publish or delivery on ``/tf`` or ``/tf_static``, to store a message.

A ``TFMessage`` of one ``TransformStamped`` (what a broadcaster sends per
``send_transform`` of one transform, and what the ROS 1 and Zenoh transports deliver per
such message) is stored here with no Python frame: the count of messages, the listener's
clock read (tf2_ros ``TransformListener::subscription_callback_impl`` reads the time on each
message), the store (``set_transform`` or ``set_transform_static`` of the buffer, the
listener's one-transform store) and the count of what it did. Anything else (another
message type, a subclass of ``TFMessage``, zero or several transforms, a ``transforms``
that is not a tuple) goes to the listener's own ``_handle``, which counts, checks and logs
it; a store that raises goes to the listener's ``_store_failed`` (counted as invalid or
malformed, and logged), as in ``_handle``. Same behaviour as ``_handle`` alone (the
pure-Python path, ``TFBUS_PURE_PYTHON``), which ``tests/test_listener_handler.py`` runs
beside this one.
"""

from tfbus.messages import TFMessage


cdef class InlineHandler:
    """``handler(message)``: store one ``/tf`` (``static`` False) or ``/tf_static``
    (``static`` True) message into ``listener``'s buffer through ``store`` (the buffer's
    ``set_transform`` or ``set_transform_static``: ``store(transform, authority) ->
    bool``, True when stored). ``now_ns()`` is the listener's clock read (int nanoseconds).

    ``messages``, ``stored`` and ``refused`` count the messages this handler stored itself
    (one transform each), which the listener adds to its own counters; every other message
    is counted by the listener.
    """

    cdef object _listener
    cdef object _store
    cdef object _now_ns
    cdef object _authority
    cdef bint _static
    cdef readonly long long messages
    """Messages of one transform handled here."""
    cdef readonly long long stored
    """Of those, transforms the buffer stored."""
    cdef readonly long long refused
    """Of those, transforms the buffer refused without raising (old or repeated data)."""

    def __cinit__(self, listener, bint static, store, now_ns, str authority):
        self._listener = listener
        self._static = static
        self._store = store
        self._now_ns = now_ns
        self._authority = authority
        self.messages = 0
        self.stored = 0
        self.refused = 0

    def __call__(self, message):
        cdef object transforms, now, stored
        if type(message) is not TFMessage:
            self._listener._handle(self._static, message)
            return
        transforms = (<tuple>message)[0]
        if type(transforms) is not tuple or len(<tuple>transforms) != 1:
            self._listener._handle(self._static, message)
            return
        self.messages += 1
        now = self._now_ns()
        try:
            stored = self._store((<tuple>transforms)[0], self._authority)
        except Exception as exc:
            self._listener._store_failed(self._static, now, exc)
            return
        if stored:
            self.stored += 1
        else:
            self.refused += 1
