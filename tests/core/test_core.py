"""``tfbus.core.BufferCore``: the batch insert and edges of the compiled core that the
tf2 corpus (``test_conformance.py``) and the property tests do not reach; and its
checks of what it is given: wrong values never crash, never half-store, and are named."""

from __future__ import annotations

import logging
import math
from collections.abc import Set as AbstractSet
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from tfbus import (
    Buffer,
    ExtrapolationException,
    Header,
    InvalidArgumentException,
    LookupException,
    Quaternion,
    Time,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.core import (
    COMPILED,
    MAX_GRAPH_DEPTH,
    BatchResult,
    BufferCore,
    FrameInfo,
    SetResult,
    TouchedFrames,
)
from tfbus.ratelimit import CountLimitedLog, RateLimitedLog


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
    """BufferCore changes its base's state only through its public methods:
    the internals are readable for white-box tests, never assignable."""
    core = BufferCore()
    core.set_transform(ts("b", parent="a", sec=1.0), "x")
    for name in ("_frame_ids", "_frame_names", "_caches", "_authority", "_generation"):
        if COMPILED:  # the pure twin's slots are plain attributes
            with pytest.raises(AttributeError):
                setattr(core, name, getattr(core, name))
    assert core.get_parent("b") == "a" and core.get_parent("a") is None
    assert core.link_info() == [("b", "a", "x", False, 1, 10**9, 10**9)]
    assert core.common_time("a", "b") == (0, 10**9)
    core.clear()
    assert core.link_info() == [("b", "NO_PARENT", "x", False, 0, 0, 0)]


@pytest.mark.skipif(not COMPILED, reason="the compiled core's result recycling")
def test_a_dropped_lookup_result_is_recycled_and_a_kept_one_never_changes() -> None:
    """A never-repeated lookup whose result nobody kept reuses the objects of the result
    its memo slot drops (no allocation: tracemalloc's peak stays put); a result the
    caller keeps, or any part of it, is never touched."""
    import tracemalloc

    core = BufferCore(cache_time=100.0)
    for k in range(11):  # x = k metres at k s, a quarter turn about z over 10 s
        yaw = math.pi / 2 * k / 10
        core.set_transform(TransformStamped(
            Header(Time.from_sec(k), "a"), "b",
            Transform(Vector3(float(k), 0.0, 0.0),
                      Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))))  # fmt: skip
    times = [Time.from_ns(10**9 + 7_919 * i) for i in range(1, 3001)]  # never repeated
    kept = core.lookup_transform("a", "b", Time.from_sec(2.5))
    x = kept.transform.translation
    qz = kept.transform.rotation.z
    lookup = core.lookup_transform
    warm, measured = times[:1000], times[1000:]
    for t in warm:  # every memo slot now holds a result nobody else holds
        lookup("a", "b", t)
    tracemalloc.start()
    try:
        before, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for t in measured:
            lookup("a", "b", t)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak - before < 200  # a new result of 5 NamedTuples would take ~450 bytes
    assert kept.header.stamp == Time.from_sec(2.5)
    assert kept.header.frame_id == "a" and kept.child_frame_id == "b"
    assert x == (2.5, 0.0, 0.0)
    assert qz is kept.transform.rotation.z
    assert qz == pytest.approx(math.sin(math.pi / 2 * 0.25 / 2), rel=1e-12)
    last = lookup("a", "b", times[-1])
    assert last.header.stamp is times[-1]
    assert last.transform.translation.x == pytest.approx(1.0 + 3000 * 7_919e-9, rel=1e-12)


