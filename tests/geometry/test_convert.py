"""tfbus.convert: Buffer.transform / transform_full dispatch by registration (tf2_ros's
TransformRegistration), on asyncio and trio, with hand-computed numbers."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import NamedTuple

import anyio
import anyio.lowlevel
import pytest

from tfbus import (
    Header,
    Point,
    PointStamped,
    Pose,
    PoseStamped,
    Quaternion,
    Time,
    Transform,
    TransformStamped,
    Vector3,
    Vector3Stamped,
)
from tfbus.buffer import Buffer
from tfbus.clock import ManualClock
from tfbus.convert import (
    TransformRegistration,
    do_transform_point,
    do_transform_pose,
    do_transform_transform,
    do_transform_vector3,
    get_transform_function,
    register_transform,
    registered_types,
)

pytestmark = pytest.mark.anyio

T0 = Time(1000)
S45 = math.sqrt(0.5)  # sin 45° = cos 45°
YAW90 = Quaternion(0.0, 0.0, S45, S45)  # 90° about z, (x, y, z, w)


def tf(
    parent: str, child: str, stamp: Time, xyz: tuple[float, float, float], q: Quaternion
) -> TransformStamped:
    return TransformStamped(Header(stamp, parent), child, Transform(Vector3(*xyz), q))


class SegmentStamped(NamedTuple):
    """A user's own stamped type: a line segment (metres) in ``header.frame_id``."""

    header: Header
    start: Point
    end: Point


def do_transform_segment(s: SegmentStamped, transform: TransformStamped) -> SegmentStamped:
    """A user's function (tf2_ros order: object, transform)."""
    a, b = (do_transform_point(PointStamped(s.header, p), transform).point for p in s[1:])
    return SegmentStamped(transform.header, a, b)


@pytest.fixture
def user_type() -> Iterator[type[SegmentStamped]]:
    register_transform(SegmentStamped, do_transform_segment)
    yield SegmentStamped
    TransformRegistration._table.pop(SegmentStamped, None)


def test_stamped_geometry_types_are_preregistered() -> None:
    assert get_transform_function(PointStamped) is do_transform_point
    assert get_transform_function(PoseStamped) is do_transform_pose
    assert get_transform_function(Vector3Stamped) is do_transform_vector3
    assert get_transform_function(TransformStamped) is do_transform_transform
    assert set(registered_types()) >= {PointStamped, PoseStamped, Vector3Stamped, TransformStamped}
    # tf2_ros's spelling: every instance shares one table
    assert TransformRegistration().get(PointStamped) is do_transform_point


def test_unregistered_type_is_a_clear_type_error() -> None:
    with pytest.raises(TypeError, match=r"no transform function registered for type str") as e:
        get_transform_function(str)
    assert "PointStamped" in str(e.value) and "register_transform(str, fn)" in str(e.value)


def test_registration_rejects_non_types_and_non_callables() -> None:
    with pytest.raises(TypeError, match="key must be a class"):
        register_transform("PointStamped", do_transform_point)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="must be callable"):
        register_transform(SegmentStamped, None)  # type: ignore[arg-type]
    assert SegmentStamped not in registered_types()


def test_subclass_is_dispatched_by_its_registered_base() -> None:
    class MyPoint(PointStamped):
        __slots__ = ()

    assert get_transform_function(MyPoint) is do_transform_point


def test_do_transform_transform_hand_computed() -> None:
    # laser in laser_mount: 1 m forward. laser_mount in base_link: 1 m up, yawed 90°.
    # So the laser sits at R(90°)(1, 0, 0) + (0, 0, 1) = (0, 1, 1), rotation 90° yaw.
    laser = tf("laser_mount", "laser", T0, (1.0, 0.0, 0.0), Quaternion())
    mount = tf("base_link", "laser_mount", Time(7), (0.0, 0.0, 1.0), YAW90)
    out = do_transform_transform(laser, mount)
    assert out.header == Header(Time(7), "base_link")
    assert out.child_frame_id == "laser"
    assert tuple(out.transform.translation) == pytest.approx((0.0, 1.0, 1.0), abs=1e-15)
    assert tuple(out.transform.rotation) == pytest.approx(tuple(YAW90), abs=1e-15)


async def test_transform_of_a_transform_matches_the_buffers_own_chain() -> None:
    """Re-expressing laser_mount->laser in base_link gives what a lookup through the
    chain gives (tf2's Transform product)."""
    buf = Buffer(clock=ManualClock(T0))
    mount = tf("base_link", "laser_mount", T0, (0.3, -0.2, 1.0), YAW90)
    laser = tf("laser_mount", "laser", T0, (1.0, 0.5, 0.0), Quaternion(0.0, S45, 0.0, S45))
    buf.set_transform(mount)
    out = await buf.transform(laser, "base_link")
    buf.set_transform(laser)
    chained = buf.lookup_transform("base_link", "laser", T0)
    assert out.header == chained.header
    assert out.child_frame_id == chained.child_frame_id == "laser"
    assert tuple(out.transform.translation) == pytest.approx(
        tuple(chained.transform.translation), abs=1e-15
    )
    assert tuple(out.transform.rotation) == pytest.approx(
        tuple(chained.transform.rotation), abs=1e-15
    )


