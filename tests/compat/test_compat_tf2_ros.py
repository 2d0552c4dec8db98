"""``tfbus.compat.tf2_ros``: ROS 2 tf2_ros call shapes on tfbus — the buffer's
synchronous and awaitable methods (timeouts on a ManualClock), arguments in rospy /
rclpy / builtin_interfaces forms and duck-typed messages, the registries, ``Stamped``,
and a listener fed by the broadcasters over a tfbus bus."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import anyio
import pytest
from test_compat_tf2_py import (
    Hdr,
    MsgTime,
    Quat,
    RclpyTime,
    RospyTime,
    RosTransformStamped,
    Tf,
    Vec,
)

import tfbus
from tfbus import ManualClock, PointStamped, Time, TransformStamped
from tfbus.bus import Bus
from tfbus.compat import tf2_ros


@dataclass
class RosPointStamped:
    header: Hdr
    point: Vec


def _yaw_tf(parent: str, child: str, stamp: Any, x: float, yaw: float) -> RosTransformStamped:
    return RosTransformStamped(Hdr(stamp, parent), child,
                               Tf(Vec(x, 0, 0), Quat(0, 0, math.sin(yaw / 2), math.cos(yaw / 2))))


def test_exceptions_are_tfbus_classes_under_tf2_names() -> None:
    for name in ("TransformException", "LookupException", "ConnectivityException",
                 "ExtrapolationException", "InvalidArgumentException", "TimeoutException"):
        assert getattr(tf2_ros, name) is getattr(tfbus, name)
    assert issubclass(tf2_ros.LookupException, tf2_ros.TransformException)


def test_sync_methods_with_ros2_call_shapes() -> None:
    buf = tf2_ros.Buffer()
    assert buf.set_transform(_yaw_tf("map", "base", RospyTime(1, 0), 1.0, 0.0), "a") is None  # type: ignore[func-returns-value]
    buf.set_transform(_yaw_tf("map", "base", RclpyTime(2 * 10**9), 2.0, 0.0), "a")
    buf.set_transform_static(_yaw_tf("base", "laser", MsgTime(0, 0), 0.5, math.pi / 2), "b")
    # lookup_transform(target, source, time, timeout): the timeout positional, as ROS 2
    t = buf.lookup_transform("map", "laser", RclpyTime(1_500_000_000), RclpyTime(10**9))
    assert isinstance(t, TransformStamped)
    assert t.header.stamp == Time.from_ns(1_500_000_000)
    assert list(t.transform.translation) == pytest.approx([2.0, 0.0, 0.0])
    assert buf.can_transform("map", "laser", MsgTime(1, 0), RclpyTime(0)) is True
    assert buf.can_transform("map", "nope", MsgTime(1, 0), return_debug_tuple=True) == (
        False, "canTransform: source_frame nope does not exist.")
    assert buf.can_transform_full("laser", MsgTime(2, 0), "laser", MsgTime(1, 0), "map") is True
    full = buf.lookup_transform_full("laser", RospyTime(2, 0), "laser", RospyTime(1, 0), "map")
    assert list(full.transform.translation) == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)
    with pytest.raises(tf2_ros.ExtrapolationException):
        buf.lookup_transform("map", "laser", RospyTime(5, 0), RospyTime(1, 0))
    # transform(): a foreign PointStamped by its fields, the tfbus type back
    out = buf.transform(RosPointStamped(Hdr(RospyTime(1, 0), "laser"), Vec(1.0, 0, 0)), "map")
    assert isinstance(out, PointStamped)
    assert out.header.frame_id == "map"
    assert list(out.point) == pytest.approx([1.5, 1.0, 0.0], abs=1e-12)
    laser_point = PointStamped(tfbus.Header(Time(1), "laser"), tfbus.Point(1, 0, 0))
    out_full = buf.transform_full(laser_point, "laser", Time(2), "map")
    assert list(out_full.point) == pytest.approx([1.0, 1.0, 0.0], abs=1e-12)  # laser moved +1 x
    buf.clear()
    assert not buf.can_transform("map", "base", Time(0))


def test_registries_convert_and_stamped() -> None:
    class Celsius(float):
        pass

    reg = tf2_ros.ConvertRegistration()
    reg.add_to_msg(Celsius, lambda c: {"celsius": float(c)})
    reg.add_from_msg(str, lambda m: f"{m['celsius']:.1f} C")
    assert tf2_ros.convert(Celsius(21.5), str) == "21.5 C"
    assert tf2_ros.convert("same", str) == "same"
    with pytest.raises(tf2_ros.TypeException, match="not loaded or supported"):
        reg.get_to_msg(bytes)
    assert tf2_ros.Buffer.registration.get(PointStamped) is not None
    p = tf2_ros.Stamped(PointStamped(), RospyTime(3, 5), "odom")
    assert p.header == tfbus.Header(Time(3, 5), "odom")

    @dataclass
    class Mutable:
        header: Any = None

    m = Mutable()
    assert tf2_ros.Stamped(m, MsgTime(1, 2), "x") is m and m.header.frame_id == "x"


@pytest.mark.anyio
async def test_awaitable_waits_and_timeouts() -> None:
    clock = ManualClock(Time(0))
    buf = tf2_ros.Buffer(RospyTime(10, 0), clock=clock)
    got: list[Any] = []
    failed: list[BaseException] = []

    async def wait_ok() -> None:
        got.append(await buf.wait_for_transform_async("map", "base", RclpyTime(10**9),
                                                      timeout=RclpyTime(5 * 10**9)))
        got.append(await buf.lookup_transform_async("map", "base", MsgTime(1, 0)))
        got.append(await buf.lookup_transform_full_async("base", MsgTime(1, 0), "base",
                                                         MsgTime(1, 0), "map", timeout=1.0))
        got.append(await buf.wait_for_transform_full_async("base", Time(1), "base", Time(1),
                                                           "map"))

    async def wait_too_long() -> None:
        try:
            await buf.lookup_transform_async("map", "elsewhere", Time(0), timeout=2.0)
        except tf2_ros.TimeoutException as e:
            failed.append(e)

    async with anyio.create_task_group() as tg:
        tg.start_soon(wait_ok)
        tg.start_soon(wait_too_long)
        await clock.advance(0)
        assert not got
        buf.set_transform(_yaw_tf("map", "base", RospyTime(1, 0), 1.0, 0.0), "a")
        await clock.advance(2.5)
    assert got[0] is True and got[3] is True
    assert got[1].header.stamp == Time(1)
    assert len(failed) == 1 and "elsewhere" in str(failed[0])
    assert buf.buffer.pending_waits == 0


@pytest.mark.anyio
async def test_listener_and_broadcasters_on_a_tfbus_bus() -> None:
    async with Bus() as bus:
        buf = tf2_ros.Buffer()
        async with tf2_ros.TransformListener(buf, bus=bus):
            tf2_ros.StaticTransformBroadcaster(bus).sendTransform(
                _yaw_tf("base", "laser", MsgTime(0, 0), 0.5, 0.0))
            caster = tf2_ros.TransformBroadcaster(bus)
            caster.sendTransform([_yaw_tf("map", "base", RospyTime(1, 0), 1.0, 0.0),
                                  _yaw_tf("map", "base", RospyTime(2, 0), 2.0, 0.0)])
            t = await buf.lookup_transform_async("map", "laser", RospyTime(1, 500_000_000),
                                                 timeout=5.0)
    assert list(t.transform.translation) == pytest.approx([2.0, 0.0, 0.0])


@pytest.mark.parametrize("cls", [tf2_ros.TransformBroadcaster,
                                 tf2_ros.StaticTransformBroadcaster])
@pytest.mark.parametrize(("node", "shown"), [("x", "str 'x'"), (42, "int 42")])
def test_broadcaster_on_a_non_node_names_the_argument(
    cls: type[tf2_ros.TransformBroadcaster], node: object, shown: str
) -> None:
    """A broadcaster given neither an rclpy node nor a bus says so, with the type and
    value given (it said "No module named 'rclpy'")."""
    with pytest.raises(TypeError) as info:
        cls(node)
    assert str(info.value) == (
        f"{cls.__name__}: node must be an rclpy Node or a tfbus.Bus, got {shown}")


def test_listener_on_a_non_bus_or_non_node_names_the_argument() -> None:
    """``TransformListener(buffer, bus="x")`` raised an empty AssertionError; a non-node
    ``node`` said "No module named 'rclpy'". Each names the argument and its type."""
    with pytest.raises(TypeError) as info:
        tf2_ros.TransformListener(tf2_ros.Buffer(), bus="x")  # type: ignore[arg-type]
    assert str(info.value) == "TransformListener: bus must be a tfbus.Bus, got str 'x'"
    with pytest.raises(TypeError) as info:
        tf2_ros.TransformListener(tf2_ros.Buffer(), {})
    assert str(info.value) == (
        "TransformListener: node must be an rclpy Node or a tfbus.Bus, got dict {}")
    long = "n" * 100
    with pytest.raises(TypeError, match=f"got str '{'n' * 59}\\.\\.\\.$"):
        tf2_ros.TransformListener(tf2_ros.Buffer(), long)


def test_ros2_extrapolation_classes_are_tfbus_classes_and_raised() -> None:
    """``from tf2_ros import ForwardExtrapolationException`` (and Backward-, NoData-)
    gives the classes tfbus raises; a lookup of the compat buffer raises each."""
    for name in ("ForwardExtrapolationException", "BackwardExtrapolationException",
                 "NoDataForExtrapolationException"):
        assert getattr(tf2_ros, name) is getattr(tfbus, name)
        assert name in tf2_ros.__all__
        assert issubclass(getattr(tf2_ros, name), tf2_ros.ExtrapolationException)
    buf = tf2_ros.Buffer()
    buf.set_transform(_yaw_tf("map", "base", RospyTime(1, 0), 1.0, 0.0), "a")
    with pytest.raises(tf2_ros.NoDataForExtrapolationException):  # one sample, at 1 s
        buf.lookup_transform("map", "base", RospyTime(2, 0))
    buf.set_transform(_yaw_tf("map", "base", RospyTime(2, 0), 2.0, 0.0), "a")
    with pytest.raises(tf2_ros.ForwardExtrapolationException):
        buf.lookup_transform("map", "base", RospyTime(3, 0))
    with pytest.raises(tf2_ros.BackwardExtrapolationException):
        buf.lookup_transform("map", "base", RclpyTime(500_000_000), timeout=-1.0)
    # ROS 2's tf2_py (tf2_py/src/tf2_py.cpp, geometry2 0.39.1) registers six exception
    # classes and none of the extrapolation subclasses: the compat tf2_py the same six.
    from tfbus.compat import tf2_py

    exceptions = {n for n in tf2_py.__all__ if n.endswith("Exception")}
    assert exceptions == {"TransformException", "ConnectivityException", "LookupException",
                          "ExtrapolationException", "InvalidArgumentException",
                          "TimeoutException"}
    assert all(getattr(tf2_py, n) is getattr(tfbus, n) for n in exceptions)


@pytest.mark.parametrize("cls", [tf2_ros.TransformBroadcaster,
                                 tf2_ros.StaticTransformBroadcaster])
def test_broadcaster_on_none_names_the_argument(cls: type[tf2_ros.TransformBroadcaster]) -> None:
    """``TransformBroadcaster(None)`` (ROS 2's ``node`` not set yet) is refused, naming
    the value and what is accepted; it silently joined the ROS 1 graph (no argument
    keeps doing that, ROS 1's idiom)."""
    with pytest.raises(TypeError) as info:
        cls(None)
    assert str(info.value) == (
        f"{cls.__name__}: node must be an rclpy Node or a tfbus.Bus, got None (for ROS 1's "
        f"graph at ROS_MASTER_URI give no argument: {cls.__name__}())")


_FORMS = ("a duration (rclpy Duration, builtin_interfaces Duration, rospy Duration, tfbus "
          "Duration) or seconds (int, float), or None")


@pytest.mark.parametrize(("timeout", "error", "text"), [
    ("x", TypeError, f"timeout must be {_FORMS}, got str 'x'"),
    (True, TypeError, f"timeout must be {_FORMS}, got bool True"),
    (Time(1), TypeError, f"timeout must be {_FORMS}, got Time Time(sec=1, nanosec=0)"),
    (math.nan, ValueError, f"timeout must not be NaN, got nan ({_FORMS})"),
])
@pytest.mark.parametrize("call", ["lookup_transform", "lookup_transform_full",
                                  "can_transform", "transform", "wait_for_transform_async"])
def test_a_bad_timeout_names_itself_before_the_lookup(
    call: str, timeout: object, error: type[Exception], text: str
) -> None:
    """``Buffer().lookup_transform('a', 'a', Time(0), timeout='x')`` answered (the
    identity) without a word about the timeout; every timeout is checked first."""
    buf = tf2_ros.Buffer()
    calls = {
        "lookup_transform": lambda: buf.lookup_transform("a", "a", Time(0), timeout=timeout),
        "lookup_transform_full": lambda: buf.lookup_transform_full(
            "a", Time(0), "a", Time(0), "a", timeout=timeout),
        "can_transform": lambda: buf.can_transform("a", "a", Time(0), timeout=timeout),
        "transform": lambda: buf.transform(
            PointStamped(tfbus.Header(Time(0), "a"), tfbus.Point()), "a", timeout),
        "wait_for_transform_async": lambda: buf.wait_for_transform_async(
            "a", "a", Time(0), timeout=timeout),
    }
    with pytest.raises(error) as info:
        calls[call]()
    assert str(info.value) == text
