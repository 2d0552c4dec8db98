"""Tests for tfbus.geometry: known numbers first, then hypothesis properties."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from tfbus import convert
from tfbus import geometry as g
from tfbus.core import _pymath
from tfbus.messages import (
    Header,
    Point,
    PointStamped,
    Pose,
    PoseStamped,
    Quaternion,
    Transform,
    TransformStamped,
    Vector3,
    Vector3Stamped,
)
from tfbus.time import Time

S45 = math.sqrt(0.5)
YAW90 = (0.0, 0.0, S45, S45)  # +90° about z, (x, y, z, w)
IDENTITY_Q = (0.0, 0.0, 0.0, 1.0)

FAST = settings(max_examples=60, deadline=None)


def rotation_angle(q0: object, q1: object) -> float:
    """Angle in radians of the rotation taking q0 to q1; insensitive to the sign of either."""
    a = np.asarray(q0, dtype=float)
    b = np.asarray(q1, dtype=float)
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    if np.dot(a, b) < 0:
        b = -b
    # 2·atan2 form: accurate for tiny angles, unlike acos of the dot product.
    return 4.0 * math.atan2(float(np.linalg.norm(a - b)), float(np.linalg.norm(a + b)))


def assert_same_rotation(q0: object, q1: object, tol: float = 1e-9) -> None:
    assert rotation_angle(q0, q1) < tol, (q0, q1)


def stamped(
    parent: str, child: str, t: tuple[float, float, float], q: tuple[float, ...], ns: int = 0
) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), parent), child, Transform(Vector3(*t), Quaternion(*q))
    )


# --------------------------------------------------------------------------- strategies


def _unit(v: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    n = math.sqrt(sum(c * c for c in v))
    x, y, z, w = (c / n for c in v)
    return (x, y, z, w)


unit_quaternions = (
    st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(lambda v: sum(c * c for c in v) > 0.01).map(_unit)
)
translations = st.tuples(*[st.floats(-100.0, 100.0)] * 3)
ratios = st.floats(0.0, 1.0)


@st.composite
def batches(draw: st.DrawFn, n_max: int = 8) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    n = draw(st.integers(1, n_max))
    t = np.array(draw(st.lists(translations, min_size=n, max_size=n)))
    q = np.array(draw(st.lists(unit_quaternions, min_size=n, max_size=n)))
    return t, q


# --------------------------------------------------------------------------- known numbers


def test_tutorial_laser_point() -> None:
    # tf2 tutorial: base_laser at (0.1, 0, 0.2) in base_link, no rotation.
    out = g.apply_transform([0.1, 0.0, 0.2], IDENTITY_Q, [[1.0, 0.2, 0.0]])
    assert out.shape == (1, 3)
    assert out.dtype == np.float64
    np.testing.assert_allclose(out, [[1.1, 0.2, 0.2]], atol=1e-15)


def test_yaw_90_rotates_x_to_y() -> None:
    np.testing.assert_allclose(g.rotate_vectors(YAW90, [1.0, 0.0, 0.0]), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(
        g.rotate_vectors(YAW90, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        [[0, 1, 0], [-1, 0, 0], [0, 0, 1]],
        atol=1e-15,
    )
    np.testing.assert_allclose(
        g.apply_transform([1.0, 2.0, 3.0], YAW90, [1.0, 0.0, 0.0]), [1, 3, 3], atol=1e-15
    )


def test_compose_and_inverse_known() -> None:
    t, q = g.compose([1.0, 0.0, 0.0], YAW90, [1.0, 0.0, 0.0], IDENTITY_Q)
    np.testing.assert_allclose(t, [1, 1, 0], atol=1e-15)
    np.testing.assert_allclose(q, YAW90, atol=1e-15)

    t, q = g.inverse([1.0, 0.0, 0.0], YAW90)
    np.testing.assert_allclose(t, [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(q, [0, 0, -S45, S45], atol=1e-15)

    np.testing.assert_allclose(g.quat_multiply(YAW90, YAW90), [0, 0, 1, 0], atol=1e-15)


def test_batched_shapes_broadcast_single_operands() -> None:
    t, q = g.compose([1.0, 0.0, 0.0], YAW90, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], IDENTITY_Q)
    assert t.shape == (2, 3)
    assert q.shape == (2, 4)
    np.testing.assert_allclose(t, [[1, 1, 0], [0, 0, 0]], atol=1e-15)
    np.testing.assert_allclose(q, [YAW90, YAW90], atol=1e-15)

    t, q = g.inverse([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]], YAW90)
    assert t.shape == (2, 3)
    assert q.shape == (2, 4)


def test_shape_errors() -> None:
    with pytest.raises(
        ValueError, match=r"points must have shape \(3,\) or \(N, 3\), got \(2, 2\)"
    ):
        g.apply_transform([0, 0, 0], IDENTITY_Q, [[1, 2], [3, 4]])
    with pytest.raises(ValueError, match="rotation must have shape"):
        g.rotate_vectors([0, 0, 1], [1, 0, 0])
    with pytest.raises(ValueError, match="translation_b"):
        g.compose([0, 0, 0], IDENTITY_Q, np.zeros((2, 2, 3)), IDENTITY_Q)
    with pytest.raises(ValueError, match="same number of rows"):
        g.apply_transform(np.zeros((2, 3)), IDENTITY_Q, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="ratio has 3 rows"):
        g.slerp_batch(np.tile(IDENTITY_Q, (2, 1)), YAW90, [0.0, 0.5, 1.0])
    with pytest.raises(ValueError, match="q1 must have shape"):
        g.slerp(IDENTITY_Q, [0, 0, 1], 0.5)
    with pytest.raises(ValueError, match=r"shape \(4, 4\)"):
        g.from_matrix(np.eye(3))
    with pytest.raises(ValueError, match="bottom row"):
        g.from_matrix(np.ones((4, 4)))
    with pytest.raises(ValueError, match="rotation must have shape"):
        g.euler_from_quaternion([0, 0, 1])
    with pytest.raises(ValueError, match=r"translation must have shape \(3,\)"):
        g.to_matrix([0, 0], IDENTITY_Q)


def test_non_unit_quaternion_follows_tf2() -> None:
    # q v q* scales by |q|²; the inverse is the conjugate; matrices normalise.
    np.testing.assert_allclose(g.rotate_vectors([0, 0, 0, 2.0], [1.0, 2.0, 3.0]), [4, 8, 12])
    np.testing.assert_allclose(
        g.rotate_vectors([0, 0, 0, 2.0], [[1.0, 2.0, 3.0]]), [[4, 8, 12]], atol=1e-15
    )
    _, q = g.inverse([0, 0, 0], [0, 0, 0, 2.0])
    np.testing.assert_array_equal(q, [-0.0, -0.0, -0.0, 2.0])
    np.testing.assert_allclose(g.to_matrix([0, 0, 0], [0, 0, 0, 2.0]), np.eye(4))


def test_slerp_known() -> None:
    half = g.slerp(IDENTITY_Q, YAW90, 0.5)
    assert isinstance(half, Quaternion)
    expected = (0.0, 0.0, math.sin(math.pi / 8), math.cos(math.pi / 8))
    np.testing.assert_allclose(half, expected, atol=1e-15)
    # -YAW90 is the same rotation; tf2 takes the short way, towards -(-YAW90).
    np.testing.assert_allclose(g.slerp(IDENTITY_Q, [-c for c in YAW90], 0.5), expected, atol=1e-15)
    # Zero angle: q0 is returned unchanged (tf2 Quaternion::slerp).
    assert g.slerp(YAW90, [-c for c in YAW90], 0.3) == Quaternion(*YAW90)
    batch = g.slerp_batch(IDENTITY_Q, YAW90, [0.0, 0.5, 1.0])
    assert batch.shape == (3, 4)
    np.testing.assert_allclose(batch, [IDENTITY_Q, expected, YAW90], atol=1e-15)
    np.testing.assert_array_equal(g.slerp_batch(YAW90, YAW90, 0.7), YAW90)


# Two rotations 1e-14 apart whose normalised dot product rounds to just above 1 (from a
# tf2 recording: tf2Acos clamps it, so the angle is 0 and the first rotation comes back).
NEAR_A = (-0.10034160459801901, -0.48624984361471457, -0.22642117855190708, 0.8379893208594761)
NEAR_B = (-0.10034160459799965, -0.48624984361470064, -0.2264211785518684, 0.837989320859497)


def test_slerp_of_a_cosine_rounding_above_1_returns_the_first_rotation() -> None:
    ax, ay, az, aw = NEAR_A
    bx, by, bz, bw = NEAR_B
    dot = ax * bx + ay * by + az * bz + aw * bw
    norms = (ax * ax + ay * ay + az * az + aw * aw) * (bx * bx + by * by + bz * bz + bw * bw)
    assert dot / math.sqrt(norms) > 1.0  # the case in point
    assert _pymath.slerp(*NEAR_A, *NEAR_B, 0.069) == NEAR_A
    assert g.slerp(NEAR_A, NEAR_B, 0.069) == Quaternion(*NEAR_A)
    np.testing.assert_array_equal(g.slerp_batch(NEAR_A, NEAR_B, [0.069, 0.5]), [NEAR_A] * 2)


def test_slerp_batch_zero_quaternion_is_nan() -> None:
    out = g.slerp_batch([[0.0, 0.0, 0.0, 0.0], list(IDENTITY_Q)], YAW90, 0.5)
    assert np.isnan(out[0]).all()
    assert np.isfinite(out[1]).all()


def test_matrix_known() -> None:
    m = g.to_matrix([1.0, 2.0, 3.0], YAW90)
    np.testing.assert_allclose(
        m, [[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]], atol=1e-15
    )
    t, q = g.from_matrix(m)
    np.testing.assert_allclose(t, [1, 2, 3])
    np.testing.assert_allclose(q, YAW90, atol=1e-15)
    # transforms3d returns w >= 0: a 180° yaw comes back as (0, 0, ±1, 0), same rotation.
    _, q = g.from_matrix(np.diag([-1.0, -1.0, 1.0, 1.0]))
    assert_same_rotation(q, (0, 0, 1, 0))


def test_euler_known() -> None:
    np.testing.assert_allclose(g.quaternion_from_euler(0.0, 0.0, math.pi / 2), YAW90, atol=1e-15)
    np.testing.assert_allclose(
        g.quaternion_from_euler(math.pi / 2, 0.0, 0.0), [S45, 0, 0, S45], atol=1e-15
    )
    roll, pitch, yaw = g.euler_from_quaternion(YAW90)
    assert (roll, pitch) == pytest.approx((0.0, 0.0), abs=1e-15)
    assert yaw == pytest.approx(math.pi / 2)
    # Rotating axes z, y', x'': the first angle is about z.
    np.testing.assert_allclose(
        g.quaternion_from_euler(math.pi / 2, 0.0, 0.0, axes="rzyx"), YAW90, atol=1e-15
    )


def test_message_helpers() -> None:
    ts = stamped("map", "odom", (1.0, 2.0, 3.0), YAW90)
    t, q = g.transform_to_arrays(ts)
    np.testing.assert_array_equal(t, [1, 2, 3])
    np.testing.assert_array_equal(q, YAW90)
    tf = g.transform_from_arrays(t, q)
    assert tf == ts.transform
    assert type(tf.translation) is Vector3
    assert type(tf.translation.x) is float
    m = g.transform_to_matrix(ts.transform)
    np.testing.assert_allclose(m, g.to_matrix(t, q))
    back = g.transform_from_matrix(m)
    np.testing.assert_allclose(back.translation, [1, 2, 3])
    assert_same_rotation(back.rotation, YAW90)
    with pytest.raises(ValueError, match="rotation"):
        g.transform_from_arrays([0, 0, 0], [0, 0, 1])


def test_transform_points_messages() -> None:
    ts = stamped("base_link", "base_laser", (0.1, 0.0, 0.2), IDENTITY_Q)
    pts = np.array([[1.0, 0.2, 0.0], [0.0, 0.0, 0.0]])
    out = g.transform_points(ts, pts)
    np.testing.assert_allclose(out, [[1.1, 0.2, 0.2], [0.1, 0.0, 0.2]], atol=1e-15)
    np.testing.assert_array_equal(g.transform_points(ts.transform, pts), out)
    with pytest.raises(ValueError, match="points"):
        g.transform_points(ts, np.zeros((4, 2)))


def test_do_transform_point_tutorial() -> None:
    ts = stamped("base_link", "base_laser", (0.1, 0.0, 0.2), IDENTITY_Q, ns=5_000_000_000)
    p = PointStamped(Header(Time(4), "base_laser"), Point(1.0, 0.2, 0.0))
    out = convert.do_transform_point(p, ts)
    assert isinstance(out, PointStamped)
    assert out.header == Header(Time(5), "base_link")  # the transform's header
    assert out.point == pytest.approx(Point(1.1, 0.2, 0.2), abs=1e-15)


def test_do_transform_vector3_rotation_only() -> None:
    ts = stamped("map", "robot", (10.0, 20.0, 30.0), YAW90, ns=7)
    v = Vector3Stamped(Header(Time.from_ns(7), "robot"), Vector3(1.0, 0.0, 0.0))
    out = convert.do_transform_vector3(v, ts)
    assert isinstance(out, Vector3Stamped)
    assert out.header == ts.header
    assert out.vector == pytest.approx(Vector3(0.0, 1.0, 0.0), abs=1e-15)


def test_do_transform_pose() -> None:
    ts = stamped("map", "robot", (1.0, 0.0, 0.0), YAW90, ns=3)
    pose = PoseStamped(Header(Time.from_ns(3), "robot"), Pose(Point(1.0, 0.0, 0.0), Quaternion()))
    out = convert.do_transform_pose(pose, ts)
    assert isinstance(out, PoseStamped)
    assert out.header == ts.header
    assert out.pose.position == pytest.approx(Point(1.0, 1.0, 0.0), abs=1e-15)
    assert out.pose.orientation == pytest.approx(Quaternion(*YAW90), abs=1e-15)
    # A pose already yawed by 90° ends up yawed by 180°.
    pose = pose._replace(pose=pose.pose._replace(orientation=Quaternion(*YAW90)))
    assert_same_rotation(convert.do_transform_pose(pose, ts).pose.orientation, (0, 0, 1, 0))


def test_swap_is_done_in_one_place() -> None:
    import inspect

    src = inspect.getsource(g)
    assert src.count("[3, 0, 1, 2]") == 1
    assert src.count("[1, 2, 3, 0]") == 1


# --------------------------------------------------------------------------- properties


@FAST
@given(translations, unit_quaternions)
def test_compose_with_inverse_is_identity(t: tuple[float, ...], q: tuple[float, ...]) -> None:
    ti, qi = g.inverse(t, q)
    for tc, qc in (g.compose(t, q, ti, qi), g.compose(ti, qi, t, q)):
        np.testing.assert_allclose(tc, [0, 0, 0], atol=1e-12)
        assert_same_rotation(qc, IDENTITY_Q)
    t2, q2 = g.inverse(ti, qi)
    np.testing.assert_allclose(t2, t, atol=1e-12)
    np.testing.assert_allclose(q2, q, atol=0)


@FAST
@given(
    translations, unit_quaternions, translations, unit_quaternions, translations, unit_quaternions
)
def test_compose_is_associative(
    ta: tuple[float, ...],
    qa: tuple[float, ...],
    tb: tuple[float, ...],
    qb: tuple[float, ...],
    tc: tuple[float, ...],
    qc: tuple[float, ...],
) -> None:
    left = g.compose(*g.compose(ta, qa, tb, qb), tc, qc)
    right = g.compose(ta, qa, *g.compose(tb, qb, tc, qc))
    np.testing.assert_allclose(left[0], right[0], atol=1e-11)
    np.testing.assert_allclose(left[1], right[1], atol=1e-12)


@FAST
@given(translations, unit_quaternions, translations, unit_quaternions, translations)
def test_compose_applies_b_then_a(
    ta: tuple[float, ...],
    qa: tuple[float, ...],
    tb: tuple[float, ...],
    qb: tuple[float, ...],
    p: tuple[float, ...],
) -> None:
    tab, qab = g.compose(ta, qa, tb, qb)
    direct = g.apply_transform(tab, qab, p)
    stepwise = g.apply_transform(ta, qa, g.apply_transform(tb, qb, p))
    np.testing.assert_allclose(direct, stepwise, atol=1e-11)


@FAST
@given(batches(), batches())
def test_batched_rows_equal_tf2_scalar_math(
    a: tuple[NDArray[np.float64], NDArray[np.float64]],
    b: tuple[NDArray[np.float64], NDArray[np.float64]],
) -> None:
    n = min(len(a[0]), len(b[0]))
    ta, qa, tb, qb = a[0][:n], a[1][:n], b[0][:n], b[1][:n]
    tc, qc = g.compose(ta, qa, tb, qb)
    ti, qi = g.inverse(ta, qa)
    pts = g.apply_transform(ta, qa, tb)
    for i in range(n):
        ra = (*ta[i].tolist(), *qa[i].tolist())
        rb = (*tb[i].tolist(), *qb[i].tolist())
        # Row by row the batched forms are bit-for-bit tf2's scalar arithmetic.
        assert (*tc[i].tolist(), *qc[i].tolist()) == _pymath.compose(ra, rb)
        assert (*ti[i].tolist(), *qi[i].tolist()) == _pymath.inverse(ra)
        assert tuple(pts[i].tolist()) == tuple(tc[i].tolist())


@FAST
@given(batches(n_max=16), translations, unit_quaternions)
def test_one_transform_many_points_matches_scalar(
    batch: tuple[NDArray[np.float64], NDArray[np.float64]],
    t: tuple[float, ...],
    q: tuple[float, ...],
) -> None:
    points = batch[0]
    out = g.apply_transform(t, q, points)
    rotated = g.rotate_vectors(q, points)
    assert out.shape == rotated.shape == points.shape
    for i, p in enumerate(points.tolist()):
        expected = _pymath.quat_rotate(*q, *p)
        np.testing.assert_allclose(rotated[i], expected, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(out[i], np.add(expected, t), rtol=1e-13, atol=1e-12)
        # and the single-point path is tf2's exactly
        assert tuple(g.rotate_vectors(q, p).tolist()) == expected


@FAST
@given(unit_quaternions, unit_quaternions)
def test_slerp_endpoints(q0: tuple[float, ...], q1: tuple[float, ...]) -> None:
    np.testing.assert_allclose(g.slerp(q0, q1, 0.0), q0, atol=1e-9)
    dot = float(np.dot(q0, q1))
    end = g.slerp(q0, q1, 1.0)
    if abs(dot) / math.sqrt(float(np.dot(q0, q0) * np.dot(q1, q1))) >= 1.0:
        # tf2's half-angle rounds to exactly 0: it returns q0 unchanged.
        assert end == q0
    else:
        np.testing.assert_allclose(end, np.multiply(1.0 if dot >= 0 else -1.0, q1), atol=1e-9)
    assert_same_rotation(end, q1, tol=1e-7)


@FAST
@given(unit_quaternions, unit_quaternions, ratios)
def test_slerp_takes_shortest_path(q0: tuple[float, ...], q1: tuple[float, ...], r: float) -> None:
    q = g.slerp(q0, q1, r)
    total = rotation_angle(q0, q1)
    # Constant speed along the short arc: the angle travelled is r times the whole.
    assert rotation_angle(q0, q) <= total + 1e-9
    assert rotation_angle(q0, q) == pytest.approx(r * total, abs=1e-7)
    assert rotation_angle(q, q1) == pytest.approx((1.0 - r) * total, abs=1e-7)
    # The result stays on q0's side of the 4-sphere: it uses -q1 when q0·q1 < 0.
    assert np.dot(q, q0) >= -1e-12
    negated = tuple(-c for c in q1)
    assert g.slerp(q0, negated, r) == pytest.approx(q, abs=1e-12)
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-9)


@FAST
@given(st.lists(st.tuples(unit_quaternions, unit_quaternions, ratios), min_size=1, max_size=10))
def test_slerp_batch_equals_scalar(
    rows: list[tuple[tuple[float, ...], tuple[float, ...], float]],
) -> None:
    q0 = np.array([r[0] for r in rows])
    q1 = np.array([r[1] for r in rows])
    ratio = np.array([r[2] for r in rows])
    out = g.slerp_batch(q0, q1, ratio)
    assert out.shape == (len(rows), 4)
    for i, (a, b, r) in enumerate(rows):
        np.testing.assert_allclose(out[i], g.slerp(a, b, r), rtol=0, atol=1e-12)


@FAST
@given(translations, unit_quaternions, translations, unit_quaternions, translations)
def test_matrix_round_trip_and_product(
    ta: tuple[float, ...],
    qa: tuple[float, ...],
    tb: tuple[float, ...],
    qb: tuple[float, ...],
    p: tuple[float, ...],
) -> None:
    ma = g.to_matrix(ta, qa)
    t, q = g.from_matrix(ma)
    np.testing.assert_allclose(t, ta, atol=0)
    assert_same_rotation(q, qa, tol=1e-7)
    assert q[3] >= 0.0
    np.testing.assert_allclose(
        g.to_matrix(*g.compose(ta, qa, tb, qb)), ma @ g.to_matrix(tb, qb), atol=1e-11
    )
    np.testing.assert_allclose((ma @ [*p, 1.0])[:3], g.apply_transform(ta, qa, p), atol=1e-11)


@FAST
@given(unit_quaternions)
def test_euler_round_trip(q: tuple[float, ...]) -> None:
    for axes in ("sxyz", "rzyx", "szxz"):
        angles = g.euler_from_quaternion(q, axes=axes)
        assert_same_rotation(g.quaternion_from_euler(*angles, axes=axes), q, tol=1e-7)


@FAST
@given(
    st.floats(-math.pi + 1e-6, math.pi - 1e-6),
    st.floats(-math.pi / 2 + 1e-3, math.pi / 2 - 1e-3),
    st.floats(-math.pi + 1e-6, math.pi - 1e-6),
)
def test_euler_angles_round_trip(roll: float, pitch: float, yaw: float) -> None:
    q = g.quaternion_from_euler(roll, pitch, yaw)
    assert np.linalg.norm(q) == pytest.approx(1.0)
    assert g.euler_from_quaternion(q) == pytest.approx((roll, pitch, yaw), abs=1e-9)


@FAST
@given(translations, unit_quaternions, translations, st.integers(0, 2**63 - 1))
def test_do_transform_point_matches_arrays(
    t: tuple[float, float, float], q: tuple[float, ...], p: tuple[float, ...], ns: int
) -> None:
    ts = stamped("target", "source", t, q, ns=ns)
    out = convert.do_transform_point(PointStamped(Header(Time(1), "source"), Point(*p)), ts)
    assert out.header is ts.header
    assert out.point == tuple(g.apply_transform(t, q, p).tolist())
    vec = convert.do_transform_vector3(Vector3Stamped(Header(), Vector3(*p)), ts)
    assert vec.header is ts.header
    assert vec.vector == tuple(g.rotate_vectors(q, p).tolist())
    pose = convert.do_transform_pose(PoseStamped(Header(), Pose(Point(*p), Quaternion(*q))), ts)
    assert pose.header is ts.header
    assert pose.pose.position == out.point
    assert pose.pose.orientation == tuple(g.quat_multiply(q, q).tolist())
