"""``Doctor.add``'s two loops over a message's transforms, the compiled one
(``tfbus.doctor._cchecks.account``, on the typed per-link fields) and ``Doctor.add``'s own
(the pure-Python path, ``TFBUS_PURE_PYTHON``), leave the same state and give the same
report, bit for bit: on every recording of ``doctor_faults`` (each with one fault), on
streams with what only a peer sends (junk items, subclasses, stamps far from the receive
clock, a receive time beyond 64 bits), on random streams, and against the pure-Python core
in a process of its own."""

from __future__ import annotations

import json
import sys
from collections import deque
from collections.abc import Iterable
from typing import Any

import pytest
from doctor_faults import FAULTS, T0, Record, tf
from hypothesis import given, settings
from hypothesis import strategies as st
from twin_streams import (
    MS,
    by_receive_time,
    named_streams,
    peer_items,
    pure_states,
    records_of,
    stream_strategy,
)

import tfbus.doctor._cchecks
import tfbus.doctor.checks
from tfbus.doctor import Doctor, Thresholds
from tfbus.messages import TransformStamped

COMPILED = tfbus.doctor.checks._ACCOUNT

needs_compiled = pytest.mark.skipif(
    COMPILED is None,
    reason="the compiled accounting is not in use (TFBUS_PURE_PYTHON, or no extensions)")


def _span(s: Any) -> tuple[int, int, int] | None:
    return None if s is None else (s.count, s.first, s.last)


def state(doctor: Doctor) -> str:
    """Everything the doctor keeps, as exact text (floats by repr)."""
    links = {}
    for child, link in sorted(doctor._links.items()):
        links[child] = [
            link.parent, {k: _span(v) for k, v in link.parents.items()},
            {k: _span(v) for k, v in link.static.items()},
            {k: _span(v) for k, v in link.dynamic.items()},
            link.static_values, list(link.sender_stamp.items()), list(link.delay.items()),
            None if link.hot is None else list(link.hot[:3]), link.newest, list(link.recent),
            link.repeated, _span(link.repeat_span), link.out_of_order, link.old_data,
            _span(link.order_span), link.last_received, link.period, link.intervals,
            link.consecutive_gaps, link.gap_count, link.gap_largest, sorted(link.gap_senders),
            link.first_gap, link.last_gap, link.baseline, link.drop_first, link.drop_last,
            link.drop_worst,
        ]
    samples = {k: [s.cap, s.n, s.stride, s.values] for k, s in sorted(doctor._delays.items())}
    slashed = {k: [_span(v[0]), sorted(v[1]), v[2]] for k, v in sorted(doctor._slashed.items())}
    whole = [doctor.messages, doctor.transforms, doctor.start, doctor.end, doctor.sim_time,
             doctor._newest_stamp, doctor.untracked, doctor.loops_untracked, links, samples,
             doctor._latest, sorted(map(str, doctor._loops.values())), sorted(doctor._senders),
             slashed, doctor.report().to_dict()]
    return json.dumps(whole, default=repr, sort_keys=True)


def feed(records: Iterable[Record], compiled: bool,
         thresholds: Thresholds | None = None) -> Doctor:
    doctor = Doctor(thresholds)
    if not compiled:
        doctor._account = None
    for t, topic, caller, transforms in records:
        doctor.add(t, transforms, caller, static=topic == "/tf_static")
    return doctor


@needs_compiled
@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_every_fault_gives_the_same_state_and_report(fault: str) -> None:
    records = by_receive_time(FAULTS[fault]())
    assert state(feed(records, True)) == state(feed(records, False))


def peer_stream() -> list[Record]:
    """What only a peer or a hand-made call sends, between ordinary transforms."""
    out: list[Record] = []
    for i in range(60):
        t = T0 + i * 10 * MS
        items = peer_items(i, t)
        if i == 40:  # the same link under a leading slash, then stamped ahead
            items.append(tf("/odom", "/base_link", t + 50 * MS))
        out.append((t, "/tf", "/peer" if i % 3 else "/other", items))
    out.append((T0 + 2 * 10**9, "/tf_static", "/rsp", [tf("base_link", "laser", T0, 0.2)]))
    out.append((2**70, "/tf", "/peer", [tf("odom", "base_link", T0 + 10**9)]))  # beyond 64 bits
    return out


@needs_compiled
def test_what_a_peer_sends_gives_the_same_state_and_report() -> None:
    records = peer_stream()
    assert state(feed(records, True)) == state(feed(records, False))


@needs_compiled
def test_more_delays_than_a_sample_keeps_give_the_same_state_and_report() -> None:
    # Thresholds.delay_samples (1024) per sender at most: then every other one, and so on
    records = [(T0 + i * 10**7, "/tf", "/odometry",
                [tf("odom", "base_link", T0 + i * 10**7 - 10**6),
                 tf("base_link", "laser", T0 + i * 10**7 - 2 * 10**6)]) for i in range(1500)]
    compiled, pure = feed(records, True), feed(records, False)
    assert compiled._delays["/odometry"].stride > 1
    assert state(compiled) == state(pure)


