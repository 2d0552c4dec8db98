"""The laws of a decoder that shares and refills its TransformStampeds by position
(``tfbus.codecs._cwire``, ROS 1's wire and tfbus's own): the objects of a message nobody
holds any more are refilled, and nothing a caller holds ever changes. The two wires' tests
call these with their own decode of a message (``tests/codecs/test_codec_ros1.py``,
``tests/codecs/test_codec_native_compiled.py``), which checks each decode against that
wire's reference decoder."""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence

from hypothesis import strategies as st

from tfbus.messages import Quaternion, Transform, TransformStamped, Vector3

Decode = Callable[[Sequence[tuple[float, ...]], int], Sequence[TransformStamped]]
"""``decode(values, stamp)``: the decoded transforms of a message of ``map -> c<k>``
transforms, one per 7-tuple of values (translation x y z, rotation x y z w), all stamped
``stamp`` (whole seconds or nanoseconds: the wire's choice), checked against the wire's
reference decoder."""


def bits(obj: object) -> bytes:
    """What ``obj`` (a float, a TransformStamped, a Transform, a Vector3, a Quaternion, or
    a sequence of TransformStampeds) holds, every float by its bits."""
    if isinstance(obj, float):
        return struct.pack("<d", obj)
    if isinstance(obj, TransformStamped):
        return (struct.pack("<q", obj.header.stamp.ns) + obj.header.frame_id.encode() + b"\0"
                + obj.child_frame_id.encode() + b"\0" + bits(obj.transform))
    if isinstance(obj, Transform):
        return struct.pack("<7d", *obj.translation, *obj.rotation)
    if isinstance(obj, (Vector3, Quaternion)):
        return struct.pack(f"<{len(obj)}d", *obj)
    assert isinstance(obj, (list, tuple))
    return b"".join(bits(t) for t in obj)


def check_refilled_and_held(decode: Decode, reuses: bool) -> None:
    """Values that change every message cannot be shared, but the objects of the message
    decoded two messages earlier that nothing references any more are refilled in place
    (when ``reuses``: the same TransformStamped, Transform, Vector3 and Quaternion, with
    the new values). A transform, a Transform, a Vector3, a Quaternion or a float a
    caller still holds keeps its values, and a new object takes its place."""

    def moving(j: int) -> Sequence[TransformStamped]:
        return decode([(float(k + j), 0.5 * j, -1.0, 0.0, 0.0, 0.01 * j, 1.0)
                       for k in range(5)], j)

    first = moving(1)
    ids = [(id(t), id(t.transform), id(t.transform.translation), id(t.transform.rotation))
           for t in first]
    del first
    second = moving(2)  # the previous message is usually still held (an async for)
    third = moving(3)
    if reuses:
        assert [(id(t), id(t.transform), id(t.transform.translation),
                 id(t.transform.rotation)) for t in third] == ids
    assert second[0].transform.translation == Vector3(2.0, 1.0, -1.0)
    # Held parts, one per position: a whole transform, a Transform, a Vector3, a
    # Quaternion, a float.
    ts, tf = third[0], third[1].transform
    vec, rot = third[2].transform.translation, third[3].transform.rotation
    z = third[4].transform.rotation.z
    held = (ts, tf, vec, rot, z)
    snapshot = [bits(part) for part in held]
    del second, third
    for j in range(4, 9):
        out = moving(j)
        assert [bits(t.transform) for t in out] == [
            struct.pack("<7d", k + j, 0.5 * j, -1.0, 0.0, 0.0, 0.01 * j, 1.0) for k in range(5)]
        assert [bits(part) for part in held] == snapshot
        assert out[0] is not ts and out[1].transform is not tf
        assert out[2].transform.translation is not vec
        assert out[3].transform.rotation is not rot
        assert out[4].transform.rotation.z is not z
        del out


Step = tuple[Sequence[tuple[float, bool]], int, Sequence[int]]
"""One message of :func:`check_nothing_held_changes`: 28 ``(value, repeats)`` pairs, the
number of transforms (0..4) and what to keep."""


def steps(values: Sequence[float]) -> st.SearchStrategy[list[Step]]:
    """1-12 steps of :func:`check_nothing_held_changes`, each value one of ``values``.
    A step's 28 pairs are drawn as 28 bytes (one draw instead of 56, a tenth of the
    generation time): byte ``b`` is ``values[b % len(values)]``, repeated when
    ``b // len(values)`` is odd."""
    k = len(values)
    pairs = st.binary(min_size=28, max_size=28).map(
        lambda data: [(values[b % k], bool((b // k) % 2)) for b in data])
    return st.lists(st.tuples(pairs, st.integers(0, 4), st.lists(st.integers(0, 5), max_size=4)),
                    min_size=1, max_size=12)


def check_nothing_held_changes(
    decode: Decode, steps: Sequence[Step]
) -> None:
    """Messages of ``n`` transforms (each step: 28 ``(value, repeats)`` pairs, ``n`` in
    0..4, and what to keep); a value that does not repeat is moved by the step's number.
    After each decode the caller keeps some of what it got (``0``: the whole message;
    ``1``-``5``: a transform, a transform, a Transform, a Vector3, a Quaternion, a float
    of the transform at that index) and drops the rest: nothing kept ever changes."""
    kept: list[tuple[object, bytes]] = []
    for stamp, (values, n, keep) in enumerate(steps, start=1):
        vals = [v if same else v + stamp for v, same in values]
        out = decode([tuple(vals[7 * i: 7 * i + 7]) for i in range(n)], stamp)
        for choice in keep:
            if choice == 0 or not out:
                kept.append((out, bits(out)))
                continue
            ts = out[choice % len(out)]
            part = [ts, ts, ts.transform, ts.transform.translation, ts.transform.rotation,
                    ts.transform.rotation.w][choice]
            kept.append((part, bits(part)))
        del out
        assert all(bits(obj) == snap for obj, snap in kept)
