"""Lookup policies (``tfbus.core.policy``): Nearest, Clamp, Previous, Window and the
Exact default, on ``BufferCore.lookup_transform`` / ``lookup_transform_full`` /
``check_transform_policy`` and the batched ``lookup_transforms``.

* Known numbers on a small tree (every policy, inside, between and beyond the data).
* Property tests: random trees (dynamic links with 1-5 samples, static links), random
  frame pairs, times and policies, against a brute-force model that picks each link's
  sample by scanning its samples and composes the path with 4x4 matrices: the same
  answer (to 1e-9), the same report (frames, stamps, largest delta) or the same failure.
* ``Exact()`` through the reporting walk is ``lookup_transform`` bit for bit; the
  compiled and the pure-Python cores agree bit for bit on every policy.
"""

from __future__ import annotations

import itertools
import math
import struct
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tfbus import (
    ExtrapolationException,
    Header,
    Quaternion,
    Time,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.core import BufferCore, _pycore
from tfbus.core.policy import (
    Clamp,
    Exact,
    Nearest,
    PolicyReport,
    PolicyResult,
    Previous,
    Window,
)
from tfbus.errors import (
    BackwardExtrapolationException,
    ForwardExtrapolationException,
    LookupException,
)
from tfbus.time import Duration

NS = 1_000_000_000


def _ts(parent: str, child: str, ns: int, v: tuple[float, ...]) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), parent),
        child,
        Transform(Vector3(v[0], v[1], v[2]), Quaternion(v[3], v[4], v[5], v[6])),
    )


def _x(parent: str, child: str, ns: int, x: float) -> TransformStamped:
    return _ts(parent, child, ns, (x, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))


