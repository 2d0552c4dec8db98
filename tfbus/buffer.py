"""Buffer: a BufferCore whose lookups you can ``await`` until the data arrives.

The async surface over the sans-I/O core, as tf2_ros's ``Buffer`` is over tf2's
``BufferCore``. Waiting is event-driven, never polled (tf2_ros polls at 20 Hz): a waiter
is indexed by the names of the frames its answer depends on — the source and target
(and fixed) frames and their ancestors, both by each link's newest parent and by its
parent at the requested time — and re-checked only when a transform for one of those
frames is stored. A wait for a time in the future resolves as soon as data covering that
time arrives. A wait whose time has fallen out of the cache window fails at once, as
tf2's transformable requests do (``BufferCore::addTransformableRequest``,
``testTransformableRequests``). A clock that jumps backwards clears the buffer (tf2_ros
``Buffer`` on a time jump back) and pending waits are re-evaluated.

``timeout=`` arguments are measured on the buffer's clock (so a ``ManualClock`` drives
them in tests); anyio cancel scopes (``fail_after``, ``move_on_after``) work as well. A
cancelled or timed-out wait leaves nothing registered.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Protocol, TypeVar, overload

import anyio.lowlevel
import numpy as np
import numpy.typing as npt

from tfbus._aio import Awaiting, Wakeup, coroutine_method, running_asyncio_loop
from tfbus.clock import Clock, JumpCallback, SystemClock, timeout_ns
from tfbus.convert import TransformRegistration
from tfbus.core import BufferCore, SetResult
from tfbus.core.batch import Errors, TimesLike, TransformArray, as_times
from tfbus.core.buffer_core import OnRepeat
from tfbus.core.cache import format_sec
from tfbus.core.policy import (
    Clamp,
    Exact,
    ExpireAfter,
    LookupPolicy,
    Nearest,
    PolicyReport,
    PolicyResult,
    Previous,
    Window,
    policy_args,
)
from tfbus.core.velocity import check_velocity_arguments
from tfbus.errors import BufferClosedException, TimeoutException, TransformException
from tfbus.messages import Header, TransformStamped, Vector3, VelocityStamped
from tfbus.time import Duration, Time

if TYPE_CHECKING:
    from asyncio import AbstractEventLoop

__all__ = ["Buffer", "clear_on_jump_back"]

_log = logging.getLogger(__name__)

_T = TypeVar("_T")
_NO_FRAMES: frozenset[str] = frozenset()
_M = TypeVar("_M")
_core_lookup_transform = BufferCore.lookup_transform


class _Clearable(Protocol):
    """What a jump back clears: a ``BufferCore``, a ``Buffer``, any transform sink."""

    def clear(self) -> None: ...


def clear_on_jump_back(
    sink: _Clearable, clock: Clock, then: Callable[[], None] | None = None
) -> Callable[[], None]:
    """tf2_ros's "a clock jump back clears the buffer" (tf2_ros ``Buffer`` /
    ``TransformListener``): when ``clock`` jumps back (:meth:`Clock.on_jump
    <tfbus.clock.Clock.on_jump>`; a :class:`~tfbus.clock.SystemClock` notices it when read,
    as a listener does on every message), log one warning line and ``sink.clear()``, then
    call ``then`` (a :class:`Buffer` re-evaluates its pending waits).

    The clear is registered on the clock under one key per sink object:
    a :class:`Buffer` follows its own clock and a
    :class:`~tfbus.listener.TransformListener` asks for its sink and clock while it
    listens; on the same clock they share that one callback, so the buffer is cleared
    (and the jump logged) once per jump. ``then`` is a callback of its own, after it.

    Returns:
        A function that stops this follow (idempotent); the clock drops the clear with
        the last owner.
    """
    stops = [clock.on_jump(_clear(sink), key=_ClearKey(sink))]
    if then is not None:
        stops.append(clock.on_jump(lambda _old, _new: then()))

    def stop() -> None:
        for unregister in stops:
            unregister()

    return stop


class _ClearKey:
    """The clock key of "clear ``sink`` on a jump back": equal for the same sink object
    (identity, whatever the sink's own ``==``), holding it while registered."""

    __slots__ = ("sink",)

    def __init__(self, sink: _Clearable) -> None:
        self.sink = sink

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _ClearKey) and other.sink is self.sink

    def __hash__(self) -> int:
        return hash((_ClearKey, id(self.sink)))


def _clear(sink: _Clearable) -> JumpCallback:
    """The clock callback that logs a jump back and clears ``sink``."""

    def on_jump(old: Time, new: Time) -> None:
        _log.warning(
            "Detected jump back in time of %.3f s. Clearing TF buffer.",
            (old.ns - new.ns) / 1e9,
        )
        sink.clear()

    return on_jump


class _Waiter(Wakeup, Generic[_T]):
    """One pending wait: ``check()`` returns the answer, or None while unavailable, or
    returns or raises the TransformException that fails the wait. Indexed under
    ``frames`` (from ``frames_fn()``) while pending. :meth:`~tfbus._aio.Wakeup.wake` ends
    the wait (the answer came, or the deadline).

    ``exact`` is ``(target, source, time, fail_fast)`` for a wait of
    ``lookup_transform_async`` / ``wait_for_transform`` without a policy: the recheck
    asks the core directly (``check_transform`` of those arguments; ``check`` and
    ``frames_fn`` are then None: the buffer derives both from ``exact``, so such a wait
    allocates no callables).
    """

    __slots__ = ("check", "error", "exact", "frames", "frames_fn", "result")

    def __init__(
        self,
        check: Callable[[], _T | TransformException | None] | None,
        frames_fn: Callable[[], frozenset[str]] | None,
        loop: AbstractEventLoop | None,
        exact: tuple[str, str, Time, bool] | None = None,
    ) -> None:
        super().__init__(loop)
        self.check = check
        self.frames_fn = frames_fn
        self.exact = exact
        self.frames: frozenset[str] = frozenset()
        self.result: _T | None = None
        self.error: BaseException | None = None


