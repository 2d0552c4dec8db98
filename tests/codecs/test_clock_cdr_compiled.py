"""The compiled reader of a ROS 2 ``rosgraph_msgs/msg/Clock`` sample
(``tfbus.codecs._cwire._clock_from_cdr``, what ``decode_clock`` and the ROS 2 transport's
receiving thread try first for every ``/clock`` sample): wherever it answers, the
:mod:`struct` reading (``_decode_clock_struct``) gives the same Clock; everything that
reading refuses, and anything that is not ``bytes``, it leaves to that reading (None), so
``decode_clock`` answers or raises as the struct reading does. Checked on rosbags' and
tfbus's own encodings, every encapsulation and byte order, the ends of the value ranges
and damaged samples (``fuzz_support.mutants``). No I/O."""

from __future__ import annotations

import struct

import pytest
from fuzz_support import mutants
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from tfbus.codecs import cdr
from tfbus.errors import WireDecodeError
from tfbus.messages import Clock
from tfbus.time import NSEC_PER_SEC, Time

compiled = cdr._compiled_clock
pytestmark = pytest.mark.skipif(
    compiled is None, reason="the compiled core is not built here (pure-Python install)"
)
PROPERTY = settings(max_examples=300, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow])
SECS = st.integers(0, 2**31 - 1) | st.sampled_from([0, 1, 2**31 - 1, 1_700_000_000])
NANOS = st.integers(0, NSEC_PER_SEC - 1) | st.sampled_from([0, NSEC_PER_SEC - 1])
# encapsulation kind -> struct format of (int32 sec, uint32 nanosec)
KINDS = {0x0001: "<iI", 0x0007: "<iI", 0x0000: ">iI", 0x0006: ">iI"}


def _fast(data: object) -> Clock | None:
    assert compiled is not None
    return compiled(data)


def _struct(data: bytes) -> Clock | WireDecodeError:
    try:
        return cdr._decode_clock_struct(data)
    except WireDecodeError as exc:
        return exc


@PROPERTY
@given(sec=SECS, nanosec=NANOS, kind=st.sampled_from(sorted(KINDS)),
       options=st.binary(min_size=2, max_size=2), tail=st.binary(max_size=4))
@example(sec=0, nanosec=0, kind=0x0001, options=b"\0\0", tail=b"")
@example(sec=2**31 - 1, nanosec=NSEC_PER_SEC - 1, kind=0x0000, options=b"\0\0", tail=b"")
def test_every_encapsulation_is_read_in_c_to_the_struct_readings_clock(
    sec: int, nanosec: int, kind: int, options: bytes, tail: bytes
) -> None:
    data = kind.to_bytes(2, "big") + options + struct.pack(KINDS[kind], sec, nanosec) + tail
    want = Clock(Time.from_ns(sec * NSEC_PER_SEC + nanosec))
    got = _fast(data)
    assert got == want and type(got) is Clock and type(got.clock) is Time
    assert got.clock.ns == sec * NSEC_PER_SEC + nanosec
    assert _struct(data) == want
    assert cdr.decode_clock(data) == want


def test_what_the_codec_writes_is_read_in_c() -> None:
    clock = Clock(Time(1_700_000_123, 456_789_012))
    assert _fast(cdr.encode_clock(clock)) == clock


@pytest.mark.parametrize(("data", "why"), [
    (b"", "too short"),
    (b"\x00\x01\x00\x00" + struct.pack("<i", 5), "too short"),
    (b"\x00\x02\x00\x00" + struct.pack("<iI", 5, 7), "encapsulation 0x0002"),
    (b"\x01\x01\x00\x00" + struct.pack("<iI", 5, 7), "encapsulation 0x0101"),
    (b"\x00\x01\x00\x00" + struct.pack("<iI", -1, 7), "clock.sec=-1"),
    (b"\x00\x00\x00\x00" + struct.pack(">iI", -(2**31), 7), "clock.sec=-2147483648"),
    (b"\x00\x07\x00\x00" + struct.pack("<iI", 5, NSEC_PER_SEC), "clock.nanosec=1000000000"),
    (b"\x00\x06\x00\x00" + struct.pack(">iI", 5, 2**32 - 1), "clock.nanosec=4294967295"),
])
def test_what_the_struct_reading_refuses_is_left_to_it(data: bytes, why: str) -> None:
    assert _fast(data) is None
    with pytest.raises(WireDecodeError, match=why):
        cdr.decode_clock(data)


def test_a_sample_that_is_not_bytes_is_left_to_the_struct_reading() -> None:
    raw = b"\x00\x01\x00\x00" + struct.pack("<iI", 5, 7)
    for data in (memoryview(raw), bytearray(raw)):
        assert _fast(data) is None
        assert cdr.decode_clock(memoryview(data)) == Clock(Time(5, 7))


@PROPERTY
@given(data=st.data())
def test_damaged_samples_are_read_as_the_struct_reading_reads_them_or_left_to_it(
    data: st.DataObject,
) -> None:
    kind = data.draw(st.sampled_from(sorted(KINDS)))
    valid = kind.to_bytes(2, "big") + b"\0\0" + struct.pack(
        KINDS[kind], data.draw(SECS), data.draw(NANOS))
    damaged = data.draw(mutants(valid))
    fast, slow = _fast(damaged), _struct(damaged)
    if fast is None:
        assert isinstance(slow, WireDecodeError), (damaged.hex(), slow)
    else:
        assert fast == slow, (damaged.hex(), fast, slow)
    if isinstance(slow, WireDecodeError):
        with pytest.raises(WireDecodeError, match=str(slow).split(":")[0]):
            cdr.decode_clock(damaged)
    else:
        assert cdr.decode_clock(damaged) == slow
