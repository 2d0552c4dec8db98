"""Frame expiry: ``BufferCore.forget(older_than)`` and ``cache_policy=expire_after(...)``.

tf2 keeps every frame it has seen (ros/geometry2 #409, #239). The rule checked here, on
both core twins (compiled ``_ccore``, pure ``_pycore``): a dynamic link is removed when
its newest sample is older than ``older_than``; static links never are; a frame id stays
known while it has a link or a remaining link has named it as a parent, else it becomes
unknown as if never seen. The property test compares the buffer after random inserts
and forgets with a fresh buffer fed only the samples of the links a brute-force model
says remain.
"""

from __future__ import annotations

import math
from types import ModuleType
from typing import Any

import anyio
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.buffer import Buffer
from tfbus.clock import ManualClock
from tfbus.core import BufferCore, _pycore
from tfbus.core.policy import ExpireAfter, expire_after
from tfbus.errors import (
    ConnectivityException,
    LookupException,
    TimeoutException,
    TransformException,
)

_ccore = pytest.importorskip("tfbus.core._ccore", reason="the compiled core is not built")

CORES: dict[str, ModuleType] = {"compiled": _ccore, "pure": _pycore}
S = 1_000_000_000


def buffer_core(twin: str, **kwargs: Any) -> BufferCore:
    """``BufferCore``'s own methods over the given core's ``CoreBase``."""
    body = {k: v for k, v in vars(BufferCore).items() if k not in {"__dict__", "__weakref__"}}
    klass: type[BufferCore] = type("BufferCore", (CORES[twin].CoreBase,), body)
    return klass(**kwargs)


def ts(parent: str, child: str, ns: int, x: float = 1.0, yaw: float = 0.0) -> TransformStamped:
    q = Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    return TransformStamped(
        Header(Time.from_ns(ns), parent), child, Transform(Vector3(x, 0.0, 0.0), q)
    )


def outcome(core: BufferCore, target: str, source: str, t: int) -> object:
    """The lookup's answer, or its exception's class and message."""
    try:
        return core.lookup_transform(target, source, Time.from_ns(t))
    except TransformException as exc:
        return type(exc), str(exc)


# ---------------------------------------------------------------------- the rule


@pytest.mark.parametrize("twin", sorted(CORES))
def test_forget_removes_links_older_than_the_limit_and_their_unnamed_frames(twin: str) -> None:
    core = buffer_core(twin)
    core.set_transform(ts("map", "odom", 10 * S))
    core.set_transform(ts("odom", "base", 20 * S))
    core.set_transform(ts("odom", "base", 21 * S))
    core.set_transform(ts("map", "cup", 5 * S))
    core.set_transform_static(ts("base", "laser", 1 * S))
    assert core.forget(5 * S) == 0  # strictly older: cup's newest 5 s stays
    assert core.forget(8 * S) == 1  # cup
    assert core.get_frame_names() == ["odom", "map", "base", "laser"]
    assert core.forget(Time(15)) == 1  # odom's link; base still names odom: odom stays
    assert core.get_frame_names() == ["odom", "base", "laser"]  # map was named by odom only
    assert core.lookup_transform("odom", "laser", Time(0)).transform.translation.x == 2.0
    assert core.all_frames_as_string() == (
        "Frame base exists with parent odom.\nFrame laser exists with parent base.\n"
    )
    assert core.forget(Time(21)) == 0  # base's newest is 21 s
    assert core.forget(Time(22)) == 1  # base; the static laser link stays and names base
    assert core.get_frame_names() == ["base", "laser"]
    assert core.lookup_transform("base", "laser", Time(0)).transform.translation.x == 1.0


@pytest.mark.parametrize("twin", sorted(CORES))
def test_a_forgotten_frame_is_unknown_exactly_as_if_never_seen(twin: str) -> None:
    core = buffer_core(twin)
    core.set_transform(ts("map", "cup", 5 * S))
    core.set_transform(ts("map", "base", 30 * S))
    core.forget(Time(10))
    never = buffer_core(twin)
    never.set_transform(ts("map", "base", 30 * S))
    for args in (("map", "cup"), ("cup", "base"), ("base", "cup")):
        with pytest.raises(LookupException) as got:
            core.lookup_transform(*args, Time(0))
        with pytest.raises(LookupException) as want:
            never.lookup_transform(*args, Time(0))
        assert str(got.value) == str(want.value)
        assert "cup" in str(got.value) and "does not exist" in str(got.value)
    assert core.frame_exists("cup") is False
    assert core.can_transform("map", "cup", Time(0)) is False
    assert "cup" not in core.all_frames_as_yaml()
    assert core.all_frames_as_yaml() == never.all_frames_as_yaml()
    # It comes back with new data, under the number of a forgotten frame.
    core.set_transform(ts("base", "cup", 30 * S, x=0.25))
    assert core.lookup_transform("map", "cup", Time(0)).transform.translation.x == 1.25
    assert sorted(core.get_frame_names()) == ["base", "cup", "map"]