@pytest.mark.skipif(not COMPILED, reason="the compiled core's result recycling")
def test_a_dropped_batch_result_is_filled_in_again_and_a_kept_one_never_changes() -> None:
    """set_transforms keeps the last BatchResult it built; when the caller dropped it
    (with its TouchedFrames and errors list), the next batch fills it in again instead
    of allocating a result, a TouchedFrames and two lists (tracemalloc's peak stays
    put); a result the caller keeps, or its ``touched`` or ``errors``, is never
    changed by a later batch."""
    import tracemalloc

    core = BufferCore()
    # Static links: re-storing one writes its values in place (no cache growth).
    batches = [[ts(f"c{i}", sec=1.0, x=float(k + i)) for i in range(4)] for k in range(400)]
    insert = core.set_transforms
    warm, measured = batches[:100], batches[100:]
    for batch in warm:
        insert(batch, "au", True)
    tracemalloc.start()
    try:
        before, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for batch in measured:
            insert(batch, "au", True)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak - before < 100  # a new result, frames and lists take ~300 bytes a batch
    assert core.lookup_transform("base", "c3", Time(0)).transform.translation.x == 402.0

    kept = insert(batches[0], "au", True)
    touched = insert([ts("d", sec=2.0)], "au", True).touched
    errors = insert([ts("e", sec=2.0)], "au", True).errors
    later = [insert([ts("f", sec=3.0), ts("g", sec=3.0)], "au", True) for _ in range(3)]
    assert kept == (4, 0, [], {"c0", "c1", "c2", "c3", "base"}, False)
    assert sorted(kept.touched) == ["base", "c0", "c1", "c2", "c3"]
    assert sorted(touched) == ["base", "d"] and errors == []
    errors.append((0, ValueError("kept by the caller")))
    assert insert([ts("h", sec=3.0)], "au", True) == (1, 0, [], {"h", "base"}, True)
    assert later[0] == (2, 0, [], {"f", "g", "base"}, True)  # two new links
    assert later[1] == later[2] == (2, 0, [], {"f", "g", "base"}, False)
    assert later[1] is not later[0] and later[2] is not later[1]
    assert len(errors) == 1 and sorted(touched) == ["base", "d"]


def test_set_transforms_enters_no_python_frame_outside_the_core() -> None:
    """BufferCore.set_transforms is the core's own method, as set_transform is: a batch
    that stores reaches the inserts with no Python frame of tfbus in between (the
    pure-Python core's own frames aside); it had one, ``BufferCore.set_transforms``."""
    import sys
    from pathlib import Path

    import tfbus

    tfbus_dir = str(Path(tfbus.__file__).parent)
    # The pure-Python core's frames: its own module and the TouchedFrames it builds.
    twin = (str(Path(tfbus_dir, "core", "_py")), str(Path(tfbus_dir, "core", "results.py")))
    core = BufferCore()
    entered: list[str] = []

    def profile(frame: Any, event: str, arg: Any) -> None:
        name = frame.f_code.co_filename
        own = name.startswith(tfbus_dir) and (COMPILED or not name.startswith(twin))
        if event == "call" and own:
            entered.append(frame.f_code.co_qualname)

    batch = [ts("a", sec=2.0), ts("b", parent="a", sec=2.0)]
    sys.setprofile(profile)
    try:
        result = core.set_transforms(batch, "au")
    finally:
        sys.setprofile(None)
    assert entered == []
    assert result == (2, 0, [], {"a", "b", "base"}, True)
    assert core.lookup_transform("base", "b", Time.from_sec(2.0)).transform.translation.x == 2.0


@pytest.mark.parametrize("kind", [BufferCore, Buffer])
def test_the_parent_of_a_frame_is_reached_by_one_public_name_get_parent(kind: type) -> None:
    """tf2's ``_getParent`` is ``get_parent(frame_id, time=Time(0))``; the core's
    ``parent_of(frame_id, time_ns)`` is not reachable from a buffer, and a guess of it
    names the public method."""
    buf = kind()
    buf.set_transform(ts("b", parent="a", sec=1.0), "x")
    buf.set_transform(ts("b", parent="c", sec=3.0), "x")  # b re-parented at 3 s
    assert buf.get_parent("b") == "c"
    assert buf.get_parent("b", Time.from_sec(1.0)) == "a"
    assert buf.get_parent("b", Time.from_sec(3.0)) == "c"
    assert buf.get_parent("a") is None and buf.get_parent("unknown") is None
    with pytest.raises(AttributeError, match=r"has no attribute 'parent_of'.*get_parent\(") as e:
        buf.parent_of("b", 0)  # type: ignore[attr-defined]
    assert e.value.name == "parent_of"
    assert not hasattr(buf, "parent_of") and not hasattr(kind, "parent_of")
    assert "parent_of" not in dir(buf) and "get_parent" in dir(buf)
    with pytest.raises(TypeError, match=r"time must be a tfbus Time.*got int 0"):
        buf.get_parent("b", 0)


