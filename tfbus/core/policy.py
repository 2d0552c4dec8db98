"""Lookup policies: how a lookup picks each link's sample when tf2's exact rule (interpolate
between the two samples around the time, never extrapolate) would refuse, or when a
sample rather than an interpolation is wanted.

tf2 refuses to extrapolate, not even by 1 ns (ros/geometry2 #98); users then raise
tolerances to hide it. Peers offer the choice explicitly: NVIDIA Holoscan's PoseTree
``AccessMethod`` (``kExact``, ``kNearest``, ``kPrevious``, ``kInterpolate``, ...) and
Foxglove's transform ``maxDelta``. tfbus keeps tf2's rule as the default
(:class:`Exact`) and offers, per lookup, the rules below. Each applies **per link** of
the path (a link is one child frame and its parent); static links are valid at every
time under every policy.

* :class:`Exact` — tf2 (the default; results bit for bit tf2's).
* :class:`Nearest` ``(max_delta)`` — the link's sample nearest to the time, if it is
  within ``max_delta`` (a tie goes to the older sample); otherwise tf2's rule for that
  link (an interpolation between its samples, or tf2's extrapolation error).
* :class:`Clamp` ``(max_delta)`` — tf2's interpolation inside the link's data; up to
  ``max_delta`` before its oldest / after its newest sample, that edge sample (held);
  beyond, tf2's error.
* :class:`Previous` ``()`` — the link's last sample at or before the time (held for any
  time after the newest); before the oldest sample, tf2's error.
* :class:`Window` ``(past, future_wait)`` — tf2's interpolation inside the data; up to
  ``past`` after the newest sample, the newest sample; else tf2's error. An awaited
  lookup (``Buffer.lookup_transform_async``) waits up to ``future_wait`` for data at
  the time.

A policy never answers where tf2 would answer differently unless it says so: a lookup
with a non-exact policy returns a :class:`PolicyResult`, the ``TransformStamped`` and a
:class:`PolicyReport` naming every link's sample stamp and the largest ``|stamp - time|``.
Where a policy finds no sample, the error raised is tf2's (the same class and message as
the exact lookup for that link at that time).

Durations (``max_delta``, ``past``, ``future_wait``) are seconds (a real number) or a
:class:`~tfbus.time.Duration`, like ``cache_time`` and ``timeout`` everywhere in tfbus;
they are held as int nanoseconds.
"""

from __future__ import annotations

import math
from numbers import Real
from typing import Final, NamedTuple

from tfbus.messages import TransformStamped
from tfbus.time import TIME_MAX_NS, Duration, Time

__all__ = [
    "Clamp",
    "Exact",
    "ExpireAfter",
    "LookupPolicy",
    "Nearest",
    "PolicyReport",
    "PolicyResult",
    "Previous",
    "Window",
    "expire_after",
]

# Modes of the core's per-link pick (CoreBase._query_policy): what the twins read.
MODE_NEAREST: Final = 1
MODE_CLAMP: Final = 2
MODE_PREVIOUS: Final = 3


def _duration_ns(value: object, name: str) -> int:
    """A policy duration (seconds or a Duration) as int ns in [0, 2**63 - 1].

    Raises:
        TypeError: not a real number (a bool included) nor a Duration.
        ValueError: negative, NaN, infinite or beyond int64 nanoseconds.
    """
    if isinstance(value, Duration):
        ns = value.ns
    elif isinstance(value, Real) and not isinstance(value, bool):
        seconds = float(value)
        if not math.isfinite(seconds) or not 0.0 <= seconds <= TIME_MAX_NS / 1e9:
            raise ValueError(
                f"{name} must be finite seconds in [0, 9.2e9] (int64 nanoseconds), got {value!r}"
            )
        ns = Duration.from_sec(seconds).ns
    else:
        raise TypeError(f"{name} must be seconds (a real number) or a Duration, got {value!r}")
    if not 0 <= ns <= TIME_MAX_NS:
        raise ValueError(f"{name} must be in [0, 2**63 - 1] ns, got {ns} ns")
    return ns


class _Policy:
    """Common base: the core's ``(mode, before_ns, after_ns)`` and a readable repr."""

    __slots__ = ("_args",)

    _args: tuple[int, int, int]  # (mode, before ns, after ns): what the core reads

    @property
    def _mode(self) -> int:
        return self._args[0]

    @property
    def _before(self) -> int:
        return self._args[1]

    @property
    def _after(self) -> int:
        return self._args[2]

    def __eq__(self, other: object) -> bool:
        return (
            type(other) is type(self) and isinstance(other, _Policy) and self._args == other._args
        )

    def __hash__(self) -> int:
        return hash((type(self).__name__, self._args))


