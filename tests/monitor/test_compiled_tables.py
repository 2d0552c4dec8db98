"""``TfSummary.add``'s two loops over a message's transforms, the compiled one
(``tfbus._cmonitor.account``, on the typed fields of the tables) and ``TfSummary.add``'s
own (the pure-Python path, ``TFBUS_PURE_PYTHON``), leave the same tables, bit for bit: on
every recording of the doctor's fault set, on what only a peer sends (junk items,
subclasses, repeated and out-of-order stamps, stamps far from the receive clock, a receive
time beyond 64 bits), in simulated time, on random streams, and against the pure-Python
core in a process of its own."""

from __future__ import annotations

import json
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings

import tfbus.monitor
from tfbus.messages import Header, TransformStamped
from tfbus.monitor import RateWindow, TfSummary
from tfbus.time import Time

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "doctor"))

from doctor_faults import FAULTS, T0, Record, tf
from twin_streams import (
    MS,
    by_receive_time,
    named_streams,
    peer_items,
    pure_states,
    records_of,
    stream_strategy,
)

COMPILED = tfbus.monitor._ACCOUNT

needs_compiled = pytest.mark.skipif(
    COMPILED is None,
    reason="the compiled tables are not in use (TFBUS_PURE_PYTHON, or no extensions)")


def _window(w: RateWindow) -> list[Any]:
    return [w.window_ns, w.maxlen, w.distinct, w.last_received, list(w._received),
            list(w._values), list(w._out_of_order), w._seq,
            None if w._held is None else sorted(w._held)]


def state(summary: TfSummary) -> str:
    """Everything the tables keep, as exact text (floats by repr)."""
    frames = {child: [f.child, f.parent, f.static,
                      [[repr(k), v] for k, v in f.authorities.items()], f.authority,
                      f.count, f.distinct_stamps,
                      f.first_stamp, f.last_stamp, f.delay_sum, f.delay_count, f.delay_max,
                      _window(f.received)]
              for child, f in sorted(summary.frames.items())}
    authorities = {repr(name): [a.authority, a.messages, a.first, a.last, a.delay_sum,
                                a.delay_count, a.delay_max, _window(a.received)]
                   for name, a in summary.authorities.items()}
    chains = [[c.source, c.target, c.frames, c.delay_sum, c.delay_count, c.delay_max]
              for c in summary.chains]
    whole = [summary.start, summary.end, summary.messages, frames, authorities,
             summary.sim_time, summary._newest_stamp, chains]
    return json.dumps(whole, default=repr, sort_keys=True)


def feed(records: Iterable[Record], compiled: bool) -> TfSummary:
    summary = TfSummary()
    summary.watch_chain("map", "base_link")
    was = tfbus.monitor._ACCOUNT
    tfbus.monitor._ACCOUNT = COMPILED if compiled else None
    try:
        for t, topic, caller, transforms in records:
            summary.add(Time.from_ns(t) if t < 2**63 else _Late(t),
                        transforms, caller, static=topic == "/tf_static")
    finally:
        tfbus.monitor._ACCOUNT = was
    return summary


class _Late(Time):
    """A receive time beyond 64 bits (a Time only a hand-made call builds)."""

    def __init__(self, ns: int) -> None:
        self._ns = ns


@needs_compiled
@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_every_fault_recording_gives_the_same_tables(fault: str) -> None:
    records = by_receive_time(FAULTS[fault]())
    assert state(feed(records, True)) == state(feed(records, False))


def peer_stream() -> list[Record]:
    """What only a peer or a hand-made call sends, between ordinary transforms."""
    out: list[Record] = []
    for i in range(80):
        t = T0 + i * 10 * MS
        items = peer_items(i, t)
        if i % 13 == 0:  # a parent that is not a str
            items.append(TransformStamped(Header(Time.from_ns(t), 7), "y"))  # type: ignore[arg-type]
        if i % 9 == 0:  # a repeated stamp, then one out of order
            items.append(tf("odom", "base_link", t - 5 * MS))
            items.append(tf("odom", "base_link", t - 45 * MS))
        if i == 50:  # the frame now static, then dynamic again
            out.append((t, "/tf_static", "/rsp", [tf("odom", "base_link", t)]))
        out.append((t, "/tf", "/peer" if i % 3 else "/other", items))
        if i == 60:  # an authority that is not a str (TfSummary.add takes any key)
            out.append((t, "/tf", 7, [tf("odom", "base_link", t)]))  # type: ignore[list-item]
    out.append((2**70, "/tf", "/peer", [tf("odom", "base_link", T0 + 10**9)]))  # beyond 64 bits
    return out


