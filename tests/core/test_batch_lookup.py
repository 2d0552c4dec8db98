"""Batched lookups (``tfbus.core.batch``) against N single ``lookup_transform`` calls.

The oracle is the single lookup itself (checked bit for bit against tf2 by the
conformance corpus): every row must equal it to 1e-12, every failure must raise the same
exception with the same message as the single lookup for the first failing time.

Each row comparison runs twice (fixture ``simd``): as shipped, where slerp's per-time
sines may come from libmvec's vector sin (``tfbus.core._cbatch._BATCH_VECTOR_SIN``; rows within the
tolerance 1e-12, a few ulp in practice), and with the batch forced onto its scalar loops
(libm's sin), where every row must be the single lookup's bit for bit. Rows whose math
has no per-time sine (exact stamps, statics, constant rotations) are bit-identical either
way (``test_rows_without_sines_are_bit_exact_with_the_vector_sine``).
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tfbus import (
    BufferCore,
    ConnectivityException,
    ExtrapolationException,
    Header,
    InvalidArgumentException,
    LookupException,
    Quaternion,
    Time,
    Transform,
    TransformException,
    TransformStamped,
    Vector3,
)
from tfbus.core import COMPILED
from tfbus.core._select import IMPLEMENTATIONS, batch_lookup
from tfbus.core.batch import TransformArray, as_times
from tfbus.core.policy import Nearest
from tfbus.errors import (
    BackwardExtrapolationException,
    ForwardExtrapolationException,
    NoDataForExtrapolationException,
    TF2Error,
    tf2_error_of,
)


def _batch_simd(on: bool) -> bool:
    """Turn the compiled batch's SIMD paths and vector sine on or off; whether the vector
    sine is now in use. The pure-Python core (this file also runs against it, see
    ``tests/core/test_pycore.py``) has neither: its rows are always the single walk's."""
    return bool(IMPLEMENTATIONS[3]._batch_simd(on)) if COMPILED else False


def _vector_sin_available() -> bool:
    return bool(IMPLEMENTATIONS[3]._BATCH_VECTOR_SIN) if COMPILED else False

FRAMES = ["a", "b", "c", "d", "e", "f"]


def _ts(parent: str, child: str, ns: int, v: tuple[float, ...]) -> TransformStamped:
    n = math.sqrt(sum(x * x for x in v[3:]))
    q = [x / n for x in v[3:]]
    return TransformStamped(
        Header(Time.from_ns(ns), parent),
        child,
        Transform(Vector3(*v[:3]), Quaternion(*q)),
    )


values = st.tuples(
    *[st.floats(-50.0, 50.0, allow_nan=False)] * 3,
    *[st.floats(-1.0, 1.0, allow_nan=False)] * 4,
).filter(lambda v: sum(x * x for x in v[3:]) > 0.1)


@st.composite
def buffers(draw: st.DrawFn) -> tuple[BufferCore, list[int]]:
    """A random forest over FRAMES: static and dynamic links, some re-parented, some
    empty of data near the query times; returns the core and every stored stamp."""
    core = BufferCore(cache_time=1000.0)
    stamps: list[int] = []
    for i, child in enumerate(FRAMES[1:], start=1):
        parent = FRAMES[draw(st.integers(0, i - 1))]
        kind = draw(st.sampled_from(["static", "dynamic", "dynamic", "none"]))
        if kind == "static":
            core.set_transform_static(_ts(parent, child, 0, draw(values)))
        elif kind == "dynamic":
            n = draw(st.integers(1, 6))
            times = sorted(draw(st.sets(st.integers(1, 10_000), min_size=n, max_size=n)))
            for t in times:
                p = parent
                if draw(st.integers(0, 9)) == 0:  # an occasional re-parenting
                    p = FRAMES[draw(st.integers(0, i - 1))]
                core.set_transform(_ts(p, child, t * 1_000_000, draw(values)))
                stamps.append(t * 1_000_000)
    return core, stamps