def _waits_no_more(policy: LookupPolicy) -> bool:
    """Whether an awaited lookup under ``policy`` answers at once, never waiting
    (``Window`` with ``future_wait`` 0: tf2's error at once)."""
    return isinstance(policy, Window) and policy.future_wait.ns == 0


def _policy_timeout(
    policy: LookupPolicy, timeout: float | Duration | None
) -> float | Duration | None:
    """The wait of an awaited lookup under ``policy``: ``timeout``, or ``Window``'s
    ``future_wait`` when that is shorter."""
    if isinstance(policy, Window):
        limit = timeout_ns(timeout)
        if limit is None or policy.future_wait.ns < limit:
            return policy.future_wait
    return timeout


class Buffer(BufferCore):
    """A :class:`~tfbus.core.BufferCore` plus awaitable lookups (tf2_ros ``Buffer``).

    Args:
        cache_time: history kept per dynamic link, seconds or a Duration.
        clock: time source for timeouts and for detecting backward jumps; defaults to
            :class:`~tfbus.clock.SystemClock`.
        on_repeat: ``"reject"`` (tf2) or ``"replace"``: see
            :class:`~tfbus.core.BufferCore`.
        cache_policy: None (tf2: frames are kept) or ``expire_after(seconds)``: see
            :class:`~tfbus.core.BufferCore`. A wait on a frame that expires keeps
            waiting: new data for it may still come.

    Every synchronous method of BufferCore is available unchanged; an insert that
    stores (``set_transform``, ``set_transform_static``, ``set_transforms``,
    ``insert_transform``) re-checks the waits that depend on the frames it touched,
    settling those it answers before it returns. Use from one event loop (the one that
    runs its waits); not thread-safe.

    The waiting methods (``wait_for_transform``, ``transform``, ``transform_full`` and
    every ``*_async``) are coroutines: ``await`` them (tf2_ros's calls block instead).
    A call left without ``await`` names that mistake: using its result (``p2.point``,
    ``if buffer.can_transform_async(...)``) raises AttributeError or TypeError saying
    "Buffer.transform(...) is a coroutine: write ``await buffer.transform(...)``", and
    dropping it warns with that text (RuntimeWarning), not Python's bare "coroutine
    ... was never awaited".
    """

    def __init__(
        self,
        cache_time: float | Duration = 10.0,
        *,
        clock: Clock | None = None,
        on_repeat: OnRepeat = "reject",
        cache_policy: ExpireAfter | None = None,
    ) -> None:
        super().__init__(cache_time, on_repeat=on_repeat, cache_policy=cache_policy)
        self.clock: Clock = clock if clock is not None else SystemClock()
        # The core (sans-I/O) limits its refusal log by count; with a clock, by time too.
        self._refusal_log.clock = lambda: self.clock.now().ns / 1e9
        self._index: dict[str, set[_Waiter[Any]]] = {}
        # set_transform, set_transform_static and set_transforms (the core's own
        # methods) settle these waits in the core, and give the rest to _recheck_rest.
        # A wait the core settles is left in the index and listed here, removed by the
        # next _reindex or _pending: not on the path between the insert and the waiting
        # task's resume.
        self._settled: list[_Waiter[Any]] = []
        self._follow_waits(self._index, self._settled)
        self._unregister_jump = clear_on_jump_back(self, self.clock, then=self._recheck_pending)
        self._closed = False
        self._listeners = 0  # TransformListeners feeding this buffer now

    @overload
    def lookup_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        policy: Exact | None = None,
    ) -> TransformStamped: ...

    @overload
    def lookup_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        policy: Nearest | Clamp | Previous | Window,
    ) -> PolicyResult: ...

    def lookup_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        policy: LookupPolicy | None = None,
    ) -> TransformStamped | PolicyResult:
        """:meth:`BufferCore.lookup_transform` (never waits). ``timeout`` exists for
        tf2_ros habits: ``None`` or 0 is tf2_ros's default (no wait); any other value is
        a TypeError pointing to :meth:`lookup_transform_async`, since a call that blocks
        would stop the event loop that delivers the data. ``policy`` as in
        :meth:`BufferCore.lookup_transform` (a non-exact one returns a
        :class:`~tfbus.core.policy.PolicyResult`).

        Raises:
            TypeError: a non-zero ``timeout``.
            InvalidArgumentException, LookupException, ConnectivityException,
            ExtrapolationException: as :meth:`BufferCore.lookup_transform`.
        """
        if timeout is not None and timeout_ns(timeout) != 0:
            raise TypeError(
                "Buffer.lookup_transform does not wait (it would block the event loop "
                "that delivers the data): use 'await buffer.lookup_transform_async("
                f"{target_frame!r}, {source_frame!r}, time, timeout={timeout!r})'"
            )
        if policy is not None and type(policy) is not Exact:
            return self._lookup_policy(target_frame, source_frame, time, policy)
        return _core_lookup_transform(self, target_frame, source_frame, time)

    # ------------------------------------------------------------------ notification

    def insert_transform(
        self, transform: TransformStamped, authority: str = "default", is_static: bool = False
    ) -> SetResult:
        """:meth:`BufferCore.insert_transform`, then the waits re-checked as by
        :meth:`set_transform`."""
        result = super().insert_transform(transform, authority, is_static)
        if result is SetResult.STORED and self._index:
            self._recheck_last()
        return result

    def _recheck_last(self) -> None:
        """Re-check the waits on the frames of the transform the core stored last (what
        it reports for one insert: its two ids, and whether the tree's shape may have
        changed)."""
        rest = self._settle(self._index, None)
        if rest is not None:
            self._recheck_rest(rest, self._last_touched()[2])

    def _recheck_rest(
        self, rest: list[tuple[Any, tuple[int, ...] | None]], relinked: bool
    ) -> None:
        """The waits the core's ``_settle`` left: an exact wait whose lookup failed
        (its failure tuple) or another kind of wait (None)."""
        for waiter, failure in rest:
            self._recheck(waiter, relinked, failure)

    def _recheck(
        self,
        waiter: _Waiter[Any],
        relinked: bool = True,
        failure: tuple[int, ...] | None = None,
    ) -> None:
        """One walk (the waiter's check); the frames it depends on are recomputed only if
        the tree's shape may have changed, so an insert costs O(waiters it touches).
        ``failure``: the failed lookup of an exact wait, just walked by ``_settle``."""
        exact = waiter.exact
        if exact is not None:  # check_transform(*exact), without the calls in between
            target, source, time, fail_fast = exact
            out = self._query(target, source, time) if failure is None else failure
            result = (
                out
                if isinstance(out, TransformStamped)
                else self._hopeless(target, source, out, time, fail_fast)
            )
        else:
            assert waiter.check is not None  # every wait but an exact one has its check
            try:
                result = waiter.check()
            except TransformException as exc:
                result = exc
        if result is None:
            if relinked:  # the path may have changed
                self._reindex(waiter, self._waiter_frames(waiter))
            return
        if isinstance(result, TransformException):
            waiter.error = result
        else:
            waiter.result = result
        index = self._index
        for name in waiter.frames:  # _unindex, inlined: this is the wake-up path
            waiters = index.get(name)
            if waiters is not None:
                waiters.discard(waiter)
                if not waiters:
                    del index[name]
        waiter.frames = _NO_FRAMES
        future = waiter.future  # Wakeup.wake, inlined for asyncio
        if future is None:
            waiter.wake()
        elif not future.done():
            future.set_result(None)

    def _recheck_pending(self) -> None:
        """Re-evaluate every pending wait (after the buffer was cleared on a jump back)."""
        for waiter in self._pending():
            self._recheck(waiter)

    def _pending(self) -> set[_Waiter[Any]]:
        self._unindex_settled()
        return {w for ws in self._index.values() for w in ws}

    def _unindex_settled(self) -> None:
        """Remove from the index the waits the core settled since the last call (it
        leaves them there, off the wake-up's path; see ``_follow_waits``)."""
        settled = self._settled
        if settled:
            for waiter in settled:
                self._unindex(waiter)
            settled.clear()

    @property
    def pending_waits(self) -> int:
        """How many waits are currently registered (0 once every wait has ended)."""
        return len(self._pending())

    @property
    def closed(self) -> bool:
        """True once :meth:`close` (or :meth:`aclose`) was called."""
        return self._closed

    def close(self) -> None:
        """Close the buffer: every pending wait fails at once with
        :class:`~tfbus.errors.BufferClosedException`, and so does every later wait that
        would have to wait (a lookup the stored data answers still succeeds, as do the
        synchronous methods); stop following the clock's jumps. Idempotent.

        A server shutting down (uvicorn's graceful shutdown, a worker's cancel scope)
        closes its buffers so the requests still waiting on them end now, not at their
        own timeouts.
        """
        if not self._closed:
            self._closed = True
            self._unregister_jump()
        self._fail_pending("the buffer was closed")

    async def aclose(self) -> None:
        """:meth:`close`, then a checkpoint (anyio's ``aclose`` convention), so the
        failed waits run before the caller goes on."""
        self.close()
        await anyio.lowlevel.checkpoint()

    def _fail_pending(self, why: str) -> int:
        """Fail every pending wait with a BufferClosedException saying ``why`` (one
        instance each: each task raises its own); returns how many."""
        waiters = self._pending()
        for waiter in waiters:
            self._unindex(waiter)
            waiter.error = BufferClosedException(f"{why} while waiting")
            waiter.wake()
        return len(waiters)

    def _listener_entered(self) -> None:
        """A :class:`~tfbus.listener.TransformListener` starts feeding this buffer."""
        self._listeners += 1

    def _listener_left(self) -> None:
        """A TransformListener stops feeding this buffer; when it was the last one, the
        waits pending now fail: nothing will store the data they wait for."""
        self._listeners -= 1
        if self._listeners == 0:
            self._fail_pending("the last TransformListener feeding the buffer was left")

    # ------------------------------------------------------------------ indexing

    def _reindex(self, waiter: _Waiter[Any], frames: frozenset[str]) -> None:
        if self._settled:
            self._unindex_settled()
        self._unindex(waiter)
        waiter.frames = frames
        for name in frames:
            self._index.setdefault(name, set()).add(waiter)

    def _unindex(self, waiter: _Waiter[Any]) -> None:
        for name in waiter.frames:
            waiters = self._index.get(name)
            if waiters is not None:
                waiters.discard(waiter)
                if not waiters:
                    del self._index[name]
        waiter.frames = frozenset()

    # ------------------------------------------------------------------ waiting

    def _try_lookup(
        self, target: str, source: str, time: Time, fail_fast: bool = False
    ) -> TransformStamped | None:
        """The transform, None while it may still arrive; raises when waiting cannot
        help (:meth:`BufferCore.check_transform`: one walk)."""
        result = self.check_transform(target, source, time, fail_fast)
        if isinstance(result, TransformException):
            raise result
        return result

    def _frames_of(self, target: str, source: str, time: Time) -> frozenset[str]:
        return frozenset(self.chain_frames(target, source, time))

    def _waiter_frames(self, waiter: _Waiter[Any]) -> frozenset[str]:
        """The frames ``waiter`` depends on now (its ``frames_fn``, or for an exact wait
        the chain of its lookup)."""
        if waiter.frames_fn is not None:
            return waiter.frames_fn()
        assert waiter.exact is not None
        return self._frames_of(waiter.exact[0], waiter.exact[1], waiter.exact[2])

    async def _wait_exact(
        self,
        target: str,
        source: str,
        time: Time,
        fail_fast: bool,
        timeout: float | Duration | None,
        checked: bool = False,
    ) -> TransformStamped:
        """:meth:`_wait` for ``check_transform(target, source, time, fail_fast)`` (the
        exact waits of :meth:`lookup_transform_async` and :meth:`wait_for_transform`):
        the same steps, with no callables built (the recheck and the index derive them
        from the waiter's ``exact``) and the answer the insert's recheck stored in the
        waiter returned as it is (never looked up again). ``checked``: the caller has
        just asked ``check_transform`` (None: not answerable yet), with a timeout that is
        None or a finite float."""
        if not checked:
            if timeout is not None and timeout_ns(timeout) is None:
                timeout = None  # inf: no deadline (and NaN or a str raised here, up front)
            result = self.check_transform(target, source, time, fail_fast)
            if result is not None:
                if isinstance(result, TransformException):
                    raise result
                return result
        if self._closed:
            raise BufferClosedException(
                f"the buffer is closed: not waiting for {self._describe(target, source, time)}"
            )
        waiter: _Waiter[TransformStamped] = _Waiter(
            None, None, running_asyncio_loop(), (target, source, time, fail_fast)
        )
        self._reindex(waiter, self._frames_of(target, source, time))
        try:
            if timeout is None:
                await waiter.wait()
            else:
                cancel = self.clock.call_later(timeout, waiter.wake)
                if cancel is None:
                    with self.clock.move_on_after(timeout):
                        await waiter.wait()
                else:
                    try:
                        await waiter.wait()
                    finally:
                        cancel()
        finally:
            if waiter.frames and waiter.result is None:  # not settled by an insert
                self._unindex(waiter)
        found = waiter.result
        if found is not None:
            return found
        if waiter.error is not None:
            raise waiter.error
        assert timeout is not None  # the deadline, not the data, ended the wait
        raise TimeoutException(
            f"{_timed_out(timeout)} waiting for {self._describe(target, source, time)}"
        ) from _failure(partial(_core_lookup_transform, self, target, source, time))

    async def _wait(
        self,
        check: Callable[[], _T | TransformException | None],
        frames: Callable[[], frozenset[str]],
        timeout: float | Duration | None,
        describe: Callable[[], str],
        retry: Callable[[], object],
        exact: tuple[str, str, Time, bool] | None = None,
    ) -> _T:
        """Wait until ``check()`` gives an answer (or fails the wait), rechecked on every
        insert of ``frames()``; ``exact``: ``check`` is ``check_transform(*exact)``
        (see :class:`_Waiter`). ``retry``: the synchronous lookup the wait stands for;
        at the deadline, the exception it raises is the TimeoutException's
        ``__cause__``."""
        if (
            timeout is not None
            and not (type(timeout) is float and math.isfinite(timeout))  # the common case
            and timeout_ns(timeout) is None
        ):
            timeout = None  # inf: no deadline (and NaN or a str raised here, up front)
        result = check()
        if result is not None:
            if isinstance(result, TransformException):
                raise result
            return result
        if self._closed:
            raise BufferClosedException(f"the buffer is closed: not waiting for {describe()}")
        waiter: _Waiter[_T] = _Waiter(check, frames, running_asyncio_loop(), exact)
        self._reindex(waiter, frames())
        try:
            if timeout is None:
                await waiter.wait()
            else:
                # The clock's deadline callback wakes the wait as the data would (no
                # cancel scope to enter and leave); a clock that cannot schedule one in
                # this loop (Clock.call_later returns None) gives its cancel scope instead.
                cancel = self.clock.call_later(timeout, waiter.wake)
                if cancel is None:
                    with self.clock.move_on_after(timeout):
                        await waiter.wait()
                else:
                    try:
                        await waiter.wait()
                    finally:
                        cancel()
        finally:
            if waiter.frames:  # not already unindexed by the recheck that woke it
                self._unindex(waiter)
        if waiter.error is not None:
            raise waiter.error
        if waiter.result is None:  # the deadline, not the data, ended the wait
            assert timeout is not None
            raise TimeoutException(
                f"{_timed_out(timeout)} waiting for {describe()}"
            ) from _failure(retry)
        return waiter.result

    async def _wait_policy(
        self,
        target: str,
        source: str,
        time: Time,
        timeout: float | Duration | None,
        policy: LookupPolicy,
    ) -> PolicyResult:
        """An awaited lookup under a non-exact policy (``lookup_transform_async``)."""
        policy_args(policy)  # a TypeError for anything else, before any wait
        timeout_ns(timeout)  # a str, bool or NaN timeout refused even when data is there
        if _waits_no_more(policy):
            return self._lookup_policy(target, source, time, policy)
        timeout = _policy_timeout(policy, timeout)
        check = partial(self.check_transform_policy, target, source, time, policy)
        found = check()
        if found is not None:
            if isinstance(found, TransformException):
                raise found
            return found
        return await self._wait(
            check,
            partial(self._frames_of, target, source, time),
            timeout,
            partial(self._describe, target, source, time),
            partial(self._lookup_policy, target, source, time, policy),
        )

    def _describe(self, target: str, source: str, time: Time) -> str:
        answer = self.can_transform(target, source, time, return_debug_tuple=True)
        reason = answer[1] if isinstance(answer, tuple) else ""
        what = f"transform from [{source}] to [{target}] at time {format_sec(time.ns)}"
        return f"{what}: {reason}" if reason else what

    @overload
    def wait_for_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Exact | None = None,
    ) -> Awaiting[TransformStamped]: ...

    @overload
    def wait_for_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Nearest | Clamp | Previous | Window,
    ) -> Awaiting[PolicyResult]: ...

    @coroutine_method  # type: ignore[misc]
    async def wait_for_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: LookupPolicy | None = None,
    ) -> TransformStamped | PolicyResult:
        """Wait until ``lookup_transform(target_frame, source_frame, time)`` can succeed,
        and return its result. ``time`` may lie in the future; ``Time(0)`` waits until
        the two frames are connected with data.

        Args:
            timeout: seconds (or a Duration) of the buffer's clock (``clock.call_later``,
                or ``clock.move_on_after`` for a clock that cannot schedule callbacks);
                None or ``inf`` waits forever; 0 or a negative timeout does not wait (as
                tf2_ros's ``can_transform``, whose wait loop never runs then): the data
                there now, or TimeoutException at once; NaN is a ValueError, a str or
                bool a TypeError (each naming the value, checked before any lookup).
            fail_fast: give up at once, not at the timeout, when the answer can never
                come: the two frames are known and in different trees, or ``time`` is
                older than the oldest stamp a link of the path can still accept (its
                newest stamp minus ``cache_time``). Checked on the call and on every
                insert that touches the path. False (default) is tf2_ros's behaviour.

        Raises:
            TimeoutException: not available within ``timeout``; the message says what
                was missing (tf2's reason), and its ``__cause__`` is the exception the
                lookup raised at the deadline: a ForwardExtrapolationException (the data
                is not there yet), a LookupException (a frame was never heard of), a
                ConnectivityException (the frames are in different trees), ...
            ExtrapolationException: ``time`` is older than the cache window of the path
                (it can never become available); with ``fail_fast``, its subclass
                BackwardExtrapolationException also when ``time`` is older than a
                link's newest stamp minus ``cache_time``.
            ConnectivityException: with ``fail_fast``, the frames are in different trees.
            InvalidArgumentException: a frame id is empty or starts with '/'.
            LookupException: the path between the frames contains a loop.

        ``policy``: as in :meth:`lookup_transform_async`.
        """
        if policy is not None and type(policy) is not Exact:
            return await self._wait_policy(target_frame, source_frame, time, timeout, policy)
        if timeout is None or (type(timeout) is float and math.isfinite(timeout)):
            found = self.check_transform(target_frame, source_frame, time, fail_fast)
            if found is not None:  # the data is there (or can never be): no wait set up
                if isinstance(found, TransformException):
                    raise found
                return found
            return await self._wait_exact(
                target_frame, source_frame, time, fail_fast, timeout, checked=True
            )
        return await self._wait_exact(target_frame, source_frame, time, fail_fast, timeout)

    @overload
    def lookup_transform_async(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Exact | None = None,
    ) -> Awaiting[TransformStamped]: ...

    @overload
    def lookup_transform_async(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Nearest | Clamp | Previous | Window,
    ) -> Awaiting[PolicyResult]: ...

    @coroutine_method  # type: ignore[misc]
    async def lookup_transform_async(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: LookupPolicy | None = None,
    ) -> TransformStamped | PolicyResult:
        """:meth:`lookup_transform`, waiting up to ``timeout`` for the data.

        ``fail_fast``: as :meth:`wait_for_transform` (exact lookups; a policy's wait ends
        on its own terms).

        ``policy`` (:mod:`tfbus.core.policy`): a non-exact policy waits until the policy
        can answer (rechecked on every insert of the path's frames, as an exact wait) and
        returns its :class:`~tfbus.core.policy.PolicyResult`. ``Window(past,
        future_wait)``: an answer from the past within ``past`` at once, else a wait of up
        to ``future_wait`` (and ``timeout``, the shorter) for data at ``time``; with
        ``future_wait`` 0, tf2's error at once.

        Raises: as :meth:`wait_for_transform`.
        """
        if policy is not None and type(policy) is not Exact:
            return await self._wait_policy(target_frame, source_frame, time, timeout, policy)
        if timeout is None or (type(timeout) is float and math.isfinite(timeout)):
            found = self.check_transform(target_frame, source_frame, time, fail_fast)
            if found is not None:  # wait_for_transform's body: one coroutine fewer
                if isinstance(found, TransformException):
                    raise found
                return found
            if timeout is None and not self._closed:
                # _wait_exact without a deadline, inline: no coroutine of its own between
                # this call and the future the insert's recheck completes.
                exact = (target_frame, source_frame, time, fail_fast)
                waiter: _Waiter[TransformStamped] = _Waiter(
                    None, None, running_asyncio_loop(), exact
                )
                self._reindex(waiter, self._frames_of(target_frame, source_frame, time))
                try:
                    await waiter.wait()
                finally:
                    if waiter.frames and waiter.result is None:  # not settled by an insert
                        self._unindex(waiter)
                found = waiter.result
                if found is not None:
                    return found
                assert waiter.error is not None  # no deadline: the data or a failure woke it
                raise waiter.error
            return await self._wait_exact(
                target_frame, source_frame, time, fail_fast, timeout, checked=True
            )
        return await self._wait_exact(target_frame, source_frame, time, fail_fast, timeout)

    @overload
    def lookup_transform_full_async(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Exact | None = None,
    ) -> Awaiting[TransformStamped]: ...

    @overload
    def lookup_transform_full_async(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Nearest | Clamp | Previous | Window,
    ) -> Awaiting[PolicyResult]: ...

    @coroutine_method  # type: ignore[misc]
    async def lookup_transform_full_async(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: LookupPolicy | None = None,
    ) -> TransformStamped | PolicyResult:
        """:meth:`lookup_transform_full` (time travel through ``fixed_frame``), waiting up
        to ``timeout`` for both legs' data.

        Args:
            fail_fast: give up at once when a leg can never be answered, as
                :meth:`wait_for_transform` does for its one lookup (exact lookups).
            policy: a lookup policy (:mod:`tfbus.core.policy`) for both legs, as
                :meth:`lookup_transform_async`: a non-exact one waits until both legs
                can answer under it and returns the
                :class:`~tfbus.core.policy.PolicyResult` of
                :meth:`~tfbus.core.BufferCore.lookup_transform_full`; ``Window``'s
                ``future_wait`` bounds the wait as there.

        Raises:
            TimeoutException: not available within ``timeout``.
            ExtrapolationException: a leg's time fell out of the cache window (with
                ``fail_fast``: BackwardExtrapolationException as in
                :meth:`wait_for_transform`).
            ConnectivityException: with ``fail_fast``, a leg's frames are in different
                trees.
            InvalidArgumentException: a frame id is empty or starts with '/'.
        """
        for arg, frame in (
            ("target_frame", target_frame),
            ("source_frame", source_frame),
            ("fixed_frame", fixed_frame),
        ):
            invalid = self.invalid_frame_id(frame, f"lookupTransform argument {arg}")
            if invalid is not None:
                raise invalid
        if policy is not None and type(policy) is not Exact:
            return await self._wait_full_policy(
                target_frame, target_time, source_frame, source_time, fixed_frame, timeout,
                policy,
            )

        def check() -> TransformStamped | None:
            if self._try_lookup(fixed_frame, source_frame, source_time, fail_fast) is None:
                return None
            if self._try_lookup(target_frame, fixed_frame, target_time, fail_fast) is None:
                return None
            return self.lookup_transform_full(
                target_frame, target_time, source_frame, source_time, fixed_frame
            )

        def frames() -> frozenset[str]:
            return self._frames_of(fixed_frame, source_frame, source_time) | self._frames_of(
                target_frame, fixed_frame, target_time
            )

        def describe() -> str:
            return (
                f"{self._describe(fixed_frame, source_frame, source_time)}; "
                f"{self._describe(target_frame, fixed_frame, target_time)}"
            )

        return await self._wait(
            check, frames, timeout, describe,
            partial(self.lookup_transform_full, target_frame, target_time, source_frame,
                    source_time, fixed_frame),
        )

    async def _wait_full_policy(
        self,
        target_frame: str,
        target_time: Time,
        source_frame: str,
        source_time: Time,
        fixed_frame: str,
        timeout: float | Duration | None,
        policy: LookupPolicy,
    ) -> PolicyResult:
        """``lookup_transform_full_async`` under a non-exact policy."""
        policy_args(policy)  # a TypeError for anything else, before any wait
        timeout_ns(timeout)  # a str, bool or NaN timeout refused even when data is there
        def answer() -> PolicyResult:
            found = self.lookup_transform_full(
                target_frame, target_time, source_frame, source_time, fixed_frame,
                policy=policy,
            )
            assert isinstance(found, PolicyResult)
            return found

        if _waits_no_more(policy):
            return answer()

        def check() -> PolicyResult | TransformException | None:
            for target, source, at in (
                (fixed_frame, source_frame, source_time),
                (target_frame, fixed_frame, target_time),
            ):
                leg = self.check_transform_policy(target, source, at, policy)
                if not isinstance(leg, PolicyResult):
                    return leg
            return answer()

        def frames() -> frozenset[str]:
            return self._frames_of(fixed_frame, source_frame, source_time) | self._frames_of(
                target_frame, fixed_frame, target_time
            )

        def describe() -> str:
            return (
                f"{self._describe(fixed_frame, source_frame, source_time)}; "
                f"{self._describe(target_frame, fixed_frame, target_time)}"
            )

        found = check()
        if found is not None:
            if isinstance(found, TransformException):
                raise found
            return found
        return await self._wait(check, frames, _policy_timeout(policy, timeout), describe, answer)

    @coroutine_method
    async def can_transform_async(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: LookupPolicy | None = None,
    ) -> bool:
        """Whether the transform becomes available within ``timeout`` (tf2_ros
        ``can_transform`` with a timeout). Never raises a TransformException. With
        ``fail_fast``, False at once when it can never become available (as
        :meth:`wait_for_transform`); with a ``policy``, whether a lookup under it
        answers within ``timeout`` (as :meth:`lookup_transform_async`).

        Raises:
            TypeError: ``policy`` is not a lookup policy.
        """
        try:
            await self.wait_for_transform(
                target_frame, source_frame, time, timeout, fail_fast=fail_fast,
                policy=policy,
            )
        except TransformException:
            return False
        return True

    registration: ClassVar[TransformRegistration] = TransformRegistration()
    """The transform functions by type (tf2_ros ``BufferInterface.registration``), shared
    process-wide: see :mod:`tfbus.convert` to register your own stamped types."""

    @overload
    def transform(
        self,
        obj: _M,
        target_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Exact | None = None,
    ) -> Awaiting[_M]: ...

    @overload
    def transform(
        self,
        obj: _M,
        target_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Nearest | Clamp | Previous | Window,
    ) -> Awaiting[tuple[_M, PolicyReport]]: ...

    @coroutine_method  # type: ignore[misc]
    async def transform(
        self,
        obj: _M,
        target_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: LookupPolicy | None = None,
    ) -> _M | tuple[_M, PolicyReport]:
        """Express a stamped object in ``target_frame`` (tf2_ros ``Buffer.transform``):
        looks up ``target_frame <- obj.header.frame_id`` at ``obj.header.stamp``
        (``Time(0)``: latest), waiting up to ``timeout``, and applies the function
        registered for ``type(obj)`` in :mod:`tfbus.convert`.

        Preregistered: PointStamped, PoseStamped, Vector3Stamped (rotated only) and
        TransformStamped (tf2_geometry_msgs' ``doTransform``); register your own types
        with :func:`tfbus.convert.register_transform`.

        Returns:
            What the registered function returns; for the preregistered types, the same
            type with ``header.frame_id == target_frame`` and ``header.stamp`` the
            lookup's stamp (the time actually used).

        Raises:
            TypeError: no transform function is registered for ``type(obj)`` (checked
                before any wait).
            TimeoutException, ExtrapolationException, InvalidArgumentException,
            LookupException, ConnectivityException: as :meth:`wait_for_transform`,
                ``fail_fast`` too.

        ``policy`` (:mod:`tfbus.core.policy`): the lookup under that policy, as
        :meth:`lookup_transform_async`; a non-exact one returns ``(transformed object,
        PolicyReport)``, the report naming the samples the transform was built from.
        """
        do_transform = self.registration.get(type(obj))
        header = _header_of(obj)
        source, stamp = header.frame_id, header.stamp
        if policy is not None and type(policy) is not Exact:
            answer = await self._wait_policy(target_frame, source, stamp, timeout, policy)
            return do_transform(obj, answer.transform), answer.report
        ts: TransformStamped | None = None
        if timeout is None or (type(timeout) is float and math.isfinite(timeout)):
            found = self.check_transform(target_frame, source, stamp, fail_fast)
            if isinstance(found, TransformException):
                raise found
            ts = found
        if ts is None:
            ts = await self._wait(  # wait_for_transform's body: one coroutine fewer
                partial(self.check_transform, target_frame, source, stamp, fail_fast),
                partial(self._frames_of, target_frame, source, stamp),
                timeout,
                partial(self._describe, target_frame, source, stamp),
                partial(_core_lookup_transform, self, target_frame, source, stamp),
                (target_frame, source, stamp, fail_fast),
            )
        result: _M = do_transform(obj, ts)
        return result

    @overload
    def transform_full(
        self,
        obj: _M,
        target_frame: str,
        target_time: Time,
        fixed_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Exact | None = None,
    ) -> Awaiting[_M]: ...

    @overload
    def transform_full(
        self,
        obj: _M,
        target_frame: str,
        target_time: Time,
        fixed_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: Nearest | Clamp | Previous | Window,
    ) -> Awaiting[tuple[_M, PolicyReport]]: ...

    @coroutine_method  # type: ignore[misc]
    async def transform_full(
        self,
        obj: _M,
        target_frame: str,
        target_time: Time,
        fixed_frame: str,
        timeout: float | Duration | None = None,
        *,
        fail_fast: bool = False,
        policy: LookupPolicy | None = None,
    ) -> _M | tuple[_M, PolicyReport]:
        """Express a stamped object in ``target_frame`` at ``target_time``, through
        ``fixed_frame`` (tf2_ros ``Buffer.transform_full``): the transform is
        :meth:`lookup_transform_full_async` ``(target_frame, target_time,
        obj.header.frame_id, obj.header.stamp, fixed_frame, timeout)``, applied by the
        function registered for ``type(obj)``.

        Returns:
            What the registered function returns; for the preregistered types, the same
            type in ``target_frame`` stamped ``target_time`` (the time actually used).

        Raises:
            TypeError: no transform function is registered for ``type(obj)``.
            TimeoutException, ExtrapolationException, InvalidArgumentException,
                ConnectivityException: as :meth:`lookup_transform_full_async`,
                ``fail_fast`` too.

        ``policy``: as :meth:`transform` (both legs; a non-exact one returns
        ``(transformed object, PolicyReport)``).
        """
        do_transform = self.registration.get(type(obj))
        header = _header_of(obj)
        if policy is not None and type(policy) is not Exact:
            found = await self.lookup_transform_full_async(
                target_frame, target_time, header.frame_id, header.stamp, fixed_frame, timeout,
                policy=policy,
            )
            assert isinstance(found, PolicyResult)
            return do_transform(obj, found.transform), found.report
        ts = await self.lookup_transform_full_async(
            target_frame, target_time, header.frame_id, header.stamp, fixed_frame, timeout,
            fail_fast=fail_fast,
        )
        assert isinstance(ts, TransformStamped)
        result: _M = do_transform(obj, ts)
        return result

    # ------------------------------------------------------------------ velocity

    # ------------------------------------------------------------------ batched waits

    async def _wait_latest(
        self,
        target_frame: str,
        source_frame: str,
        times: npt.NDArray[np.int64],
        timeout: float | Duration | None,
        fail_fast: bool = False,
    ) -> None:
        """Wait until the latest of ``times`` can be looked up (nothing for no times).
        Time 0 means "latest available": waiting for it waits for the frames to connect."""
        if times.size:
            await self.wait_for_transform(
                target_frame, source_frame, Time.from_ns(int(times.max())), timeout,
                fail_fast=fail_fast,
            )

    @coroutine_method
    async def lookup_transforms_async(
        self,
        target_frame: str,
        source_frame: str,
        times: TimesLike,
        timeout: float | Duration | None = None,
        *,
        errors: Errors = "raise",
        fail_fast: bool = False,
    ) -> TransformArray:
        """:meth:`~tfbus.core.BufferCore.lookup_transforms`, first waiting (event-driven,
        as :meth:`wait_for_transform`) until the latest of ``times`` can be looked up.
        Data up to the latest time normally covers the earlier ones; a time that has
        fallen out of the cache, or a gap inside the requested span, is reported by the
        batched lookup as tf2's exception (or masked with ``errors="mask"``).

        Args:
            timeout: seconds (or a Duration) of the buffer's clock; None waits forever.
            fail_fast: give up at once when the latest time can never be looked up (as
                :meth:`wait_for_transform`).

        Raises:
            TimeoutException: the latest time did not become available within ``timeout``.
            ExtrapolationException: the latest time is older than the cache window.
            TransformException subclasses, ValueError: as the synchronous lookup.
        """
        t = as_times(times)
        await self._wait_latest(target_frame, source_frame, t, timeout, fail_fast)
        return self.lookup_transforms(target_frame, source_frame, t, errors=errors)

    @coroutine_method
    async def transform_points_async(
        self,
        points: npt.ArrayLike,
        target_frame: str,
        source_frame: str,
        times: TimesLike,
        timeout: float | Duration | None = None,
        *,
        errors: Errors = "raise",
        fail_fast: bool = False,
    ) -> npt.NDArray[np.float64]:
        """:meth:`~tfbus.core.BufferCore.transform_points` (each ``(N, 3)`` point, metres,
        at its own time), first waiting until the latest of ``times`` can be looked up.

        ``fail_fast`` and what is raised: as :meth:`lookup_transforms_async`; ValueError
        for malformed points.
        """
        p = np.asarray(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3), got {p.shape}")
        t = as_times(times, p.shape[0])
        await self._wait_latest(target_frame, source_frame, t, timeout, fail_fast)
        return self.transform_points(p, target_frame, source_frame, t, errors=errors)

    @coroutine_method
    async def lookup_velocity_async(
        self,
        tracking_frame: str,
        observation_frame: str,
        time: Time,
        averaging_interval: Duration | float,
        timeout: float | Duration | None = None,
        *,
        method: str = "tf2",
    ) -> VelocityStamped:
        """:meth:`~tfbus.core.BufferCore.lookup_velocity`, waiting up to ``timeout``
        (seconds of the buffer's clock) until ``tracking_frame`` can be looked up in
        ``observation_frame`` at ``time``; the velocity is then computed from the data
        at hand (tf2 clamps the averaging window to the latest common time).

        Raises:
            TimeoutException: no data within ``timeout``.
            InvalidArgumentException: bad arguments, checked before waiting.
            ExtrapolationException, LookupException, ConnectivityException: as the
                synchronous method, once the data is there.
        """
        return await self.lookup_velocity_full_async(
            tracking_frame, observation_frame, observation_frame, (0.0, 0.0, 0.0),
            tracking_frame, time, averaging_interval, timeout, method=method,
        )

    @coroutine_method
    async def lookup_velocity_full_async(
        self,
        tracking_frame: str,
        observation_frame: str,
        reference_frame: str,
        reference_point: Vector3 | tuple[float, float, float],
        reference_point_frame: str,
        time: Time,
        averaging_interval: Duration | float,
        timeout: float | Duration | None = None,
        *,
        method: str = "tf2",
    ) -> VelocityStamped:
        """:meth:`~tfbus.core.BufferCore.lookup_velocity_full`, waiting up to
        ``timeout`` for the observation, reference and reference-point frames' data at
        ``time``.

        Raises: as :meth:`lookup_velocity_async`.
        """
        check_velocity_arguments(time, averaging_interval, reference_point, method)
        pairs = (
            (observation_frame, tracking_frame),
            (reference_frame, tracking_frame),
            (reference_frame, reference_point_frame),
        )

        def check() -> VelocityStamped | TransformException | None:
            for target, source in pairs:
                found = self.check_transform(target, source, time)
                if found is None or isinstance(found, TransformException):
                    return found
            try:
                return self.lookup_velocity_full(
                    tracking_frame, observation_frame, reference_frame, reference_point,
                    reference_point_frame, time, averaging_interval, method=method,
                )
            except TransformException as e:
                return e

        def frames() -> frozenset[str]:
            out: frozenset[str] = frozenset()
            for target, source in pairs:
                out |= self._frames_of(target, source, time)
            return out

        def describe() -> str:
            return "velocity: " + "; ".join(self._describe(t, s, time) for t, s in pairs)

        def retry() -> VelocityStamped:
            for target, source in pairs:
                _core_lookup_transform(self, target, source, time)
            return self.lookup_velocity_full(
                tracking_frame, observation_frame, reference_frame, reference_point,
                reference_point_frame, time, averaging_interval, method=method,
            )

        return await self._wait(check, frames, timeout, describe, retry)