# ============================================================================ wrong values
# Wrong values given to the API never crash, never half-store,
# and are named in the error (YAML ids, str subclasses, field types); plus the core's
# reporting contract (the batch result names what it touched; the core's base calls nothing
# back). The scalar math's single home is checked in ``test_pycore.py``.

T = Time(100)


def ts_any(child: Any, parent: Any = "base", stamp: Any = T, x: Any = 1.0, w: Any = 1.0) -> Any:
    return TransformStamped(
        Header(stamp, parent), child, Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, w))
    )


# ----------------------------------------------------------------------------- YAML ids


HOSTILE_IDS = [
    "a: b",
    "#comment",
    "it's",
    'say "hi"',
    "true",
    "null",
    "Yes",
    "- item",
    "[x]",
    "{x}",
    "&anchor",
    "*alias",
    "!tag",
    "%x",
    "@x",
    "`x",
    "line\nbreak",
    "tab\there",
    "bell\x07",
    "esc\x1b[2J",
    "back\\slash\\",
    " lead",
    "trail ",
    "ünï",
    "123",
    "1.5",
    "0x10",
    "~",
    "?q",
    "a,b",
    "|",
    ">",
]


def test_all_frames_as_yaml_quotes_hostile_ids_and_reads_back_every_id() -> None:
    """Ids YAML would misread are quoted; the text is valid YAML that
    reads back every child, parent and broadcaster id unchanged."""
    core = BufferCore()
    for k, frame in enumerate(HOSTILE_IDS):
        assert core.set_transform(ts_any(frame, parent=f"p{k}"), authority=frame)
        assert core.set_transform(ts_any(f"c{k}", parent=frame), authority="x'y")
    parsed = yaml.safe_load(core.all_frames_as_yaml())
    assert isinstance(parsed, dict)
    assert set(parsed) == set(HOSTILE_IDS) | {f"c{k}" for k in range(len(HOSTILE_IDS))}
    for k, frame in enumerate(HOSTILE_IDS):
        assert parsed[frame]["parent"] == f"p{k}"
        assert parsed[frame]["broadcaster"] == frame
        assert parsed[f"c{k}"]["parent"] == frame
        assert parsed[f"c{k}"]["broadcaster"] == "x'y"


def test_all_frames_as_yaml_keeps_tf2_text_for_ordinary_ids() -> None:
    """Ordinary ids are written exactly as tf2's allFramesAsYAML does."""
    core = BufferCore()
    core.set_transform(ts_any("base_laser", parent="base_link", stamp=Time(1)), "auth")
    core.set_transform(ts_any("base_laser", parent="base_link", stamp=Time(3)), "auth")
    core.set_transform(ts_any("cam/left-1.optical", parent="base_link", stamp=Time(2)), "me")
    assert core.all_frames_as_yaml() == (
        "base_laser: \n"
        "  parent: 'base_link'\n"
        "  broadcaster: 'auth'\n"
        "  rate: 1.000\n"
        "  most_recent_transform: 3.000\n"
        "  oldest_transform: 1.000\n"
        "  buffer_length: 2.000\n"
        "cam/left-1.optical: \n"
        "  parent: 'base_link'\n"
        "  broadcaster: 'me'\n"
        "  rate: 10000.000\n"
        "  most_recent_transform: 2.000\n"
        "  oldest_transform: 2.000\n"
        "  buffer_length: 0.000\n"
    )


# -------------------------------------------------- str subclasses, nothing half-stored


def test_a_numpy_str_frame_id_is_the_string_it_is() -> None:
    """numpy.str_ (any str subclass) ids are accepted as their string,
    stored as plain ``str`` and found by plain strings (and the other way round)."""
    core = BufferCore()
    assert core.set_transform(ts_any(np.str_("laser"), parent=np.str_("/base")))
    assert core.get_frame_names() == ["laser", "base"]
    assert all(type(name) is str for name in core.get_frame_names())
    out = core.lookup_transform(np.str_("base"), np.str_("laser"), T)  # type: ignore[arg-type]
    assert out.transform.translation.x == 1.0
    assert core.lookup_transform("base", "laser", T) == out

    class Name(str):
        pass

    assert core.set_transform(ts_any(Name("cam"), parent=Name("laser")))
    assert core.can_transform("base", Name("cam"), T)


