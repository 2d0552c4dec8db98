"""sensor_msgs value types: LaserScan, PointCloud2, PointField, plus numpy helpers.

Field names, types and constants are sensor_msgs' (``LaserScan.msg``,
``PointCloud2.msg``, ``PointField.msg``). Array fields are numpy arrays of the message's
element type: a LaserScan's ``ranges`` and ``intensities`` are ``(N,) float32`` (metres
and device units), a PointCloud2's ``data`` is ``bytes``. The helpers follow
sensor_msgs_py's ``point_cloud2`` (ROS 2): :func:`read_points` returns a numpy structured
array with one named field per PointField, :func:`create_cloud` builds a cloud from one.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from tfbus.messages import Header

__all__ = [
    "LaserScan",
    "PointCloud2",
    "PointField",
    "create_cloud",
    "create_cloud_xyz32",
    "dtype_from_fields",
    "read_points",
]

_F32 = npt.NDArray[np.float32]


def _float32_array(value: Any, name: str) -> _F32:
    """``value`` as a contiguous ``(N,) float32`` array: a sequence or array of real
    numbers. ``np.ascontiguousarray`` alone makes ``None`` or a scalar one beam (NaN, or
    the scalar), and parses strings: those are refused."""
    if type(value) is np.ndarray and value.ndim == 1 and value.dtype.kind in "fiu":
        return np.ascontiguousarray(value, dtype=np.float32)  # the usual case, at once
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as err:
        raise ValueError(f"LaserScan.{name} must be a sequence of numbers, got "
                         f"{_shown(value)} ({err})") from None
    if raw.ndim != 1:
        raise ValueError(f"LaserScan.{name} must be one-dimensional, got shape {raw.shape}"
                         + (f" ({_shown(value)})" if raw.ndim == 0 else ""))
    if raw.dtype.kind not in "fiu" and raw.size:
        raise ValueError(f"LaserScan.{name} must hold numbers, got {raw.dtype} values "
                         f"({_shown(value)})")
    return np.ascontiguousarray(raw, dtype=np.float32)


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else f"a {type(value).__name__} ({text[:40]}...)"


@dataclass(eq=False)
class LaserScan:
    """sensor_msgs/LaserScan: one sweep of a planar laser range finder.

    Attributes:
        header: ``stamp`` is the acquisition time of the first beam; ``frame_id`` the
            laser frame (x forward, angles counter-clockwise about z, REP 103).
        angle_min, angle_max: angles of the first and last beam, radians (float32).
        angle_increment: angle between beams, radians (may be negative).
        time_increment: time between beams, seconds (0 if unknown).
        scan_time: time between scans, seconds.
        range_min, range_max: valid range limits, metres.
        ranges: ``(N,) float32`` metres (NaN / ±inf allowed; filtered on projection).
        intensities: ``(N,) float32`` or empty.

    Raises:
        ValueError: ``ranges`` or ``intensities`` is not a one-dimensional sequence of
            numbers (``None``, a scalar, strings, a 2-D array).
    """

    header: Header = field(default_factory=Header)
    angle_min: float = 0.0
    angle_max: float = 0.0
    angle_increment: float = 0.0
    time_increment: float = 0.0
    scan_time: float = 0.0
    range_min: float = 0.0
    range_max: float = 0.0
    ranges: _F32 = field(default_factory=lambda: np.zeros(0, dtype=np.float32))
    intensities: _F32 = field(default_factory=lambda: np.zeros(0, dtype=np.float32))

    def __post_init__(self) -> None:
        self.ranges = _float32_array(self.ranges, "ranges")
        self.intensities = _float32_array(self.intensities, "intensities")
        # float32 on the wire: keep exactly what a ROS peer would see.
        for name in (
            "angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
            "range_min", "range_max",
        ):  # fmt: skip
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.floating, np.integer)):
                raise ValueError(f"LaserScan.{name} must be a number, got {value!r}")
            setattr(self, name, float(np.float32(value)))


@dataclass(frozen=True)
class PointField:
    """sensor_msgs/PointField: one named field of a PointCloud2 point.

    Attributes:
        name: field name (``"x"``, ``"intensity"``, ...).
        offset: byte offset from the start of the point.
        datatype: one of the constants INT8 ... FLOAT64.
        count: number of elements (1 for a scalar).
    """

    name: str
    offset: int
    datatype: int
    count: int = 1

    INT8: Final = 1
    UINT8: Final = 2
    INT16: Final = 3
    UINT16: Final = 4
    INT32: Final = 5
    UINT32: Final = 6
    FLOAT32: Final = 7
    FLOAT64: Final = 8


_DATATYPES: Final[dict[int, np.dtype[Any]]] = {
    PointField.INT8: np.dtype(np.int8),
    PointField.UINT8: np.dtype(np.uint8),
    PointField.INT16: np.dtype(np.int16),
    PointField.UINT16: np.dtype(np.uint16),
    PointField.INT32: np.dtype(np.int32),
    PointField.UINT32: np.dtype(np.uint32),
    PointField.FLOAT32: np.dtype(np.float32),
    PointField.FLOAT64: np.dtype(np.float64),
}
_FROM_DTYPE: Final[dict[np.dtype[Any], int]] = {v: k for k, v in _DATATYPES.items()}


@dataclass(eq=False)
class PointCloud2:
    """sensor_msgs/PointCloud2: ``height * width`` points of ``point_step`` bytes each.

    Attributes:
        header: stamp and frame of the points.
        height, width: rows and points per row (height 1 for an unordered cloud).
        fields: the layout of one point.
        is_bigendian: byte order of ``data``.
        point_step: bytes per point; row_step: bytes per row.
        data: ``row_step * height`` bytes.
        is_dense: True if there are no invalid points.
    """

    header: Header = field(default_factory=Header)
    height: int = 1
    width: int = 0
    fields: list[PointField] = field(default_factory=list)
    is_bigendian: bool = False
    point_step: int = 0
    row_step: int = 0
    data: bytes = b""
    is_dense: bool = False


def dtype_from_fields(
    fields: Sequence[PointField], point_step: int | None = None, is_bigendian: bool = False
) -> np.dtype[np.void]:
    """The numpy structured dtype of one point (sensor_msgs_py ``dtype_from_fields``).

    Raises:
        ValueError: unknown datatype, duplicate name, or a field outside ``point_step``.
    """
    names: list[str] = []
    formats: list[Any] = []
    offsets: list[int] = []
    for f in fields:
        base = _DATATYPES.get(f.datatype)
        if base is None:
            raise ValueError(f"PointField {f.name!r} has unknown datatype {f.datatype!r}")
        if f.name in names:
            raise ValueError(f"PointField name {f.name!r} appears twice")
        if f.offset < 0 or f.count < 1:
            raise ValueError(f"PointField {f.name!r} has offset {f.offset}, count {f.count}")
        dt = base.newbyteorder(">" if is_bigendian else "<")
        names.append(f.name)
        formats.append(dt if f.count == 1 else (dt, (f.count,)))
        offsets.append(f.offset)
    spec: dict[str, Any] = {"names": names, "formats": formats, "offsets": offsets}
    if point_step is not None:
        spec["itemsize"] = point_step
    try:
        dtype: np.dtype[np.void] = np.dtype(spec)  # type: ignore[call-overload]
    except ValueError as exc:
        raise ValueError(f"fields do not fit point_step {point_step}: {exc}") from None
    return dtype


def read_points(
    cloud: PointCloud2, field_names: Sequence[str] | None = None, skip_nans: bool = False
) -> np.ndarray[Any, np.dtype[np.void]]:
    """The cloud's points as a ``(height * width,)`` numpy structured array
    (sensor_msgs_py ``read_points``; a copy, in native byte order).

    Args:
        field_names: keep only these fields (in this order); None keeps all.
        skip_nans: drop points with a NaN in any kept float field.

    Raises:
        ValueError: ``data`` is shorter than the layout needs, or an unknown field name.
    """
    dtype = dtype_from_fields(cloud.fields, cloud.point_step, cloud.is_bigendian)
    n = cloud.height * cloud.width
    need = (cloud.height - 1) * cloud.row_step + cloud.width * cloud.point_step if n else 0
    if n and (cloud.row_step < cloud.width * cloud.point_step or len(cloud.data) < need):
        raise ValueError(
            f"PointCloud2 data has {len(cloud.data)} bytes; height {cloud.height}, width "
            f"{cloud.width}, row_step {cloud.row_step}, point_step {cloud.point_step}"
        )
    rows = [
        np.frombuffer(cloud.data, dtype=dtype, count=cloud.width, offset=r * cloud.row_step)
        for r in range(cloud.height)
    ]
    points = np.concatenate(rows) if n else np.zeros(0, dtype=dtype)
    if field_names is not None:
        missing = [name for name in field_names if name not in (dtype.names or ())]
        if missing:
            raise ValueError(f"PointCloud2 has no field(s) {missing}")
        points = points[list(field_names)]
    out = np.array(points, dtype=points.dtype.newbyteorder("="), copy=True)
    if skip_nans and len(out):
        keep = np.ones(len(out), dtype=bool)
        for name in out.dtype.names or ():
            col = out[name]
            if col.dtype.kind == "f":
                keep &= ~np.isnan(col.reshape(len(out), -1)).any(axis=1)
        out = out[keep]
    return out


def create_cloud(
    header: Header, fields: Sequence[PointField], points: npt.ArrayLike
) -> PointCloud2:
    """A PointCloud2 (height 1, little-endian, point_step from the fields) holding
    ``points`` (sensor_msgs_py ``create_cloud``).

    Args:
        points: a structured array with the fields' names, or an ``(N, len(fields))``
            array of numbers (one column per scalar field).

    Raises:
        ValueError: the points do not match the fields.
    """
    point_step = (
        max((f.offset + _DATATYPES[f.datatype].itemsize * f.count for f in fields), default=0)
        if all(f.datatype in _DATATYPES for f in fields)
        else -1
    )
    if point_step < 0:
        raise ValueError("fields contain an unknown datatype")
    dtype = dtype_from_fields(fields, point_step)
    arr = np.asarray(points)
    if arr.dtype.names is None:
        if arr.ndim != 2 or arr.shape[1] != len(fields):
            raise ValueError(
                f"points must be a structured array or (N, {len(fields)}), got {arr.shape}"
            )
        out = np.zeros(arr.shape[0], dtype=dtype)
        for k, f in enumerate(fields):
            out[f.name] = arr[:, k]
    else:
        out = np.zeros(arr.shape[0], dtype=dtype)
        for f in fields:
            if f.name not in arr.dtype.names:
                raise ValueError(f"points have no field {f.name!r}")
            out[f.name] = arr[f.name]
    data = out.tobytes()
    if sys.byteorder != "little":  # pragma: no cover - big-endian hosts
        data = out.byteswap().tobytes()
    return PointCloud2(
        header=header, height=1, width=len(out), fields=list(fields), is_bigendian=False,
        point_step=point_step, row_step=point_step * len(out), data=data, is_dense=False,
    )  # fmt: skip


def create_cloud_xyz32(header: Header, points: npt.ArrayLike) -> PointCloud2:
    """A cloud of float32 x, y, z fields from ``(N, 3)`` points, metres
    (sensor_msgs_py ``create_cloud_xyz32``)."""
    fields = [
        PointField("x", 0, PointField.FLOAT32),
        PointField("y", 4, PointField.FLOAT32),
        PointField("z", 8, PointField.FLOAT32),
    ]
    return create_cloud(header, fields, points)
