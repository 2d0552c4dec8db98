"""``tfbus.core.cache`` (compiled in ``tfbus/core/_ccache.pyx``): TimeCache and StaticCache storage.

The semantics are checked op by op against tf2 by the conformance corpus; these tests
drive the storage mechanics (out-of-order inserts, pruning, growth, compaction, the
per-sample parent array after a re-parenting) against a model written as plainly as
possible: a dict of stamps, pruned by tf2's rule after every insert.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfbus.core import _pycache
from tfbus.core._select import COMPILED
from tfbus.core.cache import OK, OLD_DATA, REPEATED_DATA, StaticCache, TimeCache

Row = tuple[float, float, float, float, float, float, float]


def row(k: int) -> Row:
    return (float(k), -float(k), 0.5 * k, 0.0, 0.0, 0.0, 1.0)


class Model:
    """tf2 ``TimeCache::insertData`` + ``pruneList``, literally."""

    def __init__(self, cache_time: int) -> None:
        self.cache_time = cache_time
        self.samples: dict[int, tuple[int, Row]] = {}

    def insert(self, stamp: int, parent: int, values: Row) -> int:
        if self.samples:
            newest = max(self.samples)
            if newest > stamp + self.cache_time:
                return OLD_DATA
            if stamp in self.samples:
                return REPEATED_DATA
        self.samples[stamp] = (parent, values)
        horizon = max(self.samples) - self.cache_time
        self.samples = {t: v for t, v in self.samples.items() if t >= horizon}
        return OK


inserts = st.lists(
    st.tuples(st.integers(1, 400), st.sampled_from([1, 1, 1, 2, 3])), max_size=300
)


@settings(max_examples=200, deadline=None)
@given(inserts, st.integers(0, 120))
def test_time_cache_matches_the_model(ops: list[tuple[int, int]], cache_time: int) -> None:
    cache = TimeCache(cache_time)
    model = Model(cache_time)
    peak = 0
    for k, (stamp, parent) in enumerate(ops):
        assert cache.insert(stamp, parent, row(k)) == model.insert(stamp, parent, row(k))
        assert len(cache) == len(model.samples)
        peak = max(peak, len(model.samples))
    stamps = sorted(model.samples)
    assert cache.stamps().tolist() == stamps
    assert [tuple(r) for r in cache.values().tolist()] == [model.samples[t][1] for t in stamps]
    for t in stamps:  # exact stamps return the stored sample and its own parent
        assert cache.gather(t) == model.samples[t]
    if stamps:
        assert cache.latest() == (stamps[-1], model.samples[stamps[-1]][0])
        assert cache.gather(0) == model.samples[stamps[-1]]
        assert (cache.oldest_stamp(), cache.latest_stamp()) == (stamps[0], stamps[-1])
        # Capacity follows the most samples ever live, plus the growth slack: doubling
        # below 256 samples, 1/16 beyond.
        assert cache.nbytes() <= (64 + 4) * (peak + max(min(peak, 255), peak // 16, 4) + 8)
    else:
        assert cache.latest() == (0, 0)
        assert cache.gather(5) == ""


TWINS = [_pycache.TimeCache]
if COMPILED:
    from tfbus.core import _ccache

    TWINS.append(_ccache.TimeCache)


@pytest.mark.parametrize("twin", TWINS, ids=lambda t: t.__module__.rpartition(".")[2])
def test_capacity_doubles_up_to_256_samples_then_grows_by_a_sixteenth(twin: type) -> None:
    # 64 bytes a sample: 8 stamp + 7 x 8 values.
    cache = twin(10**12)
    caps = []
    for k in range(1, 600):
        assert cache.insert(k, 1, row(k)) == OK
        caps.append(cache.nbytes() // 64)
    # A new link's first 200 samples: 5 reallocations (8 -> 256), not one every 4-12.
    assert sorted(set(caps[:200])) == [8, 16, 32, 64, 128, 256]
    assert sorted(set(caps[200:])) == [256, 272, 289, 307, 326, 346, 367, 389, 413, 438,
                                       465, 494, 524, 556, 590, 626]  # fmt: skip
    # Once pruning frees 1/16 of the capacity below the live samples, they slide down:
    # the capacity stays put.
    pruned = twin(100)
    for k in range(1, 2000):
        pruned.insert(k, 1, row(k))
    assert len(pruned) == 101
    assert pruned.nbytes() == 128 * 64
    assert pruned.stamps().tolist() == list(range(1899, 2000))
    assert pruned.values()[0].tolist() == list(row(1899))


def test_interpolation_between_parents_uses_the_older_sample() -> None:
    cache = TimeCache(10**9)
    cache.insert(100, 1, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    cache.insert(200, 2, (2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    cache.insert(300, 2, (4.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    assert cache.gather(150) == (1, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    assert cache.gather(250) == (2, (3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))


def test_interpolating_nearly_equal_rotations_keeps_the_older_one() -> None:
    # The normalised dot product of these two rounds to just above 1; tf2Acos clamps it
    # (zero angle) and tf2 returns the older rotation. Recorded from tf2 by fuzzing.
    a = (-0.10034160459801901, -0.48624984361471457, -0.22642117855190708, 0.8379893208594761)
    b = (-0.10034160459799965, -0.48624984361470064, -0.2264211785518684, 0.837989320859497)
    cache = TimeCache(10**10)
    cache.insert(230134, 1, (0.0, 0.0, 0.0, *a))
    cache.insert(232134, 1, (2.0, 0.0, 0.0, *b))
    assert cache.gather(230272) == (1, (0.138, 0.0, 0.0, *a))


def test_extrapolation_details_are_tf2s() -> None:
    cache = TimeCache(10**10)
    cache.insert(1_000_000_000, 1, row(0))
    assert cache.gather(2_000_000_000) == (
        "Lookup would require extrapolation at time 2.000000000, but only time "
        "1.000000000 is in the buffer"
    )
    cache.insert(3_000_000_000, 1, row(1))
    assert cache.gather(4_500_000_000) == (
        "Lookup would require extrapolation 1.500000000s into the future.  Requested time "
        "4.500000000 but the latest data is at time 3.000000000"
    )
    assert cache.gather(500_000_000) == (
        "Lookup would require extrapolation 0.500000000s into the past.  Requested time "
        "0.500000000 but the earliest data is at time 1.000000000"
    )


def test_interpolation_ratio_is_exact_beyond_2_to_53_ns() -> None:
    # Spans of more than 2**53 ns (104 days) do not fit a double exactly: the ratio is
    # still the correctly rounded quotient of the integer ns, as for shorter spans.
    cache = TimeCache(2**62)
    cache.insert(1, 1, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    cache.insert(1 + 2**53 + 1, 1, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    assert cache.gather(1 + 2**52 + 1) == (1, (0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    exact = (2**52 + 1) / (2**53 + 1)
    assert exact == 0.5  # while float(2**52 + 1) / float(2**53 + 1) is 0.5 + 2**-53


def test_cache_time_beyond_int64_keeps_everything() -> None:
    cache = TimeCache(10**30)
    assert cache.cache_time_ns == 2**63 - 1
    for stamp in (1, 2**40, 2**62):
        assert cache.insert(stamp, 1, row(0)) == OK
    assert cache.stamps().tolist() == [1, 2**40, 2**62]


def test_clear_releases_and_allows_any_parent_again() -> None:
    cache = TimeCache(100)
    for k in range(50):
        cache.insert(k + 1, 1 + k % 2, row(k))
    cache.clear()
    assert len(cache) == 0 and cache.latest() == (0, 0)
    assert cache.insert(7, 5, row(1)) == OK
    assert cache.gather(0) == (5, row(1))


def test_static_cache_holds_the_last_value_at_every_time() -> None:
    cache = StaticCache()
    assert cache.is_static and len(cache) == 1
    assert cache.insert(10, 3, row(1)) == OK
    assert cache.insert(5, 4, row(2)) == OK  # last wins, whatever its stamp
    assert cache.gather(0) == cache.gather(123) == (4, row(2))
    assert cache.latest() == (0, 4) and cache.stamp_sent() == 5
    cache.clear()  # statics survive BufferCore.clear()
    assert cache.gather(1) == (4, row(2))
