"""Insert policy for a transform at the stamp of a stored sample (``on_repeat``).

``"reject"`` (default) is tf2 geometry2 0.7.6's ``TimeCache::insertData``: refused as
TF_REPEATED_DATA, the first sample wins. ``"replace"``: a transform at the stamp of the
link's *newest* sample replaces its values and parent; an equal stamp further back is
still refused. Both core twins (compiled ``_ccache``/``_ccore``, pure ``_pycache``/
``_pycore``) are checked against one model written as plainly as possible: a dict of
stamps, pruned by tf2's rule after every insert.
"""

from __future__ import annotations

import logging
import math
from types import ModuleType
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.buffer import Buffer
from tfbus.clock import ManualClock
from tfbus.core import BufferCore, SetResult, _pycache, _pycore
from tfbus.core.cache import OK, OLD_DATA, REPEATED_DATA

_ccache = pytest.importorskip("tfbus.core._ccache", reason="the compiled core is not built")
from tfbus.core import _ccore  # noqa: E402  (built with _ccache)

CACHES: dict[str, ModuleType] = {"compiled": _ccache, "pure": _pycache}
CORES: dict[str, ModuleType] = {"compiled": _ccore, "pure": _pycore}
S = 1_000_000_000

Row = tuple[float, float, float, float, float, float, float]


def row(k: int) -> Row:
    return (float(k), -float(k), 0.5 * k, 0.0, 0.0, 0.0, 1.0)


class Model:
    """tf2 ``TimeCache::insertData`` + ``pruneList``, with the replace rule."""

    def __init__(self, cache_time: int, replace: bool) -> None:
        self.cache_time = cache_time
        self.replace = replace
        self.samples: dict[int, tuple[int, Row]] = {}

    def insert(self, stamp: int, parent: int, values: Row) -> int:
        if self.samples:
            newest = max(self.samples)
            if newest > stamp + self.cache_time:
                return OLD_DATA
            if stamp in self.samples and not (self.replace and stamp == newest):
                return REPEATED_DATA
        self.samples[stamp] = (parent, values)
        horizon = max(self.samples) - self.cache_time
        self.samples = {t: v for t, v in self.samples.items() if t >= horizon}
        return OK


inserts = st.lists(
    st.tuples(st.integers(1, 60), st.sampled_from([1, 1, 1, 2, 3])), max_size=120
)


@pytest.mark.parametrize("twin", sorted(CACHES))
@pytest.mark.parametrize("replace", [False, True], ids=["reject", "replace"])
@settings(max_examples=150, deadline=None)
@given(ops=inserts, cache_time=st.integers(0, 30))
def test_time_cache_matches_the_model(
    twin: str, replace: bool, ops: list[tuple[int, int]], cache_time: int
) -> None:
    cache = CACHES[twin].TimeCache(cache_time, replace)
    assert cache.replace_repeated is replace
    model = Model(cache_time, replace)
    for k, (stamp, parent) in enumerate(ops):
        assert cache.insert(stamp, parent, row(k)) == model.insert(stamp, parent, row(k))
    stamps = sorted(model.samples)
    assert cache.stamps().tolist() == stamps
    assert [tuple(r) for r in cache.values().tolist()] == [model.samples[t][1] for t in stamps]
    for t in stamps:  # exact stamps: the stored sample and its own parent
        assert cache.gather(t) == model.samples[t]
    if stamps:
        assert cache.latest() == (stamps[-1], model.samples[stamps[-1]][0])


def tf(parent: str, child: str, sec: float, x: float, yaw: float = 0.0) -> TransformStamped:
    q = Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    return TransformStamped(Header(Time.from_sec(sec), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), q))


def buffer_core(twin: str, **kwargs: Any) -> BufferCore:
    """``BufferCore``'s own methods over the given core's ``CoreBase``."""
    body = {k: v for k, v in vars(BufferCore).items() if k not in {"__dict__", "__weakref__"}}
    klass: type[BufferCore] = type("BufferCore", (CORES[twin].CoreBase,), body)
    return klass(**kwargs)


