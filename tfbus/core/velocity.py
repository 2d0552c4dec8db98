"""Velocity of one frame relative to another from two lookups (tf2 ``lookupVelocity``).

Two methods, chosen by ``method=`` of :meth:`tfbus.core.BufferCore.lookup_velocity`:

``"tf2"`` (the default) is tf2's algorithm, operation for operation: ROS 2 geometry2
``tf2/src/buffer_core.cpp`` ``BufferCore::lookupVelocity``, a copy of ROS 1
``tf/src/tf.cpp`` ``tf::Transformer::lookupTwist`` (whose integer-nanosecond time
arithmetic is the one used here; checked against Debian's C++ libtf 1.13.2 within 1e-9
by ``tests/core/test_velocity.py``):

1. ``latest`` = latest common time of observation and tracking frame; ``time`` 0 means
   ``latest`` (ROS 1; ROS 2 takes 0 literally).
2. ``end = min(time + interval/2, latest)``, ``start = max(10 µs + interval, end) -
   interval``, ``dt = end - start`` (seconds).
3. ``S``, ``E`` = pose of tracking in observation at ``start`` and ``end``;
   ``linear = (E.origin - S.origin) / dt``; the rotation ``S.basis⁻¹ E.basis`` as a
   quaternion (Bullet's matrix→quaternion), axis ``a`` and angle ``θ = 2 acos w``:
   ``angular = S.basis a θ / dt`` (all in the observation frame).
4. ``P`` = pose of tracking in the reference frame at ``time``:
   ``angular' = P.basis angular``, ``linear' = P.basis linear + P.origin cross angular'``.
5. Re-referencing to ``reference_point``: ``delta`` = the point minus the tracking
   origin, both in the reference frame at ``time``; ``linear' += angular' * delta``
   where ``*`` is tf2's ``Vector3 * Vector3``, the element-wise product.

Steps 4 and 5 are not rigid-body kinematics: a frame moving +x at 2 m/s while yawing at
1 rad/s, seen from the frame it moves in, has at t = 0.5 s a tf2 velocity of
(1.755, -0.041, 0) m/s, not (2, 0, 0): step 4 rotates a vector already expressed in the
observation frame by the tracking frame's orientation and adds ``origin cross ω``.

``"origin"`` is the physical answer with the same window and lookups: the velocity of
the tracking frame's origin (or of ``reference_point``, taken as fixed to the tracking
frame) relative to the observation frame, ``v = (E.origin - S.origin) / dt + ω cross r``
with ``ω`` as in step 3 and ``r`` the point minus the origin (observation frame, at
``time``), then both vectors rotated into the reference frame's axes at ``time``.

Pure functions over any object with ``lookup_transform`` and ``get_latest_common_time``
(a :class:`~tfbus.core.BufferCore`, which calls them); no clock, no I/O.
"""

from __future__ import annotations

import math
from numbers import Real
from typing import Final, Protocol

from tfbus.errors import InvalidArgumentException, TransformException
from tfbus.messages import Header, Twist, Vector3, VelocityStamped
from tfbus.time import Duration, Time

__all__ = [
    "METHODS",
    "VelocityLookup",
    "check_velocity_arguments",
    "lookup_velocity",
    "velocity_window",
]

METHODS: Final = ("tf2", "origin")
"""The values ``method=`` accepts."""

_V3 = tuple[float, float, float]
_M3 = tuple[_V3, _V3, _V3]
_Q = tuple[float, float, float, float]

_TEN_MICROSECONDS: Final = 10_000  # ros::Time().fromSec(.00001), in ns
_EPSILON: Final = 2.220446049250313e-16  # DBL_EPSILON (TFSIMD_EPSILON for doubles)


class VelocityLookup(Protocol):
    """What the velocity lookup needs of a buffer (a :class:`~tfbus.core.BufferCore`)."""

    def lookup_transform(self, target_frame: str, source_frame: str, time: Time) -> object:
        """The pose of ``source_frame`` in ``target_frame`` (a TransformStamped)."""
        ...

    def get_latest_common_time(self, target_frame: str, source_frame: str) -> Time:
        """tf2 ``getLatestCommonTime``."""
        ...


# ----------------------------------------------------------------- tf2 LinearMath


def _basis(q: _Q) -> _M3:
    """tf2 ``Matrix3x3::setRotation``: the rotation matrix of (x, y, z, w), scaled by
    2/|q|² as Bullet does (so a slightly unnormalised q still gives a rotation)."""
    x, y, z, w = q
    s = 2.0 / (x * x + y * y + z * z + w * w)
    xs, ys, zs = x * s, y * s, z * s
    wx, wy, wz = w * xs, w * ys, w * zs
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz, zz = y * ys, y * zs, z * zs
    return (
        (1.0 - (yy + zz), xy - wz, xz + wy),
        (xy + wz, 1.0 - (xx + zz), yz - wx),
        (xz - wy, yz + wx, 1.0 - (xx + yy)),
    )


