"""Tests for tfbus.messages: ROS-named, immutable value types."""

from __future__ import annotations

import pickle
from collections.abc import Callable
from typing import Any

import pytest

import tfbus
from tfbus.messages import (
    Header,
    Point,
    PointStamped,
    Pose,
    PoseStamped,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
    Vector3Stamped,
)
from tfbus.time import Time

ALL_TYPES = (
    Header,
    Point,
    PointStamped,
    Pose,
    PoseStamped,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
    Vector3Stamped,
)


def sample() -> TransformStamped:
    return TransformStamped(
        header=Header(stamp=Time(1_700_000_000, 5), frame_id="base_link"),
        child_frame_id="base_laser",
        transform=Transform(
            translation=Vector3(0.1, 0.0, 0.2), rotation=Quaternion(0.0, 0.0, 0.6, 0.8)
        ),
    )


def test_defaults() -> None:
    assert Vector3() == (0.0, 0.0, 0.0)
    assert Point() == (0.0, 0.0, 0.0)
    assert Quaternion() == (0.0, 0.0, 0.0, 1.0)  # identity, w last
    assert Transform() == (Vector3(), Quaternion())
    assert Pose() == (Point(), Quaternion())
    assert Header() == (Time(0), "")
    assert Header().stamp.is_zero()
    ts = TransformStamped()
    assert (ts.header, ts.child_frame_id, ts.transform) == (Header(), "", Transform())
    assert PointStamped() == (Header(), Point())
    assert PoseStamped() == (Header(), Pose())
    assert Vector3Stamped() == (Header(), Vector3())
    assert tuple(TFMessage().transforms) == ()


def test_ros_field_names_and_order() -> None:
    assert Vector3._fields == ("x", "y", "z")
    assert Point._fields == ("x", "y", "z")
    assert Quaternion._fields == ("x", "y", "z", "w")
    assert Transform._fields == ("translation", "rotation")
    assert Pose._fields == ("position", "orientation")
    assert Header._fields == ("stamp", "frame_id")
    assert TransformStamped._fields == ("header", "child_frame_id", "transform")
    assert PointStamped._fields == ("header", "point")
    assert PoseStamped._fields == ("header", "pose")
    assert Vector3Stamped._fields == ("header", "vector")
    assert TFMessage._fields == ("transforms",)
    q = Quaternion(1.0, 2.0, 3.0, 4.0)
    assert (q.x, q.y, q.z, q.w) == (1.0, 2.0, 3.0, 4.0)
    x, y, z = Vector3(1.0, 2.0, 3.0)
    assert (x, y, z) == (1.0, 2.0, 3.0)


def test_immutable() -> None:
    ts = sample()
    with pytest.raises(AttributeError):
        ts.child_frame_id = "other"  # type: ignore[misc]
    with pytest.raises(AttributeError):
        ts.transform.translation.x = 1.0  # type: ignore[misc]
    with pytest.raises(TypeError):
        ts.header.frame_id[0] = "x"  # type: ignore[index]
    moved = ts._replace(child_frame_id="other")
    assert moved.child_frame_id == "other"
    assert ts.child_frame_id == "base_laser"


def test_default_instances_are_shared_safely() -> None:
    # Shared default values are immutable, so sharing them cannot leak changes.
    assert Transform().translation is Transform().translation
    a = TransformStamped()
    b = a._replace(header=a.header._replace(frame_id="map"))
    assert TransformStamped().header.frame_id == ""
    assert b.header.frame_id == "map"


def test_equality_and_hashing() -> None:
    assert sample() == sample()
    assert hash(sample()) == hash(sample())
    assert len({sample(), sample()}) == 1
    assert sample() != sample()._replace(header=Header(Time(1_700_000_000, 6), "base_link"))
    assert hash(TFMessage(transforms=(sample(),))) == hash(TFMessage(transforms=(sample(),)))


def test_repr_is_readable_and_round_trips() -> None:
    ts = sample()
    text = repr(ts)
    assert text == (
        "TransformStamped(header=Header(stamp=Time(sec=1700000000, nanosec=5), "
        "frame_id='base_link'), child_frame_id='base_laser', "
        "transform=Transform(translation=Vector3(x=0.1, y=0.0, z=0.2), "
        "rotation=Quaternion(x=0.0, y=0.0, z=0.6, w=0.8)))"
    )
    namespace = {name: getattr(tfbus, name) for name in tfbus.__all__}
    assert eval(text, namespace) == ts
    for cls in ALL_TYPES:
        assert eval(repr(cls()), namespace) == cls()


