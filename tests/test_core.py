"""``tfbus.core.BufferCore``: the batch insert and edges of the compiled core that the
tf2 corpus (``test_conformance.py``) and the property tests do not reach."""

from __future__ import annotations

import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfbus import (
    ExtrapolationException,
    Header,
    InvalidArgumentException,
    Quaternion,
    Time,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.core import COMPILED, BatchResult, BufferCore, SetResult


def ts(
    child: str, parent: str = "base", sec: float = 1.0, x: float = 1.0, w: float = 1.0
) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_sec(sec), parent),
        child,
        Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, w)),
    )


def test_set_transforms_stores_the_valid_and_reports_the_rest() -> None:
    core = BufferCore(cache_time=10.0)
    batch: list[Any] = [
        ts("a", sec=20.0),
        ts("nan", x=math.nan),  # invalid
        "not a transform",  # malformed
        ts("b", sec=20.0, x=2.0),
        ts("a", sec=20.0, x=9.0),  # TF_REPEATED_DATA
        ts("a", sec=5.0),  # TF_OLD_DATA (older than 20 s - 10 s)
        ts("self", parent="self"),  # invalid
    ]
    result = core.set_transforms(batch)
    assert isinstance(result, BatchResult)
    assert (result.stored, result.refused) == (2, 2)
    assert [i for i, _ in result.errors] == [1, 2, 6]
    assert isinstance(result.errors[0][1], InvalidArgumentException)
    assert result.errors[0][1].codes == ("TF_NAN_INPUT",)
    assert isinstance(result.errors[1][1], TypeError)
    assert isinstance(result.errors[2][1], InvalidArgumentException)
    a = core.lookup_transform("base", "a", Time(0))
    assert a.transform.translation.x == 1.0  # the first sample at a stamp wins
    assert core.lookup_transform("base", "b", Time(20)).transform.translation.x == 2.0
    assert not core.frame_exists("nan") and not core.frame_exists("self")


def test_set_transforms_takes_any_iterable_and_static_flag() -> None:
    core = BufferCore()
    result = core.set_transforms(
        (ts(f"s{k}", sec=1.0 + k, x=float(k)) for k in range(3)), "me", is_static=True
    )
    assert result == BatchResult(3, 0, [], {"base", "s0", "s1", "s2"}, True)
    # Static links answer at any time.
    assert core.lookup_transform("base", "s2", Time(1000)).transform.translation.x == 2.0
    assert "broadcaster: 'me'" in core.all_frames_as_yaml()


frames = st.sampled_from(["a", "b", "c", "/a", ""])
items = st.tuples(frames, frames, st.integers(1, 30), st.sampled_from([1.0, 0.0, math.nan]))


@settings(max_examples=150, deadline=None)
@given(st.lists(items, max_size=40))
def test_set_transforms_is_set_transform_in_order(
    spec: list[tuple[str, str, int, float]],
) -> None:
    batch = [
        TransformStamped(
            Header(Time(sec), parent), child, Transform(Vector3(1.0, 2.0, 3.0), Quaternion(w=w))
        )
        for child, parent, sec, w in spec
    ]
    one, many = BufferCore(cache_time=5.0), BufferCore(cache_time=5.0)
    expected_errors = []
    stored = refused = 0
    for i, t in enumerate(batch):
        try:
            r = one.insert_transform(t)
        except InvalidArgumentException as exc:
            expected_errors.append((i, str(exc)))
            continue
        stored += r is SetResult.STORED
        refused += r is not SetResult.STORED
    result = many.set_transforms(batch)
    assert (result.stored, result.refused) == (stored, refused)
    assert [(i, str(e)) for i, e in result.errors] == expected_errors
    assert list(many.frame_info()) == list(one.frame_info())
    assert many.all_frames_as_yaml() == one.all_frames_as_yaml()


def test_times_beyond_int64_ns_cannot_be_made() -> None:
    with pytest.raises(ValueError, match="int64"):
        Time.from_ns(2**63)
    core = BufferCore(cache_time=9.2e9)  # ~2**63 ns: keeps everything
    core.set_transform(ts("a", sec=1.0), "x")
    core.set_transform(ts("a", sec=9e9, x=3.0), "x")
    assert core.lookup_transform("base", "a", Time(1)).transform.translation.x == 1.0
    with pytest.raises(ExtrapolationException, match="into the future"):
        core.lookup_transform("base", "a", Time.from_ns(2**63 - 1))


def test_a_chain_of_1000_links_is_walked() -> None:
    core = BufferCore()
    for k in range(1, 1001):  # 1000 links: the deepest tree tf2 accepts
        core.set_transform(ts(f"f{k}", parent=f"f{k - 1}", x=1.0), "x")
    out = core.lookup_transform("f0", "f1000", Time(0))
    assert out.transform.translation.x == 1000.0
    assert out.transform.rotation == Quaternion()


def test_a_parent_id_outside_the_frame_table_is_a_missing_link_not_a_crash() -> None:
    # Only reachable through private attributes; the compiled walk must still stay in
    # bounds and answer as for a frame without a link.
    core = BufferCore()
    core.set_transform(ts("b", parent="a", sec=1.0), "x")
    core._caches[core._frame_ids["b"]].insert(2 * 10**9, 10**6, (0.0,) * 6 + (1.0,))  # type: ignore[union-attr]
    ok, message = core.can_transform("a", "b", Time(2), return_debug_tuple=True)  # type: ignore[misc]
    assert not ok and "not part of the same tree" in message


def test_the_compiled_base_state_is_read_only_from_python() -> None:
    """BufferCore changes its base's state only through its public methods (issue 26):
    the internals are readable for white-box tests, never assignable."""
    core = BufferCore()
    core.set_transform(ts("b", parent="a", sec=1.0), "x")
    for name in ("_frame_ids", "_frame_names", "_caches", "_authority", "_generation"):
        if COMPILED:  # the pure twin's slots are plain attributes
            with pytest.raises(AttributeError):
                setattr(core, name, getattr(core, name))
    assert core.parent_of("b", 0) == "a" and core.parent_of("a", 0) is None
    assert core.link_info() == [("b", "a", "x", False, 1, 10**9, 10**9)]
    assert core.common_time("a", "b") == (0, 10**9)
    core.clear()
    assert core.link_info() == [("b", "NO_PARENT", "x", False, 0, 0, 0)]
