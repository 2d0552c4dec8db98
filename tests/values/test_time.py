"""Tests for tfbus.time: integer-nanosecond Time and Duration."""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfbus.time import NSEC_PER_SEC, TIME_MAX_NS, Duration, Time, format_stamp, seconds_to_ns

EPOCH_NS = 1_700_000_000_123_456_789  # a 2023 wall-clock stamp with every digit significant

FAST = settings(max_examples=80, deadline=None)
stamps = st.integers(0, 2**63 - 1)
spans = st.integers(-(2**62), 2**62)


# --------------------------------------------------------------------------- Time


def test_constructors_agree() -> None:
    assert Time().ns == 0
    assert Time(3).ns == 3 * NSEC_PER_SEC
    assert Time(sec=3, nanosec=5).ns == 3_000_000_005
    assert Time(1, 2_000_000_000) == Time(3)  # nanosec may exceed a second, as it adds up
    assert Time.from_ns(3_000_000_005) == Time(3, 5)
    assert Time.from_sec(1.5) == Time(1, 500_000_000)
    assert Time(1.5) == Time(1, 500_000_000)
    assert Time.from_sec(0.25).to_sec() == 0.25


def test_sec_nanosec_fields() -> None:
    t = Time.from_ns(EPOCH_NS)
    assert (t.sec, t.nanosec) == (1_700_000_000, 123_456_789)
    assert Time(0, 999_999_999).sec == 0


def test_epoch_sized_ns_are_exact() -> None:
    t = Time(1_700_000_000, 123_456_789)
    assert t.ns == EPOCH_NS
    assert isinstance(t.ns, int)
    assert Time.from_ns(EPOCH_NS).ns == EPOCH_NS
    assert (t + Duration(0, 1)).ns == EPOCH_NS + 1
    assert (Time.from_ns(EPOCH_NS + 1) - t) == Duration.from_ns(1)
    assert Time.from_ns(EPOCH_NS + 1) != t
    # A float cannot hold it: to_sec() is the nearest double, not exact.
    assert t.to_sec() == EPOCH_NS / NSEC_PER_SEC
    assert round(t.to_sec() * NSEC_PER_SEC) != EPOCH_NS


def test_from_sec_is_within_float_precision_at_epoch_scale() -> None:
    t = Time.from_sec(Time.from_ns(EPOCH_NS).to_sec())
    # float64 spacing near 1.7e9 s is 238 ns.
    assert abs(t.ns - EPOCH_NS) < 512


def test_from_sec_rounds_to_nearest_nanosecond() -> None:
    x = 1_700_000_000.123456789
    assert Time.from_sec(x).ns == round(Fraction(x) * NSEC_PER_SEC)


def test_negative_times_raise() -> None:
    with pytest.raises(ValueError, match="negative"):
        Time(-1)
    with pytest.raises(ValueError, match="negative"):
        Time(0, -1)
    with pytest.raises(ValueError, match="negative"):
        Time.from_ns(-1)
    with pytest.raises(ValueError, match="negative"):
        Time.from_sec(-0.5)
    with pytest.raises(ValueError, match="negative"):
        Time(1) - Duration(2)
    assert Time(1, -1) == Time(0, 999_999_999)  # only the total has to be >= 0


def test_is_zero_means_latest() -> None:
    assert Time().is_zero()
    assert Time(0, 0).is_zero()
    assert not Time(0, 1).is_zero()


def test_ordering_and_hashing() -> None:
    a, b = Time(1), Time(1, 1)
    assert a < b
    assert a <= b
    assert b > a
    assert b >= a
    assert a <= Time(1)
    assert a >= Time(1)
    assert sorted([b, a, Time(0)]) == [Time(0), a, b]
    assert max(a, b) is b
    assert {Time(1), Time.from_ns(NSEC_PER_SEC), Time(1.0)} == {a}
    assert Time(1) != Duration(1)
    assert Time(1) != NSEC_PER_SEC


def test_arithmetic_with_duration() -> None:
    t = Time(10)
    assert t + Duration(1, 5) == Time(11, 5)
    assert Duration(1, 5) + t == Time(11, 5)
    assert t - Duration(0, 1) == Time(9, 999_999_999)
    assert t - Time(4) == Duration(6)
    assert Time(4) - t == Duration(-6)
    assert isinstance(t - Time(4), Duration)
    assert isinstance(t - Duration(4), Time)
    with pytest.raises(TypeError):
        t + t  # type: ignore[operator]
    with pytest.raises(TypeError):
        t + 1  # type: ignore[operator]


def test_immutable() -> None:
    t = Time(1)
    with pytest.raises(AttributeError):
        t.ns = 5  # type: ignore[misc]
    with pytest.raises(AttributeError):
        t._extra = 1  # type: ignore[attr-defined]


