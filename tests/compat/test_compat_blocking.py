"""``tfbus.compat.tf2_ros`` for synchronous callers (plain threads): blocking
``lookup_transform`` / ``can_transform`` with a timeout wait in the calling thread and are
woken by the arrival that answers them (the process's background loop,
``tfbus.compat._loop``); in an event loop's thread a needed wait raises
``LoopThreadError``; tf2_ros's submodule paths, topic names and frame dumps; Debian's
(KDL) quaternion sign; message classes default-constructible and mutable."""

from __future__ import annotations

import threading
import time as wall

import pytest

from tfbus import Time
from tfbus.compat import tf2_geometry_msgs, tf2_ros
from tfbus.compat._loop import background
from tfbus.messages import Header, Transform, TransformStamped


def _ts(stamp: Time, x: float = 1.0) -> TransformStamped:
    return TransformStamped(Header(stamp, "map"), "base",
                            Transform((x, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0)))


def _wait_pending(buf: tf2_ros.Buffer, n: int) -> None:
    deadline = wall.monotonic() + 20.0
    while background.call(lambda: buf.buffer.pending_waits) < n:  # bounded: 20 s
        assert wall.monotonic() < deadline, "the blocking call never started waiting"
        wall.sleep(0.005)


def test_blocking_lookup_is_woken_by_the_arrival() -> None:
    buf = tf2_ros.Buffer()
    got: list[object] = []
    waiter = threading.Thread(
        target=lambda: got.append(buf.lookup_transform("map", "base", Time(0), 30.0)))
    waiter.start()
    _wait_pending(buf, 1)
    assert got == []  # it waits (tf2's semantics), it did not answer at once
    buf.set_transform(_ts(Time(5)), "test")
    waiter.join(20.0)
    assert not waiter.is_alive()
    out = got[0]
    assert isinstance(out, TransformStamped)
    assert (out.header.frame_id, out.child_frame_id, out.header.stamp) == ("map", "base", Time(5))
    assert tuple(out.transform.translation) == (1.0, 2.0, 3.0)


def test_can_transform_waits_then_answers() -> None:
    buf = tf2_ros.Buffer()
    assert buf.can_transform("map", "base", Time(0), 0.05) is False  # timeout passes
    answers: list[object] = []
    waiter = threading.Thread(
        target=lambda: answers.append(buf.can_transform("map", "base", Time(0), 30.0)))
    waiter.start()
    _wait_pending(buf, 1)
    buf.set_transform(_ts(Time(1)), "test")
    waiter.join(20.0)
    assert answers == [True]


def test_no_timeout_answers_at_once() -> None:
    buf = tf2_ros.Buffer()
    with pytest.raises(tf2_ros.LookupException):
        buf.lookup_transform("map", "base", Time(0))
    with pytest.raises(tf2_ros.LookupException):
        buf.lookup_transform("map", "base", Time(0), 0.0)


@pytest.mark.anyio
async def test_a_wait_in_an_event_loop_thread_raises(anyio_backend: str) -> None:
    buf = tf2_ros.Buffer()
    with pytest.raises(tf2_ros.LoopThreadError, match="lookup_transform_async"):
        buf.lookup_transform("map", "base", Time(0), 1.0)
    buf.set_transform(_ts(Time(1)), "test")  # data at hand: answered at once, no wait
    assert buf.lookup_transform("map", "base", Time(0), 1.0).header.stamp == Time(1)


def test_submodule_paths_and_names() -> None:
    from tfbus.compat.tf2_ros.buffer import Buffer
    from tfbus.compat.tf2_ros.buffer_interface import BufferInterface
    from tfbus.compat.tf2_ros.static_transform_broadcaster import StaticTransformBroadcaster
    from tfbus.compat.tf2_ros.transform_broadcaster import TransformBroadcaster
    from tfbus.compat.tf2_ros.transform_listener import TransformListener

    assert Buffer is tf2_ros.Buffer and BufferInterface is tf2_ros.Buffer
    assert TransformListener is tf2_ros.TransformListener
    assert TransformBroadcaster is tf2_ros.TransformBroadcaster
    assert StaticTransformBroadcaster is tf2_ros.StaticTransformBroadcaster
    assert (tf2_ros.DEFAULT_TF_TOPIC, tf2_ros.DEFAULT_STATIC_TF_TOPIC) == ("/tf", "/tf_static")


def test_frame_dumps() -> None:
    buf = tf2_ros.Buffer()
    buf.set_transform(_ts(Time(2)), "dumper")
    assert "Frame base exists with parent map." in buf.all_frames_as_string()
    yaml = buf.all_frames_as_yaml()
    assert "base: \n  parent: 'map'" in yaml and "broadcaster: 'dumper'" in yaml


def test_pose_sign_is_kdl_s() -> None:
    # tf2's test_tf2_geometry_msgs: (x=1, w=0) then (x=1, w=0) gives w = +1 (KDL's matrix)
    t = _ts(Time(1))._replace(transform=Transform((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)))
    pose = tf2_geometry_msgs.PoseStamped()  # default-constructible and mutable
    pose.header.frame_id = "base"
    pose.pose.orientation.x = 1.0
    pose.pose.orientation.w = 0.0
    out = tf2_geometry_msgs.do_transform_pose(pose, t)
    assert type(out) is tf2_geometry_msgs.PoseStamped
    q = out.pose.orientation
    assert (q.x, q.y, q.z, q.w) == (0.0, 0.0, 0.0, 1.0)
    assert out.header.frame_id == "map"