def _query_times(draw: st.DrawFn, stamps: list[int]) -> list[int]:
    picks = [0, 1, 5_000_000_000, 20_000_000_000]
    for s in stamps:
        picks += [s, s - 1, s + 1]
    chosen = draw(
        st.lists(st.sampled_from(picks) | st.integers(0, 11_000_000_000), min_size=0, max_size=80)
    )
    return [t for t in chosen if t >= 0]


def _single(core: BufferCore, target: str, source: str, t: int) -> TransformStamped | Exception:
    try:
        return core.lookup_transform(target, source, Time.from_ns(t))
    except TransformException as exc:
        return exc


def _row(ts: TransformStamped) -> list[float]:
    return [*ts.transform.translation, *ts.transform.rotation]


@pytest.fixture(params=[True, False], ids=["as-shipped", "scalar"])
def simd(request: pytest.FixtureRequest) -> Iterator[bool]:
    """The batch as shipped, then forced onto its scalar loops; yields whether the
    vector sine is in use (False: rows must be bit-identical)."""
    try:
        yield _batch_simd(request.param)
    finally:
        assert _batch_simd(True) == _vector_sin_available()


def _assert_within_1e12(row: list[float], want: list[float]) -> None:
    """``np.testing.assert_allclose(row, want, rtol=0, atol=1e-12)``, its verdict and
    message, at plain-Python speed when every |a - b| <= 1e-12 (assert_allclose costs a
    millisecond a row: the 20 000-row tests' whole time). What that does not accept
    (NaN, inf, a larger error) goes to assert_allclose itself."""
    if not all(abs(a - b) <= 1e-12 for a, b in zip(row, want, strict=True)):
        np.testing.assert_allclose(row, want, rtol=0, atol=1e-12)


def _check_row(got: TransformArray, i: int, ts: TransformStamped, vector_sin: bool) -> None:
    row = [*got.translations[i], *got.rotations[i]]
    if vector_sin:  # the batch's tolerance
        _assert_within_1e12(row, _row(ts))
    else:  # the scalar walk's arithmetic, bit for bit
        assert row == _row(ts)
    assert got.stamps[i] == ts.header.stamp.ns


