"""Rate-limited logging: one helper for every component that may log the same problem
many times a second (refused transforms, malformed messages from a peer).

Pure and synchronous, it reads no clock of its own. The caller says what time it is,
in seconds of *its* clock (so a ``ManualClock`` drives it in tests), or uses the
count-limited form, which needs no time on each call (what the sans-I/O core uses): it
logs one line in every ``every`` and, when it is given a clock (a function returning
seconds: ``time.monotonic`` in a transport, the Buffer's clock for the core's refusals),
at most one per ``period`` seconds too, so that a flood of calls cannot print hundreds
of lines a second; the clock is read once per ``every`` calls::

    log = RateLimitedLog(logging.getLogger("tfbus.listener"), period=5.0)
    log.log(clock.now().to_sec(), logging.WARNING, "ignoring a %s on %s", kind, topic)

    counted = CountLimitedLog(logging.getLogger("tfbus.core"), every=1000)
    counted.log(logging.WARNING, "TF_OLD_DATA ignoring data from the past ...")

Messages are grouped by their format string (``msg``): the first of a group is logged,
the next ones within the period (or the next ``every - 1``) are counted, and the next line
logged for that group says how many were suppressed. Like ROS's ``ROS_WARN_THROTTLE``
(``rosconsole``), which is per call site.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

__all__ = ["CountLimitedLog", "RateLimitedLog"]


def _suffix(suppressed: int) -> str:
    return f" ({suppressed} more like this suppressed)" if suppressed else ""


class RateLimitedLog:
    """At most one line per format string per ``period`` seconds of the caller's clock.

    Args:
        logger: where lines go.
        period: seconds between two lines of the same format string (>= 0).

    Raises:
        ValueError: ``period`` is negative or not finite.
    """

    __slots__ = ("_last", "_logger", "_suppressed", "period")

    def __init__(self, logger: logging.Logger, period: float = 5.0) -> None:
        if not 0.0 <= period < float("inf"):
            raise ValueError(f"period must be finite and >= 0 seconds, got {period!r}")
        self._logger = logger
        self.period = period
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def log(self, now: float, level: int, msg: str, *args: object) -> bool:
        """Log ``msg % args`` at ``level`` unless a line with the same ``msg`` was logged
        less than ``period`` seconds before ``now`` (seconds, from the caller's clock; a
        clock that went backwards starts a new period).

        Returns:
            True when the line was logged, False when it was counted as suppressed (or
            the logger does not log ``level``).
        """
        if not self._logger.isEnabledFor(level):
            return False
        last = self._last.get(msg)
        if last is not None and last <= now < last + self.period:
            self._suppressed[msg] = self._suppressed.get(msg, 0) + 1
            return False
        self._last[msg] = now
        self._logger.log(level, msg + "%s", *args, _suffix(self._suppressed.pop(msg, 0)))
        return True


class CountLimitedLog:
    """The first line of each format string, then one in every ``every`` calls, and with
    a ``clock``, at most one per ``period`` seconds of it (the caller passes no time).

    Args:
        logger: where lines go.
        every: log one line per ``every`` calls with the same format string (>= 1).
        period: seconds that must pass between two lines of the same format string
            (>= 0), when there is a clock. The clock is read when a line is logged and
            once per ``every`` suppressed calls, not on every call; a clock that went
            backwards starts a new period.
        clock: a function returning seconds (``time.monotonic``, or a tfbus Clock's
            ``now().to_sec``); None limits by count only. Settable later (attribute
            ``clock``), e.g. by the owner of a sans-I/O object that has a clock.

    Raises:
        ValueError: ``every`` is smaller than 1, or ``period`` negative or not finite.
    """

    __slots__ = ("_last", "_logger", "_suppressed", "clock", "every", "period")

    def __init__(self, logger: logging.Logger, every: int = 1000, *, period: float = 5.0,
                 clock: Callable[[], float] | None = None) -> None:
        if every < 1:
            raise ValueError(f"every must be >= 1, got {every!r}")
        if not (period >= 0.0 and math.isfinite(period)):
            raise ValueError(f"period must be finite and >= 0 seconds, got {period!r}")
        self._logger = logger
        self.every = every
        self.period = period
        self.clock = clock
        self._suppressed: dict[str, int] = {}
        self._last: dict[str, float] = {}

    def log(self, level: int, msg: str, *args: object) -> bool:
        """Log ``msg % args`` at ``level`` if it is the first call with this ``msg``, or
        a multiple of ``every`` calls with it were suppressed since its last line and at
        least ``period`` seconds have passed since that line.

        Returns:
            True when the line was logged, False when it was counted as suppressed (or
            the logger does not log ``level``).
        """
        n = self._suppressed.get(msg)
        clock, now = self.clock, None
        if n is not None:
            if (n + 1) % self.every:
                self._suppressed[msg] = n + 1
                return False
            if clock is not None and self.period:
                last, now = self._last.get(msg), clock()
                if last is not None and last <= now < last + self.period:
                    self._suppressed[msg] = n + 1
                    return False
        self._suppressed[msg] = 0
        if clock is not None:
            self._last[msg] = clock() if now is None else now
        if not self._logger.isEnabledFor(level):
            return False
        self._logger.log(level, msg + "%s", *args, _suffix(n or 0))
        return True
