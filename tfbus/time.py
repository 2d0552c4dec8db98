"""Time and Duration: integer nanoseconds, as in ROS 2's ``rclcpp::Time``.

Float seconds near 1.7e9 cannot hold nanoseconds (a double has 53 bits), and tf2's
exact-stamp lookups must be exact, so tfbus keeps every stamp as an ``int`` of
nanoseconds. ``Time(0)`` means "latest available" in lookups, as ``ros::Time(0)`` does in
tf2 (``tf2/src/buffer_core.cpp``, ``BufferCore::lookupTransform``).
"""

from __future__ import annotations

import math
import operator
from fractions import Fraction
from numbers import Integral
from typing import Final, overload

__all__ = ["NSEC_PER_SEC", "TIME_MAX_NS", "Duration", "Time"]

NSEC_PER_SEC: Final = 1_000_000_000
TIME_MAX_NS: Final = 2**63 - 1
"""The latest representable Time, in ns (int64 nanoseconds, as ``rcl_time_point_value_t``;
ROS 1's uint32 seconds end well before it)."""


def _out_of_range(ns: int) -> ValueError:
    if ns < 0:
        return ValueError(f"Time cannot be negative: {ns} ns")
    return ValueError(f"Time beyond int64 nanoseconds (about year 2262): {ns} ns")


def _sec_to_ns(sec: float) -> int:
    """Float seconds to the nearest integer nanosecond of the float's exact value (the
    product ``sec * 1e9`` would round in float first, off by up to ~128 ns at 1.7e9 s)."""
    if not math.isfinite(sec):
        raise ValueError(f"time in seconds must be finite, got {sec!r}")
    return round(Fraction(sec) * NSEC_PER_SEC)


def _ns_from(sec: int | float, nanosec: int) -> int:
    # numpy integers (e.g. ROS1 uint32 stamps) are converted exactly, never multiplied in
    # their own fixed width.
    ns = operator.index(nanosec)
    if isinstance(sec, Integral):
        return operator.index(sec) * NSEC_PER_SEC + ns
    return _sec_to_ns(float(sec)) + ns


class Duration:
    """A signed span of time in integer nanoseconds (like ``rclcpp::Duration``).

    ``Duration(sec=0, nanosec=0)``; ``Duration.from_ns(n)``; ``Duration.from_sec(s)``.
    Supports ``+``, ``-``, unary ``-``, ``abs``, comparison, multiplication by a number
    and hashing. Immutable.
    """

    __slots__ = ("_ns",)
    _ns: int

    def __init__(self, sec: int | float = 0, nanosec: int = 0) -> None:
        """``sec`` (int, numpy integer or float seconds) plus ``nanosec`` (integer)."""
        self._ns = _ns_from(sec, nanosec)

    @classmethod
    def from_ns(cls, ns: int) -> Duration:
        """Build a Duration of ``ns`` nanoseconds."""
        d = cls.__new__(cls)
        d._ns = int(ns)
        return d

    @classmethod
    def from_sec(cls, sec: float) -> Duration:
        """Build a Duration from float seconds, rounded to the nearest nanosecond."""
        return cls.from_ns(_sec_to_ns(sec))

    @property
    def ns(self) -> int:
        """Length in nanoseconds (``int``)."""
        return self._ns

    def to_sec(self) -> float:
        """Length in float seconds."""
        return self._ns / NSEC_PER_SEC

    def __add__(self, other: Duration) -> Duration:
        if isinstance(other, Duration):
            return Duration.from_ns(self._ns + other._ns)
        return NotImplemented

    def __sub__(self, other: Duration) -> Duration:
        if isinstance(other, Duration):
            return Duration.from_ns(self._ns - other._ns)
        return NotImplemented

    def __neg__(self) -> Duration:
        return Duration.from_ns(-self._ns)

    def __abs__(self) -> Duration:
        return Duration.from_ns(abs(self._ns))

    def __mul__(self, k: float) -> Duration:
        if isinstance(k, int | float):
            return Duration.from_ns(round(self._ns * k))
        return NotImplemented

    __rmul__ = __mul__

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Duration) and self._ns == other._ns

    def __lt__(self, other: Duration) -> bool:
        if isinstance(other, Duration):
            return self._ns < other._ns
        return NotImplemented

    def __le__(self, other: Duration) -> bool:
        if isinstance(other, Duration):
            return self._ns <= other._ns
        return NotImplemented

    def __gt__(self, other: Duration) -> bool:
        if isinstance(other, Duration):
            return self._ns > other._ns
        return NotImplemented

    def __ge__(self, other: Duration) -> bool:
        if isinstance(other, Duration):
            return self._ns >= other._ns
        return NotImplemented

    def __hash__(self) -> int:
        return hash(("Duration", self._ns))

    def __repr__(self) -> str:
        sec, nsec = divmod(self._ns, NSEC_PER_SEC)
        return f"Duration(sec={sec}, nanosec={nsec})"


