"""Registered transforms against Debian's ROS 1 Python references (run under
``/usr/bin/python3`` in a side process, ``peers/debian/tf2_msgs_side.py``; installed by
``scripts/install/install_tf2_msgs_py.sh``): ``do_transform_wrench`` (tf2_geometry_msgs) and
``do_transform_cloud`` (tf2_sensor_msgs) on random inputs; the lever-arm wrench form,
``Stamped`` values and bad clouds on known numbers."""

from __future__ import annotations

import json
import math
import random
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from peer_install import require

from tfbus import (
    Buffer,
    Header,
    InvalidArgumentException,
    Point,
    Pose,
    Quaternion,
    Stamped,
    Time,
    Transform,
    TransformStamped,
    Vector3,
    Wrench,
    WrenchStamped,
)
from tfbus.convert import do_transform_cloud, do_transform_stamped, do_transform_wrench
from tfbus.sensor_msgs import PointCloud2, PointField, read_points

ROOT = Path(__file__).resolve().parents[2]
SIDE = ROOT / "peers" / "debian" / "tf2_msgs_side.py"
INSTALL = ROOT / "scripts" / "install" / "install_tf2_msgs_py.sh"


@pytest.fixture(scope="module", name="reference")
def reference_fixture() -> None:
    require("tf2-msgs-py", INSTALL.name, timeout=2000)


def _side(cases: dict[str, Any]) -> dict[str, Any]:
    r = subprocess.run(["/usr/bin/python3", str(SIDE)], input=json.dumps(cases),
                       capture_output=True, text=True, timeout=300, check=True)
    result: dict[str, Any] = json.loads(r.stdout)
    return result


def _unit(rng: random.Random) -> list[float]:
    v = [rng.gauss(0, 1) for _ in range(4)]
    n = math.sqrt(sum(c * c for c in v))
    return [c / n for c in v]


def _ts(t: list[float], q: list[float]) -> TransformStamped:
    return TransformStamped(Header(Time(3), "target"), "source",
                            Transform(Vector3(*t), Quaternion(*q)))


def _cloud(rng: random.Random, layout: int) -> PointCloud2:
    """Random clouds of three layouts: xyz float32; x y z float64 + intensity + a uint16
    ring with padding; float32 xyz after an rgb field, two rows with row padding."""
    n = rng.randrange(1, 40)
    if layout == 0:
        fields = [PointField("x", 0, PointField.FLOAT32), PointField("y", 4, PointField.FLOAT32),
                  PointField("z", 8, PointField.FLOAT32)]
        step, height = 12, 1
    elif layout == 1:
        fields = [PointField("x", 0, PointField.FLOAT64), PointField("y", 8, PointField.FLOAT64),
                  PointField("z", 16, PointField.FLOAT64),
                  PointField("intensity", 24, PointField.FLOAT32),
                  PointField("ring", 28, PointField.UINT16)]
        step, height = 32, 1
    else:
        fields = [PointField("rgb", 0, PointField.FLOAT32), PointField("x", 4, PointField.FLOAT32),
                  PointField("y", 8, PointField.FLOAT32), PointField("z", 12, PointField.FLOAT32)]
        step, height = 16, 2
    row_step = step * n + (0 if layout != 2 else 8)
    raw = bytearray(rng.getrandbits(8) for _ in range(row_step * height))
    # finite coordinates (random bytes would make NaNs and huge numbers)
    from tfbus.sensor_msgs import dtype_from_fields

    dtype = dtype_from_fields(fields, step)
    rows = np.ndarray((height, n), dtype=dtype, buffer=raw, strides=(row_step, step))
    for name in ("x", "y", "z"):
        rows[name] = np.array([[rng.uniform(-50, 50) for _ in range(n)] for _ in range(height)])
    if layout == 1:
        rows["intensity"] = np.array([[rng.uniform(0, 1) for _ in range(n)]])
    if layout == 2:
        rows["rgb"] = np.array([[rng.uniform(0, 1) for _ in range(n)] for _ in range(height)])
    return PointCloud2(Header(Time(1), "source"), height, n, fields, False, step, row_step,
                       bytes(raw), True)