def test_repr() -> None:
    assert repr(Time.from_ns(EPOCH_NS)) == "Time(sec=1700000000, nanosec=123456789)"
    assert repr(Time()) == "Time(sec=0, nanosec=0)"
    assert eval(repr(Time.from_ns(EPOCH_NS))) == Time.from_ns(EPOCH_NS)


def test_numpy_scalars_accepted() -> None:
    assert Time(np.float64(1.5)) == Time(1, 500_000_000)
    assert Time.from_ns(np.int64(EPOCH_NS)).ns == EPOCH_NS
    assert type(Time.from_ns(np.int64(5)).ns) is int


def test_numpy_uint32_seconds() -> None:
    with np.errstate(over="ignore"):
        assert Time(np.uint32(1_700_000_000)) == Time(1_700_000_000)


def test_ordering_against_other_types_raises_type_error() -> None:
    with pytest.raises(TypeError):
        Time(1) < 5  # type: ignore[operator]  # noqa: B015
    with pytest.raises(TypeError):
        Time(1) < Duration(2)  # type: ignore[operator]  # noqa: B015


@FAST
@given(stamps)
def test_ns_round_trip(ns: int) -> None:
    t = Time.from_ns(ns)
    assert t.ns == ns
    assert Time(t.sec, t.nanosec) == t
    assert 0 <= t.nanosec < NSEC_PER_SEC
    assert eval(repr(t)) == t


@FAST
@given(stamps, stamps)
def test_ordering_matches_ns(a: int, b: int) -> None:
    ta, tb = Time.from_ns(a), Time.from_ns(b)
    assert (ta < tb) == (a < b)
    assert (ta == tb) == (a == b)
    assert (ta >= tb) == (a >= b)
    assert (hash(ta) == hash(tb)) or a != b


@FAST
@given(stamps, spans)
def test_add_then_subtract(ns: int, d: int) -> None:
    t, dur = Time.from_ns(ns), Duration.from_ns(d)
    if not 0 <= ns + d <= 2**63 - 1:  # Time is int64 ns, never negative
        with pytest.raises(ValueError):
            t + dur
        return
    assert (t + dur).ns == ns + d
    assert (t + dur) - dur == t
    assert (t + dur) - t == dur


# --------------------------------------------------------------------------- Duration


def test_duration_basics() -> None:
    assert Duration().ns == 0
    assert Duration(2, 5).ns == 2_000_000_005
    assert Duration(-1).ns == -NSEC_PER_SEC
    assert Duration.from_sec(-1.5).ns == -1_500_000_000
    assert Duration.from_ns(7).to_sec() == 7e-9
    assert Duration(1) + Duration(0, 1) == Duration(1, 1)
    assert Duration(1) - Duration(2) == Duration(-1)
    assert -Duration(1) == Duration(-1)
    assert abs(Duration(-3)) == Duration(3)
    assert Duration(2) * 1.5 == Duration(3)
    assert 0.5 * Duration(1) == Duration(0, 500_000_000)
    assert Duration(1) < Duration(2) <= Duration(2) < Duration(3) >= Duration(3) > Duration(-1)
    assert {Duration(1), Duration.from_ns(NSEC_PER_SEC)} == {Duration(1)}
    with pytest.raises(TypeError):
        Duration(1) * Duration(1)  # type: ignore[operator]


def test_duration_repr() -> None:
    # nanosec stays in [0, 1e9), as in builtin_interfaces/Duration.
    assert repr(Duration(-1, -5)) == "Duration(sec=-2, nanosec=999999995)"
    assert eval(repr(Duration(-1, -5))) == Duration(-1, -5)
    assert repr(Duration(1, 5)) == "Duration(sec=1, nanosec=5)"


# --------------------------------------------------------------------------- conversion


@FAST
@given(st.floats(allow_nan=False, allow_infinity=False, min_value=-1e12, max_value=1e12))
def test_seconds_to_ns_is_exact_rounding_of_the_floats_value(sec: float) -> None:
    assert seconds_to_ns(sec) == round(Fraction(sec) * NSEC_PER_SEC)


