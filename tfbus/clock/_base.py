"""The ``Clock`` protocol, the one meaning of a timeout, and backward-jump callbacks.

Shared by :mod:`tfbus.clock`'s clocks and timers (see the package docstring).
"""

from __future__ import annotations

import logging
import math
import numbers
from collections.abc import Callable, Hashable
from contextlib import AbstractContextManager
from itertools import count
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import anyio

from tfbus.time import Duration, Time, seconds_to_ns

if TYPE_CHECKING:
    pass

_log = logging.getLogger("tfbus.clock")

JumpCallback = Callable[[Time, Time], None]
"""Called as ``callback(old, new)`` when a clock jumps backwards from ``old`` to ``new``."""


@runtime_checkable
class Clock(Protocol):
    """A time source: what every async tfbus component reads time from and sleeps on."""

    def now(self) -> Time:
        """The current time of this clock."""
        ...

    def now_ns(self) -> int:
        """:meth:`now` as int nanoseconds, building no Time (read on every message)."""
        ...

    async def sleep_until(self, t: Time) -> None:
        """Return once ``now() >= t`` (at once, after a checkpoint, if it already is).

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled meanwhile.
        """
        ...

    async def sleep(self, seconds: float | Duration) -> None:
        """Sleep for ``seconds`` of this clock's time (``<= 0``: just a checkpoint;
        ``math.inf``: until cancelled).

        Raises:
            anyio.get_cancelled_exc_class(): if the calling task is cancelled meanwhile.
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number nor a Duration.
        """
        ...

    def on_jump(
        self, callback: JumpCallback, *, key: Hashable | None = None
    ) -> Callable[[], None]:
        """Register ``callback(old, new)`` for backward jumps; returns an unregister function.

        With a ``key``, registrations share one callback: the first one registered under
        ``key`` runs once per jump however many owners asked for it, until the last of
        them unregisters (tf2_ros clears a buffer once per jump back, though its Buffer and
        its TransformListener both watch the clock). Without one, every registration is
        its own callback. Callbacks run in registration order.
        """
        ...

    def move_on_after(
        self, seconds: float | Duration | None, *, shield: bool = False
    ) -> AbstractContextManager[anyio.CancelScope]:
        """A context manager that cancels its block after ``seconds`` of this clock's time.

        Entering it gives the ``anyio.CancelScope`` of the block: after the block,
        ``scope.cancelled_caught`` tells whether the deadline ended it. ``seconds``:
        ``None`` or ``inf`` = no deadline, ``<= 0`` = at the first checkpoint. The
        deadline is counted from the call.

        Raises:
            ValueError: ``seconds`` is NaN (at the call, before entering).
            TypeError: ``seconds`` is not a number, a Duration or None.
        """
        ...

    def fail_after(
        self, seconds: float | Duration | None, *, shield: bool = False
    ) -> AbstractContextManager[anyio.CancelScope]:
        """As :meth:`move_on_after`, but raises ``TimeoutError`` when the deadline ends the
        block (``anyio.fail_after`` on this clock's time).

        Raises:
            TimeoutError: on leaving the block, if the deadline cancelled it.
            ValueError, TypeError: as :meth:`move_on_after`.
        """
        ...

    def call_later(
        self, seconds: float | Duration, callback: Callable[[], object]
    ) -> Callable[[], None] | None:
        """Call ``callback()`` once ``seconds`` of this clock's time have passed, from the
        running event loop: a deadline with no task and no cancel scope (how a
        :class:`~tfbus.buffer.Buffer`'s ``timeout=`` wakes its wait). ``<= 0``: called at
        once, before this returns; ``inf``: never. The deadline is counted from the call.

        Returns:
            A function that cancels the call (harmless once it ran or was cancelled), or
            ``None`` when this clock cannot schedule callbacks in the running event loop
            (:class:`~tfbus.clock.SystemClock` under trio, which has no timer callbacks):
            the caller then uses :meth:`move_on_after`.

        Raises:
            ValueError: ``seconds`` is NaN.
            TypeError: ``seconds`` is not a number nor a Duration.
        """
        ...


def timeout_ns(seconds: float | Duration | None, *, name: str = "timeout") -> int | None:
    """A timeout in nanoseconds, or ``None`` for "no deadline", the same on every clock.

    ``None``, ``math.inf`` -> ``None``; ``-math.inf`` -> ``0``; a finite number of seconds
    or a Duration -> exact nanoseconds (:func:`tfbus.time.seconds_to_ns`; negative
    values are kept: the caller expires them at once).

    Raises:
        ValueError: NaN.
        TypeError: not a number, Duration or None (a ``str`` or ``bool`` included),
            checked before any arithmetic.
    """
    if seconds is None:
        return None
    if isinstance(seconds, float) or (
        isinstance(seconds, numbers.Real) and not isinstance(seconds, numbers.Rational)
    ):
        value = float(seconds)
        if math.isnan(value):
            raise ValueError(f"{name} must not be NaN, got {seconds!r} (a timeout is seconds or a "
                             "Duration; None or math.inf: no limit)")
        if math.isinf(value):
            return None if value > 0 else 0
    return seconds_to_ns(seconds, name=name)


def _noop() -> None:
    """The canceller of a call that will never happen (or already did)."""


class _JumpCallbacks:
    """The backward-jump callbacks of one clock (:meth:`Clock.on_jump`), shared by the
    clocks: each callback once, keyed ones counted by how many owners hold them."""

    __slots__ = ("_callbacks", "_holders", "_ids")

    def __init__(self) -> None:
        self._callbacks: dict[Hashable, JumpCallback] = {}
        self._holders: dict[Hashable, int] = {}
        self._ids = count()

    def add(self, callback: JumpCallback, key: Hashable | None = None) -> Callable[[], None]:
        """Register ``callback`` (under ``key``: joined to the one held there, if any);
        returns its idempotent unregister."""
        slot: Hashable = ("key", key) if key is not None else ("id", next(self._ids))
        if slot not in self._callbacks:
            self._callbacks[slot] = callback
        self._holders[slot] = self._holders.get(slot, 0) + 1
        done = False

        def unregister() -> None:
            nonlocal done
            if done:
                return
            done = True
            left = self._holders.get(slot, 1) - 1
            if left > 0:
                self._holders[slot] = left
            else:
                self._holders.pop(slot, None)
                self._callbacks.pop(slot, None)

        return unregister

    def fire(self, old: Time, new: Time) -> None:
        # A list copy: a callback may unregister itself (or others) while we iterate.
        for callback in list(self._callbacks.values()):
            try:
                callback(old, new)
            except Exception:
                _log.exception("clock jump callback %r raised", callback)

    def __len__(self) -> int:
        return len(self._callbacks)