@settings(
    max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_rows_equal_single_lookups(simd: bool, data: st.DataObject) -> None:
    core, stamps = data.draw(buffers())
    target = data.draw(st.sampled_from(FRAMES))
    source = data.draw(st.sampled_from(FRAMES))
    times = _query_times(data.draw, stamps)
    if not times:  # no single lookup to compare with (the batch still validates ids)
        return
    singles = [_single(core, target, source, t) for t in times]
    first_error = next((r for r in singles if isinstance(r, Exception)), None)
    arr = np.array(times, dtype=np.int64)
    try:
        got = core.lookup_transforms(target, source, arr)
    except TransformException as exc:
        assert first_error is not None, f"raised {exc!r} where every single lookup works"
        assert type(exc) is type(first_error)
        assert str(exc) == str(first_error)
    else:
        assert first_error is None, f"did not raise {first_error!r}"
        assert len(got) == len(times)
        for i, ts in enumerate(singles):
            assert isinstance(ts, TransformStamped)
            _check_row(got, i, ts, simd)
    masked = (
        core.lookup_transforms(target, source, arr, errors="mask")
        if (
            (target in core.get_frame_names() and source in core.get_frame_names())
            or target == source
        )
        else None
    )
    if masked is not None:
        codes = masked.error_codes
        assert codes.shape == (len(times),) and codes.dtype == np.uint8
        for i, ts in enumerate(singles):
            if isinstance(ts, Exception):
                assert not masked.valid[i]
                assert np.isnan(masked.translations[i]).all()
                # The row says why: the single lookup's class, code and message.
                assert type(masked.error(i)) is type(ts)
                assert codes[i] == tf2_error_of(ts) != TF2Error.TF2_NO_ERROR
                assert masked.error_message(i) == str(ts)
            else:
                assert masked.valid[i]
                assert codes[i] == 0 and masked.error(i) is None
                _assert_within_1e12([*masked.translations[i], *masked.rotations[i]], _row(ts))


def _chain(depth: int, n: int = 101) -> BufferCore:
    """A chain f0 <- f1 <- ... <- f{depth}, every link sampled every 10 ms at stamps
    offset by k ns per link (so every link interpolates at a shared query time)."""
    core = BufferCore(cache_time=100.0)
    for k in range(1, depth + 1):
        for j in range(n):
            a = 0.01 * j * k
            c = math.cos(a / 2)
            core.set_transform(
                TransformStamped(
                    Header(Time.from_ns(j * 10_000_000 + k), f"f{k - 1}"),
                    f"f{k}",
                    Transform(
                        Vector3(0.1 * k + 0.01 * j, -0.2 * k, 0.3),
                        Quaternion(0.0, 0.6 * math.sin(a / 2), 0.8 * math.sin(a / 2), c),
                    ),
                )
            )
    return core


@pytest.mark.parametrize(
    ("target", "source"), [("f0", "f8"), ("f8", "f0"), ("f3", "f7"), ("f7", "f3"), ("f5", "f5")]
)
def test_chain_rows_and_split_in_two_threads(simd: bool, target: str, source: str) -> None:
    core = _chain(8)
    if COMPILED:  # a split that lost earlier (a busy machine) must not skip this one
        from tfbus.core import _cbatch

        _cbatch._split_reset()
    rng = np.random.default_rng(1)
    times = np.sort(rng.integers(10, 999_000_000, 20_000))  # above the two-thread split
    got = core.lookup_transforms(target, source, times)
    for i in range(20_000):  # every row: both threads, every block of 32 rows
        ts = core.lookup_transform(target, source, Time.from_ns(int(times[i])))
        _check_row(got, i, ts, simd and target != source)
    assert got.frame_id == target and got.child_frame_id == source
    assert got.valid.all()


@pytest.mark.skipif(not COMPILED, reason="the compiled kernel's two-thread split")
def test_a_split_that_loses_to_one_thread_backs_off_to_one_thread() -> None:
    """Each two-thread call is judged against the caller's own pace: one thread would
    have taken own_ns * n_rows / own_rows. A loss (or a worker that never started: no
    core free) runs the next 1, 2, 4, ... 64 calls on one thread; a win resets."""
    from tfbus.core import _cbatch

    _cbatch._split_reset()
    try:
        # caller: 4 096 of 8 192 rows in 400 us -> one thread ~800 us
        assert _cbatch._split_after(500_000, 400_000, 4_096, 8_192, True) == 0  # won
        assert _cbatch._split_after(900_000, 400_000, 4_096, 8_192, True) == 1  # lost
        assert _cbatch._split_after(2_000_000, 700_000, 7_680, 8_192, True) == 2
        assert _cbatch._split_after(800_000, 800_000, 8_192, 8_192, False) == 4
        for want in (8, 16, 32, 64, 64):
            assert _cbatch._split_after(3_000_000, 400_000, 4_096, 8_192, True) == want
        assert _cbatch._split_after(600_000, 400_000, 4_096, 8_192, True) == 0  # won
        assert _cbatch._split_after(900_000, 400_000, 4_096, 8_192, True) == 1
    finally:
        _cbatch._split_reset()


def _threads_of_this_process() -> set[str]:
    return set(os.listdir("/proc/self/task"))


@pytest.mark.skipif(not COMPILED, reason="the compiled kernel's two-thread split")
@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="lists threads in /proc")
def test_the_split_keeps_one_worker_thread_and_ends_it() -> None:
    """Every call that splits uses the same worker thread (started by the first, asleep
    between calls): 12 split calls start one thread, the same one stays while idle, and
    ``_worker_stop`` (run at exit) ends it; the next split starts a new one."""
    from tfbus.core import _cbatch

    core = _chain(8)
    times = np.sort(np.random.default_rng(4).integers(10, 999_000_000, 20_000))
    want = core.lookup_transforms("f0", "f8", times[:8_000])  # one thread
    assert _cbatch._worker_stop()
    before = _threads_of_this_process()
    started = _cbatch._worker_threads_started()
    seen: list[set[str]] = []
    for _ in range(12):
        _cbatch._split_reset()  # a split lost on a busy machine must not skip this one
        got = core.lookup_transforms("f0", "f8", times)
        assert np.array_equal(got.rotations[:8_000], want.rotations)
        assert np.array_equal(got.translations[:8_000], want.translations)
        seen.append(_threads_of_this_process() - before)
    assert _cbatch._worker_threads_started() == started + 1
    worker = seen[0]
    assert len(worker) == 1  # one thread, waiting for the next call
    assert all(new == worker for new in seen)  # the same thread after every call
    assert _cbatch._worker_stop()
    for _ in range(5_000):  # bounded: the thread has left its loop and is ending
        if worker.isdisjoint(_threads_of_this_process()):
            break
        time.sleep(0.001)
    assert worker.isdisjoint(_threads_of_this_process())
    _cbatch._split_reset()
    core.lookup_transforms("f0", "f8", times)
    assert _cbatch._worker_threads_started() == started + 2