def test_pickle_round_trip() -> None:
    msg = TFMessage(transforms=(sample(), sample()._replace(child_frame_id="b")))
    assert pickle.loads(pickle.dumps(msg)) == msg


def test_exported_from_package() -> None:
    for cls in ALL_TYPES:
        assert getattr(tfbus, cls.__name__) is cls


def test_arithmetic_that_means_nothing_raises_type_error() -> None:
    """``Vector3(1, 2, 3) + Vector3(1, 1, 1)`` silently gave a 6-tuple
    (tuple concatenation), ``Quaternion() * 2`` an 8-tuple. Every message type refuses
    ``+`` and ``*`` on either side, and the error says how to build a changed copy."""
    v = Vector3(1.0, 2.0, 3.0)
    with pytest.raises(TypeError, match=r"Vector3 is an immutable message.*_replace"):
        v + Vector3(1.0, 1.0, 1.0)
    for msg in (*(t() for t in ALL_TYPES), sample()):
        name = type(msg).__name__
        ops: tuple[Callable[[Any], object], ...] = (
            lambda m: m + m,
            lambda m: m + (1.0,),  # noqa: RUF005 (the concatenation is the point)
            lambda m: (1.0,) + m,  # noqa: RUF005
            lambda m: m * 2,
            lambda m: 2 * m,
            lambda m: sum([m], ()),
        )
        for op in ops:
            with pytest.raises(TypeError, match=f"{name} is an immutable message"):
                op(msg)
        with pytest.raises(TypeError, match=f"{name} is an immutable message"):
            msg += msg
    # Operations that mean something keep working: unpacking, indexing, numpy on fields.
    x, y, z = v
    assert (x, y, z) == (1.0, 2.0, 3.0) and v[2] == 3.0 and len(v) == 3
    assert (*v, 4.0) == (1.0, 2.0, 3.0, 4.0)


def test_replace_builds_a_modified_message_and_leaves_the_original() -> None:
    """The documented way to 'mutate' a message, for users of tf2_ros's mutable ones."""
    t = sample()
    t2 = t._replace(header=t.header._replace(frame_id="map", stamp=Time(5)))
    t3 = t2._replace(transform=t2.transform._replace(translation=Vector3(1.0, 0.0, 0.0)))
    assert t3.header == Header(Time(5), "map")
    assert t3.transform.translation == Vector3(1.0, 0.0, 0.0)
    assert t3.transform.rotation == t.transform.rotation
    assert t3.child_frame_id == t.child_frame_id
    assert t.header.frame_id != "map" and t == sample()  # the original is unchanged
    assert "_replace" in (tfbus.messages.__doc__ or "")


def test_transform_accepts_what_the_geometry_helpers_return() -> None:
    """quaternion_from_euler's array, lists, tuples and arrays become Vector3/Quaternion once,
    at construction (and in _replace); BufferCore.set_transform then stores them."""
    import numpy as np

    from tfbus.core import BufferCore
    from tfbus.geometry import quaternion_from_euler
    from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
    from tfbus.time import Time

    t = Transform(np.array([1.0, 2.0, 3.0]), quaternion_from_euler(0.0, 0.0, 1.0))
    assert type(t.translation) is Vector3 and type(t.rotation) is Quaternion
    assert t.translation == Vector3(1.0, 2.0, 3.0)
    assert t.rotation.z == pytest.approx(0.479425538604203, abs=1e-15)
    assert Transform([1, 2, 3], (0, 0, 0, 1)) == Transform(Vector3(1.0, 2.0, 3.0), Quaternion())
    assert type(Transform()._replace(rotation=[0.0, 0.0, 0.0, 1.0]).rotation) is Quaternion
    core = BufferCore()
    assert core.set_transform(TransformStamped(Header(Time(1), "map"), "base", t))
    got = core.lookup_transform("map", "base", Time(1)).transform
    assert got.translation == Vector3(1.0, 2.0, 3.0)


@pytest.mark.parametrize(
    "bad",
    [(1.0, 2.0), "abc", 5, None, [1.0, 2.0, float("nan")], [True, 1.0, 2.0], [[1.0, 2.0, 3.0]]],
)
def test_transform_refuses_anything_else_naming_the_field(bad: object) -> None:
    from tfbus.messages import Transform

    with pytest.raises(ValueError, match=r"Transform\.translation must be a Vector3 or a sequence"):
        Transform(bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"Transform\.rotation must be a Quaternion or a sequence"):
        Transform(rotation=bad)  # type: ignore[arg-type]