class Exact(_Policy):
    """tf2's rule (``tf2/src/cache.cpp`` ``TimeCache::getData``): interpolate between the
    two samples around the time, never extrapolate. The default of every lookup; a lookup
    given ``Exact()`` is the lookup given no policy (same result type, same speed)."""

    __slots__ = ()

    def __init__(self) -> None:
        self._args = (0, 0, 0)

    def __repr__(self) -> str:
        return "Exact()"


class Nearest(_Policy):
    """Per link, the sample nearest to the time if ``|stamp - time| <= max_delta`` (a tie
    goes to the older sample); otherwise tf2's rule for that link. No interpolation for a
    picked sample (Holoscan PoseTree ``AccessMethod::kNearest``; Foxglove ``maxDelta``).

    Args:
        max_delta: seconds or a Duration, >= 0.

    Raises:
        TypeError, ValueError: ``max_delta`` is not a non-negative finite duration.
    """

    __slots__ = ()

    def __init__(self, max_delta: float | Duration) -> None:
        ns = _duration_ns(max_delta, "max_delta")
        self._args = (MODE_NEAREST, ns, ns)

    @property
    def max_delta(self) -> Duration:
        """The largest ``|stamp - time|`` a picked sample may have."""
        return Duration.from_ns(self._before)

    def __repr__(self) -> str:
        return f"Nearest(max_delta={self._before / 1e9:g})"


class Clamp(_Policy):
    """Per link, tf2's interpolation inside the link's data; up to ``max_delta`` beyond its
    oldest or newest sample, that edge sample held; beyond that, tf2's error (Holoscan
    PoseTree's ``kInterpolate`` inside with a bounded hold at the ends).

    Args:
        max_delta: seconds or a Duration, >= 0.

    Raises:
        TypeError, ValueError: ``max_delta`` is not a non-negative finite duration.
    """

    __slots__ = ()

    def __init__(self, max_delta: float | Duration) -> None:
        ns = _duration_ns(max_delta, "max_delta")
        self._args = (MODE_CLAMP, ns, ns)

    @property
    def max_delta(self) -> Duration:
        """How far beyond the data an edge sample is held."""
        return Duration.from_ns(self._before)

    def __repr__(self) -> str:
        return f"Clamp(max_delta={self._before / 1e9:g})"


class Previous(_Policy):
    """Per link, the last sample at or before the time, however old (Holoscan PoseTree
    ``AccessMethod::kPrevious``); a time before the link's oldest sample is tf2's error."""

    __slots__ = ()

    def __init__(self) -> None:
        self._args = (MODE_PREVIOUS, 0, 0)

    def __repr__(self) -> str:
        return "Previous()"


class Window(_Policy):
    """tf2's interpolation inside the data; up to ``past`` after a link's newest sample,
    that sample; otherwise an awaited lookup waits up to ``future_wait`` for data at the
    time (a lookup that cannot wait raises tf2's error at once).

    Args:
        past: seconds or a Duration, >= 0: how old a link's newest sample may be.
        future_wait: seconds or a Duration, >= 0: the longest an awaited lookup waits
            (the call's own ``timeout`` also bounds it; the shorter one wins).

    Raises:
        TypeError, ValueError: a duration is not non-negative and finite.
    """

    __slots__ = ("_future_wait",)

    def __init__(self, past: float | Duration, future_wait: float | Duration = 0.0) -> None:
        ns = _duration_ns(past, "past")
        self._future_wait = _duration_ns(future_wait, "future_wait")
        self._args = (MODE_CLAMP, 0, ns)

    @property
    def past(self) -> Duration:
        """How old a link's newest sample may be."""
        return Duration.from_ns(self._after)

    @property
    def future_wait(self) -> Duration:
        """The longest an awaited lookup waits for data at the time."""
        return Duration.from_ns(self._future_wait)

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Window)
            and self._after == other._after
            and self._future_wait == other._future_wait
        )

    def __hash__(self) -> int:
        return hash(("Window", self._after, self._future_wait))

    def __repr__(self) -> str:
        return f"Window(past={self._after / 1e9:g}, future_wait={self._future_wait / 1e9:g})"


LookupPolicy = Exact | Nearest | Clamp | Previous | Window
"""Any lookup policy."""


