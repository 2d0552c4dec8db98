"""ROS 1 ``TFMessage`` writing, in C (``tfbus.codecs._cwire._tf_to_ros1``, with the
compiled core, for the common form of a message) and by :mod:`struct` (everything else,
and every message without the compiled core): rosbags' ``serialize_ros1`` bytes, bit for
bit (``TFCodec.encode_generic`` is that reference), and errors that name the transform."""

from __future__ import annotations

import struct
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfbus.errors import WireEncodeError
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import Time

pytest.importorskip("rosbags")
from tfbus.codecs import ros1  # needs rosbags (checked above)
from tfbus.codecs.ros1 import TFCodec, encode_tf

COMPILED = ros1._compiled_encode
"""The compiled writer, or None (a pure-Python install or ``TFBUS_PURE_PYTHON``)."""


def _struct_only(fn: Any, *args: Any) -> Any:
    """``fn(*args)`` with the compiled writer switched off: the :mod:`struct` writer's
    bytes (what a pure-Python install writes)."""
    saved = ros1._compiled_encode
    ros1._compiled_encode = None
    try:
        return fn(*args)
    finally:
        ros1._compiled_encode = saved


@pytest.fixture
def struct_writer(monkeypatch: pytest.MonkeyPatch) -> None:
    """The :mod:`struct` writer alone (the compiled one switched off)."""
    monkeypatch.setattr(ros1, "_compiled_encode", None)


def _ts(parent: Any, child: Any, ns: int, v: tuple[Any, ...]) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), parent), child, Transform(Vector3(*v[:3]), Quaternion(*v[3:]))
    )


def test_one_transform_is_the_roscpp_layout() -> None:
    """count, then seq 0, secs, nsecs, frame_id, child_frame_id, seven float64 (LE)."""
    raw = TFCodec().encode([_ts("a", "bc", 3 * 10**9 + 5, (1, 2, 3, 4, 5, 6, 7))])
    assert raw == (
        b"\x01\x00\x00\x00"  # one transform
        + b"\x00\x00\x00\x00\x03\x00\x00\x00\x05\x00\x00\x00"  # seq 0, 3 s, 5 ns
        + b"\x01\x00\x00\x00a"
        + b"\x02\x00\x00\x00bc"
        + struct.pack("<7d", 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0)
    )
    assert encode_tf([]) == b"\x00\x00\x00\x00"


_floats = st.floats(width=64)  # NaN, infinities and -0.0 included: compared as bytes
_ids = st.text(max_size=12)
_CODEC = TFCodec()
"""One codec for every example: a ``TFCodec`` holds only its rosbags typestore, which
compiles its (de)serialisers on first use (half a second each time a codec is made)."""


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(
            _ids,
            _ids,
            st.integers(min_value=0, max_value=(2**31) * 10**9 - 1),
            st.tuples(*[_floats] * 7),
        ),
        max_size=20,
    )
)
def test_struct_writer_equals_rosbags_bit_for_bit(
    items: list[tuple[str, str, int, tuple[float, ...]]],
) -> None:
    codec = _CODEC
    transforms = [_ts(p, c, ns, v) for p, c, ns, v in items]
    reference = codec.encode_generic(transforms)
    framed = len(reference).to_bytes(4, "little") + reference  # TCPROS: u32 length first
    for writer in (lambda fn, *args: fn(*args), _struct_only):
        assert writer(codec.encode, transforms) == reference
        assert writer(codec.encode, tuple(transforms)) == reference
        assert writer(codec.encode, iter(transforms)) == codec.encode_generic(iter(transforms))
        assert writer(codec.encode_framed, transforms) == framed
        assert writer(codec.encode_framed, iter(transforms)) == framed
    if COMPILED is not None:  # the common form: written in C, not handed to struct
        assert COMPILED(transforms, False) == reference
        assert COMPILED(tuple(transforms), True) == framed


def test_bad_fields_are_refused_naming_the_transform() -> None:
    codec = TFCodec()
    good = _ts("map", "a", 1, (0, 0, 0, 0, 0, 0, 1))
    with pytest.raises(WireEncodeError, match=r"transforms\[1\] \(child_frame_id 'b'\)"):
        codec.encode([good, _ts(7, "b", 1, (0, 0, 0, 0, 0, 0, 1))])
    with pytest.raises(WireEncodeError, match=r"transforms\[2\] \(child_frame_id 'c'\)"):
        codec.encode([good, good, _ts("map", "c", 1, ("x", 0, 0, 0, 0, 0, 1))])
    with pytest.raises(WireEncodeError, match=r"transforms\[0\] \(child_frame_id 'd'\)"):
        codec.encode([_ts("\udc80", "d", 1, (0, 0, 0, 0, 0, 0, 1))])  # not UTF-8
    with pytest.raises(WireEncodeError, match=r"transforms\[1\] \(child_frame_id None\)"):
        codec.encode([good, object()])  # type: ignore[list-item]
    with pytest.raises(WireEncodeError, match=r"2147483648000000000 ns of 'e' is outside"):
        codec.encode([good, _ts("map", "e", 2**31 * 10**9, (0, 0, 0, 0, 0, 0, 1))])


@settings(max_examples=200, deadline=None)
@given(_ids, _ids, st.integers(min_value=0, max_value=(2**31) * 10**9 - 1),
       st.tuples(*[_floats] * 7))  # fmt: skip