@needs_compiled
def test_simulated_time_gives_the_same_state_and_report() -> None:
    # stamps near 0 while the receive clock is near 1.7e18: delays against the newest stamp
    records = [(T0 + i * 10**7, "/tf", "/sim", [tf("odom", "base_link", 10**6 + i * 10**7),
                                               tf("map", "odom", 10**6 + (i // 2) * 2 * 10**7)])
               for i in range(200)]
    compiled, pure = feed(records, True), feed(records, False)
    assert compiled.sim_time is True
    assert state(compiled) == state(pure)


@needs_compiled
def test_a_header_that_is_not_one_raises_the_same_after_the_same_accounting() -> None:
    good = tf("odom", "base_link", T0)
    bad = TransformStamped(5, "x")  # type: ignore[arg-type]
    doctors = [feed([], compiled) for compiled in (True, False)]
    for doctor in doctors:
        with pytest.raises(AttributeError):
            doctor.add(T0 + 10**6, [good, bad, tf("odom", "base_link", T0 + 1)], "/a",
                       static=False)
    assert state(doctors[0]) == state(doctors[1])
    assert doctors[0].transforms == 1  # what came before the bad item, written back


@needs_compiled
def test_repeats_beyond_the_stamps_a_link_keeps_give_the_same_state_and_report() -> None:
    # 100 stamps in order, then stamps the link still holds (repeated) and stamps it let go
    # (older than the last 32: out of order), then in order again
    stamps = [T0 + i * 10**7 for i in range(100)]
    again = [stamps[i] for i in (99, 90, 68, 67, 66, 40, 10, 0)] + [T0 + 200 * 10**7]
    records = [(T0 + k * 10**7 + 10**6, "/tf", "/odometry", [tf("odom", "base_link", s)])
               for k, s in enumerate(stamps + again)]
    compiled, pure = feed(records, True), feed(records, False)
    link = compiled._links["base_link"]
    assert link.repeated == {"/odometry": 3}  # 99, 90, 68: among the newest 32 held
    assert link.out_of_order == {"/odometry": 5}  # 67, 66, 40, 10, 0: let go, older
    assert list(link.recent) == (stamps[74:] + [stamps[i] for i in (67, 66, 40, 10, 0)]
                                 + [T0 + 200 * 10**7])
    assert state(compiled) == state(pure)


@needs_compiled
def test_senders_taking_turns_and_renamed_give_the_same_state_and_report() -> None:
    # a link's senders in turn, runs of each, one renamed while it still sends (its
    # entries moved, then a new one for it), the state read between messages
    def run(compiled: bool) -> tuple[str, list[str]]:
        doctor = feed([], compiled)
        seen = []
        for i, name in enumerate(["/b", "/a", "/a", "/c", "/b", "/b", "/b", "/a", "/c"] * 3):
            t = T0 + i * 10 * MS
            doctor.add(t, [tf("odom", "base_link", t - MS)], name, static=False)
            if i % 4 == 0:
                seen.append(repr(list(doctor._links["base_link"].sender_stamp.items())))
            if i == 5:
                doctor.rename_authority("/b", "/a")
            if i == 20:
                doctor.rename_authority("/c", "/d")
        return state(doctor), seen

    compiled, pure = run(True), run(False)
    assert compiled == pure
    # /b's entry moved into /a's at message 5, a new /b from message 6; /c's into a new /d
    # at message 20, a new /c from message 21: each the newest stamp its sender sent
    newest = {n: T0 + i * 10 * MS - MS for i, n in enumerate(
        ["/b", "/a", "/a", "/c", "/b", "/b", "/b", "/a", "/c"] * 3)}
    assert json.loads(compiled[0])[8]["base_link"][5] == [
        ["/a", newest["/a"]], ["/b", newest["/b"]], ["/d", T0 + 17 * 10 * MS - MS],
        ["/c", newest["/c"]]]


@needs_compiled
@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.integers(0, 60)), max_size=120))
def test_a_links_recent_stamps_behave_as_the_pure_deque(
    steps: list[tuple[bool, int]]
) -> None:
    link = tfbus.doctor.checks._Link("base_link")
    twin: deque[int] = deque(maxlen=tfbus.doctor.checks._RECENT_STAMPS)
    for append, stamp in steps:
        if append:
            link.recent.append(stamp)
            twin.append(stamp)
        else:
            assert (stamp in link.recent) == (stamp in twin)
        assert list(link.recent) == list(twin)
        assert len(link.recent) == len(twin)
    assert tfbus.doctor._cchecks.RECENT_STAMPS == tfbus.doctor.checks._RECENT_STAMPS


_stream = stream_strategy(["map", "odom", "/odom", "base_link"],
                          ["odom", "base_link", "laser", "/laser"], max_size=120)


@needs_compiled
@settings(max_examples=60, deadline=None)
@given(_stream, st.integers(2, 6))
def test_random_streams_give_the_same_state_and_report(
    steps: list[tuple[int, str, str, list[tuple[str, str, int]]]], window: int
) -> None:
    records = records_of(steps)
    thresholds = Thresholds(rate_window=window, gap_min=0.05)
    assert state(feed(records, True, thresholds)) == state(feed(records, False, thresholds))


@needs_compiled
def test_the_pure_python_core_gives_the_same_state_and_report() -> None:
    pure = pure_states(__file__)
    streams = named_streams(sys.modules[__name__])
    assert sorted(pure) == sorted(streams)
    for name, records in streams.items():
        assert state(feed(records, True)) == pure[name], name