@pytest.fixture
def tree() -> BufferCore:
    """map <- odom at 1, 2, 3 s (x = 0, 1, 2); odom <- base at 1.5, 2.5, 3.5 s
    (x = 0, 10, 20); base <- laser static (x = 0.5)."""
    core = BufferCore(10.0)
    for k in range(3):
        core.set_transform(_x("map", "odom", NS + k * NS, float(k)))
        core.set_transform(_x("odom", "base", NS + NS // 2 + k * NS, 10.0 * k))
    core.set_transform_static(_x("base", "laser", 0, 0.5))
    return core


def _look(core: BufferCore, seconds: float, policy: Any) -> PolicyResult:
    result = core.lookup_transform("map", "laser", Time.from_sec(seconds), policy=policy)
    assert isinstance(result, PolicyResult)
    return result


# --------------------------------------------------------------------------- known numbers


def test_nearest_picks_each_links_nearest_sample_within_max_delta(tree: BufferCore) -> None:
    """At 1.25 s: odom's nearest sample is 1 s (x 0), base's is 1.5 s (x 0); laser is
    static (its stamp is the time): x = 0 + 0 + 0.5, largest delta 0.25 s."""
    ts, report = _look(tree, 1.25, Nearest(0.3))
    assert ts.transform.translation.x == 0.5
    assert ts.header.stamp == Time.from_sec(1.25)
    assert report == PolicyReport(
        ("laser", "base", "odom"), (1_250_000_000, 1_500_000_000, 1_000_000_000), 250_000_000
    )
    assert report.max_abs_delta == Duration.from_sec(0.25)
    assert not report.exact
    assert report.stamps()["base"] == Time.from_sec(1.5)


def test_nearest_beyond_max_delta_is_tf2s_answer(tree: BufferCore) -> None:
    """At 2 s base's samples are 0.5 s away (> 0.3): tf2 interpolates base (x 5), odom
    has a sample at 2 s: x = 1 + 5 + 0.5, every stamp the time, exact."""
    ts, report = _look(tree, 2.0, Nearest(0.3))
    assert ts.transform.translation.x == 6.5
    assert report.stamps_ns == (2 * NS, 2 * NS, 2 * NS)
    assert report.exact
    # A tie (0.5 s either side) goes to the older sample once allowed.
    ts, report = _look(tree, 2.0, Nearest(0.5))
    assert ts.transform.translation.x == 1.5
    assert report.stamps_ns == (2 * NS, 1_500_000_000, 2 * NS)


def test_nearest_raises_tf2s_error_where_no_sample_is_near(tree: BufferCore) -> None:
    with pytest.raises(ForwardExtrapolationException) as caught:
        _look(tree, 4.0, Nearest(0.3))
    exact = tree.try_lookup_transform("map", "laser", Time.from_sec(4.0))
    assert str(caught.value) == str(exact)
    with pytest.raises(BackwardExtrapolationException):
        _look(tree, 0.5, Nearest(0.3))


def test_clamp_holds_the_edge_sample_within_max_delta(tree: BufferCore) -> None:
    """At 4 s: odom holds its 3 s sample (x 2), base its 3.5 s one (x 20); at 0.5 s odom
    holds 1 s (x 0) and base 1.5 s (x 0); inside the data tf2 interpolates."""
    ts, report = _look(tree, 4.0, Clamp(1.0))
    assert ts.transform.translation.x == 22.5
    assert report.stamps_ns == (4 * NS, 3_500_000_000, 3 * NS)
    assert report.max_abs_delta_ns == NS
    ts, report = _look(tree, 0.5, Clamp(1.0))
    assert ts.transform.translation.x == 0.5
    assert report.max_abs_delta_ns == NS
    ts, report = _look(tree, 2.25, Clamp(1.0))
    assert ts.transform.translation.x == 1.25 + 7.5 + 0.5
    assert report.exact
    with pytest.raises(ForwardExtrapolationException):
        _look(tree, 4.5, Clamp(0.99))


def test_previous_takes_the_last_sample_at_or_before(tree: BufferCore) -> None:
    ts, report = _look(tree, 3.1, Previous())
    assert ts.transform.translation.x == 2.0 + 10.0 + 0.5
    assert report.stamps_ns == (3_100_000_000, 2_500_000_000, 3 * NS)
    assert report.max_abs_delta_ns == 600_000_000
    ts, report = _look(tree, 100.0, Previous())  # held however old
    assert ts.transform.translation.x == 22.5
    with pytest.raises(BackwardExtrapolationException):
        _look(tree, 1.25, Previous())  # before base's oldest sample


def test_window_holds_the_newest_sample_only_forward(tree: BufferCore) -> None:
    ts, report = _look(tree, 3.75, Window(past=1.0))
    assert ts.transform.translation.x == 22.5
    assert report.stamps_ns == (3_750_000_000, 3_500_000_000, 3 * NS)
    with pytest.raises(ForwardExtrapolationException):
        _look(tree, 4.1, Window(past=1.0))
    with pytest.raises(BackwardExtrapolationException):
        _look(tree, 0.9, Window(past=1.0))  # nothing is held backwards


def test_exact_policy_returns_the_plain_transform(tree: BufferCore) -> None:
    t = Time.from_sec(2.25)
    plain = tree.lookup_transform("map", "laser", t)
    assert tree.lookup_transform("map", "laser", t, policy=Exact()) is plain  # the memo
    assert type(plain) is TransformStamped
    with pytest.raises(ExtrapolationException):
        tree.lookup_transform("map", "laser", Time.from_sec(4.0), policy=Exact())


def test_time_zero_is_the_latest_common_time(tree: BufferCore) -> None:
    """Time(0): the latest common time (3 s, odom's newest), every link exact there."""
    ts, report = tree.lookup_transform("map", "laser", Time(0), policy=Nearest(0.1))
    assert ts.header.stamp == Time.from_sec(3.0)
    assert report.exact
    assert ts == tree.lookup_transform("map", "laser", Time(0))


def test_report_lists_the_path_only_and_in_order(tree: BufferCore) -> None:
    """From laser to odom (odom an ancestor): only the base and laser links; from odom
    to laser the same links, target side listed downwards; a frame to itself: none."""
    _, up = tree.lookup_transform("odom", "laser", Time.from_sec(4.0), policy=Clamp(1.0))
    assert up.frames == ("laser", "base")
    _, down = tree.lookup_transform("laser", "odom", Time.from_sec(4.0), policy=Clamp(1.0))
    assert down.frames == ("base", "laser")
    assert down.stamps_ns == (3_500_000_000, 4 * NS)
    ts, same = tree.lookup_transform("odom", "odom", Time.from_sec(9.0), policy=Previous())
    assert same == PolicyReport((), (), 0)
    assert ts.transform.translation.x == 0.0


def test_full_lookup_reports_both_legs(tree: BufferCore) -> None:
    """laser at 4 s (Clamp: odom 3 s, base 3.5 s) through map into laser at 1.25 s
    (Clamp: odom 1.25 s exact, base held at 1.5 s)."""
    ts, report = tree.lookup_transform_full(
        "laser", Time.from_sec(1.25), "laser", Time.from_sec(4.0), "map", policy=Clamp(1.0)
    )
    leg1, _ = _look(tree, 4.0, Clamp(1.0))
    assert report.frames == ("laser", "base", "odom", "odom", "base", "laser")
    assert report.stamps_ns[:3] == (4 * NS, 3_500_000_000, 3 * NS)
    assert report.stamps_ns[3:] == (1_250_000_000, 1_500_000_000, 1_250_000_000)
    assert report.max_abs_delta_ns == NS
    # x: laser(4 s) in map is 22.5; map in laser(1.25 s) is -(0.25 + 0 + 0.5).
    assert math.isclose(ts.transform.translation.x, 22.5 - 0.75, abs_tol=1e-12)
    assert leg1.transform.translation.x == 22.5


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: Nearest(-1.0), "max_delta must be finite seconds"),
        (lambda: Nearest(math.nan), "max_delta must be finite seconds"),
        (lambda: Clamp("1"), "max_delta must be seconds"),
        (lambda: Window(True), "past must be seconds"),
        (lambda: Window(1.0, -2.0), "future_wait must be finite seconds"),
    ],
)
def test_bad_durations_name_the_field(make: Any, message: str) -> None:
    with pytest.raises((TypeError, ValueError), match=message):
        make()