@pytest.mark.parametrize("twin", sorted(CORES))
def test_a_child_whose_parent_link_expired_is_in_another_tree(twin: str) -> None:
    core = buffer_core(twin)
    core.set_transform(ts("map", "odom", 1 * S))
    core.set_transform(ts("odom", "base", 9 * S))
    assert core.lookup_transform("map", "odom", Time(0)).transform.translation.x == 1.0
    assert core.forget(Time(5)) == 1
    with pytest.raises(LookupException, match="frame does not exist"):
        core.lookup_transform("map", "base", Time(0))  # map was named only by odom
    core.set_transform(ts("map", "elsewhere", 9 * S))
    with pytest.raises(ConnectivityException, match="not part of the same tree"):
        core.lookup_transform("map", "base", Time(0))
    assert core.get_parent("odom") is None  # a root now


@pytest.mark.parametrize("twin", sorted(CORES))
def test_static_links_never_expire_and_a_cleared_link_does(twin: str) -> None:
    core = buffer_core(twin)
    core.set_transform_static(ts("base", "camera", 1))
    core.set_transform(ts("map", "base", 50 * S))
    assert core.forget(Time(40)) == 0
    core.clear()  # keeps the links, drops the samples: newest 0
    assert core.forget(1) == 1  # the emptied dynamic link
    assert sorted(core.get_frame_names()) == ["base", "camera"]
    assert core.lookup_transform("base", "camera", Time(3)).transform.translation.x == 1.0


@pytest.mark.parametrize("twin", sorted(CORES))
def test_forget_checks_its_argument(twin: str) -> None:
    core = buffer_core(twin)
    with pytest.raises(TypeError, match="older_than must be a tfbus Time or int nanoseconds"):
        core.forget(1.5)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="got bool True"):
        core.forget(True)
    with pytest.raises(ValueError, match=r"older_than must be in \[0, 2\*\*63 - 1\] ns, got -1"):
        core.forget(-1)


@pytest.mark.parametrize("twin", sorted(CORES))
def test_a_link_refreshed_since_the_last_forget_stays(twin: str) -> None:
    """The heap keeps each link by the newest stamp seen when last examined: a link
    updated since then is examined again and kept, with its new stamp."""
    core = buffer_core(twin)
    core.set_transform(ts("map", "a", 1 * S))
    core.set_transform(ts("map", "b", 1 * S))
    for k in range(2, 30):
        core.set_transform(ts("map", "a", k * S))
    assert core.forget(Time(10)) == 1  # b only
    assert core.forget(Time(25)) == 0
    assert core.forget(Time(30)) == 1  # a, newest 29 s
    assert core.get_frame_names() == []


# ---------------------------------------------------------------------- the model


FRAMES = ("f0", "f1", "f2", "f3", "f4", "f5")

insert_op = st.tuples(
    st.just("insert"),
    st.integers(1, len(FRAMES) - 1),  # child index
    st.integers(0, len(FRAMES) - 2),  # parent index (made lower than the child's)
    st.integers(0, 40),  # stamp, seconds
    st.booleans(),  # static
)
forget_op = st.tuples(st.just("forget"), st.integers(0, 45))
ops_strategy = st.lists(st.one_of(insert_op, insert_op, insert_op, forget_op), max_size=40)


def _sample(op: tuple[Any, ...]) -> tuple[str, str, int, bool]:
    _, c, p, sec, static = op
    p = min(p, c - 1)  # parents come before children: no loops
    return FRAMES[p], FRAMES[c], sec * S, static