@pytest.mark.parametrize(
    "bad",
    [
        ts_any("ghost", parent=5),
        ts_any(5, parent="ghost_parent"),
        ts_any("ghost", x=None),
        ts_any("ghost", w="1"),
        ts_any("ghost", stamp=None),
    ],
)
def test_a_rejected_transform_leaves_no_ghost_frame(bad: TransformStamped) -> None:
    """Nothing is ever half-stored: a transform that raises registers
    no frame and changes nothing."""
    core = BufferCore()
    core.set_transform(ts_any("a"))
    before = (core.get_frame_names(), list(core.frame_info()), core.all_frames_as_yaml())
    with pytest.raises(InvalidArgumentException):
        core.set_transform(bad)
    result = core.set_transforms([bad])
    assert result.stored == 0 and isinstance(result.errors[0][1], InvalidArgumentException)
    assert (core.get_frame_names(), list(core.frame_info()), core.all_frames_as_yaml()) == before
    assert not core.frame_exists("ghost") and not core.frame_exists("ghost_parent")


# ----------------------------------------------------------------------------- field types


@pytest.mark.parametrize(
    ("transform", "field", "shown"),
    [
        (ts_any("c", x=None), "transform.translation.x", "None"),
        (ts_any("c", x="1.0"), "transform.translation.x", "'1.0'"),
        (ts_any("c", x=True), "transform.translation.x", "True"),
        (ts_any("c", x=np.bool_(True)), "transform.translation.x", "True"),
        (ts_any("c", x=10**400), "transform.translation.x", "1000000000"),
        (ts_any("c", x={}), "transform.translation.x", "{}"),
        (ts_any("c", w=False), "transform.rotation.w", "False"),
        (ts_any("c", w=[1.0]), "transform.rotation.w", "[1.0]"),
        (ts_any(None), "child_frame_id", "None"),
        (ts_any(b"c"), "child_frame_id", "b'c'"),
        (ts_any("c", parent=None), "header.frame_id", "None"),
        (ts_any("c", parent={"a": 1}), "header.frame_id", "{'a': 1}"),
        (ts_any("c", stamp=5), "header.stamp", "5"),
        (ts_any("c", stamp="now"), "header.stamp", "'now'"),
        (TransformStamped(None, "c", Transform()), "header", "None"),  # type: ignore[arg-type]
        (TransformStamped(Header(T, "b"), "c", {}), "transform", "{}"),  # type: ignore[arg-type]
        (
            # _make: as a decoder or a peer builds it (Transform(...) itself refuses None)
            TransformStamped(Header(T, "b"), "c", Transform._make((None, Quaternion()))),
            "transform.translation",
            "None",
        ),
        (
            TransformStamped(Header(T, "b"), "c", Transform._make((Vector3(0, 0, 0), (0, 0, 1)))),
            "transform.rotation",
            "(0, 0, 1)",
        ),
    ],
)
def test_wrong_types_in_a_transform_are_named(
    transform: TransformStamped, field: str, shown: str
) -> None:
    """A wrong type anywhere in a TransformStamped (None, str, bool,
    huge int, dict) is an InvalidArgumentException naming the field and the value; bool
    is not a number; nothing is stored."""
    core = BufferCore()
    with pytest.raises(InvalidArgumentException) as info:
        core.set_transform(transform)
    assert field in str(info.value) and shown in str(info.value)
    (index, error), = core.set_transforms([transform]).errors
    assert index == 0 and isinstance(error, InvalidArgumentException)
    assert core.get_frame_names() == []


def test_numbers_of_other_real_types_are_accepted() -> None:
    """The other side of the type checks: ints and numpy floats are numbers."""
    core = BufferCore()
    assert core.set_transform(ts_any("c", x=np.float32(0.5), w=1))
    assert core.set_transform(ts_any("d", x=3, w=np.float64(1.0)))
    assert core.lookup_transform("base", "d", T).transform.translation.x == 3.0


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan, 1e300, -1.0])
def test_cache_time_out_of_range_is_an_error_naming_it(value: float) -> None:
    """cache_time inf / nan / 1e300 (and negative) raise an error that
    names cache_time."""
    with pytest.raises(ValueError, match="cache_time"):
        BufferCore(cache_time=value)


