"""``CoreBase._settle``, the core's half of a Buffer's wake-up after an insert, on both
twins (compiled and pure), on asyncio and trio: an exact wait whose lookup the insert
completed is settled in the core (result, index, wake-up); what it cannot settle comes
back to the buffer with the failure it just walked."""

from __future__ import annotations

import math
from functools import partial
from types import ModuleType
from typing import Any

import pytest

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus._aio import running_asyncio_loop
from tfbus.buffer import _Waiter
from tfbus.core import BufferCore, _pycore
from tfbus.core.buffer_core import EXTRAPOLATION_ERROR

_ccore = pytest.importorskip("tfbus.core._ccore", reason="the compiled core is not built here")

pytestmark = pytest.mark.anyio

CORES: dict[str, ModuleType] = {"compiled": _ccore, "pure": _pycore}
T1 = Time(10)
T2 = Time(12)


def buffer_core(twin: str) -> BufferCore:
    """``BufferCore``'s own methods over the given core's ``CoreBase``."""
    body = {k: v for k, v in vars(BufferCore).items() if k not in {"__dict__", "__weakref__"}}
    klass: type[BufferCore] = type("BufferCore", (CORES[twin].CoreBase,), body)
    return klass()


def tf(parent: str, child: str, stamp: Time, x: float) -> TransformStamped:
    q = Quaternion(0.0, 0.0, math.sin(0.15), math.cos(0.15))
    return TransformStamped(Header(stamp, parent), child, Transform(Vector3(x, 0.5, 0.0), q))


def wait_on(
    index: dict[str, set[Any]],
    frames: frozenset[str],
    exact: tuple[str, str, Time, bool] | None,
    kind: type[_Waiter[Any]] = _Waiter,
) -> _Waiter[Any]:
    """A Buffer's wait (``tfbus.buffer._Waiter``, or ``kind``), indexed under ``frames``."""
    waiter: _Waiter[Any] = kind(lambda: None, lambda: frames, running_asyncio_loop(), exact)
    waiter.frames = frames
    for name in frames:
        index.setdefault(name, set()).add(waiter)
    return waiter


def woken(waiter: _Waiter[Any]) -> bool:
    if waiter.future is not None:  # asyncio
        return waiter.future.done()
    return waiter.woken  # trio


@pytest.mark.parametrize("twin", sorted(CORES))
async def test_an_exact_wait_the_insert_completes_is_settled_in_the_core(twin: str) -> None:
    core = buffer_core(twin)
    assert core.set_transform(tf("map", "odom", T1, 1.0))
    assert core.set_transform(tf("map", "odom", T2, 3.0))
    index: dict[str, set[Any]] = {}
    frames = frozenset({"map", "odom", "base"})
    waiter = wait_on(index, frames, ("map", "base", Time(11), False))
    other = wait_on(index, frozenset({"map", "laser"}), ("map", "laser", T1, False))
    assert core.set_transform(tf("odom", "base", T1, 0.25))
    # odom -> base is known at 10 only: the wait at 11 is not answered yet, and comes
    # back with the failure of its walk (extrapolation into the future).
    assert core._settle(index, None) == [(waiter, core._query("map", "base", Time(11)))]
    assert core._query("map", "base", Time(11))[0] == EXTRAPOLATION_ERROR
    assert waiter.result is None and not woken(waiter)
    assert core.set_transform(tf("odom", "base", T2, 0.75))
    assert core._settle(index, None) is None  # nothing left for the buffer
    # Settled by this one: interpolated (map->odom x 2.0 at 11, odom->base x 0.5).
    assert isinstance(waiter.result, TransformStamped)
    assert waiter.result.header == Header(Time(11), "map")
    assert waiter.result.child_frame_id == "base"
    assert waiter.result == core.lookup_transform("map", "base", Time(11))
    c, s = math.cos(0.3), math.sin(0.3)  # map->odom turns by 0.3 rad about z
    x, y, z = waiter.result.transform.translation
    assert (x, y, z) == pytest.approx((2.0 + 0.5 * c - 0.5 * s, 0.5 + 0.5 * s + 0.5 * c, 0.0))
    assert woken(waiter)
    assert waiter.frames == frozenset()
    # Removed under each of its frames; the other wait (not touched) stays indexed.
    assert index == {"map": {other}, "laser": {other}}
    assert other.result is None and not woken(other)