def test_bad_policy_or_time_is_a_type_error(tree: BufferCore) -> None:
    with pytest.raises(TypeError, match="policy must be Exact"):
        tree.lookup_transform("map", "laser", Time(0), policy="nearest")  # type: ignore[call-overload]
    with pytest.raises(TypeError, match=r"time must be a tfbus\.Time"):
        tree.lookup_transform("map", "laser", 1.0, policy=Previous())  # type: ignore[call-overload]


def test_durations_accept_seconds_and_duration() -> None:
    assert Nearest(0.25) == Nearest(Duration.from_ns(250_000_000))
    assert Nearest(0.25).max_delta == Duration.from_sec(0.25)
    assert Window(1.5, 0.5).past == Duration.from_sec(1.5)
    assert Window(1.5, 0.5).future_wait == Duration.from_sec(0.5)
    assert Window(1.5, 0.5) != Window(1.5, 0.25)
    assert repr(Clamp(0.5)) == "Clamp(max_delta=0.5)"


# --------------------------------------------------------------------------- the model

Values = tuple[float, float, float, float, float, float, float]


def _interp(a: tuple[int, Values], b: tuple[int, Values], t: int) -> Values:
    """Linear translation, shortest-path slerp (the textbook formula)."""
    (t0, va), (t1, vb) = a, b
    r = (t - t0) / (t1 - t0)
    p = np.array(va[:3]) * (1 - r) + np.array(vb[:3]) * r
    qa, qb = np.array(va[3:]), np.array(vb[3:])
    dot = float(qa @ qb)
    if dot < 0:
        qb, dot = -qb, -dot
    theta = math.acos(min(1.0, dot))
    if theta < 1e-12:
        q = qa * (1 - r) + qb * r
    else:
        q = (math.sin((1 - r) * theta) * qa + math.sin(r * theta) * qb) / math.sin(theta)
    return (*p.tolist(), *q.tolist())  # type: ignore[return-value]