def test_wrench_and_cloud_equal_debian_references(reference: None) -> None:
    rng = random.Random(11)
    wrenches = [[[rng.uniform(-3, 3) for _ in range(3)], _unit(rng),
                 [rng.uniform(-10, 10) for _ in range(3)], [rng.uniform(-10, 10) for _ in range(3)]]
                for _ in range(200)]
    clouds = [_cloud(rng, k % 3) for k in range(30)]
    transforms = [([rng.uniform(-3, 3) for _ in range(3)], _unit(rng)) for _ in clouds]
    ref = _side({
        "wrenches": wrenches,
        "clouds": [{"t": t, "q": q, "height": c.height, "width": c.width,
                    "point_step": c.point_step, "row_step": c.row_step, "data": c.data.hex(),
                    "fields": [[f.name, f.offset, f.datatype, f.count] for f in c.fields]}
                   for c, (t, q) in zip(clouds, transforms, strict=True)],
    })
    for (t, q, force, torque), (rf, rt) in zip(wrenches, ref["wrenches"], strict=True):
        wrench = WrenchStamped(Header(), Wrench(Vector3(*force), Vector3(*torque)))
        out = do_transform_wrench(wrench, _ts(t, q))
        assert out.header.frame_id == "target"
        assert list(out.wrench.force) == pytest.approx(rf, abs=1e-12)
        assert list(out.wrench.torque) == pytest.approx(rt, abs=1e-12)
    for cloud, (t, q), expected in zip(clouds, transforms, ref["clouds"], strict=True):
        out = do_transform_cloud(cloud, _ts(t, q))
        assert out.header == Header(Time(3), "target")
        assert (out.height, out.width, out.point_step, out.row_step) == (
            cloud.height, cloud.width, cloud.point_step, cloud.row_step)
        points = read_points(out)
        names = [f.name for f in cloud.fields]
        got = [[float(p[n]) for n in names] for p in points]
        # float32 fields: the reference rounds through Python floats the same way
        tol = 1e-4 if cloud.fields[names.index("x")].datatype == PointField.FLOAT32 else 1e-9
        if names[:3] == ["x", "y", "z"]:
            assert np.allclose(np.array(got), np.array(expected), rtol=0, atol=tol)
        else:
            # Debian's do_transform_cloud moves the first three fields whatever their
            # names (here rgb, x, y); tfbus moves the fields named x, y, z
            assert not np.allclose(np.array(got), np.array(expected), rtol=0, atol=tol)
            src = read_points(cloud)
            xyz = np.stack([src[n].astype(np.float64) for n in ("x", "y", "z")], axis=1)
            rot = _matrix(q)
            want = xyz @ rot.T + np.array(t)
            for k, n in enumerate(("x", "y", "z")):
                assert np.allclose(points[n], want[:, k], rtol=0, atol=tol)
        # the fields other than x, y, z are carried bit for bit
        for name in names:
            if name not in ("x", "y", "z"):
                assert np.array_equal(read_points(cloud)[name], points[name])


def _matrix(q: list[float]) -> Any:
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def test_wrench_lever_arm_form() -> None:
    w = WrenchStamped(Header(), Wrench(Vector3(0, 0, -10), Vector3(0, 0, 0)))
    arm = TransformStamped(Header(Time(1), "base"), "tool", Transform(Vector3(0.5, 0, 0)))
    assert do_transform_wrench(w, arm).wrench.torque == Vector3(0, 0, 0)
    # 10 N down at 0.5 m along +x: torque +5 N·m about +y at the base
    assert list(do_transform_wrench(w, arm, lever_arm=True).wrench.torque) == pytest.approx(
        [0.0, 5.0, 0.0])


def test_cloud_bad_input_names_the_field() -> None:
    cloud = PointCloud2(Header(), 1, 1, [PointField("x", 0, PointField.FLOAT32),
                                         PointField("y", 4, PointField.FLOAT32)], False, 8, 8,
                        bytes(8), True)
    with pytest.raises(InvalidArgumentException, match="no field 'z'"):
        do_transform_cloud(cloud, _ts([0, 0, 0], [0, 0, 0, 1]))
    ints = PointCloud2(Header(), 1, 1, [PointField("x", 0, PointField.INT32),
                                        PointField("y", 4, PointField.FLOAT32),
                                        PointField("z", 8, PointField.FLOAT32)], False, 12, 12,
                       bytes(12), True)
    with pytest.raises(InvalidArgumentException, match="field 'x' must be one float32"):
        do_transform_cloud(ints, _ts([0, 0, 0], [0, 0, 0, 1]))


