"""ROS 2's extrapolation classes: ``ForwardExtrapolationException``,
``BackwardExtrapolationException`` and ``NoDataForExtrapolationException``, subclasses of
``ExtrapolationException``, chosen as rolling tf2's ``TimeCache::findClosest``
(``tf2/src/cache.cpp``) chooses them, with tf2 0.7.6's messages kept.

Rolling's rule for a link's samples and a requested time t (not 0):
one sample at another time, or none: no data; t after the newest: forward; t before the
oldest: backward. The first link of the walk that fails decides, as in tf2.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfbus import (
    BackwardExtrapolationException,
    ExtrapolationException,
    ForwardExtrapolationException,
    Header,
    NoDataForExtrapolationException,
    Quaternion,
    Time,
    Transform,
    TransformException,
    TransformStamped,
    Vector3,
)
from tfbus.core import BufferCore
from tfbus.errors import extrapolation_exception

SEC = 1_000_000_000


def _tf(parent: str, child: str, ns: int, x: float = 0.0) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(ns), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion()))


def _core(stamps: list[int]) -> BufferCore:
    core = BufferCore(cache_time=1000.0)
    for i, ns in enumerate(stamps):
        assert core.set_transform(_tf("base", "laser", ns, float(i)))
    return core


def test_the_classes_are_extrapolation_exceptions() -> None:
    for cls in (ForwardExtrapolationException, BackwardExtrapolationException,
                NoDataForExtrapolationException):
        assert issubclass(cls, ExtrapolationException)
        assert issubclass(cls, TransformException)


def test_after_the_newest_sample_is_forward() -> None:
    core = _core([10 * SEC, 11 * SEC])
    with pytest.raises(ForwardExtrapolationException) as info:
        core.lookup_transform("base", "laser", Time(12))
    assert str(info.value) == (
        "Lookup would require extrapolation 1.000000000s into the future.  Requested time "
        "12.000000000 but the latest data is at time 11.000000000, when looking up transform "
        "from frame [laser] to frame [base]"
    )


def test_before_the_oldest_sample_is_backward() -> None:
    core = _core([10 * SEC, 11 * SEC])
    with pytest.raises(BackwardExtrapolationException) as info:
        core.lookup_transform("base", "laser", Time(9))
    assert str(info.value).startswith(
        "Lookup would require extrapolation 1.000000000s into the past.  Requested time "
        "9.000000000 but the earliest data is at time 10.000000000"
    )


def test_one_sample_at_another_time_is_no_data() -> None:
    core = _core([10 * SEC])
    for t in (9, 11):
        with pytest.raises(NoDataForExtrapolationException) as info:
            core.lookup_transform("base", "laser", Time(t))
        assert str(info.value).startswith(
            f"Lookup would require extrapolation at time {t}.000000000, but only time "
            "10.000000000 is in the buffer"
        )
    assert core.lookup_transform("base", "laser", Time(10)).transform.translation.x == 0.0


def test_the_first_failing_link_of_the_walk_decides() -> None:
    """odom->base has one sample (no data at 11 s), base->laser two (forward at 12 s)."""
    core = BufferCore(cache_time=1000.0)
    core.set_transform(_tf("odom", "base", 10 * SEC))
    core.set_transform(_tf("base", "laser", 10 * SEC))
    core.set_transform(_tf("base", "laser", 11 * SEC))
    with pytest.raises(NoDataForExtrapolationException):  # laser's link is fine at 11 s
        core.lookup_transform("odom", "laser", Time(11))
    with pytest.raises(ForwardExtrapolationException):  # laser's link fails first at 12 s
        core.lookup_transform("odom", "laser", Time(12))


def test_can_transform_and_full_lookups_raise_the_same_classes() -> None:
    core = _core([10 * SEC, 11 * SEC])
    ok, why = core.can_transform("base", "laser", Time(12), return_debug_tuple=True)
    assert not ok and "into the future" in why
    with pytest.raises(ForwardExtrapolationException):
        core.lookup_transform_full("base", Time(10), "laser", Time(12), "base")
    with pytest.raises(BackwardExtrapolationException):
        core.lookup_transform_full("base", Time(10), "laser", Time(9), "base")


def test_batched_lookups_raise_the_class_of_the_failing_row() -> None:
    core = _core([10 * SEC, 11 * SEC])
    with pytest.raises(BackwardExtrapolationException):
        core.lookup_transforms("base", "laser", [10 * SEC, 9 * SEC])
    with pytest.raises(ForwardExtrapolationException):
        core.lookup_transforms("base", "laser", [12 * SEC])


@settings(max_examples=300, deadline=None)
@given(
    stamps=st.lists(st.integers(1, 50), min_size=1, max_size=6, unique=True),
    t=st.integers(1, 60),
)
def test_the_class_is_rollings_choice(stamps: list[int], t: int) -> None:
    """Against a brute-force model of rolling's ``findClosest`` on one link."""
    core = _core([s * SEC for s in stamps])
    if len(stamps) == 1:
        expected = None if t == stamps[0] else NoDataForExtrapolationException
    elif t > max(stamps):
        expected = ForwardExtrapolationException
    elif t < min(stamps):
        expected = BackwardExtrapolationException
    else:
        expected = None
    if expected is None:
        core.lookup_transform("base", "laser", Time(t))
        return
    with pytest.raises(ExtrapolationException) as info:
        core.lookup_transform("base", "laser", Time(t))
    assert type(info.value) is expected


@pytest.mark.parametrize(
    ("message", "cls"),
    [
        ("Lookup would require extrapolation 0.5s into the future.  Requested time 2 but the "
         "latest data is at time 1.5, when looking up transform from frame [a] to frame [b]",
         ForwardExtrapolationException),
        ("Lookup would require extrapolation 0.5s into the past.  Requested time 1 but the "
         "earliest data is at time 1.5", BackwardExtrapolationException),
        ("Lookup would require extrapolation at time 1.000000000, but only time 2.000000000 "
         "is in the buffer", NoDataForExtrapolationException),
        ("", NoDataForExtrapolationException),
    ],
)
def test_a_message_keeps_its_text_and_gets_its_class(
    message: str, cls: type[ExtrapolationException]
) -> None:
    exc = extrapolation_exception(message)
    assert type(exc) is cls and str(exc) == message
