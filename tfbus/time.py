"""Time and Duration: integer nanoseconds, as in ROS 2's ``rclcpp::Time``.

Float seconds near 1.7e9 cannot hold nanoseconds (a double has 53 bits), and tf2's
exact-stamp lookups must be exact, so tfbus keeps every stamp as an ``int`` of
nanoseconds. ``Time(0)`` means "latest available" in lookups, as ``ros::Time(0)`` does in
tf2 (``tf2/src/buffer_core.cpp``, ``BufferCore::lookupTransform``).

Two helpers are the one place for what used to be repeated across tfbus:

* :func:`seconds_to_ns` turns seconds (``int``, ``float``, ``Fraction``, numpy numbers)
  or a :class:`Duration` into integer nanoseconds *exactly* (the float's exact binary
  value times 10⁹, rounded half-to-even), checking the type first: a ``str`` is a
  ``TypeError`` before any arithmetic (``'0.01' * 10**9`` would build a 10 GB string).
* :func:`format_stamp` prints a stamp as ``SEC.NANOSEC`` with nine digits, exactly
  (``1700000000.123456789``), where ``f"{t.to_sec():.9f}"`` would print float noise.

Both value types are plain ``__slots__`` classes holding one ``int``, ordered by it
(``<``, ``<=``, ``>``, ``>=`` between two ``Time`` or two ``Duration``; anything else is
a ``TypeError``) and treated as immutable. They are deliberately *not* dataclasses
(``@dataclass(order=True)`` was tried): serialisers that know dataclasses (msgspec on the
Zenoh wire, ``dataclasses.asdict``) would then write a stamp as the record
``{"_ns": n}`` instead of the integer nanoseconds the wire format specifies, bypassing
its stamp validation; and the generated ``==``/``<`` cost 1.5-3x the written-out ones
(``benchmarks/bench_clock.py``).
"""

from __future__ import annotations

import math
import numbers
import operator
from typing import Final, TypeGuard, overload

__all__ = [
    "NSEC_PER_SEC",
    "TIME_MAX_NS",
    "Duration",
    "Time",
    "format_stamp",
    "seconds_to_ns",
]

NSEC_PER_SEC: Final = 1_000_000_000
TIME_MAX_NS: Final = 2**63 - 1
"""The latest representable Time, in ns (int64 nanoseconds, as ``rcl_time_point_value_t``;
ROS 1's uint32 seconds end well before it)."""


def _out_of_range(ns: int) -> ValueError:
    if ns < 0:
        return ValueError(f"Time cannot be negative: {ns} ns")
    return ValueError(f"Time beyond int64 nanoseconds (about year 2262): {ns} ns")


