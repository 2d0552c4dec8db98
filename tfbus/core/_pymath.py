"""tf2's scalar transform math and its row kernels in pure Python: the twin of the
compiled :mod:`tfbus.core._cmath`, same numbers bit for bit (Python floats are IEEE
doubles, each ``+ - * /`` one separately rounded operation, ``math.sin`` / ``acos`` /
``sqrt`` the C library's; where Python raises and C does not, the IEEE result is produced
instead: :func:`_div`, :func:`_sin`). Also the C-semantics helpers (:func:`_cint`,
:func:`_int64`, :func:`_double`, the array checks of :func:`_view`) the other pure
modules use to behave as the compiled ones do.

Known difference: the compiled ``compose`` / ``inverse`` / ``compose_full`` read their
7-sequences without bounds checks (a shorter tuple is undefined behaviour there); here a
short sequence raises IndexError.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Final

import numpy as np
import numpy.typing as npt

__all__ = [
    "apply_transforms",
    "compose",
    "compose_full",
    "inverse",
    "lerp_rows",
    "quat_multiply",
    "quat_rotate",
    "slerp",
    "slerp_rows",
]

Tf7 = tuple[float, float, float, float, float, float, float]
"""A transform: (tx, ty, tz, qx, qy, qz, qw), metres and an (x, y, z, w) quaternion."""
_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]
_I32 = npt.NDArray[np.int32]


_INT64_MAX: Final = 2**63 - 1
_INT64_MIN: Final = -(2**63)
_INT_MAX: Final = 2**31 - 1
_INT_MIN: Final = -(2**31)
_IDENTITY: Final[Tf7] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
_INF: Final = math.inf
_new: Final = tuple.__new__  # a NamedTuple without its Python-level __new__

# ---------------------------------------------------------------------- C semantics


def _c_int(value: Any, lo: int, hi: int, ctype: str) -> int:
    """``value`` converted as Cython converts an argument to a C integer: ints as they
    are, other numbers truncated by ``__int__`` / ``__index__``, OverflowError outside
    [lo, hi], TypeError for anything else."""
    if type(value) is not int:
        cls = type(value)
        if isinstance(value, (str, bytes, bytearray)) or not (
            hasattr(cls, "__int__") or hasattr(cls, "__index__")
        ):
            raise TypeError(f"'{cls.__name__}' object cannot be interpreted as an integer")
        value = int(value)
    if not lo <= value <= hi:
        if ctype == "int":
            raise OverflowError("value too large to convert to int")
        raise OverflowError(f"Python int too large to convert to C {ctype}")
    return int(value)


def _int64(value: Any) -> int:
    return _c_int(value, _INT64_MIN, _INT64_MAX, "long")


def _cint(value: Any) -> int:
    return _c_int(value, _INT_MIN, _INT_MAX, "int")


def _double(value: Any) -> float:
    """``value`` converted as Cython converts an argument to a C double
    (``PyFloat_AsDouble``: ``__float__``, else ``__index__``; no strings)."""
    if type(value) is float:
        return value
    cls = type(value)
    if isinstance(value, float) or (
        hasattr(cls, "__float__") and not isinstance(value, (str, bytes, bytearray))
    ):
        return float(value)
    if hasattr(cls, "__index__"):
        return float(value.__index__())
    raise TypeError(f"must be real number, not {cls.__name__}")


def _tp_name(value: object) -> str:
    """The C ``tp_name`` of ``value``'s type, as Cython's argument errors print it:
    ``module.name`` for a static (C) type outside builtins, the bare name otherwise."""
    cls = type(value)
    if cls.__flags__ & (1 << 9) or cls.__module__ == "builtins":  # Py_TPFLAGS_HEAPTYPE
        return cls.__name__
    return f"{cls.__module__}.{cls.__name__}"


def _div(a: float, b: float) -> float:
    """``a / b`` with C's IEEE semantics: a zero divisor gives ±inf or NaN, not
    ZeroDivisionError."""
    if b != 0.0 or b != b:
        return a / b
    if a != a:
        return a + b  # NaN
    if a == 0.0:
        return _INF - _INF  # 0/0: NaN
    return math.copysign(_INF, a) * math.copysign(1.0, b)


def _sin(x: float) -> float:
    """C ``sin``: ``sin(±inf)`` is NaN (math.sin raises)."""
    if x == _INF or x == -_INF:
        return x - x
    return math.sin(x)

# ---------------------------------------------------------------------- scalar math
#
# The scalar transform arithmetic of tf2 (``tf2/LinearMath/Quaternion.h``, ``Vector3.h``;
# ``buffer_core.cpp`` ``TransformAccum``) in tf2's evaluation order, as in _cmath.pxd.


def _qrot(
    qx: float, qy: float, qz: float, qw: float, vx: float, vy: float, vz: float
) -> tuple[float, float, float]:
    # tf2 quatRotate: q ⊗ (v, 0) ⊗ conj(q), vector part.
    tx = qw * vx + qy * vz - qz * vy
    ty = qw * vy + qz * vx - qx * vz
    tz = qw * vz + qx * vy - qy * vx
    tw = -qx * vx - qy * vy - qz * vz
    return (
        -tw * qx + tx * qw - ty * qz + tz * qy,
        -tw * qy + ty * qw - tz * qx + tx * qz,
        -tw * qz + tz * qw - tx * qy + ty * qx,
    )


def _qmul(
    ax: float, ay: float, az: float, aw: float, bx: float, by: float, bz: float, bw: float
) -> tuple[float, float, float, float]:
    # Quaternion.h operator*: Hamilton product a ⊗ b.
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by + ay * bw + az * bx - ax * bz,
        aw * bz + az * bw + ax * by - ay * bx,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _compose(a: Sequence[float], b: Sequence[float]) -> Tf7:
    # a ∘ b (apply b, then a): t = quatRotate(qa, tb) + ta, q = qa ⊗ qb (TransformAccum).
    ax, ay, az, aqx, aqy, aqz, aqw = a[0], a[1], a[2], a[3], a[4], a[5], a[6]
    rx, ry, rz = _qrot(aqx, aqy, aqz, aqw, b[0], b[1], b[2])
    qx, qy, qz, qw = _qmul(aqx, aqy, aqz, aqw, b[3], b[4], b[5], b[6])
    return (rx + ax, ry + ay, rz + az, qx, qy, qz, qw)


def _slerp(
    ax: float,
    ay: float,
    az: float,
    aw: float,
    bx: float,
    by: float,
    bz: float,
    bw: float,
    r: float,
) -> tuple[float, float, float, float]:
    # Quaternion.h slerp / angleShortestPath; tf2Acos's clamp makes a cosine >= 1 a zero
    # angle, for which tf2 returns a unchanged.
    dot = ax * bx + ay * by + az * bz + aw * bw
    if dot < 0.0:
        dot = -dot
        bx = -bx
        by = -by
        bz = -bz
        bw = -bw
    c = _div(
        dot,
        math.sqrt(
            (ax * ax + ay * ay + az * az + aw * aw) * (bx * bx + by * by + bz * bz + bw * bw)
        ),
    )
    if c >= 1.0:
        return (ax, ay, az, aw)
    theta = math.acos(c)  # c is in [0, 1) or NaN here: NaN only for NaN input, as in tf2
    d = _div(1.0, math.sin(theta))
    s0 = _sin((1.0 - r) * theta)
    s1 = _sin(r * theta)
    return (
        (ax * s0 + bx * s1) * d,
        (ay * s0 + by * s1) * d,
        (az * s0 + bz * s1) * d,
        (aw * s0 + bw * s1) * d,
    )


def quat_multiply(
    ax: float, ay: float, az: float, aw: float, bx: float, by: float, bz: float, bw: float
) -> tuple[float, float, float, float]:
    """Hamilton product ``a ⊗ b`` of two (x, y, z, w) quaternions, as ``(x, y, z, w)``
    (tf2 ``Quaternion.h`` ``operator*``).

    Raises:
        TypeError: an argument is not a real number.
    """
    return _qmul(
        _double(ax), _double(ay), _double(az), _double(aw),
        _double(bx), _double(by), _double(bz), _double(bw),
    )  # fmt: skip


def quat_rotate(
    qx: float, qy: float, qz: float, qw: float, vx: float, vy: float, vz: float
) -> tuple[float, float, float]:
    """Vector ``(vx, vy, vz)`` rotated by quaternion q (x, y, z, w) as ``q ⊗ (v, 0) ⊗
    conj(q)`` (tf2 ``quatRotate``); scaled by ``|q|²`` for a non-unit q, exactly as tf2.

    Raises:
        TypeError: an argument is not a real number.
    """
    return _qrot(
        _double(qx), _double(qy), _double(qz), _double(qw),
        _double(vx), _double(vy), _double(vz),
    )  # fmt: skip


def _seven(values: Sequence[float]) -> Tf7:
    return (
        _double(values[0]), _double(values[1]), _double(values[2]), _double(values[3]),
        _double(values[4]), _double(values[5]), _double(values[6]),
    )  # fmt: skip


def compose(a: Sequence[float], b: Sequence[float]) -> Tf7:
    """``a ∘ b`` of two 7-tuples ``(tx, ty, tz, qx, qy, qz, qw)`` (metres; x, y, z, w):
    apply b, then a (tf2 ``TransformAccum::accum``).

    Raises:
        TypeError: a component is not a real number. IndexError: fewer than 7 values.
    """
    x = _seven(a)
    y = _seven(b)
    return _compose(x, y)


def inverse(a: Sequence[float]) -> Tf7:
    """tf2's inverse of a 7-tuple: rotation ``conj(q)``, translation ``quatRotate(conj(q),
    -t)`` (``TransformAccum::finalize``); exact for unit quaternions.

    Raises:
        TypeError: a component is not a real number. IndexError: fewer than 7 values.
    """
    # As compiled: the rotation part is returned as ``-a[k]`` / ``a[6]`` of the objects
    # given (an int stays an int), the translation computed in doubles.
    rx, ry, rz = _qrot(
        _double(-a[3]), _double(-a[4]), _double(-a[5]), _double(a[6]),
        _double(-a[0]), _double(-a[1]), _double(-a[2]),
    )  # fmt: skip
    return (rx, ry, rz, -a[3], -a[4], -a[5], a[6])


def slerp(
    ax: float,
    ay: float,
    az: float,
    aw: float,
    bx: float,
    by: float,
    bz: float,
    bw: float,
    ratio: float,
) -> tuple[float, float, float, float]:
    """tf2's shortest-path spherical interpolation from a (ratio 0) to b (ratio 1) of two
    (x, y, z, w) quaternions, not normalised (Quaternion.h ``slerp``): half-angle
    ``acos(|a·b| / sqrt(|a|²|b|²))``, towards ``-b`` when ``a·b < 0``, ``a`` unchanged
    when the cosine rounds to 1 or above.

    Raises:
        TypeError: an argument is not a real number.
    """
    return _slerp(
        _double(ax), _double(ay), _double(az), _double(aw),
        _double(bx), _double(by), _double(bz), _double(bw), _double(ratio),
    )  # fmt: skip


def compose_full(leg2: Sequence[float], leg1: Sequence[float]) -> Tf7:
    """tf2's time-travel composition ``leg2 ∘ leg1`` of two 7-tuples
    (``lookupTransform`` with a fixed frame): both rotations are normalised first, as
    ``tf2::Transform`` keeps a normalised rotation matrix, and so is the result's.

    Raises:
        TypeError: a component is not a real number. IndexError: fewer than 7 values.
    """
    a = list(_seven(leg2))
    b = list(_seven(leg1))
    n = math.sqrt(a[3] * a[3] + a[4] * a[4] + a[5] * a[5] + a[6] * a[6])
    for k in range(3, 7):
        a[k] = _div(a[k], n)
    n = math.sqrt(b[3] * b[3] + b[4] * b[4] + b[5] * b[5] + b[6] * b[6])
    for k in range(3, 7):
        b[k] = _div(b[k], n)
    c = _compose(a, b)
    n = math.sqrt(c[3] * c[3] + c[4] * c[4] + c[5] * c[5] + c[6] * c[6])
    return (c[0], c[1], c[2], _div(c[3], n), _div(c[4], n), _div(c[5], n), _div(c[6], n))

# ---------------------------------------------------------------------- arrays
#
# The compiled functions below take typed memoryviews; these checks give the same
# exception types (and Cython's messages) for arrays of the wrong kind.

_C_NAMES: Final = {
    ("f", 8): "double",
    ("f", 4): "float",
    ("f", 2): "half",
    ("i", 8): "long",
    ("i", 4): "int",
    ("i", 2): "short",
    ("i", 1): "signed char",
    ("u", 8): "unsigned long",
    ("u", 4): "unsigned int",
    ("u", 2): "unsigned short",
    ("u", 1): "unsigned char",
    ("b", 1): "bool",
}


def _view(obj: object, kind: str, size: int, ctype: str, ndim: int, writable: bool) -> Any:
    """``obj`` as a C-contiguous ndarray of ``ndim`` dimensions of one C type (kind and
    item size), as a Cython typed memoryview argument accepts it."""
    if isinstance(obj, np.ndarray):
        arr = obj
    else:
        try:
            arr = np.asarray(memoryview(obj))  # type: ignore[arg-type]
        except TypeError:
            raise TypeError(
                f"a bytes-like object is required, not '{type(obj).__name__}'"
            ) from None
    if writable and not arr.flags.writeable:
        raise ValueError("buffer source array is read-only")
    if not arr.flags.c_contiguous:
        raise ValueError("ndarray is not C-contiguous")
    if arr.ndim != ndim:
        raise ValueError(f"Buffer has wrong number of dimensions (expected {ndim}, got {arr.ndim})")
    if (arr.dtype.kind, arr.dtype.itemsize) != (kind, size):
        got = _C_NAMES.get((arr.dtype.kind, arr.dtype.itemsize), arr.dtype.str)
        raise ValueError(f"Buffer dtype mismatch, expected '{ctype}' but got '{got}'")
    return arr

# ----- per-point tf2 math for sensor data (laser projection)


def slerp_rows(a: Sequence[float], b: Sequence[float], ratios: _F64, out: _F64) -> None:
    """tf2 ``Quaternion::slerp(a, b, r)`` for every r of ``ratios`` (``(N,) float64``)
    into ``out`` (``(N, 4) float64``, x, y, z, w): the angle (``angleShortestPath``,
    ``tf2Acos``'s clamp) and ``1/sin`` are computed once, each row as :func:`slerp`
    computes it (a zero angle returns ``a``; laser_geometry
    ``transformLaserScanToPointCloud_`` calls this per beam).

    Raises:
        ValueError: ``out`` is not ``(N, 4)``, or an array has the wrong dtype/layout.
    """
    rs = _view(ratios, "f", 8, "const double", 1, False)
    o = _view(out, "f", 8, "double", 2, True)
    n = rs.shape[0]
    if o.shape[0] != n or o.shape[1] != 4:
        raise ValueError("slerp_rows: out must be (N, 4) for N ratios")
    ax, ay, az, aw = _double(a[0]), _double(a[1]), _double(a[2]), _double(a[3])
    bx, by, bz, bw = _double(b[0]), _double(b[1]), _double(b[2]), _double(b[3])
    dot = ax * bx + ay * by + az * bz + aw * bw
    if dot < 0.0:
        dot = -dot
        bx, by, bz, bw = -bx, -by, -bz, -bw
    c = _div(
        dot,
        math.sqrt(
            (ax * ax + ay * ay + az * az + aw * aw) * (bx * bx + by * by + bz * bz + bw * bw)
        ),
    )
    if c >= 1.0:
        o[:] = (ax, ay, az, aw)
        return
    theta = math.acos(c)
    d = _div(1.0, math.sin(theta))
    rows = []
    for r in rs.tolist():
        s0 = _sin((1.0 - r) * theta)
        s1 = _sin(r * theta)
        rows.append(
            ((ax * s0 + bx * s1) * d, (ay * s0 + by * s1) * d,
             (az * s0 + bz * s1) * d, (aw * s0 + bw * s1) * d)
        )  # fmt: skip
    if rows:
        o[:] = rows


def apply_transforms(q: _F64, v: _F64, p: _F64, out: _F64) -> None:
    """Point i mapped by the tf2::Transform with rotation ``q[i]`` (x, y, z, w) and origin
    ``v[i]`` (metres), as tf2 computes it: ``Matrix3x3::setRotation`` (its basis, which
    normalises q) then ``Transform::operator()`` (``p.dot3(row0, row1, row2) +
    origin``), in tf2's evaluation order (each numpy operation below is one IEEE
    operation per element). ``q`` (N, 4) or (1, 4), ``v`` (N, 3) or (1, 3), ``p`` and
    ``out`` (N, 3) float64; a single row is used for every point.

    Raises:
        ValueError: shapes other than those, or an array of the wrong dtype/layout.
    """
    qa = _view(q, "f", 8, "const double", 2, False)
    va = _view(v, "f", 8, "const double", 2, False)
    pa = _view(p, "f", 8, "const double", 2, False)
    o = _view(out, "f", 8, "double", 2, True)
    n = pa.shape[0]
    one_q = qa.shape[0] == 1
    one_v = va.shape[0] == 1
    if (
        pa.shape[1] != 3
        or o.shape[0] != n
        or o.shape[1] != 3
        or qa.shape[1] != 4
        or va.shape[1] != 3
        or not (one_q or qa.shape[0] == n)
        or not (one_v or va.shape[0] == n)
    ):
        raise ValueError("apply_transforms: q (N|1, 4), v (N|1, 3), p and out (N, 3)")
    if n == 0:
        return
    x, y, z, w = qa[:, 0], qa[:, 1], qa[:, 2], qa[:, 3]
    with np.errstate(all="ignore"):  # C: IEEE results, no warnings
        s = 2.0 / (((x * x + y * y) + z * z) + w * w)
        xs = x * s
        ys = y * s
        zs = z * s
        wx = w * xs
        wy = w * ys
        wz = w * zs
        xx = x * xs
        xy = x * ys
        xz = x * zs
        yy = y * ys
        yz = y * zs
        zz = z * zs
        m00 = 1.0 - (yy + zz)
        m01 = xy - wz
        m02 = xz + wy
        m10 = xy + wz
        m11 = 1.0 - (xx + zz)
        m12 = yz - wx
        m20 = xz - wy
        m21 = yz + wx
        m22 = 1.0 - (xx + yy)
        p0, p1, p2 = pa[:, 0], pa[:, 1], pa[:, 2]
        o[:, 0] = ((m00 * p0 + m01 * p1) + m02 * p2) + va[:, 0]
        o[:, 1] = ((m10 * p0 + m11 * p1) + m12 * p2) + va[:, 1]
        o[:, 2] = ((m20 * p0 + m21 * p1) + m22 * p2) + va[:, 2]


def lerp_rows(a: Sequence[float], b: Sequence[float], ratios: _F64, out: _F64) -> None:
    """``(1 - r) * a + r * b`` per component for every r of ``ratios`` (``(N,)
    float64``) into ``out`` (``(N, 3) float64``): tf2 ``lerp`` of two origins (metres),
    as laser_geometry interpolates the viewpoint between the first and last beam.

    Raises:
        ValueError: ``out`` is not ``(N, 3)``, or an array of the wrong dtype/layout.
    """
    rs = _view(ratios, "f", 8, "const double", 1, False)
    o = _view(out, "f", 8, "double", 2, True)
    n = rs.shape[0]
    if o.shape[0] != n or o.shape[1] != 3:
        raise ValueError("lerp_rows: out must be (N, 3) for N ratios")
    va = (_double(a[0]), _double(a[1]), _double(a[2]))
    vb = (_double(b[0]), _double(b[1]), _double(b[2]))
    with np.errstate(all="ignore"):
        s = 1.0 - rs
        for k in range(3):
            o[:, k] = s * va[k] + rs * vb[k]