def test_concurrent_batches_from_two_threads_give_the_same_rows() -> None:
    """Two Python threads batching at once (one may use the worker thread, the other
    runs alone): every call's rows are those of a call made alone."""
    core = _chain(8)
    times = np.sort(np.random.default_rng(5).integers(10, 999_000_000, 20_000))
    want = core.lookup_transforms("f0", "f8", times)
    results: list[TransformArray] = []

    def run() -> None:
        for _ in range(6):
            results.append(core.lookup_transforms("f0", "f8", times))

    threads = [threading.Thread(target=run) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert len(results) == 12
    for got in results:
        assert np.array_equal(got.translations, want.translations)
        assert np.array_equal(got.rotations, want.rotations)
        assert np.array_equal(got.stamps, want.stamps)


@pytest.mark.skipif(
    not COMPILED,
    reason="the pure-Python core's walks and inserts interleave between bytecodes",
)
def test_inserts_from_another_thread_during_batches_leave_the_rows_unchanged() -> None:
    """Another Python thread inserting into the same links (at times after every queried
    time, so no row's answer changes) while large batches run: the batch reads the
    links' arrays, which an insert regrows, so no insert may run inside a batch; every
    batch's rows are those of a batch made alone."""
    core = _chain(8)
    times = np.sort(np.random.default_rng(6).integers(10, 999_000_000, 20_000))[::-1].copy()
    want = core.lookup_transforms("f0", "f8", times)
    done = threading.Event()

    def insert() -> None:
        j = 0
        while not done.is_set() and j < 2_000_000:  # bounded
            k = 1 + j % 8
            core.set_transform(
                TransformStamped(
                    Header(Time.from_ns(2_000_000_000 + j * 1_000 + k), f"f{k - 1}"),
                    f"f{k}",
                    Transform(Vector3(0.1, 0.2, 0.3), Quaternion(0.0, 0.0, 0.0, 1.0)),
                )
            )
            j += 1

    inserter = threading.Thread(target=insert)
    inserter.start()
    differing = 0
    try:
        for _ in range(150):
            got = core.lookup_transforms("f0", "f8", times)
            same = np.array_equal(got.translations, want.translations) and np.array_equal(
                got.rotations, want.rotations
            )
            differing += not same
    finally:
        done.set()
        inserter.join(timeout=60)
    assert not inserter.is_alive()
    assert differing == 0


@pytest.mark.parametrize(
    "order", ["random", "reversed", "reversed-duplicated", "duplicated", "mixed", "wide", "short"]
)
def test_rows_do_not_depend_on_the_order_of_times(simd: bool, order: str) -> None:
    """Unsorted times are walked sorted and written back to their rows: each row is the
    single lookup at its own time (bit for bit on the scalar loops), and the same bits
    as the sorted batch's row for that time; time 0 and failing times keep their rows."""
    core = _chain(8)
    rng = np.random.default_rng(2)
    base = rng.integers(10, 999_000_000, 20_000)  # above the two-thread split
    times = {
        "random": base,
        "reversed": np.sort(base)[::-1].copy(),
        "duplicated": rng.permutation(np.repeat(base[:5_000], 4)),  # each time 4 times
        # time 0, times before and after the data (masked), exact stamps
        "mixed": rng.permutation(
            np.r_[base[:3_000], [0] * 5, [1, 2, 5, 2_000_000_000] * 3, [10_000_008] * 7]
        ),
        "reversed-duplicated": np.sort(np.repeat(base[:5_000], 4))[::-1].copy(),
        # times too far apart to pack a time and its row into one int64 sort key
        "wide": rng.permutation(np.r_[base[:3_000], [2**62, 2**61 + 5] * 3, [1] * 6]),
        "short": base[:63],  # below the rows from which unsorted times are sorted
    }[order]
    got = core.lookup_transforms("f0", "f8", times, errors="mask")
    order_idx = np.argsort(times, kind="stable")
    ordered = core.lookup_transforms("f0", "f8", times[order_idx], errors="mask")
    for name in ("translations", "rotations", "stamps", "valid"):
        a, b = getattr(got, name)[order_idx], getattr(ordered, name)
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), name
    for i in range(times.shape[0]):
        single = _single(core, "f0", "f8", int(times[i]))
        if isinstance(single, Exception):
            assert not got.valid[i] and np.isnan(got.translations[i]).all()
            assert got.stamps[i] == times[i]
        else:
            assert got.valid[i]
            _check_row(got, i, single, simd)
    # before and after the data
    assert (~got.valid).sum() == (12 if order in ("mixed", "wide") else 0)