class PolicyReport(NamedTuple):
    """What a lookup under a policy used: per link on the path between the two frames,
    the sample's stamp.

    Attributes:
        frames: the child frame id of each link on the path, from the source frame up to
            the frames' common ancestor, then down to the target frame.
        stamps_ns: per link, the stamp (int ns) of the sample used; the lookup's time
            when the link was interpolated (tf2's rule) or is static.
        max_abs_delta_ns: the largest ``|stamp - time|`` over the links, ns; 0 when the
            answer is tf2's exact one.
    """

    frames: tuple[str, ...]
    stamps_ns: tuple[int, ...]
    max_abs_delta_ns: int

    @property
    def max_abs_delta(self) -> Duration:
        """``max_abs_delta_ns`` as a Duration."""
        return Duration.from_ns(self.max_abs_delta_ns)

    @property
    def exact(self) -> bool:
        """Whether every link was answered at the lookup's time (tf2's own answer)."""
        return self.max_abs_delta_ns == 0

    def stamps(self) -> dict[str, Time]:
        """``{child frame id: stamp of its sample}`` for the links on the path."""
        return {f: Time.from_ns(s) for f, s in zip(self.frames, self.stamps_ns, strict=True)}


class PolicyResult(NamedTuple):
    """A lookup's answer under a non-exact policy: unpack as ``transform, report``.

    Attributes:
        transform: the ``TransformStamped`` (``header.stamp`` the time looked up: the
            requested time, or the latest common time for ``Time(0)``).
        report: the :class:`PolicyReport` of the samples used.
    """

    transform: TransformStamped
    report: PolicyReport


def policy_args(policy: object) -> tuple[int, int, int]:
    """``(mode, before_ns, after_ns)`` of a policy for the core; mode 0 is :class:`Exact`.

    Raises:
        TypeError: ``policy`` is not one of :data:`LookupPolicy`.
    """
    if isinstance(policy, _Policy):
        return policy._args
    raise TypeError(
        "policy must be Exact(), Nearest(max_delta), Clamp(max_delta), Previous() or "
        f"Window(past, future_wait), got {policy!r}"
    )


def policy_error(policy: object, time: object, err: AttributeError) -> Exception:
    """The error of a policy lookup whose core call raised AttributeError: a TypeError
    naming the ``policy`` or ``time`` argument that is not what it must be."""
    if not isinstance(policy, _Policy):
        try:
            policy_args(policy)
        except TypeError as bad:
            return bad
    if not isinstance(time, Time):
        return TypeError(
            f"time must be a tfbus.Time (Time(0) for the latest data), not "
            f"{type(time).__name__} {time!r}"
        )
    return err


class ExpireAfter(NamedTuple):
    """A buffer's frame expiry (``BufferCore(cache_policy=expire_after(seconds))``): a
    dynamic link whose newest sample is more than ``after_ns`` older than the newest
    dynamic stamp the buffer has stored is removed (:meth:`BufferCore.forget
    <tfbus.core.BufferCore.forget>`), checked as data arrives whenever that newest stamp
    has advanced ``every_ns`` since the last check. Stamp time, not the wall clock, as
    tf2's ``cache_time`` (a buffer fed a bag expires by the bag's stamps).

    tf2 keeps every frame it has seen for the life of the buffer: "the cache length is
    per transform", and tf2's maintainers would consider "a method to iterate and prune
    old frames" but not a check on receipt, "the most exercised code path"
    (ros/geometry2 #409, #239). Here the receipt path pays one integer comparison; the
    pruning runs at most once per ``every_ns`` of stamp time.

    Attributes:
        after_ns: the age limit, int ns (> 0).
        every_ns: how far the newest stamp moves between two checks, int ns (> 0); a
            link is removed at most ``after_ns + every_ns`` of stamp time after its
            newest sample.
    """

    after_ns: int
    every_ns: int

    @property
    def after(self) -> Duration:
        """``after_ns`` as a Duration."""
        return Duration.from_ns(self.after_ns)


def expire_after(seconds: float | Duration, *, every: float | Duration = 1.0) -> ExpireAfter:
    """The cache policy that removes frames whose data stopped more than ``seconds`` ago
    (see :class:`ExpireAfter`).

    Args:
        seconds: the age limit, seconds (a real number) or a Duration, > 0.
        every: the stamp time between two checks, seconds or a Duration, > 0 (default 1 s).

    Raises:
        TypeError: ``seconds`` or ``every`` is not a real number (a bool included) nor a
            Duration.
        ValueError: ``seconds`` or ``every`` is not positive, NaN, infinite or beyond
            int64 nanoseconds.
    """
    after_ns = _duration_ns(seconds, "expire_after seconds")
    every_ns = _duration_ns(every, "expire_after every")
    if after_ns == 0:
        raise ValueError(f"expire_after seconds must be > 0, got {seconds!r}")
    if every_ns == 0:
        raise ValueError(f"expire_after every must be > 0, got {every!r}")
    return ExpireAfter(after_ns, every_ns)