def _exact(samples: list[tuple[int, Values]], t: int) -> Values | None:
    for s, v in samples:
        if s == t:
            return v
    for a, b in itertools.pairwise(samples):
        if a[0] < t < b[0]:
            return _interp(a, b, t)
    return None


def _pick(
    samples: list[tuple[int, Values]] | Values, t: int, policy: Any
) -> tuple[Values, int] | None:
    """A link's (values, stamp used) under a policy, by scanning; None: no data."""
    if not isinstance(samples, list):  # static
        return samples, t
    stamps = [s for s, _ in samples]
    chosen: tuple[int, Values] | None = None
    if isinstance(policy, Previous):
        before = [sv for sv in samples if sv[0] <= t]
        chosen = before[-1] if before else None
    elif isinstance(policy, Nearest):
        best = min(samples, key=lambda sv: (abs(sv[0] - t), sv[0]))
        if abs(best[0] - t) <= policy.max_delta.ns:
            chosen = best
    elif isinstance(policy, (Clamp, Window)):
        back = policy.max_delta.ns if isinstance(policy, Clamp) else 0
        ahead = policy.max_delta.ns if isinstance(policy, Clamp) else policy.past.ns
        if t > stamps[-1] and t - stamps[-1] <= ahead:
            chosen = samples[-1]
        elif t < stamps[0] and stamps[0] - t <= back:
            chosen = samples[0]
    if chosen is not None:
        return chosen[1], chosen[0]
    v = _exact(samples, t)
    return None if v is None else (v, t)