@pytest.mark.parametrize("value", ["10", True, None, [10.0]])
def test_cache_time_of_the_wrong_type_is_a_type_error_naming_it(value: Any) -> None:
    """A cache_time that is not a number is refused before anything
    is allocated (and bool is not a number)."""
    with pytest.raises(TypeError, match="cache_time"):
        BufferCore(cache_time=value)


# -------------------------------------------------------- the core's reporting contract


def test_cache_time_lives_in_one_place() -> None:
    """cache_time has one home; it cannot be changed behind the links'
    backs (what is reported is what is kept)."""
    core = BufferCore(cache_time=2.0)
    assert core.cache_time_ns == 2_000_000_000
    with pytest.raises(AttributeError):
        core.cache_time_ns = 5  # type: ignore[misc]
    core.set_transform(ts_any("a", stamp=Time(10)))
    core.set_transform(ts_any("a", stamp=Time(12)))
    core.set_transform(ts_any("a", stamp=Time(13)))
    info = next(core.frame_info())
    assert isinstance(info, FrameInfo)
    assert (info.samples, info.oldest_ns) == (2, 12 * 10**9)


def test_set_transforms_reports_the_frames_it_touched() -> None:
    """The batch result names the (stripped) frames of what was stored and
    whether the tree's shape may have changed."""
    core = BufferCore()
    r = core.set_transforms([ts_any("/a", parent="/base"), ts_any("b", x=math.nan)])
    assert r.touched == {"a", "base"} and r.relinked
    r = core.set_transforms([ts_any("a", stamp=Time(101))])
    assert r.touched == {"a", "base"} and not r.relinked  # same parent: same shape
    r = core.set_transforms([ts_any("a", parent="other", stamp=Time(102))])
    assert r.relinked
    r = core.set_transforms([ts_any("a", stamp=Time(101))])  # refused (repeated)
    assert r.stored == 0 and r.refused == 1 and not r.touched


def test_touched_frames_is_a_set_built_only_when_asked() -> None:
    """The batch only records the ids it stored (so a batch nobody inspects
    hashes none); ``touched`` is a read-only set all the same, equal to and combinable
    with any set."""
    core = BufferCore()
    r = core.set_transforms(
        [
            ts_any("a"),
            ts_any("b", parent="a"),
            ts_any("/a", stamp=Time(11)),
            ts_any("c", x=math.nan),
        ]
    )
    t = r.touched
    assert isinstance(t, TouchedFrames) and isinstance(t, AbstractSet)
    assert t and type(t._ids) is list  # truth needs no set
    assert (len(t), sorted(t)) == (3, ["a", "b", "base"])
    assert type(t._ids) is frozenset  # built once, on first use
    assert "a" in t and "c" not in t and 1 not in t
    assert t == {"a", "b", "base"} == t and t != {"a", "b"} and t != ["a", "b", "base"]
    assert (t & {"a", "x"}, t | {"x"}, t - {"a"}, t ^ {"a", "x"}) == (
        {"a"},
        {"a", "b", "base", "x"},
        {"b", "base"},
        {"b", "base", "x"},
    )
    assert {"a"} <= t and t < {"a", "b", "base", "x"} and t.isdisjoint({"x"})
    assert hash(t) == hash(frozenset({"a", "b", "base"}))
    assert repr(t) == "TouchedFrames(['a', 'b', 'base'])"
    empty = core.set_transforms([]).touched
    assert not empty and empty == frozenset() and len(empty) == 0 and list(empty) == []
    assert TouchedFrames(["x", "x"]) == {"x"}


@pytest.mark.parametrize("child, parent", [("a", "a"), ("/a", "a"), ("base", "/base"), ("n", "n")])
def test_self_transform_is_refused_for_known_and_new_frames(child: str, parent: str) -> None:
    """tf2 ``setTransformImpl``: a transform whose two (stripped) ids are one frame is
    refused, whether that frame is known (the check compares ids) or new (it compares
    strings); nothing is registered."""
    core = BufferCore()
    core.set_transform(ts_any("a"))
    with pytest.raises(InvalidArgumentException, match="are the same"):
        core.set_transform(ts_any(child, parent=parent, stamp=Time(20)))
    r = core.set_transforms([ts_any(child, parent=parent, stamp=Time(20)), ts_any("b")])
    assert (r.stored, [i for i, _ in r.errors], set(r.touched)) == (1, [0], {"b", "base"})
    assert sorted(core.get_frame_names()) == ["a", "b", "base"]


