"""``do_transform_cloud`` works on a copy of the cloud block by block; whatever the cloud's
size (one block, many blocks and a partial last one), row padding, field type (float32,
float64, big-endian) or interleaved fields, each point must come out as the one-shot
``transform_points`` of its x, y, z (float64 math, stored back in the field's type), and
every byte that is not x, y or z (other fields, padding) must be kept."""

from __future__ import annotations

import numpy as np
import pytest

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.convert import _CLOUD_BLOCK, do_transform_cloud
from tfbus.geometry import transform_points
from tfbus.sensor_msgs import PointCloud2, PointField


@pytest.mark.parametrize(
    ("height", "width", "float64", "bigendian", "pad_row"),
    [
        (1, 1, False, False, 0),
        (1, _CLOUD_BLOCK, False, False, 0),
        (1, 3 * _CLOUD_BLOCK + 7, False, False, 0),
        (3, _CLOUD_BLOCK + 11, True, False, 0),
        (4, 2 * _CLOUD_BLOCK - 1, False, False, 24),
        (2, 1000, True, True, 8),
    ],
)
def test_blocks_equal_one_shot_transform(
    height: int, width: int, float64: bool, bigendian: bool, pad_row: int
) -> None:
    rng = np.random.default_rng(height * 7919 + width)
    size = 8 if float64 else 4
    kind = PointField.FLOAT64 if float64 else PointField.FLOAT32
    # intensity between y and z: x, y, z are not side by side
    fields = [PointField("x", 0, kind), PointField("y", size, kind),
              PointField("intensity", 2 * size, PointField.FLOAT32),
              PointField("z", 2 * size + 4, kind)]  # fmt: skip
    point_step = 3 * size + 4 + 4  # 4 bytes of padding per point
    row_step = width * point_step + pad_row
    data = rng.integers(0, 256, height * row_step, dtype=np.uint8)
    order = ">" if bigendian else "<"
    ftype = f"{order}f{size}"
    dtype = np.dtype({"names": ["x", "y", "z"], "formats": [ftype] * 3,
                      "offsets": [0, size, 2 * size + 4], "itemsize": point_step})  # fmt: skip
    rows = np.ndarray((height, width), dtype=dtype, buffer=data, strides=(row_step, point_step))
    for name in "xyz":
        rows[name] = rng.standard_normal((height, width)) * 50.0
    cloud = PointCloud2(Header(Time(3), "laser"), height, width, fields, bigendian,
                        point_step, row_step, data.tobytes(), True)  # fmt: skip
    q = rng.standard_normal(4)
    q *= 1.3 / np.linalg.norm(q)  # non-unit: scales by |q|^2, as tf2 does
    t = rng.standard_normal(3)
    tf = TransformStamped(Header(Time(3), "odom"), "laser",
                          Transform(Vector3(*t.tolist()), Quaternion(*q.tolist())))  # fmt: skip

    out = do_transform_cloud(cloud, tf)

    assert (out.height, out.width, out.point_step, out.row_step) == (
        height, width, point_step, row_step)  # fmt: skip
    assert out.header == tf.header
    got = np.ndarray((height, width), dtype=dtype, buffer=out.data,
                     strides=(row_step, point_step))  # fmt: skip
    xyz = np.stack([rows[name].astype(np.float64).ravel() for name in "xyz"], axis=1)
    want = transform_points(tf, xyz).astype(ftype)
    for k, name in enumerate("xyz"):
        np.testing.assert_array_max_ulp(got[name].ravel(), want[:, k], maxulp=1)
    # every other byte (intensity, per-point and per-row padding) is unchanged
    before = np.frombuffer(cloud.data, dtype=np.uint8).reshape(height, row_step).copy()
    after = np.frombuffer(out.data, dtype=np.uint8).reshape(height, row_step).copy()
    for raw in (before, after):
        points = raw[:, : width * point_step].reshape(height, width, point_step)  # a view
        for off in (0, size, 2 * size + 4):
            points[:, :, off : off + size] = 0
    assert np.array_equal(before, after)