def _matrix(v: Values) -> np.ndarray:
    x, y, z, w = v[3:]
    m = np.eye(4)
    m[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    m[:3, 3] = v[:3]
    return m


def _model(
    parents: dict[str, str],
    links: dict[str, Any],
    target: str,
    source: str,
    t: int,
    policy: Any,
) -> tuple[np.ndarray, tuple[str, ...], tuple[int, ...]] | None:
    """target <- source under the policy: (4x4, frames, stamps), or None (no data)."""

    def up(f: str) -> list[str]:
        out = [f]
        while out[-1] in parents:
            out.append(parents[out[-1]])
        return out

    a, b = up(source), up(target)
    lca = next(f for f in a if f in b)
    src_links = a[: a.index(lca)]
    tgt_links = b[: b.index(lca)]
    m_src, m_tgt = np.eye(4), np.eye(4)
    frames: list[str] = []
    stamps: list[int] = []
    for child in src_links:
        got = _pick(links[child], t, policy)
        if got is None:
            return None
        m_src = _matrix(got[0]) @ m_src
        frames.append(child)
        stamps.append(got[1])
    down: list[tuple[str, int]] = []
    for child in tgt_links:
        got = _pick(links[child], t, policy)
        if got is None:
            return None
        m_tgt = _matrix(got[0]) @ m_tgt
        down.append((child, got[1]))
    for child, stamp in reversed(down):
        frames.append(child)
        stamps.append(stamp)
    return np.linalg.inv(m_tgt) @ m_src, tuple(frames), tuple(stamps)


def _unit(draw: Any) -> tuple[float, float, float, float]:
    q = np.array([draw(st.floats(-1, 1)) for _ in range(4)])
    n = float(np.linalg.norm(q))
    if n < 0.1:
        return (0.0, 0.0, 0.0, 1.0)
    return tuple((q / n).tolist())  # type: ignore[return-value]


@st.composite
def trees(draw: Any) -> tuple[dict[str, str], dict[str, Any]]:
    n = draw(st.integers(2, 6))
    parents: dict[str, str] = {}
    links: dict[str, Any] = {}
    for i in range(1, n):
        child = f"f{i}"
        parents[child] = f"f{draw(st.integers(0, i - 1))}"

        def values() -> Values:
            p = [draw(st.floats(-5, 5)) for _ in range(3)]
            return (*p, *_unit(draw))  # type: ignore[return-value]

        if draw(st.integers(0, 4)) == 0:
            links[child] = values()
        else:
            stamps = sorted(draw(st.sets(st.integers(1, 8), min_size=1, max_size=5)))
            links[child] = [(1000 * s, values()) for s in stamps]
    return parents, links


POLICIES = st.one_of(
    st.builds(Nearest, st.sampled_from([Duration.from_ns(d) for d in (0, 499, 1000, 5000)])),
    st.builds(Clamp, st.sampled_from([Duration.from_ns(d) for d in (0, 500, 1000, 5000)])),
    st.just(Previous()),
    st.builds(Window, st.sampled_from([Duration.from_ns(d) for d in (0, 700, 3000)])),
)


def _fill(core: BufferCore, parents: dict[str, str], links: dict[str, Any]) -> None:
    for child, data in links.items():
        if isinstance(data, list):
            for stamp, v in data:
                core.set_transform(_ts(parents[child], child, stamp, v))
        else:
            core.set_transform_static(_ts(parents[child], child, 0, data))


def _times(links: dict[str, Any]) -> st.SearchStrategy[int]:
    """Query times: multiples of 500 ns around the samples, half of them midway between
    two samples of a link (where Nearest's tie rule decides)."""
    mids = sorted(
        {
            (a[0] + b[0]) // 2
            for data in links.values()
            if isinstance(data, list)
            for a, b in itertools.pairwise(data)
        }
    )
    grid = st.integers(1, 19).map(lambda k: 500 * k)
    return st.one_of(grid, st.sampled_from(mids)) if mids else grid


SETTINGS = settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(trees(), st.data(), POLICIES)
def test_every_policy_matches_the_brute_force_model(
    tree: tuple[dict[str, str], dict[str, Any]], data: Any, policy: Any
) -> None:
    parents, links = tree
    core = BufferCore(1000.0)
    _fill(core, parents, links)
    frames = ["f0", *links]
    source = data.draw(st.sampled_from(frames))
    target = data.draw(st.sampled_from([f for f in frames if f != source]))
    t = data.draw(_times(links))
    want = _model(parents, links, target, source, t, policy)
    if want is None:
        with pytest.raises(ExtrapolationException):
            core.lookup_transform(target, source, Time.from_ns(t), policy=policy)
        return
    ts, report = core.lookup_transform(target, source, Time.from_ns(t), policy=policy)
    matrix, want_frames, want_stamps = want
    got = _matrix(tuple(ts.transform.translation) + tuple(ts.transform.rotation))
    assert np.allclose(got, matrix, atol=1e-9), (got, matrix)
    assert report.frames == want_frames
    assert report.stamps_ns == want_stamps
    assert report.max_abs_delta_ns == max((abs(s - t) for s in want_stamps), default=0)
    assert ts.header.stamp == Time.from_ns(t)


def _bits(value: Any) -> Any:
    """Floats by their bits, recursively (NamedTuples and Times as plain values)."""
    if isinstance(value, float):
        return struct.pack("<d", value)
    if isinstance(value, Time):
        return ("T", value.ns)
    if isinstance(value, BaseException):
        return (type(value).__name__, str(value))
    if isinstance(value, tuple):
        return (type(value).__name__, tuple(_bits(v) for v in value))
    return value


def _outcome(fn: Any) -> Any:
    try:
        return _bits(fn())
    except Exception as exc:  # the exception is the outcome compared
        return _bits(exc)


PURE_BUFFER: type[BufferCore] = type(
    "BufferCore",
    (_pycore.CoreBase,),
    {k: v for k, v in vars(BufferCore).items() if k not in {"__dict__", "__weakref__"}},
)


@SETTINGS
@given(trees(), st.data(), st.one_of(POLICIES, st.just(Exact())))
def test_both_cores_and_exact_agree_bit_for_bit(
    tree: tuple[dict[str, str], dict[str, Any]], data: Any, policy: Any
) -> None:
    """The compiled and the pure-Python core give the same policy results bit for bit
    (values, reports, messages); ``Exact()`` through the reporting walk is
    ``lookup_transform``'s answer bit for bit (time 0 included)."""
    parents, links = tree
    cores = [BufferCore(1000.0), PURE_BUFFER(1000.0)]
    for core in cores:
        _fill(core, parents, links)
    frames = ["f0", *links]
    source = data.draw(st.sampled_from(frames))
    target = data.draw(st.sampled_from(frames))
    t = Time.from_ns(data.draw(st.integers(0, 19)) * 500)
    outs = [
        _outcome(lambda c=core: c.check_transform_policy(target, source, t, policy))
        for core in cores
    ]
    assert outs[0] == outs[1]
    full = [
        _outcome(lambda c=core: c.lookup_transform_full(target, t, source, t, "f0", policy=policy))
        for core in cores
    ]
    assert full[0] == full[1]
    if isinstance(policy, Exact):
        for core in cores:
            exact = core.check_transform(target, source, t)
            checked = core.check_transform_policy(target, source, t, policy)
            if isinstance(exact, TransformStamped):
                assert isinstance(checked, PolicyResult)
                assert _bits(checked.transform) == _bits(exact)
                assert checked.report.exact
            else:
                assert _bits(checked) == _bits(exact)


# --------------------------------------------------------------------------- batches


def test_batched_rows_are_the_single_policy_lookups(tree: BufferCore) -> None:
    times = [int(s * NS) for s in (0.5, 1.25, 2.0, 3.1, 4.0, 9.0)]
    arr = tree.lookup_transforms("map", "laser", times, errors="mask", policy=Clamp(1.0))
    assert arr.reports is not None and arr.max_abs_delta_ns is not None
    assert arr.valid.tolist() == [True, True, True, True, True, False]
    assert arr.max_abs_delta_ns.tolist() == [NS, 250_000_000, 0, 100_000_000, NS, -1]
    for i, ns in enumerate(times[:5]):
        ts, report = tree.lookup_transform("map", "laser", Time.from_ns(ns), policy=Clamp(1.0))
        assert arr.reports[i] == report
        assert arr.translations[i].tolist() == list(ts.transform.translation)
        assert arr.rotations[i].tolist() == list(ts.transform.rotation)
        assert arr.stamps[i] == ns
    assert arr.reports[5] is None
    assert np.isnan(arr.translations[5]).all()


def test_batched_policy_raises_the_first_rows_error(tree: BufferCore) -> None:
    with pytest.raises(ForwardExtrapolationException) as caught:
        tree.lookup_transforms("map", "laser", [2 * NS, 9 * NS], policy=Nearest(0.1))
    single = tree.try_lookup_transform("map", "laser", Time.from_ns(9 * NS))
    assert str(caught.value) == str(single)
    with pytest.raises(LookupException):
        tree.lookup_transforms("map", "nowhere", [2 * NS], errors="mask", policy=Previous())


def test_exact_batches_carry_no_reports(tree: BufferCore) -> None:
    arr = tree.lookup_transforms("map", "laser", [2 * NS], policy=Exact())
    assert arr.reports is None and arr.max_abs_delta_ns is None


def test_batched_full_rows_are_the_single_full_policy_lookups(tree: BufferCore) -> None:
    src = [4 * NS, int(1.25 * NS), 9 * NS]
    tgt = [int(1.25 * NS), 4 * NS, 2 * NS]
    arr = tree.lookup_transforms_full(
        "laser", tgt, "laser", src, "map", errors="mask", policy=Clamp(1.0)
    )
    assert arr.valid.tolist() == [True, True, False]
    assert arr.reports is not None and arr.max_abs_delta_ns is not None
    assert arr.max_abs_delta_ns.tolist() == [NS, NS, -1]
    for i in range(2):
        ts, report = tree.lookup_transform_full(
            "laser", Time.from_ns(tgt[i]), "laser", Time.from_ns(src[i]), "map", policy=Clamp(1.0)
        )
        assert arr.reports[i] == report
        assert np.allclose(arr.translations[i], list(ts.transform.translation), atol=1e-12)
        assert np.allclose(arr.rotations[i], list(ts.transform.rotation), atol=1e-12)
    with pytest.raises(ForwardExtrapolationException):
        tree.lookup_transforms_full("laser", tgt, "laser", src, "map", policy=Clamp(1.0))