async def test_buffer_transform_uses_a_user_registration(
    user_type: type[SegmentStamped],
) -> None:
    buf = Buffer(clock=ManualClock(T0))
    buf.set_transform(tf("base_link", "sonar", T0, (0.5, 0.0, 0.0), YAW90))
    seg = user_type(Header(T0, "sonar"), Point(0.0, 0.0, 0.0), Point(2.0, 0.0, 0.0))
    out = await buf.transform(seg, "base_link")
    # The sonar's x axis points along base_link's y; its origin is at (0.5, 0, 0).
    assert isinstance(out, SegmentStamped)
    assert out.header == Header(T0, "base_link")
    assert tuple(out.start) == pytest.approx((0.5, 0.0, 0.0), abs=1e-15)
    assert tuple(out.end) == pytest.approx((0.5, 2.0, 0.0), abs=1e-15)


async def test_unregistered_type_fails_before_waiting() -> None:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    with pytest.raises(TypeError, match="no transform function registered for type str"):
        await buf.transform("not a message", "base_link")
    with pytest.raises(TypeError, match="no transform function registered"):
        await buf.transform_full(3.5, "a", T0, "odom")
    assert buf.pending_waits == 0 and clock.pending == 0


async def test_registered_object_without_a_usable_header_is_a_type_error(
    user_type: type[SegmentStamped],
) -> None:
    buf = Buffer(clock=ManualClock(T0))
    with pytest.raises(TypeError, match="has no header with a str frame_id and a Time stamp"):
        bad = user_type(Header(1000, "sonar"), Point(), Point())  # type: ignore[arg-type]
        await buf.transform(bad, "base_link")


async def test_transform_waits_for_the_data() -> None:
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    got: list[PoseStamped] = []
    pose = PoseStamped(Header(T0, "camera"), Pose(Point(1.0, 0.0, 0.0), Quaternion()))

    async def waiter() -> None:
        got.append(await buf.transform(pose, "base_link", timeout=5.0))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await clock.advance(1.0)
        assert not got and buf.pending_waits == 1
        buf.set_transform(tf("base_link", "camera", T0, (0.0, 0.0, 2.0), YAW90))
    assert got[0].header == Header(T0, "base_link")
    assert tuple(got[0].pose.position) == pytest.approx((0.0, 1.0, 2.0), abs=1e-15)
    assert tuple(got[0].pose.orientation) == pytest.approx(tuple(YAW90), abs=1e-15)


async def test_transform_full_through_a_fixed_frame_hand_computed() -> None:
    """tf2_ros transform_full: a point seen in base_link at t=1 s, expressed in base_link
    at t=2 s through odom. base_link moves from x=1 to x=3 in odom, so a point at the
    robot's origin at t=1 (odom x=1) is 2 m behind it at t=2."""
    t1, t2 = Time(1), Time(2)
    buf = Buffer(clock=ManualClock(t2))
    buf.set_transform(tf("odom", "base_link", t1, (1.0, 0.0, 0.0), Quaternion()))
    buf.set_transform(tf("odom", "base_link", t2, (3.0, 0.0, 0.0), Quaternion()))
    p = PointStamped(Header(t1, "base_link"), Point(0.0, 0.0, 0.0))
    out = await buf.transform_full(p, "base_link", t2, "odom")
    assert out.header == Header(t2, "base_link")
    assert tuple(out.point) == pytest.approx((-2.0, 0.0, 0.0), abs=1e-15)
    v = Vector3Stamped(Header(t1, "base_link"), Vector3(1.0, 0.0, 0.0))
    assert tuple((await buf.transform_full(v, "base_link", t2, "odom")).vector) == (1.0, 0.0, 0.0)


async def test_transform_full_waits_for_both_legs() -> None:
    t1, t2 = Time(1), Time(2)
    clock = ManualClock(t1)
    buf = Buffer(clock=clock)
    got: list[PointStamped] = []
    p = PointStamped(Header(t1, "base_link"), Point(0.0, 0.0, 0.0))

    async def waiter() -> None:
        got.append(await buf.transform_full(p, "base_link", t2, "odom", timeout=10.0))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await clock.advance(0)
        buf.set_transform(tf("odom", "base_link", t1, (1.0, 0.0, 0.0), Quaternion()))
        await clock.advance(1.0)
        assert not got  # the t2 leg is still missing
        buf.set_transform(tf("odom", "base_link", t2, (3.0, 0.0, 0.0), Quaternion()))
    assert tuple(got[0].point) == pytest.approx((-2.0, 0.0, 0.0), abs=1e-15)
    assert buf.pending_waits == 0