def test_one_transform_from_the_frame_pair_cache_equals_rosbags(
    parent: str, child: str, ns: int, v: tuple[float, ...]
) -> None:
    """A one-transform message (a broadcaster's tick), as a list and as a tuple, first
    and then with its frame pair's id bytes already kept: rosbags' bytes every time."""
    codec = TFCodec()
    one = _ts(parent, child, ns, v)
    reference = codec.encode_generic([one])
    framed = len(reference).to_bytes(4, "little") + reference  # TCPROS: u32 length first
    for writer in (lambda fn, *args: fn(*args), _struct_only):
        assert writer(codec.encode, [one]) == reference
        assert writer(codec.encode, (one,)) == reference
        assert writer(codec.encode, [one]) == reference
        assert writer(codec.encode_framed, [one]) == framed
        assert writer(codec.encode_framed, (one,)) == framed


def _c_calls(fn: Any, *args: Any) -> tuple[Any, list[str]]:
    """``fn(*args)`` and the C functions it called, in order (``sys.setprofile``)."""
    import sys

    c_calls: list[str] = []

    def profile(frame: Any, event: str, arg: Any) -> None:
        if event == "c_call":
            c_calls.append(getattr(arg, "__qualname__", repr(arg)))

    sys.setprofile(profile)
    try:
        result = fn(*args)
    finally:
        sys.setprofile(None)
    c_calls.remove("setprofile")
    return result, c_calls


def test_one_transform_encodes_its_frame_ids_once_per_frame_pair(struct_writer: None) -> None:
    """A broadcaster's tick re-sends the same frame pair: after the first message the
    ids are not re-encoded (no ``str.encode``) and the message is two ``struct`` packs
    and one join (C calls counted with the profiler: 6 for the whole tick, at most 8
    allowed, where encoding the ids, four packs and six appends took 15)."""
    codec = TFCodec()
    first = _ts("world", "turtle_one_tick", 1_700_000_000_123_456_789,
                (1.0, 2.0, 0.0, 0.0, 0.0, 0.3, 0.95))  # fmt: skip
    later = first._replace(header=Header(Time.from_ns(1_700_000_000_133_456_789), "world"))
    codec.encode([first])
    raw, c_calls = _c_calls(codec.encode, [later])
    assert raw == codec.encode_generic([later])
    assert "str.encode" not in c_calls, c_calls
    assert len(c_calls) <= 8, c_calls


def test_a_ticks_tcpros_frame_is_one_join_with_its_length(struct_writer: None) -> None:
    """A broadcaster's tick framed for TCPROS (``encode_framed``, what the ROS 1
    publisher writes): the length prefix is packed with the header (one ``struct``
    call) inside the same join, not a second pack and a copy of the whole message (C
    calls counted with the profiler: 6, as for the bare message; the old
    ``encode`` + ``frame`` took 8). The bytes are rosbags' message after its
    ``uint32`` length."""
    codec = TFCodec()
    first = _ts("base_link", "base_laser", 1_700_000_000_123_456_789,
                (0.1, 0.0, 0.2, 0.0, 0.0, 0.0, 1.0))  # fmt: skip
    later = first._replace(header=Header(Time.from_ns(1_700_000_000_133_456_789), "base_link"))
    codec.encode_framed([first])
    raw, c_calls = _c_calls(codec.encode_framed, [later])
    reference = codec.encode_generic([later])
    assert raw == len(reference).to_bytes(4, "little") + reference
    assert len(reference) == 4 + 16 + 9 + 4 + 10 + 56
    assert len(c_calls) <= 6, c_calls
    assert c_calls.count("Struct.pack") == 2, c_calls


def test_frame_pair_cache_is_bounded(struct_writer: None) -> None:
    """Many distinct frame pairs (a peer naming a new child every message) keep at most
    ``_PAIR_BYTES_MAX`` pairs' bytes, and every message is still rosbags' bytes."""
    from tfbus.codecs import ros1

    codec = TFCodec()
    for i in range(ros1._PAIR_BYTES_MAX + 500):
        one = _ts("map", f"child_{i}", i, (0, 0, 0, 0, 0, 0, 1))
        raw = codec.encode([one])
        if i % 997 == 0:
            assert raw == codec.encode_generic([one])
        assert len(ros1._pair_bytes) <= ros1._PAIR_BYTES_MAX


@pytest.mark.skipif(COMPILED is None, reason="the compiled writer is built with the "
                    "compiled core only (a pure-Python install, or TFBUS_PURE_PYTHON)")
def test_the_compiled_writer_hands_back_what_is_not_the_common_form() -> None:
    """What the C writer does not write (values that are ints or numpy floats, an id
    with a lone surrogate, a stamp ROS 1 cannot carry, a subclass of the message
    classes, a generator) is None from it: the struct writer writes it, converting with
    ``float()``, or raises the error naming the transform."""
    import numpy as np

    codec = TFCodec()
    good = _ts("map", "a", 5, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    assert COMPILED([good], False) == codec.encode_generic([good])
    assert COMPILED([], True) == b"\x04\x00\x00\x00\x00\x00\x00\x00"

    class _Sub(TransformStamped):
        pass

    others: list[Any] = [
        [good, _ts("map", "b", 5, (0, 0, 0, 0, 0, 0, 1))],
        [_ts("map", "c", 5, (np.float64(0.5), 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))],
        [_ts("map", "\udc80", 5, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))],
        [_ts("map", "d", 2**31 * 10**9, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))],
        [_Sub(*good)],
        iter([good]),
        {"a": good}.values(),
    ]
    for held in (1.5, -1, 2**63):  # a Time holding what Time never makes
        stamp = Time.__new__(Time)
        stamp._ns = held
        others.append([TransformStamped(Header(stamp, "map"), "e", good.transform)])
    for message in others:
        assert COMPILED(message, False) is None, message
    for message in others[:2] + others[4:5]:  # written by struct, as rosbags does
        assert codec.encode(message) == codec.encode_generic(message)
    for message in others[2:4]:
        with pytest.raises(WireEncodeError, match=r"transforms\[0\]|outside ROS 1's time"):
            codec.encode(message)