def test_seconds_to_ns_accepts_every_real_kind() -> None:
    assert seconds_to_ns(3) == 3 * NSEC_PER_SEC
    assert seconds_to_ns(np.int64(3)) == 3 * NSEC_PER_SEC
    assert seconds_to_ns(np.uint32(4_000_000_000)) == 4_000_000_000 * NSEC_PER_SEC
    assert seconds_to_ns(np.float32(0.5)) == 500_000_000
    assert seconds_to_ns(np.float64(1_700_000_000.123456789)) == round(
        Fraction(1_700_000_000.123456789) * NSEC_PER_SEC
    )
    assert seconds_to_ns(Fraction(1, 3)) == 333_333_333  # type: ignore[arg-type]
    assert seconds_to_ns(Fraction(5, 2 * NSEC_PER_SEC)) == 2  # type: ignore[arg-type]
    assert seconds_to_ns(Duration(2, 7)) == 2_000_000_007
    # 0.1 s is not exactly representable: the float's value is just above 0.1.
    assert seconds_to_ns(0.1) == 100_000_000
    # A float product rounds first (off by 32 ns here); the exact conversion does not.
    x = 1700000000.1343641
    assert round(x * 1e9) == 1_700_000_000_134_364_160
    assert seconds_to_ns(x) == 1_700_000_000_134_364_128 == round(Fraction(x) * NSEC_PER_SEC)


def test_seconds_to_ns_checks_types_first_and_names_the_argument() -> None:
    class Poison(str):
        def __mul__(self, other: object) -> str:
            raise AssertionError("multiplied before the type check")

    for bad in (Poison("10"), "10", None, True, 1j, [1.0], b"1"):
        with pytest.raises(TypeError, match=r"cache_time must be a number of seconds"):
            seconds_to_ns(bad, name="cache_time")  # type: ignore[arg-type]
    for bad_value in (math.inf, -math.inf, math.nan, np.float64("nan")):
        with pytest.raises(ValueError, match="period must be finite"):
            seconds_to_ns(bad_value, name="period")


def test_time_and_duration_refuse_strings_and_bools() -> None:
    for bad in ("1", True, None):
        with pytest.raises(TypeError):
            Time(bad)  # type: ignore[arg-type]
        with pytest.raises(TypeError):
            Duration(bad)  # type: ignore[arg-type]
        with pytest.raises(TypeError):
            Time.from_sec(bad)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="nanosec must be an integer"):
        Time(1, 0.5)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="nanosec must be an integer"):
        Time(1, False)
    with pytest.raises(TypeError):
        Duration(1) * "3"  # type: ignore[operator]
    with pytest.raises(TypeError):
        Duration(1) * True


def test_duration_multiplication_is_exact() -> None:
    d = Duration.from_ns(1_700_000_000_123_456_789)
    assert (d * 0.5).ns == 850_000_000_061_728_394  # ...394.5 rounds half to even
    assert (d * 3).ns == 3 * d.ns
    assert (d * Fraction(1, 3)).ns == round(Fraction(d.ns, 3))  # type: ignore[operator]
    assert (d * np.float64(0.25)).ns == round(Fraction(d.ns) / 4)
    with pytest.raises(ValueError, match="not finite"):
        d * math.inf


# --------------------------------------------------------------------------- formatting


def test_format_stamp_is_exact_sec_dot_nine_digit_nanosec() -> None:
    assert format_stamp(Time.from_ns(EPOCH_NS)) == "1700000000.123456789"
    assert format_stamp(Time(0)) == "0.000000000"
    assert format_stamp(Time(0, 5)) == "0.000000005"
    assert format_stamp(Time.from_ns(TIME_MAX_NS)) == "9223372036.854775807"
    assert format_stamp(EPOCH_NS) == "1700000000.123456789"
    assert format_stamp(np.int64(EPOCH_NS)) == "1700000000.123456789"  # type: ignore[arg-type]
    assert format_stamp(Duration.from_ns(-500_000_000)) == "-0.500000000"
    assert format_stamp(Duration(-2, 1)) == "-1.999999999"
    # a float print of the same stamp is wrong in the last digits
    assert f"{Time.from_ns(EPOCH_NS).to_sec():.9f}" != format_stamp(Time.from_ns(EPOCH_NS))
    for bad in (1.5, "1", True, None):
        with pytest.raises(TypeError, match="format_stamp takes"):
            format_stamp(bad)  # type: ignore[arg-type]


@FAST
@given(spans)
def test_format_stamp_round_trips_through_fraction(ns: int) -> None:
    assert Fraction(format_stamp(ns)) * NSEC_PER_SEC == ns


def test_time_is_an_opaque_int_to_serialisers_not_a_record() -> None:
    """Time stays a plain class (not a dataclass): msgspec, which the Zenoh wire uses,
    would otherwise write ``{"_ns": n}`` and skip the wire's stamp checks."""
    msgspec = pytest.importorskip("msgspec")
    assert not dataclasses.is_dataclass(Time) and not dataclasses.is_dataclass(Duration)
    enc = msgspec.msgpack.Encoder(enc_hook=lambda t: t.ns)
    assert enc.encode(Time.from_ns(EPOCH_NS)) == enc.encode(EPOCH_NS)
    assert not hasattr(Time(1), "__dict__")  # slots: one int per stamp
