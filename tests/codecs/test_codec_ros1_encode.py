"""ROS 1 ``TFMessage`` writing by :mod:`struct`: rosbags' ``serialize_ros1`` bytes, bit for
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
from tfbus.codecs.ros1 import TFCodec, encode_tf  # needs rosbags (checked above)


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
    assert codec.encode(transforms) == codec.encode_generic(transforms)
    assert codec.encode(iter(transforms)) == codec.encode_generic(iter(transforms))


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