def test_first_failing_time_decides_the_exception() -> None:
    core = _chain(2)
    times = [5_000_000, 2_000_000_000, 1, 3_000_000]
    with pytest.raises(ExtrapolationException) as info:
        core.lookup_transforms("f0", "f2", times)
    with pytest.raises(ExtrapolationException) as single:
        core.lookup_transform("f0", "f2", Time.from_ns(2_000_000_000))
    assert str(info.value) == str(single.value)
    assert "into the future" in str(info.value)
    masked = core.lookup_transforms("f0", "f2", times, errors="mask")
    assert masked.valid.tolist() == [True, False, False, True]
    assert np.isnan(masked.rotations[1]).all()
    assert masked.stamps.tolist() == times


def test_masked_rows_carry_ros2_tf2_codes_and_messages() -> None:
    """A chain f0 <- f1 <- f2 sampled 0..1 s, f2 re-parented to a lone frame x at 1.5 s, a
    link f0 <- f3 with one sample at 0.5 s: each row's code is ROS 2 tf2's TF2Error of the
    exception the single lookup raises for it (tf2/include/tf2/exceptions.hpp)."""
    core = _chain(2)
    core.set_transform(_ts("f0", "f3", 500_000_000, (0, 0, 0, 0, 0, 0, 1)))
    core.set_transform(_ts("x", "f2", 1_500_000_000, (0, 0, 0, 0, 0, 0, 1)))
    rows = [
        ("f0", "f2", 500_000_003, TF2Error.TF2_NO_ERROR, None),
        ("f0", "f1", 0, TF2Error.TF2_NO_ERROR, None),
        ("f0", "f1", 2_000_000_000, TF2Error.TF2_FORWARD_EXTRAPOLATION_ERROR,
         ForwardExtrapolationException),
        ("f1", "f2", 1, TF2Error.TF2_BACKWARD_EXTRAPOLATION_ERROR,
         BackwardExtrapolationException),
        ("f1", "f3", 600_000_000, TF2Error.TF2_NO_DATA_FOR_EXTRAPOLATION_ERROR,
         NoDataForExtrapolationException),
        ("f0", "f2", 1_500_000_000, TF2Error.TF2_CONNECTIVITY_ERROR, ConnectivityException),
    ]
    for target, source, ns, code, exc_type in rows:
        got = core.lookup_transforms(target, source, [ns, ns], errors="mask")
        assert got.error_codes.tolist() == [code, code], (target, source, ns)
        if exc_type is None:
            assert got.valid.all() and got.error(0) is None and got.error_message(-1) is None
            continue
        with pytest.raises(exc_type) as single:
            core.lookup_transform(target, source, Time.from_ns(ns))
        assert type(got.error(1)) is exc_type
        assert got.error_message(0) == got.error_message(-2) == str(single.value)
    with pytest.raises(IndexError, match="row 2 is out of range for 2 rows"):
        got.error(2)
    # One batch, mixed rows: answered rows 0, each failed row its own code.
    mixed = core.lookup_transforms("f1", "f2", [1, 500_000_002, 2_000_000_000], errors="mask")
    assert mixed.error_codes.tolist() == [7, 0, 8]
    # lookup_transforms_full: a row failing on both legs keeps the source leg's reason,
    # the leg the single call looks up first.
    full = core.lookup_transforms_full(
        "f1", [2_000_000_000, 2_000_000_000, 500_000_002], "f2", [1, 500_000_002, 500_000_002],
        "f0", errors="mask",
    )
    assert full.error_codes.tolist() == [7, 8, 0]
    with pytest.raises(BackwardExtrapolationException) as single:
        core.lookup_transform_full(
            "f1", Time.from_ns(2_000_000_000), "f2", Time.from_ns(1), "f0"
        )
    assert full.error_message(0) == str(single.value)
    # A non-exact policy: each row as lookup_transform(..., policy=) raises it.
    near = Nearest(0.001)
    policy_rows = core.lookup_transforms(
        "f1", "f2", [1, 500_000_002, 3_000_000_000], errors="mask", policy=near
    )
    assert policy_rows.valid.tolist() == [True, True, False]
    assert policy_rows.error_codes.tolist() == [0, 0, tf2_error_of(policy_rows.error(2))]
    with pytest.raises(TransformException) as single:
        core.lookup_transform("f1", "f2", Time.from_ns(3_000_000_000), policy=near)
    assert type(policy_rows.error(2)) is type(single.value)
    assert policy_rows.error_message(2) == str(single.value)