@pytest.mark.parametrize("twin", sorted(CORES))
async def test_what_the_core_cannot_settle_comes_back_with_its_failure(twin: str) -> None:
    core = buffer_core(twin)
    assert core.set_transform(tf("map", "odom", T1, 1.0))
    index: dict[str, set[Any]] = {}
    late = wait_on(index, frozenset({"map", "odom"}), ("map", "odom", T2, False))
    policy = wait_on(index, frozenset({"odom"}), None)  # a policy's wait: the buffer's check
    assert core.set_transform(tf("map", "odom", Time(11), 2.0))
    rest = core._settle(index, None)
    assert rest is not None
    by_wait = dict(rest)
    assert set(by_wait) == {late, policy}
    assert by_wait[policy] is None
    failure = by_wait[late]
    assert failure == core._query("map", "odom", T2)  # the walk it just did
    assert failure is not None and failure[0] == EXTRAPOLATION_ERROR
    # Neither is settled: both stay indexed, unwoken, for the buffer's own recheck.
    assert index == {"map": {late}, "odom": {late, policy}}
    assert not woken(late) and not woken(policy)


def following_core(twin: str) -> tuple[BufferCore, dict[str, set[Any]], list[Any]]:
    """A ``buffer_core(twin)`` whose inserts settle the waits of a dict (the core's
    ``_follow_waits``), with the subclass's ``_recheck_rest`` recording what it is given."""
    core = buffer_core(twin)
    index: dict[str, set[Any]] = {}
    handed: list[Any] = []
    core._follow_waits(index)
    type(core)._recheck_rest = lambda self, rest, relinked: handed.append((rest, relinked))
    return core, index, handed


@pytest.mark.parametrize("twin", sorted(CORES))
@pytest.mark.parametrize("static", [False, True], ids=["set_transform", "set_transform_static"])
async def test_the_insert_settles_the_waits_it_answers_before_it_returns(
    twin: str, static: bool
) -> None:
    core, index, handed = following_core(twin)
    insert = core.set_transform_static if static else core.set_transform
    assert core.set_transform(tf("map", "odom", T1, 1.0))
    assert core.set_transform(tf("map", "odom", T2, 3.0))
    stamp = T1 if static else Time(11)  # a static link answers at every time
    waiter = wait_on(index, frozenset({"map", "odom", "base"}), ("map", "base", stamp, False))
    assert insert(tf("odom", "base", T1, 0.25))
    if not static:  # known at 10 only: not answered yet, handed back with its failure
        assert handed == [([(waiter, core._query("map", "base", stamp))], True)]
        assert not woken(waiter) and waiter.result is None
        handed.clear()
        assert insert(tf("odom", "base", T2, 0.75))
    # Settled inside the insert: result, index, wake-up; nothing handed to the subclass.
    assert handed == []
    assert woken(waiter) and index == {}
    assert waiter.result == core.lookup_transform("map", "base", stamp)
    assert waiter.result.header.stamp == stamp and waiter.result.child_frame_id == "base"


@pytest.mark.parametrize("twin", sorted(CORES))
async def test_a_refused_insert_settles_nothing_and_a_plain_core_follows_no_waits(
    twin: str,
) -> None:
    core, index, handed = following_core(twin)
    assert core.set_transform(tf("map", "odom", T2, 1.0))
    waiter = wait_on(index, frozenset({"map", "odom"}), ("map", "odom", T1, False))
    # The same stamp again: TF_REPEATED_DATA, refused (on_repeat="reject").
    assert not core.set_transform(tf("map", "odom", T2, 5.0))
    assert handed == [] and not woken(waiter) and index == {"map": {waiter}, "odom": {waiter}}
    # Without _follow_waits (a BufferCore), an insert never reads the dict.
    plain = buffer_core(twin)
    waiter2 = wait_on(index, frozenset({"map", "odom"}), ("map", "odom", T1, False))
    assert plain.set_transform(tf("map", "odom", T1, 1.0))
    assert not woken(waiter2) and waiter2 in index["map"]
    core._follow_waits(None)  # stops following: the answer stays unsettled
    assert core.set_transform(tf("map", "odom", T1, 1.0))
    assert not woken(waiter) and handed == []


class _CountedWaiter(_Waiter[Any]):
    """A wait that counts how often the settle reads its ``exact`` (once per wait it
    takes: the compiled core queries through C, so a counting ``_query`` would miss it)."""

    reads = 0

    @property  # type: ignore[override]
    def exact(self) -> tuple[str, str, Time, bool] | None:
        type(self).reads += 1
        return self._exact  # type: ignore[no-any-return]

    @exact.setter
    def exact(self, value: tuple[str, str, Time, bool] | None) -> None:
        self._exact = value


@pytest.mark.parametrize("twin", sorted(CORES))
async def test_a_batch_settles_each_wait_once_whatever_the_repeats(twin: str) -> None:
    core = buffer_core(twin)
    index: dict[str, set[Any]] = {}
    frames = frozenset({"map", "odom", "base"})
    waiter = _CountedWaiter(
        lambda: None, lambda: frames, running_asyncio_loop(), ("map", "base", T1, False)
    )
    waiter.frames = frames
    for name in frames:
        index.setdefault(name, set()).add(waiter)
    result = core.set_transforms(
        [tf("map", "odom", T1, 1.0), tf("odom", "base", T1, 0.5)], "test"
    )
    assert result.stored == 2
    _CountedWaiter.reads = 0
    # The ids as recorded (child, parent per transform: "odom" twice).
    assert core._settle(index, ["odom", "map", "base", "odom"]) is None
    assert _CountedWaiter.reads == 1
    assert waiter.result == core.lookup_transform("map", "base", T1)
    assert index == {} and woken(waiter)