def test_stamped_values() -> None:
    yaw = [0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)]  # +90° about z
    tf = _ts([1.0, 0.0, 0.0], yaw)
    h = Header(Time(1), "source")
    assert list(do_transform_stamped(Stamped(h, Point(1, 0, 0)), tf).data) == pytest.approx(
        [1.0, 1.0, 0.0])
    assert list(do_transform_stamped(Stamped(h, Vector3(1, 0, 0)), tf).data) == pytest.approx(
        [0.0, 1.0, 0.0])
    pose = do_transform_stamped(Stamped(h, Pose(Point(1, 0, 0))), tf).data
    assert list(pose.position) == pytest.approx([1.0, 1.0, 0.0])
    assert list(pose.orientation) == pytest.approx(yaw)
    assert list(do_transform_stamped(Stamped(h, Quaternion()), tf).data) == pytest.approx(yaw)
    moved = do_transform_stamped(Stamped(h, Transform(Vector3(0, 2, 0))), tf)
    assert moved.header == tf.header
    assert list(moved.data.translation) == pytest.approx([-1.0, 0.0, 0.0])
    with pytest.raises(TypeError, match="str"):
        do_transform_stamped(Stamped(h, "text"), tf)


@pytest.mark.anyio
async def test_buffer_transform_accepts_stamped() -> None:
    buf = Buffer()
    buf.set_transform(TransformStamped(Header(Time(1), "map"), "laser",
                                       Transform(Vector3(1.0, 2.0, 3.0))))
    out = await buf.transform(Stamped[Point](Header(Time(1), "laser"), Point(1, 0, 0)), "map",
                              timeout=1.0)
    assert out == Stamped(Header(Time(1), "map"), Point(2.0, 2.0, 3.0))


def test_twist_velocity_and_polygon() -> None:
    from tfbus import Point32, Polygon, PolygonStamped, Twist, TwistStamped, VelocityStamped
    from tfbus.convert import do_transform_polygon, do_transform_twist, do_transform_velocity

    yaw = [0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)]  # +90° about z
    tf = _ts([1.0, 0.0, 0.0], yaw)
    tw = Twist(Vector3(1.0, 0.0, 0.0), Vector3(0.0, 0.0, 1.0))
    # ω' = R ω = (0, 0, 1); v' = R v + t x ω' = (0, 1, 0) + (0, -1, 0)
    out = do_transform_twist(TwistStamped(Header(Time(1), "source"), tw), tf)
    assert out.header == tf.header
    assert list(out.twist.angular) == pytest.approx([0.0, 0.0, 1.0])
    assert list(out.twist.linear) == pytest.approx([0.0, 0.0, 0.0], abs=1e-15)
    vel = VelocityStamped(Header(Time(1), "source"), "body", "world", tw)
    moved = do_transform_velocity(vel, tf)
    assert (moved.header, moved.body_frame_id, moved.reference_frame_id) == (
        tf.header, "body", "world")
    assert moved.velocity == out.twist
    poly = PolygonStamped(Header(Time(1), "source"),
                          Polygon((Point32(1, 0, 0), Point32(0, 1, 0), Point32(0, 0, 2))))
    moved_poly = do_transform_polygon(poly, tf)
    assert moved_poly.header == tf.header
    assert [list(p) for p in moved_poly.polygon.points] == [
        pytest.approx([1.0, 1.0, 0.0]), pytest.approx([0.0, 0.0, 0.0]),
        pytest.approx([1.0, 0.0, 2.0])]


@pytest.mark.anyio
async def test_buffer_transform_of_the_new_types() -> None:
    from tfbus import PoseWithCovariance, PoseWithCovarianceStamped, Twist, TwistStamped

    buf = Buffer()
    buf.set_transform(TransformStamped(Header(Time(1), "map"), "laser",
                                       Transform(Vector3(0.0, 0.0, 0.0),
                                                 Quaternion(1.0, 0.0, 0.0, 0.0))))
    tw = await buf.transform(TwistStamped(Header(Time(1), "laser"),
                                          Twist(Vector3(0, 1, 0), Vector3(0, 0, 1))), "map")
    assert list(tw.twist.linear) == pytest.approx([0, -1, 0]) and tw.header.frame_id == "map"
    cov = tuple(float(i) for i in range(36))
    pc = await buf.transform(PoseWithCovarianceStamped(Header(Time(1), "laser"),
                                                       PoseWithCovariance(Pose(), cov)), "map")
    signs = np.array([1, -1, -1, 1, -1, -1])
    assert np.array_equal(np.array(pc.pose.covariance).reshape(6, 6),
                          np.array(cov).reshape(6, 6) * np.outer(signs, signs))
    with pytest.raises(InvalidArgumentException, match="36 finite numbers"):
        await buf.transform(PoseWithCovarianceStamped(Header(Time(1), "laser"),
                                                      PoseWithCovariance(Pose(), (1.0,) * 35)),
                            "map")
