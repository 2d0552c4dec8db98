"""The compiled reader of a ``Clock`` payload's stamp on tfbus's own wire
(``tfbus.codecs._cwire._clock_stamp_native``, what ``clock_stamp`` tries first in Zenoh's
thread for every ``/clock`` sample a ``SimClock`` follows): wherever it gives a stamp,
msgspec's typed reading (``_clock_stamp_schema``) gives the same one; anything else it
leaves to that reading (-1), so ``clock_stamp`` always answers what the schema answers.
Checked on what tfbus writes, on damaged payloads and on other writers' encodings. No
I/O."""

from __future__ import annotations

import struct

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

pytest.importorskip("zenoh")

from tfbus.codecs import native as wire
from tfbus.messages import Clock
from tfbus.time import TIME_MAX_NS, Time
from tfbus.transports.zenoh.transport import (
    _clock_stamp_schema,
    clock_stamp,
)

compiled = wire._compiled_clock_stamp()
pytestmark = pytest.mark.skipif(
    compiled is None, reason="the compiled core is not built here (pure-Python install)"
)
PROPERTY = settings(max_examples=300, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow])
HEAD = bytes([wire.MAGIC, wire.WIRE_VERSION])
stamps = st.integers(0, TIME_MAX_NS) | st.sampled_from([0, 1, 127, 128, 2**32, TIME_MAX_NS])
ids = st.integers(1, 2**63 - 1) | st.sampled_from([1, 127, 128, 255, 256, 2**63 - 1])


def _fast(payload: bytes) -> int:
    assert compiled is not None
    return compiled(payload, wire.MAGIC, wire.WIRE_VERSION)


@PROPERTY
@given(ns=stamps, sender=ids, seq=ids)
@example(ns=0, sender=1, seq=1)
@example(ns=TIME_MAX_NS, sender=2**63 - 1, seq=2**63 - 1)
def test_what_tfbus_writes_is_read_in_c_to_the_schemas_stamp(ns: int, sender: int,
                                                             seq: int) -> None:
    payload = wire.WireCodec().encode(Clock(Time.from_ns(ns)), sender=sender, seq=seq)
    assert _fast(payload) == ns
    assert _clock_stamp_schema(payload) == ns
    assert clock_stamp(payload) == ns


@PROPERTY
@given(data=st.data())
def test_damaged_payloads_are_read_as_the_schema_reads_them_or_left_to_it(
    data: st.DataObject,
) -> None:
    payload = bytearray(wire.WireCodec().encode(
        Clock(Time.from_ns(data.draw(stamps))), sender=data.draw(ids), seq=data.draw(ids)))
    for _ in range(data.draw(st.integers(1, 3))):
        kind = data.draw(st.sampled_from(["flip", "cut", "extend", "set"]))
        if kind == "flip" and payload:
            i = data.draw(st.integers(0, len(payload) - 1))
            payload[i] ^= 1 << data.draw(st.integers(0, 7))
        elif kind == "cut":
            del payload[data.draw(st.integers(0, len(payload))):]
        elif kind == "extend":
            payload += data.draw(st.binary(min_size=1, max_size=8))
        elif payload:
            payload[data.draw(st.integers(0, len(payload) - 1))] = data.draw(
                st.integers(0, 255))
    damaged = bytes(payload)
    fast, schema = _fast(damaged), _clock_stamp_schema(damaged)
    assert fast == -1 or fast == schema, (damaged.hex(), fast, schema)
    assert clock_stamp(damaged) == schema


def _body(sender: bytes = b"\x05", seq: bytes = b"\x07", tag: bytes = b"\xa5Clock",
          stamp: bytes = b"\xcf" + struct.pack(">Q", 1_500_000_000), array: bytes = b"\x94",
          inner: bytes = b"\x91") -> bytes:
    return HEAD + array + sender + seq + tag + inner + stamp


def test_the_hand_built_plain_payload_is_read_in_c() -> None:
    assert _fast(_body()) == 1_500_000_000 == _clock_stamp_schema(_body())
    assert _fast(_body(stamp=b"\x00")) == 0


@pytest.mark.parametrize("payload", [
    _body(array=b"\xdc\x00\x04"),  # array 16
    _body(array=b"\xdd\x00\x00\x00\x04"),  # array 32
    _body(inner=b"\xdc\x00\x01"),
    _body(sender=b"\xcf" + struct.pack(">Q", 5)),  # uint 64 sender
    _body(seq=b"\xd3" + struct.pack(">q", 7)),  # int 64 sequence number
    _body(stamp=b"\xd2" + struct.pack(">i", 9)),  # int 32 stamp
    _body(stamp=b"\xcc\xff"),  # uint 8 stamp
])
def test_other_writers_encodings_read_as_the_schema_reads_them(payload: bytes) -> None:
    fast, schema = _fast(payload), _clock_stamp_schema(payload)
    assert schema is not None
    assert fast in (-1, schema)
    assert clock_stamp(payload) == schema


@pytest.mark.parametrize("payload", [
    b"", HEAD, bytes([wire.MAGIC, wire.WIRE_VERSION + 1]) + _body()[2:],
    bytes([0x00, wire.WIRE_VERSION]) + _body()[2:],
    _body(sender=b"\x00"), _body(seq=b"\x00"),  # sender / sequence number 0
    _body(sender=b"\xcf" + struct.pack(">Q", 2**63)),  # over 2**63 - 1
    _body(stamp=b"\xff"),  # a negative stamp (negative fixint)
    _body(stamp=b"\xcf" + struct.pack(">Q", 2**64 - 1)),
    _body(tag=b"\xa5clock"), _body(tag=b"\xa2tf"), _body(tag=b"\xd9\x05Clock"),
    _body(array=b"\x93"), _body(inner=b"\x92"), _body(inner=b"\x90"),
    _body() + b"\x00",  # a byte left over
    _body()[:-1],  # cut short
    _body(stamp=b"\xcb" + struct.pack(">d", 1.0)),  # a float for the stamp
])
def test_anything_else_is_left_to_the_schema(payload: bytes) -> None:
    schema = _clock_stamp_schema(payload)
    fast = _fast(payload)
    assert fast == -1 or fast == schema
    assert clock_stamp(payload) == schema
    if payload[:2] == HEAD and payload != _body(tag=b"\xd9\x05Clock"):
        # every one of these but the str 8 tag is refused by the schema too
        assert schema is None, payload.hex()