async def test_both_twins_settle_with_the_same_transform_bit_for_bit() -> None:
    results = []
    for twin in sorted(CORES):
        core = buffer_core(twin)
        index: dict[str, set[Any]] = {}
        waiter = wait_on(index, frozenset({"a", "b", "c"}), ("a", "c", Time(11), False))
        for stamp, x in ((T1, 0.1), (T2, 0.7)):
            core.set_transform(tf("a", "b", stamp, x))
        core.set_transform(tf("b", "c", T1, 1.0 / 3.0))
        core.set_transform(tf("b", "c", T2, 2.0 / 3.0))
        assert core._settle(index, None) is None
        results.append(waiter.result)
    assert results[0] is not None
    assert results[0] == results[1]  # every float equal (no -0.0 or NaN here)


@pytest.mark.parametrize("twin", sorted(CORES))
async def test_a_settled_wait_is_listed_and_left_in_the_index_when_asked(twin: str) -> None:
    """``_follow_waits(index, settled)`` (what a Buffer passes): the insert that answers
    a wait settles it (result, wake-up) without editing ``index``; the wait is appended
    to ``settled`` for the buffer to remove later, keeps its ``frames``, and a later
    insert on the same frames skips it (settled once, listed once)."""
    core = buffer_core(twin)
    assert core.set_transform(tf("map", "odom", T1, 1.0))
    index: dict[str, set[Any]] = {}
    settled: list[Any] = []
    core._follow_waits(index, settled)
    frames = frozenset({"map", "odom"})
    waiter = wait_on(index, frames, ("map", "odom", T2, False))
    assert core.set_transform(tf("map", "odom", T2, 3.0))
    assert woken(waiter)
    assert waiter.result == core.lookup_transform("map", "odom", T2)
    assert waiter.result.transform.translation.x == 3.0
    assert settled == [waiter]
    assert waiter.frames == frames
    assert index == {"map": {waiter}, "odom": {waiter}}
    first = waiter.result
    assert core.set_transform(tf("map", "odom", Time(14), 5.0))
    assert settled == [waiter]  # not settled again
    assert waiter.result is first
    assert core._settle(index, None) is None


@pytest.mark.parametrize("twin", sorted(CORES))
@pytest.mark.parametrize("batch", [False, True], ids=["one insert", "a batch"])
async def test_with_a_settled_list_each_wait_under_the_ids_is_taken_once(
    twin: str, batch: bool
) -> None:
    """A Buffer's settle (``settled`` kept): the waits under the ids an insert touched
    (its two ids, or a batch's with repeats) -- one under both, one under either alone,
    one under a third id of the batch -- are each read and settled once, listed once,
    and the index is left as it was; a wait the data does not answer comes back once
    with its failure."""
    core = buffer_core(twin)
    for transform in (tf("map", "odom", T1, 1.0), tf("odom", "base", T1, 2.0),
                      tf("odom", "base", T2, 4.0), tf("map", "odom", T2, 3.0)):
        assert core.set_transform(transform)  # the last insert's ids: odom, map
    index: dict[str, set[Any]] = {}
    settled: list[Any] = []
    core._follow_waits(index, settled)
    wait = partial(wait_on, index, kind=_CountedWaiter)
    both = wait(frozenset({"map", "odom"}), ("map", "odom", T2, False))
    parent_only = wait(frozenset({"map"}), ("map", "odom", T2, False))
    child_only = wait(frozenset({"odom"}), ("odom", "map", T2, False))
    later = wait(frozenset({"map", "odom"}), ("map", "odom", Time(99), False))
    third = wait(frozenset({"base"}), ("odom", "base", T2, False))
    before = {name: set(ws) for name, ws in index.items()}
    _CountedWaiter.reads = 0
    if batch:
        rest = core._settle(index, ["odom", "map", "base", "odom", "map"])
        answered = [both, parent_only, child_only, third]
    else:
        rest = core._settle(index, None)
        answered = [both, parent_only, child_only]
        assert third.result is None and not woken(third)
    assert _CountedWaiter.reads == len(answered) + 1  # and ``later``'s, once
    assert rest is not None and [waiter for waiter, _ in rest] == [later]
    assert rest[0][1][0] == EXTRAPOLATION_ERROR
    assert sorted(map(id, settled)) == sorted(map(id, answered))
    for waiter in answered:
        assert woken(waiter)
        assert waiter.exact is not None
        assert waiter.result == core.lookup_transform(*waiter.exact[:3])
    assert not woken(later) and later.result is None
    assert index == before