def _is_real(value: object) -> TypeGuard[numbers.Real]:
    """A real number that is not a ``bool`` (``True`` is not a number of seconds)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _scale_exact(num: int, den: int, k: int) -> int:
    """``round(num / den * k)`` in integers, ties to even (as ``round(Fraction)``)."""
    q, r = divmod(num * k, den)
    twice = 2 * r
    if twice > den or (twice == den and q & 1):
        q += 1
    return q


def seconds_to_ns(seconds: float | Duration, *, name: str = "seconds") -> int:
    """Seconds, or a :class:`Duration`, as integer nanoseconds, exactly.

    Args:
        seconds: an ``int``, ``float``, ``fractions.Fraction``, numpy integer or float
            (seconds), or a :class:`Duration` (its ``ns``).
        name: the argument's name, used in error messages (``"cache_time"``,
            ``"timeout"``, ``"period"``).

    Returns:
        ``int`` nanoseconds: integers are multiplied exactly; a float is taken at its
        exact binary value (``float.as_integer_ratio``) times 10⁹ and rounded to the
        nearest nanosecond, ties to even. ``1.7e9 * 1e9`` in float arithmetic would be off
        by up to ~128 ns; this is not. Equal to ``round(Fraction(seconds) * 10**9)``.

    Raises:
        TypeError: ``seconds`` is not a real number nor a Duration (``str``, ``bool``,
            ``None``, ``complex``, …); checked before any arithmetic.
        ValueError: ``seconds`` is infinite or NaN.
    """
    # The common exact types first, with no ABC checks (a few hundred ns each).
    if type(seconds) is float:
        if not math.isfinite(seconds):
            raise ValueError(f"{name} must be finite, got {seconds!r}")
        num, den = seconds.as_integer_ratio()
        return _scale_exact(num, den, NSEC_PER_SEC)
    if type(seconds) is int:
        return seconds * NSEC_PER_SEC
    return _other_seconds_to_ns(seconds, name)


def _other_seconds_to_ns(seconds: object, name: str) -> int:
    if isinstance(seconds, Duration):
        return seconds.ns
    if not _is_real(seconds):
        raise TypeError(
            f"{name} must be a number of seconds or a Duration, "
            f"got {seconds!r} ({type(seconds).__name__})"
        )
    if isinstance(seconds, numbers.Integral):
        return operator.index(seconds) * NSEC_PER_SEC
    if isinstance(seconds, numbers.Rational):
        return _scale_exact(int(seconds.numerator), int(seconds.denominator), NSEC_PER_SEC)
    value = float(seconds)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {seconds!r}")
    num, den = value.as_integer_ratio()
    return _scale_exact(num, den, NSEC_PER_SEC)


def format_stamp(stamp: Time | Duration | int) -> str:
    """A stamp (or span) as ``SEC.NANOSEC`` with exactly nine decimals, no float rounding.

    Args:
        stamp: a :class:`Time`, a :class:`Duration` or integer nanoseconds.

    Returns:
        e.g. ``"1700000000.123456789"`` for ``Time(1700000000, 123456789)``,
        ``"-0.500000000"`` for ``Duration.from_ns(-500_000_000)``. The digits are those
        of ``rosbag``/``tf_echo`` style ``sec.nsec`` stamps, exact at any magnitude.

    Raises:
        TypeError: ``stamp`` is none of the above (a ``bool`` included).
    """
    if isinstance(stamp, Time | Duration):
        ns = stamp.ns
    elif isinstance(stamp, numbers.Integral) and not isinstance(stamp, bool):
        ns = operator.index(stamp)
    else:
        raise TypeError(
            f"format_stamp takes a Time, a Duration or int nanoseconds, "
            f"got {stamp!r} ({type(stamp).__name__})"
        )
    sign = "-" if ns < 0 else ""
    sec, nsec = divmod(abs(ns), NSEC_PER_SEC)
    return f"{sign}{sec}.{nsec:09d}"


def _ns_from(sec: int | float, nanosec: int) -> int:
    # numpy integers (e.g. ROS1 uint32 stamps) are converted exactly, never multiplied in
    # their own fixed width.
    if type(nanosec) is not int and (
        not isinstance(nanosec, numbers.Integral) or isinstance(nanosec, bool)
    ):
        raise TypeError(f"nanosec must be an integer, got {nanosec!r} ({type(nanosec).__name__})")
    return seconds_to_ns(sec, name="sec") + operator.index(nanosec)


class Duration:
    """A signed span of time in integer nanoseconds (like ``rclcpp::Duration``).

    ``Duration(sec=0, nanosec=0)``; ``Duration.from_ns(n)``; ``Duration.from_sec(s)``.
    Supports ``+``, ``-``, unary ``-``, ``abs``, ordering, multiplication by a real
    number (exact, rounded to the nearest nanosecond) and hashing. Immutable.

    Raises:
        TypeError: ``sec`` is not a real number or ``nanosec`` not an integer.
        ValueError: ``sec`` is infinite or NaN.
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
        """Build a Duration from seconds, exactly rounded to the nearest nanosecond.

        Raises:
            TypeError, ValueError: as :func:`seconds_to_ns`.
        """
        return cls.from_ns(seconds_to_ns(sec, name="sec"))

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
        if type(k) is int:
            return Duration.from_ns(self._ns * k)
        if type(k) is float and math.isfinite(k):
            num, den = k.as_integer_ratio()
            return Duration.from_ns(_scale_exact(num, den, self._ns))
        if not _is_real(k):
            return NotImplemented
        if isinstance(k, numbers.Integral):
            return Duration.from_ns(self._ns * operator.index(k))
        if isinstance(k, numbers.Rational):
            return Duration.from_ns(_scale_exact(int(k.numerator), int(k.denominator), self._ns))
        value = float(k)
        if not math.isfinite(value):
            raise ValueError(f"cannot multiply a Duration by {k!r}: not finite")
        num, den = value.as_integer_ratio()
        return Duration.from_ns(_scale_exact(num, den, self._ns))

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
    immutable.
    ``Time(0)`` asks lookups for the latest available data (tf2 semantics).
    :func:`format_stamp` prints one exactly.

    Raises:
        ValueError: for a negative time (ROS times are unsigned), or one beyond
            ``TIME_MAX_NS`` (int64 nanoseconds, as in ROS 2); ``sec`` not finite.
        TypeError: ``sec`` is not a real number or ``nanosec`` not an integer.
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
        """Build a Time from seconds, exactly rounded to the nearest nanosecond.

        Raises:
            ValueError: if ``sec`` is negative, too large or not finite.
            TypeError: if ``sec`` is not a real number.
        """
        return cls.from_ns(seconds_to_ns(sec, name="sec"))

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
