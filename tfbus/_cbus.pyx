# cython: language_level=3, boundscheck=False, wraparound=False
"""The compiled delivery of :class:`tfbus.bus.Bus`: what a publish and a transport's
delivery run for every message, with no Python frame between the publisher and a
callback subscriber (a :class:`~tfbus.listener.TransformListener`'s handler).

* :class:`Delivery` -- ``Bus._deliver_each``: ``/tf_static`` latched, the topic's counters,
  the message put into each queued subscription and passed to each callback (the
  callback's exception counted and logged by its subscription, never the publisher's);
* :class:`TopicCounters` -- the counters of one topic (``published``, ``remote``,
  ``delivered``, ``dropped``) as C integers, the base of ``tfbus.subscription``'s
  ``_TopicCounters``;
* :class:`CallbackFields` -- the fields of a
  :class:`~tfbus.subscription.CallbackSubscription` a delivery reads and counts (its
  callback, its count of calls, its topic's counters), its base;
* :class:`AsyncioCancelCalled` -- on anyio's asyncio backend, whether a cancel scope
  around the calling task was cancelled (``tfbus.bus._asyncio_cancel_called``'s walk over
  the same fields), which a publish asks before it awaits anyio's checkpoint;
* :class:`ShieldedYield` -- the yield after a publish on asyncio
  (``tfbus._aio.ShieldedYield``), stepped in C.

Each does what the pure-Python code beside it does (``Bus._deliver_each``, the
``_asyncio_cancel_called`` closure, ``tfbus._aio.ShieldedYield``), in the same order;
used with the compiled core (``tfbus.core.COMPILED``), the pure-Python code otherwise.
``tests/test_bus_compiled.py`` runs both on the same publishes.
"""

cimport cython
from cpython.weakref cimport PyWeakref_NewRef

from tfbus.topics import TF_STATIC_TOPIC


cdef class TopicCounters:
    """The counters of one topic on one bus (what ``Bus.statistics()`` reports for it):
    messages ``published`` here (local and remote), of which ``remote`` came through the
    transport, copies ``delivered`` to subscribers, copies ``dropped`` unread from full
    queues. 64-bit integers."""

    cdef public long long published, remote, delivered, dropped

    def __init__(self):
        self.published = 0
        self.remote = 0
        self.delivered = 0
        self.dropped = 0


cdef class CallbackFields:
    """The fields of a :class:`~tfbus.subscription.CallbackSubscription` that
    :class:`Delivery` reads and counts: ``_callback`` (called with each message),
    ``_delivered`` (messages passed to it, a 64-bit integer) and ``_counters`` (its
    topic's :class:`TopicCounters`)."""

    cdef public object _callback
    cdef public long long _delivered
    cdef public TopicCounters _counters


cdef class Delivery:
    """:meth:`deliver`: ``Bus._deliver_each`` of the bus whose state is given,
    kept by reference (the bus edits these objects, never replaces them):

    Args:
        latch: the bus's ``StaticLatch`` (a ``/tf_static`` message is added first);
        topic_counters: topic -> :class:`TopicCounters` (made by ``new_counters(topic)``
            when missing, as ``Bus._counters`` makes them);
        subscriptions: topic -> list of queued subscriptions (each gets ``_put(message)``);
        callbacks: topic -> list of callback subscriptions (:class:`CallbackFields`: each
            counted, then called; an exception goes to its ``_failed``).
    """

    cdef object _latch
    cdef dict _topic_counters
    cdef dict _subscriptions
    cdef dict _callbacks
    cdef object _new_counters

    def __cinit__(self, latch, dict topic_counters, dict subscriptions, dict callbacks,
                  new_counters):
        self._latch = latch
        self._topic_counters = topic_counters
        self._subscriptions = subscriptions
        self._callbacks = callbacks
        self._new_counters = new_counters

    def deliver(self, topic, message):
        """Deliver ``message`` on ``topic`` (what ``Bus._deliver_each`` does, in its
        order)."""
        cdef TopicCounters counters
        cdef CallbackFields cb
        cdef object found, sub
        if topic == TF_STATIC_TOPIC:
            self._latch.add(message)
        found = self._topic_counters.get(topic)
        if found is None:
            found = self._new_counters(topic)
        counters = <TopicCounters?>found
        counters.published += 1
        found = self._subscriptions.get(topic)
        if found:
            for sub in <list?>found:
                sub._put(message)
        found = self._callbacks.get(topic)
        if found:
            for cb in <list?>found:
                cb._delivered += 1
                counters.delivered += 1
                try:
                    cb._callback(message)
                except Exception as exc:  # never the publisher's problem
                    cb._failed(exc)


cdef class AsyncioCancelCalled:
    """:meth:`called`: whether a cancel scope around the task running now in
    ``loop`` was cancelled, with no shielded scope in between (anyio's asyncio backend:
    the task's state in ``states``, the dict under anyio's ``_task_states``, keyed by a
    weak reference to the task; the task from ``tasks``, asyncio's table of each loop's
    current task). The walk of ``tfbus.bus._asyncio_cancel_called``'s closure, over the
    same fields: ``cancel_scope``, then each scope's ``_cancel_called``, ``_shield`` and
    ``_parent_scope``."""

    cdef object _loop
    cdef dict _tasks
    cdef dict _states

    def __cinit__(self, loop, dict tasks, dict states):
        self._loop = loop
        self._tasks = tasks
        self._states = states

    def called(self):
        """Whether the running task's innermost unshielded cancel scopes were cancelled
        (True or False)."""
        cdef object task = self._tasks.get(self._loop)
        cdef object state, scope
        if task is None:
            return False
        state = self._states.get(PyWeakref_NewRef(task, None))
        if state is None:
            return False
        scope = state.cancel_scope
        while scope is not None:
            if scope._cancel_called:
                return True
            if scope._shield:
                return False
            scope = scope._parent_scope
        return False


cdef class ShieldedYield:
    """``await shielded_yield``: ``tfbus._aio.ShieldedYield`` (its docstring says why and
    how: one yield on a future of ``loop`` that is done for good, resumed as after
    ``sleep(0)``, never cancelled by anyio), each ``await`` stepping a small C iterator
    (:class:`_YieldOnce`) rather than a Python generator.

    Args:
        loop: the asyncio loop whose tasks await it.
    """

    cdef object _future

    def __cinit__(self, loop):
        self._future = loop.create_future()
        self._future.set_result(None)

    def __await__(self):
        return _YieldOnce(self._future)


@cython.freelist(4)
cdef class _YieldOnce:
    """The iterator of one ``await`` of :class:`ShieldedYield`: yields its done future
    once (marked ``_asyncio_future_blocking``, as ``Future.__await__`` marks it: "wait on
    me"), then stops, returning None. An exception thrown in (``Task.cancel``) is raised
    at the ``await``, as from the generator it stands for."""

    cdef object _future

    def __cinit__(self, future):
        self._future = future

    def __iter__(self):
        return self

    def __next__(self):
        cdef object future = self._future
        if future is None:
            raise StopIteration
        self._future = None
        future._asyncio_future_blocking = True
        return future