def test_frame_errors_match_the_single_lookup() -> None:
    core = _chain(2)
    core.set_transform_static(_ts("x", "y", 0, (0, 0, 0, 0, 0, 0, 1)))
    for target, source, exc_type in [
        ("", "f1", InvalidArgumentException),
        ("/f0", "f1", InvalidArgumentException),
        ("f0", "nope", LookupException),
        ("f0", "y", ConnectivityException),
    ]:
        with pytest.raises(exc_type) as batch:
            core.lookup_transforms(target, source, [1_000_000, 0])
        with pytest.raises(exc_type) as single:
            core.lookup_transform(target, source, Time.from_ns(1_000_000))
        assert str(batch.value) == str(single.value)


def test_time_zero_and_identity() -> None:
    core = _chain(2)
    got = core.lookup_transforms("f0", "f2", [0, 0])
    latest = core.lookup_transform("f0", "f2", Time(0))
    assert got.stamps.tolist() == [latest.header.stamp.ns] * 2
    ident = core.lookup_transforms("f1", "f1", [0, 7])
    assert ident.stamps.tolist() == [core.lookup_transform("f1", "f1", Time(0)).header.stamp.ns, 7]
    assert ident.rotations.tolist() == [[0.0, 0.0, 0.0, 1.0]] * 2