def test_the_compiled_base_calls_nothing_back(caplog: pytest.LogCaptureFixture) -> None:
    """The compiled base reports codes; a subclass overriding the names the
    old base called (``_reject``, ``_refused``) is never called."""
    calls: list[str] = []

    class Spy(BufferCore):
        def _reject(self, *args: object) -> None:
            calls.append("_reject")

        def _refused(self, *args: object) -> None:
            calls.append("_refused")

    core = Spy()
    caplog.set_level(logging.WARNING, logger="tfbus.core")
    with pytest.raises(InvalidArgumentException, match="= nan"):
        core.set_transform(ts_any("a", x=math.nan))
    core.set_transform(ts_any("a"))
    assert not core.set_transform(ts_any("a"))  # TF_REPEATED_DATA
    assert calls == []
    assert any("TF_REPEATED_DATA" in r.getMessage() for r in caplog.records)


def test_chain_frames_is_bounded_by_the_graph_depth() -> None:
    """The frames a wait depends on are at most
    MAX_GRAPH_DEPTH + 1 per chain, whatever the depth of the tree."""
    core = BufferCore()
    depth = 3 * MAX_GRAPH_DEPTH
    core.set_transforms(ts_any(f"f{k + 1}", parent=f"f{k}") for k in range(depth))
    frames = core.chain_frames(f"f{depth}", "missing", T)
    assert "missing" in frames and f"f{depth}" in frames
    assert len(frames) <= MAX_GRAPH_DEPTH + 3
    assert core.chain_frames("f2", "f0", Time(0)) == ["f0", "f2", "f1"]


# ------------------------------------------------------------------ rate-limited log


def test_rate_limited_log_takes_time_from_the_caller(caplog: pytest.LogCaptureFixture) -> None:
    """The helper reads no clock: ``now`` comes from the caller."""
    log = RateLimitedLog(logging.getLogger("tfbus.test"), period=5.0)
    caplog.set_level(logging.WARNING, logger="tfbus.test")
    assert log.log(100.0, logging.WARNING, "x %s", 1)
    assert not log.log(104.9, logging.WARNING, "x %s", 2)
    assert not log.log(101.0, logging.WARNING, "x %s", 3)
    assert log.log(99.0, logging.WARNING, "x %s", 4)  # clock went back: a new period
    assert log.log(100.0, logging.WARNING, "y")  # another format string: its own limit
    assert [r.getMessage() for r in caplog.records] == [
        "x 1",
        "x 4 (2 more like this suppressed)",
        "y",
    ]
    with pytest.raises(ValueError):
        RateLimitedLog(logging.getLogger("tfbus.test"), period=math.inf)


def test_count_limited_log(caplog: pytest.LogCaptureFixture) -> None:
    log = CountLimitedLog(logging.getLogger("tfbus.test"), every=3, period=0.0)  # count only
    caplog.set_level(logging.WARNING, logger="tfbus.test")
    logged = [log.log(logging.WARNING, "z %d", k) for k in range(7)]
    assert logged == [True, False, False, True, False, False, True]
    assert [r.getMessage() for r in caplog.records] == [
        "z 0",
        "z 3 (2 more like this suppressed)",
        "z 6 (2 more like this suppressed)",
    ]


def test_a_loop_is_reported_by_lookup() -> None:
    core = BufferCore()
    core.set_transform(ts_any("b", parent="a"))
    core.set_transform(ts_any("a", parent="b"))
    core.set_transform(ts_any("d", parent="b"))
    core.set_transform(ts_any("e", parent="x"))
    with pytest.raises(LookupException, match="loop"):
        core.lookup_transform("e", "d", Time(0))