def _cofac(m: _M3, r1: int, c1: int, r2: int, c2: int) -> float:
    return m[r1][c1] * m[r2][c2] - m[r1][c2] * m[r2][c1]


def _inverse(m: _M3) -> _M3:
    """tf2 ``Matrix3x3::inverse`` (cofactors over the determinant, not the transpose)."""
    co = (_cofac(m, 1, 1, 2, 2), _cofac(m, 1, 2, 2, 0), _cofac(m, 1, 0, 2, 1))
    det = m[0][0] * co[0] + m[0][1] * co[1] + m[0][2] * co[2]
    s = 1.0 / det
    return (
        (co[0] * s, _cofac(m, 0, 2, 2, 1) * s, _cofac(m, 0, 1, 1, 2) * s),
        (co[1] * s, _cofac(m, 0, 0, 2, 2) * s, _cofac(m, 0, 2, 1, 0) * s),
        (co[2] * s, _cofac(m, 0, 1, 2, 0) * s, _cofac(m, 0, 0, 1, 1) * s),
    )


def _matmul(a: _M3, b: _M3) -> _M3:
    rows = []
    for r in a:
        rows.append(
            (
                r[0] * b[0][0] + r[1] * b[1][0] + r[2] * b[2][0],
                r[0] * b[0][1] + r[1] * b[1][1] + r[2] * b[2][1],
                r[0] * b[0][2] + r[1] * b[1][2] + r[2] * b[2][2],
            )
        )
    return (rows[0], rows[1], rows[2])


def _mv(m: _M3, v: _V3) -> _V3:
    return (
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    )


def _cross(a: _V3, b: _V3) -> _V3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _add(a: _V3, b: _V3) -> _V3:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _sub(a: _V3, b: _V3) -> _V3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _get_rotation(m: _M3) -> _Q:
    """tf2 ``Matrix3x3::getRotation`` (Bullet's matrix → quaternion, x, y, z, w)."""
    trace = m[0][0] + m[1][1] + m[2][2]
    t = [0.0, 0.0, 0.0, 0.0]
    if trace > 0.0:
        s = math.sqrt(trace + 1.0)
        t[3] = s * 0.5
        s = 0.5 / s
        t[0] = (m[2][1] - m[1][2]) * s
        t[1] = (m[0][2] - m[2][0]) * s
        t[2] = (m[1][0] - m[0][1]) * s
    else:
        i = (2 if m[1][1] < m[2][2] else 1) if m[0][0] < m[1][1] else (
            2 if m[0][0] < m[2][2] else 0
        )
        j = (i + 1) % 3
        k = (i + 2) % 3
        s = math.sqrt(m[i][i] - m[j][j] - m[k][k] + 1.0)
        t[i] = s * 0.5
        s = 0.5 / s
        t[3] = (m[k][j] - m[j][k]) * s
        t[j] = (m[j][i] + m[i][j]) * s
        t[k] = (m[k][i] + m[i][k]) * s
    return (t[0], t[1], t[2], t[3])


def _axis(q: _Q) -> _V3:
    """tf2 ``Quaternion::getAxis``: (1, 0, 0) for a (near) identity rotation."""
    s_squared = 1.0 - q[3] * q[3]
    if s_squared < 10.0 * _EPSILON:
        return (1.0, 0.0, 0.0)
    s = 1.0 / math.sqrt(s_squared)
    return (q[0] * s, q[1] * s, q[2] * s)


def _angle(q: _Q) -> float:
    """tf2 ``Quaternion::getAngle``: 2 acos(w), w clamped to [-1, 1] (in [0, 2π])."""
    return 2.0 * math.acos(min(1.0, max(-1.0, q[3])))


# ----------------------------------------------------------------- arguments


def _interval_ns(value: object) -> int:
    if isinstance(value, Duration):
        ns = value.ns
    elif isinstance(value, Real) and not isinstance(value, bool):
        seconds = float(value)
        if not math.isfinite(seconds) or abs(seconds) > 9.2e9:
            raise InvalidArgumentException(
                f"averaging_interval must be finite seconds > 0, got {value!r}"
            )
        ns = Duration.from_sec(seconds).ns
    else:
        raise InvalidArgumentException(
            f"averaging_interval must be seconds (a real number) or a Duration, got {value!r}"
        )
    if ns <= 0:
        raise InvalidArgumentException(
            f"averaging_interval must be > 0, got {value!r} ({ns} ns)"
        )
    return ns


