"""Property tests (hypothesis) for ``tfbus.core.BufferCore``.

The oracle here is a few lines of textbook quaternion algebra written independently of
tfbus, applied to random trees and chains of random rigid transforms:

* ``lookup(a, b) · lookup(b, a)`` is the identity;
* interpolating between two samples stays on the geodesic: the rotation angle from
  ``q0`` grows linearly with the ratio (and the rest of the way to ``q1`` shrinks
  linearly), the translation is linear;
* a lookup at a sample's stamp returns that sample exactly;
* a lookup at time 0 equals the lookup at ``get_latest_common_time``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from hypothesis import assume, given, settings
from hypothesis import strategies as st

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.core import BufferCore

Vec = tuple[float, float, float]
Quat = tuple[float, float, float, float]  # (x, y, z, w)

settings.register_profile("tfbus-core", max_examples=150, deadline=None)
settings.load_profile("tfbus-core")

# --------------------------------------------------------------------------- the oracle


def q_mul(a: Sequence[float], b: Sequence[float]) -> Quat:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def q_rotate(q: Sequence[float], v: Sequence[float]) -> Vec:
    x, y, z, _ = q_mul(q_mul(q, (v[0], v[1], v[2], 0.0)), (-q[0], -q[1], -q[2], q[3]))
    return (x, y, z)


def compose(a: Transform, b: Transform) -> tuple[Vec, Quat]:
    """``a ∘ b``: first ``b``, then ``a``."""
    r = q_rotate(a.rotation, b.translation)
    t = a.translation
    return (r[0] + t[0], r[1] + t[1], r[2] + t[2]), q_mul(a.rotation, b.rotation)


def angle_between(a: Sequence[float], b: Sequence[float]) -> float:
    """Rotation angle (rad, in [0, π]) taking ``a`` to ``b``; sign-insensitive, exact for
    tiny angles (``4·atan2(|a - s·b|, |a + s·b|)``)."""
    na = math.sqrt(sum(x * x for x in a))
    nb = math.sqrt(sum(x * x for x in b))
    ua = [x / na for x in a]
    ub = [x / nb for x in b]
    s = 1.0 if sum(x * y for x, y in zip(ua, ub, strict=True)) >= 0.0 else -1.0
    d = math.sqrt(sum((x - s * y) ** 2 for x, y in zip(ua, ub, strict=True)))
    p = math.sqrt(sum((x + s * y) ** 2 for x, y in zip(ua, ub, strict=True)))
    return 4.0 * math.atan2(d, p)


# --------------------------------------------------------------------------- strategies


def _unit(v: Sequence[float]) -> Quat:
    n = math.sqrt(sum(x * x for x in v))
    return (v[0] / n, v[1] / n, v[2] / n, v[3] / n)


unit_quaternions = (
    st.tuples(*[st.floats(-1.0, 1.0, allow_nan=False)] * 4)
    .filter(lambda v: math.sqrt(sum(x * x for x in v)) > 0.1)
    .map(_unit)
)
translations = st.tuples(*[st.floats(-50.0, 50.0, allow_nan=False)] * 3)
transforms = st.builds(
    lambda t, q: Transform(Vector3(*t), Quaternion(*q)), translations, unit_quaternions
)


def stamped(parent: str, child: str, stamp_ns: int, tf: Transform) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(stamp_ns), parent), child, tf)


@dataclass(frozen=True)
class Tree:
    """Frames ``f0`` (root) … ``fN``; ``parents[i]`` is the parent index of ``f{i+1}``."""

    parents: list[int]
    links: list[list[tuple[int, Transform]]]
    """Per child: its samples as (stamp ns, transform), stamps increasing."""
    static: list[bool]


@st.composite
def trees(draw: st.DrawFn, max_frames: int = 12, chain: bool = False) -> Tree:
    """A random tree (or chain) whose dynamic links all cover a common window of time,
    so every pair of frames can be looked up at time 0."""
    n = draw(st.integers(1, max_frames))
    parents = [i if chain else draw(st.integers(0, i)) for i in range(n)]
    base = draw(st.integers(10**10, 10**12), label="window start")
    window = draw(st.integers(0, 10**10), label="window length")
    links: list[list[tuple[int, Transform]]] = []
    static: list[bool] = []
    for _ in range(n):
        is_static = draw(st.integers(0, 3)) == 0
        if is_static:
            stamps = [draw(st.integers(0, 10**12))]
        else:
            first = base - draw(st.integers(0, 10**10))
            last = base + window + draw(st.integers(0, 10**10))
            inner = draw(st.lists(st.integers(first, last), max_size=3))
            stamps = sorted({first, *inner, last})
        links.append([(s, draw(transforms)) for s in stamps])
        static.append(is_static)
    return Tree(parents, links, static)


def build(tree: Tree) -> BufferCore:
    core = BufferCore(cache_time=1e6)
    for i, (parent, samples) in enumerate(zip(tree.parents, tree.links, strict=True)):
        for stamp, tf in samples:
            ts = stamped(f"f{parent}", f"f{i + 1}", stamp, tf)
            ok = core.set_transform_static(ts) if tree.static[i] else core.set_transform(ts)
            assert ok
    return core


def assert_identity(t: Sequence[float], q: Sequence[float]) -> None:
    """Within the corpus tolerances: 1e-9 m per component, 1e-9 rad, unit norm."""
    assert all(abs(x) <= 1e-9 for x in t), t
    assert angle_between(q, (0.0, 0.0, 0.0, 1.0)) <= 1e-9, q
    assert abs(math.sqrt(sum(x * x for x in q)) - 1.0) <= 1e-9, q


# --------------------------------------------------------------------------- properties


@given(tree=st.one_of(trees(), trees(max_frames=32, chain=True)), data=st.data())
def test_lookup_then_inverse_lookup_is_identity(tree: Tree, data: st.DataObject) -> None:
    core = build(tree)
    n = len(tree.parents) + 1
    a = f"f{data.draw(st.integers(0, n - 1), label='a')}"
    b = f"f{data.draw(st.integers(0, n - 1), label='b')}"
    latest = core.get_latest_common_time(a, b).ns
    ab0 = core.lookup_transform(a, b, Time(0))
    if latest:
        # Any time in the common range of the path works; try the latest and a bit before.
        when = data.draw(st.sampled_from([latest, max(1, latest - 1)]), label="when")
        assume(core.can_transform(a, b, Time.from_ns(when)))
        time = Time.from_ns(when)
    else:
        time = Time(0)
    ab = core.lookup_transform(a, b, time) if latest else ab0
    ba = core.lookup_transform(b, a, time)
    assert (ab.header.frame_id, ab.child_frame_id) == (a, b)
    assert (ba.header.frame_id, ba.child_frame_id) == (b, a)
    assert_identity(*compose(ab.transform, ba.transform))
    assert_identity(*compose(ba.transform, ab.transform))


@given(
    t0=st.integers(1, 10**12),
    span=st.integers(2, 10**10),
    k=st.integers(0, 1000),
    tf0=transforms,
    tf1=transforms,
)
def test_interpolation_stays_on_the_geodesic(
    t0: int, span: int, k: int, tf0: Transform, tf1: Transform
) -> None:
    theta = angle_between(tf0.rotation, tf1.rotation)
    assume(1e-6 < theta < math.pi - 1e-3)  # tf2 returns q0 for tiny angles; π is ambiguous
    core = BufferCore(cache_time=1e6)
    assert core.set_transform(stamped("p", "c", t0, tf0))
    assert core.set_transform(stamped("p", "c", t0 + span, tf1))
    when = t0 + span * k // 1000
    ratio = (when - t0) / span
    result = core.lookup_transform("p", "c", Time.from_ns(when))
    assert result.header.stamp.ns == when
    q = result.transform.rotation
    tol = 1e-9
    assert abs(angle_between(tf0.rotation, q) - ratio * theta) <= tol
    assert abs(angle_between(q, tf1.rotation) - (1.0 - ratio) * theta) <= tol
    assert abs(math.sqrt(sum(x * x for x in q)) - 1.0) <= 1e-12
    for a, b, x in zip(tf0.translation, tf1.translation, result.transform.translation, strict=True):
        assert abs(x - (a + ratio * (b - a))) <= 1e-9


@given(tree=trees(max_frames=6), data=st.data())
def test_lookup_at_a_sample_stamp_returns_the_sample_exactly(
    tree: Tree, data: st.DataObject
) -> None:
    core = build(tree)
    child = data.draw(st.integers(1, len(tree.parents)), label="child")
    parent = f"f{tree.parents[child - 1]}"
    stamp, tf = data.draw(st.sampled_from(tree.links[child - 1]), label="sample")
    # A query at time 0 means "latest" (tf2), not the sample stamped 0.
    assume(stamp != 0 or len(tree.links[child - 1]) == 1 or tree.static[child - 1])
    if tree.static[child - 1]:
        stamp = data.draw(st.integers(0, 10**13), label="any time")  # static: any time
    result = core.lookup_transform(parent, f"f{child}", Time.from_ns(stamp))
    assert result.header.stamp.ns == stamp
    assert result.transform == tf


@given(tree=trees(), data=st.data())
def test_time_zero_is_the_latest_common_time(tree: Tree, data: st.DataObject) -> None:
    core = build(tree)
    n = len(tree.parents) + 1
    a = f"f{data.draw(st.integers(0, n - 1), label='a')}"
    b = f"f{data.draw(st.integers(0, n - 1), label='b')}"
    assume(a != b)  # lookup(x, x, 0) is the identity short-circuit, stamped differently
    latest = core.get_latest_common_time(a, b)
    at_zero = core.lookup_transform(a, b, Time(0))
    assert at_zero.header.stamp == latest
    if latest.ns:
        assert core.lookup_transform(a, b, latest) == at_zero
    assert core.can_transform(a, b, Time(0))