@pytest.mark.parametrize("twin", sorted(CORES))
@settings(max_examples=150, deadline=None)
@given(ops=ops_strategy)
def test_forget_matches_a_fresh_buffer_fed_only_the_surviving_links(
    twin: str, ops: list[tuple[Any, ...]]
) -> None:
    core = buffer_core(twin, cache_time=5.0)
    # The model: every sample sent, in order, with the number that made its values; per
    # child frame whether its link is static. A link's newest stamp is the largest sent
    # to it (a refused sample is never newer than the newest stored one).
    sent: list[tuple[str, str, int, bool, int]] = []
    static_of: dict[str, bool] = {}
    for k, op in enumerate(ops):
        if op[0] == "insert":
            parent, child, ns, static = _sample(op)
            (core.set_transform_static if static else core.set_transform)(
                ts(parent, child, ns, x=float(k), yaw=0.1 * k)
            )
            static_of.setdefault(child, static)
            sent.append((parent, child, ns, static, k))
        else:
            limit = op[1] * S
            newest: dict[str, int] = {}
            for _, child, ns, _, _ in sent:
                newest[child] = max(newest.get(child, 0), ns)
            gone = {c for c, n in newest.items() if not static_of[c] and n < limit}
            assert core.forget(limit) == len(gone)
            sent = [s for s in sent if s[1] not in gone]
            for c in gone:
                del static_of[c]
    fresh = buffer_core(twin, cache_time=5.0)
    for parent, child, ns, static, k in sent:
        (fresh.set_transform_static if static else fresh.set_transform)(
            ts(parent, child, ns, x=float(k), yaw=0.1 * k)
        )
    assert sorted(core.get_frame_names()) == sorted(fresh.get_frame_names())
    assert sorted(core.all_frames_as_string().splitlines()) == sorted(
        fresh.all_frames_as_string().splitlines()
    )
    for target in FRAMES:
        for source in FRAMES:
            for sec in (0, 3, 17, 38):
                assert outcome(core, target, source, sec * S) == outcome(
                    fresh, target, source, sec * S
                )


@settings(max_examples=100, deadline=None)
@given(ops=ops_strategy)
def test_both_twins_number_frames_alike_through_forgets(ops: list[tuple[Any, ...]]) -> None:
    """The frame table (ids, names, freed numbers reused) is the same on both twins."""
    cores = [buffer_core(twin) for twin in sorted(CORES)]
    for k, op in enumerate(ops):
        for core in cores:
            if op[0] == "insert":
                parent, child, ns, static = _sample(op)
                sample = ts(parent, child, ns, x=float(k))
                (core.set_transform_static if static else core.set_transform)(sample)
            else:
                core.forget(op[1] * S)
        a, b = cores
        assert a._frame_names == b._frame_names
        assert a._frame_ids == b._frame_ids
        assert a.link_info() == b.link_info()


# ---------------------------------------------------------------------- expire_after


def test_expire_after_checks_its_arguments() -> None:
    assert expire_after(2.5) == ExpireAfter(2_500_000_000, S)
    assert expire_after(1, every=0.25).every_ns == 250_000_000
    with pytest.raises(ValueError, match="expire_after seconds must be > 0, got 0"):
        expire_after(0)
    with pytest.raises(ValueError, match="expire_after every must be > 0"):
        expire_after(1.0, every=0.0)
    with pytest.raises(TypeError, match="expire_after seconds must be seconds"):
        expire_after("10")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="cache_policy must be None or expire_after"):
        BufferCore(cache_policy=10.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"cache_policy.every_ns must be an int in \[1,"):
        BufferCore(cache_policy=ExpireAfter(S, 0))