def _failure(lookup: Callable[[], object]) -> TransformException | None:
    """The TransformException ``lookup()`` raises now (None if it answers): the reason an
    awaited lookup gave up at its deadline, chained as its TimeoutException's
    ``__cause__`` (a ForwardExtrapolationException: the data may still come; a
    LookupException or ConnectivityException: the frames are unknown or apart)."""
    try:
        lookup()
    except TransformException as exc:
        return exc
    return None


def _timed_out(timeout: float | Duration) -> str:
    """The start of a TimeoutException's message: ``Timed out after 2 s``; a negative
    timeout, which does not wait (tf2_ros's ``can_transform`` loop never runs), reads
    ``Timed out after 0 s (timeout=-1 s: a negative timeout does not wait)``."""
    seconds = timeout.to_sec() if isinstance(timeout, Duration) else float(timeout)
    if seconds < 0:
        return f"Timed out after 0 s (timeout={seconds:g} s: a negative timeout does not wait)"
    return f"Timed out after {seconds:g} s"


def _header_of(obj: object) -> Header:
    """``obj.header``, checked enough to make a clear error of a malformed object."""
    header = getattr(obj, "header", None)
    frame_id = getattr(header, "frame_id", None)
    stamp = getattr(header, "stamp", None)
    if not isinstance(frame_id, str) or not isinstance(stamp, Time):
        raise TypeError(
            f"{type(obj).__name__} has no header with a str frame_id and a Time stamp "
            f"(header={header!r})"
        )
    return Header(stamp, frame_id)