@pytest.mark.parametrize("twin", sorted(CORES))
def test_reject_keeps_the_first_sample_and_logs_tf2s_line(
    twin: str, caplog: pytest.LogCaptureFixture
) -> None:
    core = buffer_core(twin)
    assert core.on_repeat == "reject"
    assert core.set_transform(tf("odom", "base", 10.0, x=1.0))
    with caplog.at_level(logging.WARNING, "tfbus.core"):
        assert core.set_transform(tf("odom", "base", 10.0, x=2.0)) is False
    assert core.lookup_transform("odom", "base", Time.from_sec(10)).transform.translation.x == 1.0
    assert caplog.messages == [
        "TF_REPEATED_DATA ignoring data with redundant timestamp for frame base at time "
        "10.000000 according to authority default"
    ]


@pytest.mark.parametrize("twin", sorted(CORES))
def test_replace_takes_the_new_values_at_the_newest_stamp(
    twin: str, caplog: pytest.LogCaptureFixture
) -> None:
    core = buffer_core(twin, on_repeat="replace")
    assert core.on_repeat == "replace"
    core.set_transform(tf("odom", "base", 10.0, x=0.0))
    core.set_transform(tf("odom", "base", 20.0, x=1.0))
    with caplog.at_level(logging.WARNING, "tfbus.core"):
        assert core.insert_transform(tf("odom", "base", 20.0, x=3.0)) is SetResult.STORED
    assert not caplog.messages
    at = core.lookup_transform("odom", "base", Time.from_sec(20))
    assert at.transform.translation.x == 3.0
    # Interpolation uses the replaced sample: 0 + 0.25 * (3 - 0).
    assert core.lookup_transform("odom", "base", Time.from_sec(12.5)).transform.translation.x == (
        0.75
    )
    # An equal stamp further back is still tf2's TF_REPEATED_DATA.
    with caplog.at_level(logging.WARNING, "tfbus.core"):
        assert core.insert_transform(tf("odom", "base", 10.0, x=9.0)) is (
            SetResult.REPEATED_DATA
        )
    assert core.lookup_transform("odom", "base", Time.from_sec(10)).transform.translation.x == 0.0
    assert len(caplog.messages) == 1 and caplog.messages[0].startswith("TF_REPEATED_DATA")


@pytest.mark.parametrize("twin", sorted(CORES))
def test_replace_can_move_the_newest_sample_to_another_parent(twin: str) -> None:
    core = buffer_core(twin, on_repeat="replace")
    core.set_transform(tf("map", "odom", 20.0, x=100.0))
    core.set_transform(tf("world", "odom", 20.0, x=5.0))  # the only sample: new parent
    assert core.get_parent("odom") == "world"
    assert core.lookup_transform("world", "odom", Time.from_sec(20)).transform.translation.x == (
        5.0
    )
    core.set_transform(tf("world", "base", 10.0, x=1.0))
    core.set_transform(tf("world", "base", 20.0, x=2.0))
    core.set_transform(tf("map", "base", 20.0, x=7.0))  # two samples: one parent each
    assert core.get_parent("base", Time.from_sec(20)) == "map"
    assert core.get_parent("base", Time.from_sec(10)) == "world"
    assert core.lookup_transform("map", "base", Time.from_sec(20)).transform.translation.x == 7.0
    # Between samples of two parents, the older sample is used (tf2).
    assert core.lookup_transform("world", "base", Time.from_sec(15)).transform.translation.x == (
        1.0
    )


def test_static_transforms_always_replace_and_bad_options_are_named() -> None:
    core = BufferCore()
    core.set_transform_static(tf("base", "laser", 0.0, x=1.0))
    core.set_transform_static(tf("base", "laser", 0.0, x=2.0))
    assert core.lookup_transform("base", "laser", Time(0)).transform.translation.x == 2.0
    with pytest.raises(ValueError, match="on_repeat must be 'reject' or 'replace', got 'keep'"):
        BufferCore(on_repeat="keep")  # type: ignore[arg-type]


@pytest.mark.anyio
async def test_a_replacing_insert_answers_a_wait_with_the_new_values() -> None:
    buf = Buffer(clock=ManualClock(Time.from_sec(20)), on_repeat="replace")
    assert buf.on_repeat == "replace"
    buf.set_transform(tf("odom", "base", 20.0, x=1.0))
    assert buf.set_transform(tf("odom", "base", 20.0, x=4.0))
    got = await buf.wait_for_transform("odom", "base", Time.from_sec(20), timeout=1.0)
    assert got.transform.translation.x == 4.0