def test_as_matrices_and_transform_points() -> None:
    core = _chain(3)
    times = np.array([1_000_000, 333_333_333, 777_777_777])
    arr = core.lookup_transforms("f0", "f3", times)
    m = arr.as_matrices()
    assert m.shape == (3, 4, 4)
    pts = np.array([[1.0, 2.0, 3.0], [-1.0, 0.5, 0.0], [0.0, 0.0, 0.0]])
    expected = []
    for t, p in zip(times, pts, strict=True):
        ts = core.lookup_transform("f0", "f3", Time.from_ns(int(t)))
        x, y, z, w = ts.transform.rotation
        # q p q* computed independently as a rotation matrix
        r = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )
        expected.append(r @ p + np.array(ts.transform.translation))
    np.testing.assert_allclose(core.transform_points(pts, "f0", "f3", times), expected, atol=1e-12)
    homog = np.einsum("nij,nj->ni", m, np.c_[pts, np.ones(3)])[:, :3]
    np.testing.assert_allclose(homog, expected, atol=1e-12)


def test_lookup_transforms_full_matches_single() -> None:
    core = _chain(3)
    tt = np.array([100_000_000, 200_000_000, 300_000_000])
    stt = np.array([150_000_000, 50_000_000, 900_000_000])
    got = core.lookup_transforms_full("f3", tt, "f2", stt, "f0")
    for i in range(3):
        ts = core.lookup_transform_full(
            "f3", Time.from_ns(int(tt[i])), "f2", Time.from_ns(int(stt[i])), "f0"
        )
        np.testing.assert_allclose(
            np.r_[got.translations[i], got.rotations[i]], _row(ts), atol=1e-12
        )
        assert got.stamps[i] == ts.header.stamp.ns
    with pytest.raises(ExtrapolationException) as batch:
        core.lookup_transforms_full("f3", [1, 5_000_000_000], "f2", 1_000_000, "f0")
    with pytest.raises(ExtrapolationException) as single:
        core.lookup_transform_full("f3", Time.from_ns(1), "f2", Time.from_ns(1_000_000), "f0")
    assert str(batch.value) == str(single.value)


def test_bad_times_are_refused_with_the_field_named() -> None:
    core = _chain(1)
    with pytest.raises(ValueError, match="times must be integer"):
        core.lookup_transforms("f0", "f1", np.array([0.5]))
    with pytest.raises(ValueError, match="one-dimensional"):
        core.lookup_transforms("f0", "f1", np.zeros((2, 2), dtype=np.int64))
    with pytest.raises(ValueError, match=">= 0"):
        core.lookup_transforms("f0", "f1", [-1])
    with pytest.raises(ValueError, match="errors must be"):
        core.lookup_transforms("f0", "f1", [1], errors="ignore")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="points must have shape"):
        core.transform_points(np.zeros((2, 2)), "f0", "f1", [1, 2])
    assert as_times([Time(1), Time(2)]).tolist() == [1_000_000_000, 2_000_000_000]
    assert len(core.lookup_transforms("f0", "f1", [])) == 0
    assert isinstance(core.lookup_transforms("f0", "f1", Time(0)), TransformArray)


def _spin_chain(steps: list[float], n: int = 41) -> BufferCore:
    """A chain f0 <- f1 <- ... whose link k turns by ``steps[k - 1]`` rad about a tilted
    axis between consecutive samples (10 ms apart): slerp angles from ~1e-9 (a cosine
    that may round to 1: tf2's zero angle) to beyond pi/2 between the quaternions (the
    sign flip of b)."""
    core = BufferCore(cache_time=100.0)
    for k, step in enumerate(steps, start=1):
        for j in range(n):
            a = step * j
            s = math.sin(a / 2)
            core.set_transform(
                _ts(f"f{k - 1}", f"f{k}", j * 10_000_000 + 3 * k,
                    (0.5 * k, 0.01 * j, -0.1, 0.48 * s, 0.6 * s, 0.64 * s, math.cos(a / 2)))
            )  # fmt: skip
    return core