class Time:
    """A point in time: integer nanoseconds since the clock's epoch (ROS ``Time``).

    ``Time(sec=0, nanosec=0)``; ``Time.from_ns(n)``; ``Time.from_sec(s)``; ``t.ns``;
    ``t.sec`` / ``t.nanosec`` (ROS message fields); ``t.to_sec()``.
    ``Time - Time -> Duration``; ``Time ± Duration -> Time``. Ordered, hashable,
    immutable. ``Time(0)`` asks lookups for the latest available data (tf2 semantics).

    Raises:
        ValueError: for a negative time (ROS times are unsigned), or one beyond
            ``TIME_MAX_NS`` (int64 nanoseconds, as in ROS 2).
    """

    __slots__ = ("_ns",)
    _ns: int

    def __init__(self, sec: int | float = 0, nanosec: int = 0) -> None:
        ns = _ns_from(sec, nanosec)
        if not 0 <= ns <= TIME_MAX_NS:
            raise _out_of_range(ns)
        self._ns = ns

    @classmethod
    def from_ns(cls, ns: int) -> Time:
        """Build a Time of ``ns`` nanoseconds since the epoch.

        Raises:
            ValueError: if ``ns`` is negative or beyond ``TIME_MAX_NS``.
        """
        ns = int(ns)
        if not 0 <= ns <= TIME_MAX_NS:
            raise _out_of_range(ns)
        t = cls.__new__(cls)
        t._ns = ns
        return t

    @classmethod
    def from_sec(cls, sec: float) -> Time:
        """Build a Time from float seconds, rounded to the nearest nanosecond.

        Raises:
            ValueError: if ``sec`` is negative, too large or not finite.
        """
        return cls.from_ns(_sec_to_ns(sec))

    @property
    def ns(self) -> int:
        """Nanoseconds since the epoch (``int``)."""
        return self._ns

    @property
    def sec(self) -> int:
        """Whole seconds (``builtin_interfaces/Time.sec``)."""
        return self._ns // NSEC_PER_SEC

    @property
    def nanosec(self) -> int:
        """Nanoseconds past ``sec`` (``builtin_interfaces/Time.nanosec``)."""
        return self._ns % NSEC_PER_SEC

    def to_sec(self) -> float:
        """Float seconds since the epoch (loses precision below ~0.2 µs near 1.7e9 s)."""
        return self._ns / NSEC_PER_SEC

    def is_zero(self) -> bool:
        """True for ``Time(0)``, tf2's "latest available"."""
        return self._ns == 0

    def __add__(self, other: Duration) -> Time:
        if isinstance(other, Duration):
            return Time.from_ns(self._ns + other.ns)
        return NotImplemented

    __radd__ = __add__

    @overload
    def __sub__(self, other: Time) -> Duration: ...
    @overload
    def __sub__(self, other: Duration) -> Time: ...
    def __sub__(self, other: Time | Duration) -> Time | Duration:
        if isinstance(other, Time):
            return Duration.from_ns(self._ns - other._ns)
        if isinstance(other, Duration):
            return Time.from_ns(self._ns - other.ns)
        return NotImplemented

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Time) and self._ns == other._ns

    def __lt__(self, other: Time) -> bool:
        if isinstance(other, Time):
            return self._ns < other._ns
        return NotImplemented

    def __le__(self, other: Time) -> bool:
        if isinstance(other, Time):
            return self._ns <= other._ns
        return NotImplemented

    def __gt__(self, other: Time) -> bool:
        if isinstance(other, Time):
            return self._ns > other._ns
        return NotImplemented

    def __ge__(self, other: Time) -> bool:
        if isinstance(other, Time):
            return self._ns >= other._ns
        return NotImplemented

    def __hash__(self) -> int:
        return hash(self._ns)

    def __repr__(self) -> str:
        sec, nsec = divmod(self._ns, NSEC_PER_SEC)
        return f"Time(sec={sec}, nanosec={nsec})"
