"""ROS 2 geometry2's ``tf2_geometry_msgs/test/test_tf2_geometry_msgs.py`` (its one case,
``test_transform``), written again against ``tfbus.compat`` (our code: the same calls and
assertions, rclpy messages stood in for by objects with their fields); plus the
covariance rotation against its definition (ROS 2 ``transform_covariance``: every 3x3
block ``B`` becomes ``R B Rᵀ``) on random inputs, and its bad input.

Upstream passes ``new_type=PointStamped`` (rclpy's class); here it is tfbus's
``PointStamped``, the type the compat layer returns. The transformed orientation's
sign is upstream's (w = +1, through KDL's matrix), exactly.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

import numpy as np
import pytest
from test_upstream_tf2_py import Q4, V3, Hd, RclTime, TfMsg

from tfbus import Header, InvalidArgumentException, PointStamped, Time
from tfbus.compat import tf2_geometry_msgs, tf2_ros


@dataclass
class PointMsg:
    header: Hd = field(default_factory=Hd)
    point: V3 = field(default_factory=V3)


@dataclass
class PoseMsg:
    position: V3 = field(default_factory=V3)
    orientation: Q4 = field(default_factory=lambda: Q4(w=1.0))


@dataclass
class PoseStampedMsg:
    header: Hd = field(default_factory=Hd)
    pose: PoseMsg = field(default_factory=PoseMsg)


@dataclass
class PoseCovMsg:
    pose: PoseMsg = field(default_factory=PoseMsg)
    covariance: tuple[float, ...] = (0.0,) * 36


@dataclass
class PoseCovStampedMsg:
    header: Hd = field(default_factory=Hd)
    pose: PoseCovMsg = field(default_factory=PoseCovMsg)


@dataclass
class Vector3StampedMsg:
    header: Hd = field(default_factory=Hd)
    vector: V3 = field(default_factory=V3)


COV = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0) * 6


def test_transform() -> None:
    b = tf2_ros.Buffer()
    t = TfMsg(Hd(RclTime(seconds=2.0).to_msg(), "a"), "b")
    t.transform.translation.x = 1.0
    t.transform.rotation = Q4(w=0.0, x=1.0, y=0.0, z=0.0)
    b.set_transform(t, "eitan_rocks")
    out = b.lookup_transform("a", "b", RclTime(seconds=2.0).to_msg(), RclTime(seconds=2))
    assert out.transform.translation.x == 1
    assert out.transform.rotation.x == 1
    assert out.header.frame_id == "a"
    assert out.child_frame_id == "b"

    v = PointMsg(Hd(RclTime(seconds=2.0).to_msg(), "a"), V3(1.0, 2.0, 3.0))
    p = b.transform(v, "b", new_type=PointStamped)
    assert (p.point.x, p.point.y, p.point.z) == (0, -2, -3)

    pose = PoseStampedMsg(Hd(RclTime(seconds=2.0).to_msg(), "a"),
                          PoseMsg(V3(1.0, 2.0, 3.0), Q4(w=0.0, x=1.0, y=0.0, z=0.0)))
    ps = b.transform(pose, "b")
    assert (ps.pose.position.x, ps.pose.position.y, ps.pose.position.z) == (0, -2, -3)

    cov = PoseCovStampedMsg(Hd(RclTime(seconds=2.0).to_msg(), "a"),
                            PoseCovMsg(PoseMsg(V3(1.0, 2.0, 3.0), Q4(w=0.0, x=1.0)), COV))
    pc = b.transform(cov, "b")
    assert (pc.pose.pose.position.x, pc.pose.pose.position.y, pc.pose.pose.position.z) == (
        0, -2, -3)

    # translation does not affect a Vector3
    t = TfMsg()
    t.transform.translation = V3(1.0, 2.0, 3.0)
    t.transform.rotation = Q4(w=1.0)
    out_v = tf2_geometry_msgs.do_transform_vector3(Vector3StampedMsg(vector=V3(1.0)), t)
    assert (out_v.vector.x, out_v.vector.y, out_v.vector.z) == (1, 0, 0)

    # 180 degrees about y
    t.transform.rotation = Q4(w=0.0, x=0.0, y=1.0, z=0.0)
    out_v = tf2_geometry_msgs.do_transform_vector3(Vector3StampedMsg(vector=V3(1.0)), t)
    assert (out_v.vector.x, out_v.vector.y, out_v.vector.z) == (-1, 0, 0)

    # pose and covariance
    t.transform.rotation = Q4(w=0.0, x=1.0, y=0.0, z=0.0)
    out_c = tf2_geometry_msgs.do_transform_pose_with_covariance_stamped(cov, t)
    expected = np.array([
        1.0, -2.0, -3.0, 4.0, -5.0, -6.0,
        -1.0, 2.0, 3.0, -4.0, 5.0, 6.0,
        -1.0, 2.0, 3.0, -4.0, 5.0, 6.0,
        1.0, -2.0, -3.0, 4.0, -5.0, -6.0,
        -1.0, 2.0, 3.0, -4.0, 5.0, 6.0,
        -1.0, 2.0, 3.0, -4.0, 5.0, 6.0,
    ])  # fmt: skip
    position, orientation = out_c.pose.pose
    assert (position.x, position.y, position.z) == (2, 0, 0)
    assert (orientation.x, orientation.y, orientation.z, orientation.w) == (0, 0, 0, 1)
    assert np.array_equal(out_c.pose.covariance, expected)


def test_transform_pose_with_covariance_orientation_sign() -> None:
    t = TfMsg()
    t.transform.translation = V3(1.0, 2.0, 3.0)
    t.transform.rotation = Q4(w=0.0, x=1.0, y=0.0, z=0.0)
    cov = PoseCovStampedMsg(Hd(RclTime(seconds=2.0).to_msg(), "a"),
                            PoseCovMsg(PoseMsg(V3(1.0, 2.0, 3.0), Q4(w=0.0, x=1.0)), COV))
    out = tf2_geometry_msgs.do_transform_pose_with_covariance_stamped(cov, t)
    assert tuple(out.pose.pose.orientation) == (0.0, 0.0, 0.0, 1.0)


def test_covariance_blocks_rotate_as_defined() -> None:
    rng = random.Random(3)
    for _ in range(50):
        q = [rng.gauss(0, 1) for _ in range(4)]
        n = math.sqrt(sum(c * c for c in q))
        x, y, z, w = (c / n for c in q)
        rot = np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ])  # fmt: skip
        a = np.array([rng.uniform(-1, 1) for _ in range(36)]).reshape(6, 6)
        cov = a @ a.T
        t = TfMsg()
        t.transform.translation = V3(rng.uniform(-5, 5), 0.0, 1.0)
        t.transform.rotation = Q4(x, y, z, w)
        got = np.array(tf2_geometry_msgs.transform_covariance(tuple(cov.ravel()), t)).reshape(6, 6)
        for bi in (0, 3):
            for bj in (0, 3):
                block = cov[bi:bi + 3, bj:bj + 3]
                assert np.allclose(got[bi:bi + 3, bj:bj + 3], rot @ block @ rot.T, atol=1e-12)


def test_covariance_bad_input() -> None:
    t = TfMsg()
    t.transform.rotation = Q4(w=1.0)
    for bad in ((1.0,) * 35, (math.nan,) * 36, "thirty-six"):
        with pytest.raises(InvalidArgumentException, match="36 finite numbers"):
            tf2_geometry_msgs.transform_covariance(bad, t)


def test_ros1_and_ros2_pose_forms() -> None:
    t = TfMsg(Hd(Time(1), "map"), "base")
    t.transform.translation = V3(1.0, 0.0, 0.0)
    t.transform.rotation = Q4(w=1.0)
    ros2 = tf2_geometry_msgs.do_transform_pose(PoseMsg(V3(0.0, 1.0, 0.0)), t)
    # a message given, the same class returned (mutable, as ROS's)
    assert type(ros2) is PoseMsg and ros2.position == V3(1.0, 1.0, 0.0)
    ros1 = tf2_geometry_msgs.do_transform_pose(PoseStampedMsg(Hd(Time(1), "base"),
                                                              PoseMsg(V3(0.0, 1.0, 0.0))), t)
    assert type(ros1) is PoseStampedMsg and ros1.pose.position == V3(1.0, 1.0, 0.0)
    assert (ros1.header.stamp.sec, ros1.header.stamp.nanosec, ros1.header.frame_id) == (1, 0, "map")
    stamped = tf2_geometry_msgs.do_transform_pose_stamped(
        PoseStampedMsg(Hd(Time(1), "base")), t)
    assert stamped.pose.position == V3(1.0, 0.0, 0.0)


@dataclass
class PolygonMsg:
    points: list[V3] = field(default_factory=list)


@dataclass
class PolygonStampedMsg:
    header: Hd = field(default_factory=Hd)
    polygon: PolygonMsg = field(default_factory=PolygonMsg)


def test_polygon_stamped_by_fields() -> None:
    t = TfMsg(Hd(Time(2), "map"), "base")
    t.transform.translation = V3(1.0, 2.0, 3.0)
    t.transform.rotation = Q4(w=1.0)
    poly = PolygonStampedMsg(Hd(Time(2), "base"), PolygonMsg([V3(1.0), V3(0.0, 1.0)]))
    out = tf2_geometry_msgs.do_transform_polygon_stamped(poly, t)
    assert out.header == Header(Time(2), "map")
    assert [list(p) for p in out.polygon.points] == [[2.0, 2.0, 3.0], [1.0, 3.0, 3.0]]
    b = tf2_ros.Buffer()
    b.set_transform(t, "test")
    assert b.transform(poly, "map") == out