def _point(value: object) -> _V3:
    try:
        if isinstance(value, (str, bytes)):
            raise TypeError
        x, y, z = (float(c) for c in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        raise InvalidArgumentException(
            f"reference_point must be 3 finite numbers (metres), got {value!r}"
        ) from None
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        raise InvalidArgumentException(
            f"reference_point must be 3 finite numbers (metres), got {value!r}"
        )
    return (x, y, z)


def check_velocity_arguments(
    time: object, averaging_interval: object, reference_point: object, method: object
) -> int:
    """Validate the non-frame arguments of :func:`lookup_velocity` (before any wait).

    Returns:
        ``averaging_interval`` in int nanoseconds.

    Raises:
        InvalidArgumentException: naming the argument and its value, as
            :func:`lookup_velocity` would.
    """
    if method not in METHODS:
        raise InvalidArgumentException(f"method must be one of {METHODS}, got {method!r}")
    if not isinstance(time, Time):
        raise InvalidArgumentException(f"time must be a tfbus Time, got {time!r}")
    interval = _interval_ns(averaging_interval)
    _point(reference_point)
    return interval


def _ros1_half(ns: int) -> int:
    """``ros::Duration * 0.5`` as ROS 1 rostime computes it: through float seconds
    (``toSec() * 0.5``) and back with ``fromSec`` (floor seconds, nanoseconds rounded
    half away from zero, ``boost::math::round``)."""
    sec, nsec = divmod(ns, 1_000_000_000)
    d = (sec + 1e-9 * nsec) * 0.5
    whole = math.floor(d)
    return whole * 1_000_000_000 + math.floor((d - whole) * 1e9 + 0.5)


def _ros1_sec(ns: int) -> float:
    """``ros::Duration::toSec``: sec + 1e-9 * nsec with nsec in [0, 1e9)."""
    sec, nsec = divmod(ns, 1_000_000_000)
    return sec + 1e-9 * nsec


def velocity_window(latest: Time, time: Time, averaging_interval_ns: int) -> tuple[int, int, int]:
    """tf2's averaging window (``lookupTwist``): ``(target, start, end)`` in int ns.

    ``target`` is ``time`` or, for ``Time(0)``, ``latest``;
    ``end = min(target + interval/2, latest)``; ``start = max(10 µs + interval, end) -
    interval`` (``interval/2`` rounded as ROS 1 ``Duration * 0.5``).
    """
    target = latest.ns if time.ns == 0 else time.ns
    end = min(target + _ros1_half(averaging_interval_ns), latest.ns)
    start = max(_TEN_MICROSECONDS + averaging_interval_ns, end) - averaging_interval_ns
    return target, start, end


# ----------------------------------------------------------------- the lookup


def _pose(core: VelocityLookup, target: str, source: str, ns: int) -> tuple[_V3, _Q]:
    ts = core.lookup_transform(target, source, Time.from_ns(ns))
    tr, rot = ts.transform  # type: ignore[attr-defined]
    return (float(tr[0]), float(tr[1]), float(tr[2])), (
        float(rot[0]),
        float(rot[1]),
        float(rot[2]),
        float(rot[3]),
    )


def lookup_velocity(
    core: VelocityLookup,
    tracking_frame: str,
    observation_frame: str,
    reference_frame: str,
    reference_point: object,
    reference_point_frame: str,
    time: Time,
    averaging_interval: Duration | float,
    method: str = "tf2",
) -> VelocityStamped:
    """The velocity of ``tracking_frame`` relative to ``observation_frame``, expressed in
    ``reference_frame`` about ``reference_point`` (metres, in ``reference_point_frame``),
    averaged over ``averaging_interval`` around ``time`` (see the module docs for both
    methods and their sources).

    Returns:
        VelocityStamped: ``header.frame_id = reference_frame``, ``header.stamp`` the
        window's start plus half the interval (as ROS 2), ``body_frame_id =
        tracking_frame``, ``reference_frame_id = observation_frame`` (ROS 2 leaves it
        empty); ``velocity.linear`` m/s, ``velocity.angular`` rad/s.

    Raises:
        InvalidArgumentException: ``averaging_interval`` ≤ 0, NaN, Inf or not a number
            or Duration; ``reference_point`` not 3 finite numbers; ``method`` unknown;
            ``time`` not a Time; the window is empty (``end == start``, data only up to
            10 µs + interval); or a frame id as the lookups raise it.
        LookupException, ConnectivityException, ExtrapolationException: from the
            lookups (window ends, then the reference frame at ``time``).
    """
    interval = check_velocity_arguments(time, averaging_interval, reference_point, method)
    point = _point(reference_point)
    try:
        latest = core.get_latest_common_time(observation_frame, tracking_frame)
    except TransformException:
        latest = Time(0)  # as tf2 (error code ignored); the lookups below raise
    target, start, end = velocity_window(latest, time, interval)
    dt = _ros1_sec(end - start)
    s_origin, s_q = _pose(core, observation_frame, tracking_frame, start)
    e_origin, e_q = _pose(core, observation_frame, tracking_frame, end)
    if dt == 0.0:
        raise InvalidArgumentException(
            f"averaging window is empty: start == end == {end} ns (latest common time "
            f"{latest.ns} ns, averaging_interval {interval} ns)"
        )
    s_basis = _basis(s_q)
    rel = _get_rotation(_matmul(_inverse(s_basis), _basis(e_q)))
    o = _mv(s_basis, _axis(rel))
    rate = _angle(rel) / dt
    twist_rot = (o[0] * rate, o[1] * rate, o[2] * rate)
    twist_vel = (
        (e_origin[0] - s_origin[0]) / dt,
        (e_origin[1] - s_origin[1]) / dt,
        (e_origin[2] - s_origin[2]) / dt,
    )
    if method == "origin":
        twist_rot = _mv(s_basis, _rotation_vector(s_q, e_q, dt))
    if method == "tf2":
        linear, angular = _tf2_reexpress(
            core, tracking_frame, reference_frame, point, reference_point_frame,
            target, twist_vel, twist_rot,
        )
    else:
        linear, angular = _origin_reexpress(
            core, tracking_frame, observation_frame, reference_frame, point,
            reference_point_frame, target, twist_vel, twist_rot,
        )
    return VelocityStamped(
        Header(Time.from_ns(start + _ros1_half(interval)), reference_frame),
        tracking_frame,
        observation_frame,
        Twist(Vector3(*linear), Vector3(*angular)),
    )


def _tf2_reexpress(
    core: VelocityLookup,
    tracking: str,
    reference: str,
    point: _V3,
    point_frame: str,
    target: int,
    twist_vel: _V3,
    twist_rot: _V3,
) -> tuple[_V3, _V3]:
    """Steps 4 and 5 of tf2's ``lookupTwist`` (module docs), verbatim."""
    inv_origin, inv_q = _pose(core, reference, tracking, target)
    inv_basis = _basis(inv_q)
    out_rot = _mv(inv_basis, twist_rot)
    out_vel = _add(_mv(inv_basis, twist_vel), _cross(inv_origin, out_rot))
    rp_orig = _add(_mv(inv_basis, (0.0, 0.0, 0.0)), inv_origin)
    d_origin, d_q = _pose(core, reference, point_frame, target)
    rp_desired = _add(_mv(_basis(d_q), point), d_origin)
    delta = _sub(rp_desired, rp_orig)
    out_vel = (
        out_vel[0] + out_rot[0] * delta[0],
        out_vel[1] + out_rot[1] * delta[1],
        out_vel[2] + out_rot[2] * delta[2],
    )
    return out_vel, out_rot


def _rotation_vector(q_start: _Q, q_end: _Q, dt: float) -> _V3:
    """Angular velocity (rad/s, start-frame axes) of the rotation from ``q_start`` to
    ``q_end`` in ``dt`` s: conj(q_start) ⊗ q_end as axis · angle, the angle by atan2
    (well conditioned near zero, where tf2's 2·acos(w) amplifies rounding), taking the
    shorter way round (the quaternion with w ≥ 0)."""
    ax, ay, az, aw = -q_start[0], -q_start[1], -q_start[2], q_start[3]
    bx, by, bz, bw = q_end
    x = aw * bx + ax * bw + ay * bz - az * by
    y = aw * by - ax * bz + ay * bw + az * bx
    z = aw * bz + ax * by - ay * bx + az * bw
    w = aw * bw - ax * bx - ay * by - az * bz
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    n = math.sqrt(x * x + y * y + z * z)
    if n == 0.0:
        return (0.0, 0.0, 0.0)
    k = 2.0 * math.atan2(n, w) / (n * dt)
    return (x * k, y * k, z * k)


def _origin_reexpress(
    core: VelocityLookup,
    tracking: str,
    observation: str,
    reference: str,
    point: _V3,
    point_frame: str,
    target: int,
    twist_vel: _V3,
    twist_rot: _V3,
) -> tuple[_V3, _V3]:
    """The physical velocity of the point fixed to the tracking frame (module docs)."""
    origin, _ = _pose(core, observation, tracking, target)
    p_origin, p_q = _pose(core, observation, point_frame, target)
    r = _sub(_add(_mv(_basis(p_q), point), p_origin), origin)
    v_obs = _add(twist_vel, _cross(twist_rot, r))
    _, ro_q = _pose(core, reference, observation, target)
    ro = _basis(ro_q)
    return _mv(ro, v_obs), _mv(ro, twist_rot)