def test_rows_over_every_slerp_angle(simd: bool) -> None:
    steps = [1e-9, 3e-8, 1e-3, 0.05, 0.2, 0.3, 1.0, 4.0]
    core = _spin_chain(steps)
    rng = np.random.default_rng(5)
    times = np.sort(rng.integers(10_000_000, 399_000_000, 9_000))
    times[::97] = (times[::97] // 10_000_000) * 10_000_000 + 3  # exact stamps of link 1
    shuffled = rng.permutation(times)  # the search cursor also meets unsorted times
    for arr in (times, shuffled):
        for target, source in [("f0", "f8"), ("f8", "f2")]:
            got = core.lookup_transforms(target, source, arr)
            for i in range(0, arr.shape[0], 7):
                ts = core.lookup_transform(target, source, Time.from_ns(int(arr[i])))
                _check_row(got, i, ts, simd)


def test_rows_without_sines_are_bit_exact_with_the_vector_sine() -> None:
    """As shipped (vector sine or not): rows at exact stamps of every dynamic link,
    through static links, and rows interpolated on links whose rotation is constant
    (tf2's zero slerp angle: no sine) are the single lookup's bit for bit."""
    assert _batch_simd(True) == _vector_sin_available()
    core = BufferCore(cache_time=100.0)
    for k in range(1, 7):
        parent, child = f"f{k - 1}", f"f{k}"
        if k % 3 == 0:
            core.set_transform_static(
                _ts(parent, child, 0, (0.1 * k, 0.2, -0.3, 0.1, 0.2, 0.3, 0.9))
            )
            continue
        for j in range(60):
            a = 0.0 if k == 4 else 0.07 * j * k  # link 4: constant rotation, moving origin
            v = (0.5 * k + 0.01 * j, -0.2, 0.3, 0.36 * math.sin(a), 0.48 * math.sin(a),
                 0.8 * math.sin(a), math.cos(a))  # fmt: skip
            core.set_transform(_ts(parent, child, j * 10_000_000, v))
    stamps = np.arange(1, 59, dtype=np.int64) * 10_000_000
    rng = np.random.default_rng(9)
    times = np.sort(np.r_[np.repeat(stamps, 150), 0])  # > the two-thread split, with time 0
    for target, source in [("f0", "f6"), ("f6", "f1"), ("f2", "f5")]:
        got = core.lookup_transforms(target, source, times)
        for i in rng.choice(times.shape[0], 600, replace=False):
            ts = core.lookup_transform(target, source, Time.from_ns(int(times[i])))
            _check_row(got, int(i), ts, vector_sin=False)
    # link 4 alone between samples: a constant rotation, no sine
    mid = stamps + 3_333_333
    got = core.lookup_transforms("f3", "f4", mid)
    for i in range(mid.shape[0]):
        _check_row(got, i, core.lookup_transform("f3", "f4", Time.from_ns(int(mid[i]))), False)


def test_compiled_batch_lookup_stays_bit_exact() -> None:
    """The core's ``batch_lookup`` (the entry the pure-Python core twins) keeps libm's sines
    whatever the CPU: every row bit for bit the single lookup's, across both threads;
    only ``lookup_transforms`` (``_batch_lookup_vector``) may vectorise them."""
    assert _batch_simd(True) == _vector_sin_available()
    core = _chain(8)
    times = np.sort(np.random.default_rng(3).integers(10, 999_000_000, 12_000))
    out = np.zeros((times.shape[0], 7))
    stamps = times.copy()
    ok = np.zeros(times.shape[0], dtype=np.int8)
    assert batch_lookup(core, "f1", "f8", times, out, stamps, ok) == times.shape[0]
    for i in range(times.shape[0]):
        ts = core.lookup_transform("f1", "f8", Time.from_ns(int(times[i])))
        assert out[i].tolist() == _row(ts)