def test_invalid_frame_id_checks_form_only() -> None:
    core = BufferCore()
    assert core.invalid_frame_id("unknown_yet") is None
    error = core.invalid_frame_id("/x", "lookupTransform argument fixed_frame")
    assert isinstance(error, InvalidArgumentException)
    assert str(error) == (
        'Invalid argument "/x" passed to lookupTransform argument fixed_frame in tf2 '
        "frame_ids cannot start with a '/' like: "
    )
    assert isinstance(core.invalid_frame_id(""), InvalidArgumentException)
    assert isinstance(core.invalid_frame_id(3), InvalidArgumentException)  # type: ignore[arg-type]


# ----------------------------------------------------------- lookup times, limited logs


@pytest.mark.parametrize("time", [None, 5, 1.5, "0", 10**9])
def test_lookup_time_of_the_wrong_type_is_a_type_error(time: Any) -> None:
    """lookup_transform(..., time=None) (or an int) raised AttributeError: '_ns' from
    the compiled query; every lookup now raises a TypeError naming the argument, and
    the core goes on answering (run under both cores: TFBUS_PURE_PYTHON=1)."""
    core = BufferCore()
    core.set_transform(ts_any("child"), "a")
    for call in (core.lookup_transform, core.try_lookup_transform, core.can_transform,
                 core.check_transform):
        with pytest.raises(TypeError, match=r"^time must be a tfbus\.Time .*, not "
                                            rf"{type(time).__name__} "):
            call("base", "child", time)
    with pytest.raises(TypeError, match=r"time must be a tfbus\.Time"):
        core.lookup_transform_full("base", time, "child", T, "base")
    assert core.lookup_transform("base", "child", Time(0)).transform.translation.x == 1.0


def test_count_limited_log_is_limited_by_time_too(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Refusal logs were limited by count only (1 per 1000): a flood printed ~180 lines
    a second. Now also at most one line per ``period`` seconds; the clock (injected
    here) is read once per ``every`` calls, not on every call."""
    now = [0.0]
    reads = [0]

    def clock() -> float:
        reads[0] += 1
        return now[0]

    log = CountLimitedLog(logging.getLogger("tfbus.test"), every=1000, period=5.0,
                          clock=clock)
    caplog.set_level(logging.WARNING, logger="tfbus.test")
    lines = 0
    for k in range(1_000_001):  # 10 s of a flood at 100 000 calls a second
        now[0] = k / 100_000
        lines += log.log(logging.WARNING, "w %d", k)
    # at t = 0, then at the first 1000th call at or after 5 s and 10 s (count: 1000 lines)
    assert [r.getMessage() for r in caplog.records] == [
        "w 0",
        "w 500000 (499999 more like this suppressed)",
        "w 1000000 (499999 more like this suppressed)",
    ]
    assert lines == 3
    assert reads[0] == 1 + 1000  # at the first line, then once per 1000 calls
    counted = CountLimitedLog(logging.getLogger("tfbus.test"), every=1000)  # no clock
    assert sum(counted.log(logging.WARNING, "c %d", k) for k in range(10_000)) == 10
    with pytest.raises(ValueError):
        CountLimitedLog(logging.getLogger("tfbus.test"), period=-1.0)


def test_a_flood_of_refused_transforms_logs_a_few_lines(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A Buffer's TF_REPEATED_DATA log under a flood: 50 000 repeated stamps over 10 s
    of the buffer's clock (a ManualClock) give 3 lines, not 51 (the sans-I/O core
    counts; the Buffer lends it its clock); every one is still refused and the buffer
    goes on storing new data."""
    from tfbus.buffer import Buffer
    from tfbus.clock import ManualClock

    clock = ManualClock(Time(1000))
    buffer = Buffer(clock=clock)
    caplog.set_level(logging.WARNING, logger="tfbus.core")
    buffer.set_transform(ts_any("child"), "flood")
    for k in range(50_001):
        clock.set_nowait(Time.from_ns(1000 * 10**9 + k * 200_000))
        buffer.set_transform(ts_any("child"), "flood")
    lines = [r for r in caplog.records if "TF_REPEATED_DATA" in r.getMessage()]
    assert len(lines) == 3, len(lines)
    buffer.set_transform(ts_any("child", stamp=Time(101), x=2.0), "flood")
    assert buffer.lookup_transform("base", "child", Time(0)).transform.translation.x == 2.0