@pytest.mark.parametrize("twin", sorted(CORES))
def test_expire_after_removes_frames_as_data_arrives_once_per_every(twin: str) -> None:
    """expire_after(3 s, every=1 s): checks run when the newest dynamic stamp reaches
    1, 2, 3, ... s; each removes the links whose newest sample is older than newest
    minus 3 s."""
    core = buffer_core(twin, cache_policy=expire_after(3.0, every=1.0))
    assert core.cache_policy == ExpireAfter(3 * S, S)
    core.set_transform(ts("map", "cup", 0))
    core.set_transform(ts("map", "ball", S // 2))
    for k in range(1, 8):
        core.set_transforms([ts("map", "base", k * S)])
        if k <= 3:
            assert core.frame_exists("cup") and core.frame_exists("ball"), k
        if k == 4:  # newest 4 s: limit 1 s; cup (0 s) and ball (0.5 s) are older
            assert not core.frame_exists("cup") and not core.frame_exists("ball")
            assert core.statistics().frames_expired == 2
    core.set_transform_static(ts("base", "laser", 0))
    assert core.statistics() == (3, 2, 2)  # map, base, laser; two links; two expired
    core.set_transform(ts("map", "base", 100 * S))
    assert core.statistics().frames_expired == 2  # base's own newest is 100 s
    core.set_transform(ts("map", "cup", 100 * S))
    core.set_transform(ts("map", "ball", 101 * S))  # cup: 100 > 101 - 3, kept
    assert core.frame_exists("cup")
    core.set_transform(ts("map", "ball", 104 * S))  # limit 101 s: cup and base's links go
    assert sorted(core.get_frame_names()) == ["ball", "base", "laser", "map"]  # laser names base
    assert core.get_parent("base") is None
    assert core.statistics().frames_expired == 4
    assert core.forget(Time(200)) == 1  # called directly: not counted as expired
    assert core.statistics().frames_expired == 4


@pytest.mark.parametrize("twin", sorted(CORES))
def test_expire_after_starts_over_after_clear(twin: str) -> None:
    """A clock that jumped back clears the buffer (tf2_ros); the stamps that follow are
    older than before: expiry goes by them, not by the newest stamp before the clear."""
    core = buffer_core(twin, cache_policy=expire_after(3.0, every=1.0))
    for k in range(100, 110):
        core.set_transform(ts("map", "base", k * S))
    core.clear()
    core.set_transform(ts("map", "cup", 0))
    for k in range(0, 5):
        core.set_transform(ts("map", "base", k * S))
    assert not core.frame_exists("cup")  # its 0 s is older than 4 s - 3 s
    assert core.statistics().frames_expired == 1


@pytest.mark.parametrize("twin", sorted(CORES))
def test_without_a_cache_policy_nothing_expires(twin: str) -> None:
    core = buffer_core(twin)
    assert core.cache_policy is None
    core.set_transform(ts("map", "cup", 0))
    for k in range(1, 100):
        core.set_transform(ts("map", "base", k * 10 * S))
    assert core.frame_exists("cup") and core.statistics().frames_expired == 0


@pytest.mark.anyio
async def test_a_wait_on_a_frame_that_expires_keeps_waiting() -> None:
    """The wait's frame expires while it waits (no error, still pending); data for it
    at the time asked then answers the wait."""
    clock = ManualClock(Time(100))
    buf = Buffer(clock=clock, cache_policy=expire_after(2.0, every=0.5))
    buf.set_transform(ts("map", "cup", 10 * S, x=1.0))
    got: list[TransformStamped] = []

    async def waiter() -> None:
        got.append(await buf.wait_for_transform("map", "cup", Time(20), timeout=30.0))

    with anyio.fail_after(10):
        async with anyio.create_task_group() as tg:
            tg.start_soon(waiter)
            await clock.advance(1.0)
            assert buf.pending_waits == 1
            buf.set_transform(ts("map", "base", 15 * S))  # newest 15 s: cup (10 s) expires
            assert not buf.frame_exists("cup") and buf.statistics().frames_expired == 1
            await clock.advance(1.0)
            assert not got and buf.pending_waits == 1
            buf.set_transform(ts("map", "cup", 19 * S, x=3.0))
            buf.set_transform(ts("map", "cup", 21 * S, x=5.0))
    assert got[0].transform.translation.x == 4.0
    assert got[0].header.stamp == Time(20)
    assert buf.pending_waits == 0


@pytest.mark.anyio
async def test_a_wait_on_an_expired_frame_times_out_on_the_buffers_clock() -> None:
    clock = ManualClock(Time(100))
    buf = Buffer(clock=clock, cache_policy=expire_after(1.0))
    buf.set_transform(ts("map", "cup", 10 * S))
    buf.set_transform(ts("map", "base", 20 * S))
    assert not buf.frame_exists("cup")
    errors: list[BaseException] = []

    async def waiter() -> None:
        try:
            await buf.lookup_transform_async("map", "cup", Time(0), timeout=5.0)
        except TimeoutException as exc:
            errors.append(exc)

    with anyio.fail_after(10):
        async with anyio.create_task_group() as tg:
            tg.start_soon(waiter)
            await clock.advance(4.0)
            assert not errors and buf.pending_waits == 1
            await clock.advance(2.0)
    assert len(errors) == 1 and "Timed out after 5 s" in str(errors[0])
