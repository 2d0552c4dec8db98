"""An awaited lookup that times out says why: its TimeoutException (a TimeoutError) has
the exception the lookup raised at the deadline as ``__cause__`` — a
ForwardExtrapolationException ("not yet"), a LookupException or a ConnectivityException
("never", as things stand) — on every awaited lookup of :class:`tfbus.Buffer` and of
``tfbus.compat.tf2_ros.Buffer``; the requested time reads the same in every part of the
message; a negative timeout does not wait (tf2_ros's ``can_transform`` loop never runs)
and a NaN or non-number timeout is refused naming its value. On asyncio and trio, driven
by a ManualClock."""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import pytest

from tfbus import (
    ConnectivityException,
    ForwardExtrapolationException,
    Header,
    LookupException,
    Point,
    PointStamped,
    Quaternion,
    Time,
    TimeoutException,
    Transform,
    TransformException,
    TransformStamped,
    Vector3,
)
from tfbus.buffer import Buffer
from tfbus.clock import ManualClock
from tfbus.compat import tf2_ros
from tfbus.core.policy import Nearest
from tfbus.time import Duration

pytestmark = pytest.mark.anyio

SEC = 1_000_000_000


def tf(parent: str, child: str, ns: int, x: float = 0.0) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(ns), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion()))