@needs_compiled
def test_what_a_peer_sends_gives_the_same_tables() -> None:
    records = peer_stream()
    assert state(feed(records, True)) == state(feed(records, False))


@needs_compiled
def test_more_samples_than_a_window_holds_give_the_same_tables() -> None:
    # RECENT_SAMPLES (1000) per frame at most: the oldest leave as new ones come
    records = [(T0 + i * 10**7, "/tf", "/odometry",
                [tf("odom", "base_link", T0 + i * 10**7 - 10**6)]) for i in range(1500)]
    compiled, pure = feed(records, True), feed(records, False)
    assert len(compiled.frames["base_link"].received) == tfbus.monitor.RECENT_SAMPLES
    assert state(compiled) == state(pure)


@needs_compiled
def test_simulated_time_gives_the_same_tables() -> None:
    records = [(T0 + i * 10**7, "/tf", "/sim", [tf("odom", "base_link", 10**6 + i * 10**7),
                                               tf("map", "odom", 10**6 + (i // 2) * 2 * 10**7)])
               for i in range(300)]
    compiled, pure = feed(records, True), feed(records, False)
    assert compiled.sim_time is True
    assert state(compiled) == state(pure)


@needs_compiled
def test_a_header_that_is_not_one_raises_the_same_after_the_same_accounting() -> None:
    good = tf("odom", "base_link", T0)
    bad = TransformStamped(5, "x")  # type: ignore[arg-type]
    summaries = [feed([], compiled) for compiled in (True, False)]
    for summary, compiled in zip(summaries, (True, False), strict=True):
        tfbus.monitor._ACCOUNT = COMPILED if compiled else None
        try:
            with pytest.raises(AttributeError):
                summary.add(Time.from_ns(T0 + 10**6), [good, bad], "/a", static=False)
        finally:
            tfbus.monitor._ACCOUNT = COMPILED
    assert state(summaries[0]) == state(summaries[1])
    assert summaries[0].frames["base_link"].count == 1  # accounted before the bad item


@needs_compiled
def test_broadcasters_taking_turns_and_renamed_give_the_same_tables() -> None:
    # a frame's broadcasters in turn, runs of each, one renamed into another (its counts
    # moved), the counts read between messages: counts and their order the same
    def run(compiled: bool) -> tuple[str, list[str]]:
        summary = feed([], compiled)
        was = tfbus.monitor._ACCOUNT
        tfbus.monitor._ACCOUNT = COMPILED if compiled else None
        seen = []
        try:
            for i, name in enumerate(["/b", "/a", "/a", "/c", "/b", "/b", "/b", "/a", "/c"] * 3):
                t = T0 + i * 10 * MS
                summary.add(Time.from_ns(t), [tf("odom", "base_link", t),
                                              tf("base_link", "laser", t)], name, static=False)
                if i % 4 == 0:
                    seen.append(repr(list(summary.frames["laser"].authorities.items())))
                if i == 5:  # /b sends the next message too: counted under a new /b
                    summary.rename_authority("/b", "/a")
                if i == 20:
                    summary.rename_authority("/c", "/d")
        finally:
            tfbus.monitor._ACCOUNT = was
        return state(summary), seen

    compiled, pure = run(True), run(False)
    assert compiled == pure
    # by hand: /b 3, /a 2, /c 1 up to message 5; /b renamed /a (5, in /a's place); then
    # /b 6 (new, last), /a 11, /c 4 up to message 20; /c renamed /d (4, last); then /c 2
    # (new, last), /b 9, /a 12
    laser = json.loads(compiled[0])[3]["laser"]
    assert laser[3] == [["'/a'", 12], ["'/b'", 9], ["'/d'", 4], ["'/c'", 2]]
    assert laser[4] == "/a"


_stream = stream_strategy(["map", "odom", "base_link"], ["odom", "base_link", "laser"],
                          max_size=150)


@needs_compiled
@settings(max_examples=60, deadline=None)
@given(_stream)
def test_random_streams_give_the_same_tables(
    steps: list[tuple[int, str, str, list[tuple[str, str, int]]]],
) -> None:
    records = records_of(steps)
    assert state(feed(records, True)) == state(feed(records, False))


@needs_compiled
def test_the_pure_python_core_gives_the_same_tables() -> None:
    pure = pure_states(__file__)
    streams = named_streams(sys.modules[__name__])
    assert sorted(pure) == sorted(streams)
    for name, records in streams.items():
        assert state(feed(records, True)) == pure[name], name