def _buffer(clock: ManualClock) -> Buffer:
    """map -> odom -> base with data at 1 s and 2 s; a separate tree island -> rock."""
    buf = Buffer(clock=clock)
    for ns in (SEC, 2 * SEC):
        buf.set_transform(tf("map", "odom", ns, 1.0), "a")
        buf.set_transform(tf("odom", "base", ns, float(ns // SEC)), "a")
    buf.set_transform_static(tf("island", "rock", 0), "a")
    return buf


Lookup = Callable[[Buffer, str, str, Time], Awaitable[object]]

LOOKUPS: dict[str, Lookup] = {
    "lookup_transform_async": lambda b, t, s, at: b.lookup_transform_async(t, s, at, 1.0),
    "lookup_transform_async Duration": lambda b, t, s, at: b.lookup_transform_async(
        t, s, at, Duration.from_sec(1.0)),
    "wait_for_transform": lambda b, t, s, at: b.wait_for_transform(t, s, at, 1.0),
    "wait_for_transform int": lambda b, t, s, at: b.wait_for_transform(t, s, at, 1),
    "lookup_transform_async Nearest": lambda b, t, s, at: b.lookup_transform_async(
        t, s, at, 1.0, policy=Nearest(0.0)),
    "transform": lambda b, t, s, at: b.transform(
        PointStamped(Header(at, s), Point(1.0, 0.0, 0.0)), t, 1.0),
    "transform_full": lambda b, t, s, at: b.transform_full(
        PointStamped(Header(at, s), Point(1.0, 0.0, 0.0)), t, at, t, 1.0),
    "lookup_transform_full_async": lambda b, t, s, at: b.lookup_transform_full_async(
        t, at, s, at, t, 1.0),
    "lookup_transforms_async": lambda b, t, s, at: b.lookup_transforms_async(
        t, s, [at.ns], 1.0),
    "lookup_velocity_async": lambda b, t, s, at: b.lookup_velocity_async(
        s, t, at, 0.5, 1.0),
    "compat lookup_transform_async": lambda b, t, s, at: _compat(b).lookup_transform_async(
        t, s, at, timeout=1.0),
    "compat wait_for_transform_async": lambda b, t, s, at: _compat(
        b).wait_for_transform_async(t, s, at, timeout=1.0),
    "compat lookup_transform_full_async": lambda b, t, s, at: _compat(
        b).lookup_transform_full_async(t, at, s, at, t, timeout=1.0),
}


def _compat(buf: Buffer) -> tf2_ros.Buffer:
    """A compat tf2_ros Buffer over ``buf`` (its clock and data)."""
    compat = tf2_ros.Buffer(clock=buf.clock)
    compat.buffer = buf
    return compat


async def _timed_out(lookup: Lookup, target: str, source: str, at: Time) -> TimeoutException:
    """Run ``lookup`` until the ManualClock passes its 1 s timeout; its TimeoutException."""
    clock = ManualClock(Time(100))
    buf = _buffer(clock)
    caught: list[BaseException] = []

    async def run() -> None:
        try:
            await lookup(buf, target, source, at)
        except BaseException as exc:  # what the lookup raised, examined below
            caught.append(exc)

    async with anyio.create_task_group() as tg:
        tg.start_soon(run)
        await clock.advance(0)
        assert not caught  # waiting
        await clock.advance(1.5)
    assert len(caught) == 1
    error = caught[0]
    assert isinstance(error, TimeoutException) and isinstance(error, TimeoutError), error
    assert buf.pending_waits == 0
    return error


@pytest.mark.parametrize("name", list(LOOKUPS))
async def test_data_not_there_yet_is_a_forward_extrapolation_cause(name: str) -> None:
    """Data up to 2 s, asked at 3 s: the deadline's reason is "not yet"."""
    error = await _timed_out(LOOKUPS[name], "map", "base", Time(3))
    assert isinstance(error.__cause__, ForwardExtrapolationException), repr(error.__cause__)
    assert str(error.__cause__).startswith(
        "Lookup would require extrapolation 1.000000000s into the future.  Requested time "
        "3.000000000 but the latest data is at time 2.000000000, when looking up transform "
        "from frame [")


@pytest.mark.parametrize("name", list(LOOKUPS))
async def test_unknown_frame_is_a_lookup_exception_cause(name: str) -> None:
    error = await _timed_out(LOOKUPS[name], "map", "nowhere", Time(1))
    assert type(error.__cause__) is LookupException, repr(error.__cause__)
    assert "nowhere" in str(error.__cause__)


@pytest.mark.parametrize("name", list(LOOKUPS))
async def test_unconnected_trees_are_a_connectivity_cause(name: str) -> None:
    error = await _timed_out(LOOKUPS[name], "map", "rock", Time(1))
    assert type(error.__cause__) is ConnectivityException, repr(error.__cause__)
    assert "not part of the same tree" in str(error.__cause__)


async def test_timeout_error_tells_not_yet_from_never() -> None:
    """The pattern the cause is for: ``except TimeoutError`` then look at ``__cause__``."""
    verdicts = []
    for source, at in (("base", Time(3)), ("nowhere", Time(1))):
        try:
            raise await _timed_out(LOOKUPS["lookup_transform_async"], "map", source, at)
        except TimeoutError as e:
            verdicts.append("not yet" if isinstance(e.__cause__, ForwardExtrapolationException)
                            else "never")
    assert verdicts == ["not yet", "never"]


async def test_the_requested_time_reads_the_same_throughout_the_message() -> None:
    """A wall-clock time whose ``ns / 1e9`` rounds to other last digits than tf2's
    ``(double)sec + 1e-9 * nsec``: the message printed it both ways (…789419889 and tf2's
    …789419651)."""
    asked = 1_924_948_642_789_419_743
    clock = ManualClock(Time(100))
    buf = Buffer(clock=clock)
    buf.set_transform(tf("odom", "base_link", asked - 600), "a")
    buf.set_transform(tf("odom", "base_link", asked - 143), "a")
    with pytest.raises(TimeoutException) as info:
        await buf.lookup_transform_async("odom", "base_link", Time.from_ns(asked), 0.0)
    assert str(info.value) == (
        "Timed out after 0 s waiting for transform from [base_link] to [odom] at time "
        "1924948642.789419651: Lookup would require extrapolation 0.000000143s into the "
        "future.  Requested time 1924948642.789419651 but the latest data is at time "
        "1924948642.789419651, when looking up transform from frame [base_link] to frame "
        "[odom]")


@pytest.mark.parametrize("timeout", [-1, -1.0, Duration.from_sec(-1.0)])
async def test_a_negative_timeout_does_not_wait_and_says_so(timeout: Any) -> None:
    """tf2_ros's ``while now < start + timeout`` never runs for a negative timeout: no
    wait. The message said "Timed out after -1 s"."""
    clock = ManualClock(Time(100))
    buf = _buffer(clock)
    with pytest.raises(TimeoutException) as info:
        await buf.lookup_transform_async("map", "base", Time(3), timeout)
    assert str(info.value).startswith(
        "Timed out after 0 s (timeout=-1 s: a negative timeout does not wait) waiting for "
        "transform from [base] to [map] at time 3.000000000: Lookup would require")
    assert isinstance(info.value.__cause__, ForwardExtrapolationException)
    assert clock.now() == Time(100) and buf.pending_waits == 0
    # the data there: answered, whatever the timeout
    assert (await buf.lookup_transform_async("map", "base", Time(2), timeout)).header.stamp \
        == Time(2)


_NAN = (math.nan, ValueError, "timeout must not be NaN, got nan (a timeout is seconds or a "
        "Duration; None or math.inf: no limit)")


@pytest.mark.parametrize(("name", "timeout", "error", "text"), [
    *[(name, *_NAN) for name in ("lookup_transform_async", "wait_for_transform",
                                 "lookup_transform_full_async", "transform",
                                 "lookup_transform_async Nearest")],
    ("lookup_transform_async Nearest", "x", TypeError,
     "timeout must be a number of seconds or a Duration, got 'x' (str)"),
    ("lookup_transform_async Nearest", True, TypeError,
     "timeout must be a number of seconds or a Duration, got True (bool)"),
])
async def test_a_bad_timeout_is_refused_even_when_the_data_is_there(
    name: str, timeout: object, error: type[Exception], text: str
) -> None:
    """Checked before the lookup: a lookup the data answers does not hide it."""
    buf = _buffer(ManualClock(Time(100)))
    lookups: dict[str, Callable[[], Awaitable[object]]] = {
        "lookup_transform_async": lambda: buf.lookup_transform_async(
            "map", "base", Time(1), timeout),  # type: ignore[arg-type]
        "wait_for_transform": lambda: buf.wait_for_transform(
            "map", "base", Time(1), timeout),  # type: ignore[arg-type]
        "lookup_transform_full_async": lambda: buf.lookup_transform_full_async(
            "map", Time(1), "base", Time(1), "map", timeout),  # type: ignore[arg-type]
        "transform": lambda: buf.transform(
            PointStamped(Header(Time(1), "base"), Point()), "map", timeout),  # type: ignore[arg-type]
        "lookup_transform_async Nearest": lambda: buf.lookup_transform_async(
            "map", "base", Time(1), timeout, policy=Nearest(0.0)),  # type: ignore[arg-type]
    }
    with pytest.raises(error) as info:
        await lookups[name]()
    assert str(info.value).startswith(text)
    assert not isinstance(info.value, TransformException)
