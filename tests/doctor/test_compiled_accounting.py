"""``Doctor.add``'s two loops over a message's transforms, the compiled one
(``tfbus.doctor._cchecks.account``, on the typed per-link fields) and ``Doctor.add``'s own
(the pure-Python path, ``TFBUS_PURE_PYTHON``), leave the same state and give the same
report, bit for bit: on every recording of ``doctor_faults`` (each with one fault), on
streams with what only a peer sends (junk items, subclasses, stamps far from the receive
clock, a receive time beyond 64 bits), on random streams, and against the pure-Python core
in a process of its own."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pytest
from doctor_faults import FAULTS, T0, Record, tf
from hypothesis import given, settings
from hypothesis import strategies as st

import tfbus.doctor.checks
from tfbus.doctor import Doctor, Thresholds
from tfbus.messages import Header, TransformStamped
from tfbus.time import Time

COMPILED = tfbus.doctor.checks._ACCOUNT
HERE = Path(__file__).resolve().parent

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
            link.static_values, link.sender_stamp, link.delay,
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


def _sorted(records: list[Record]) -> list[Record]:
    return sorted(records, key=lambda r: r[0])


@needs_compiled
@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_every_fault_gives_the_same_state_and_report(fault: str) -> None:
    records = _sorted(FAULTS[fault]())
    assert state(feed(records, True)) == state(feed(records, False))


class _Stamped(TransformStamped):
    """A subclass of TransformStamped (read by attribute, as Doctor.add reads it)."""


class _Header(Header):
    """A subclass of Header."""


def peer_stream() -> list[Record]:
    """What only a peer or a hand-made call sends, between ordinary transforms."""
    out: list[Record] = []
    ms = 1_000_000
    for i in range(60):
        t = T0 + i * 10 * ms
        items: list[Any] = [tf("odom", "base_link", t - 5 * ms)]
        if i % 7 == 0:
            items.append("junk")
        if i % 11 == 0:
            items.append(TransformStamped(Header(Time.from_ns(t), "odom"), 5))  # type: ignore[arg-type]
        if i % 13 == 0:
            items.append(TransformStamped(Header(5, "odom"), "x"))  # type: ignore[arg-type]
        if i % 5 == 0:
            base = tf("map", "odom", t - 20 * ms)
            items.append(_Stamped(_Header(*base.header), base.child_frame_id, base.transform))
        if i == 30:  # a stamp far behind the receive clock: a delay beyond 2**53 ns
            items.append(tf("odom", "far", 1))
        if i == 40:  # the same link under a leading slash, then stamped ahead
            items.append(tf("/odom", "/base_link", t + 50 * ms))
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


_stream = st.lists(
    st.tuples(
        st.integers(0, 3 * 10**8),  # receive time step, ns
        st.sampled_from(["/tf", "/tf", "/tf", "/tf_static"]),
        st.sampled_from(["/a", "/b", "/a"]),
        st.lists(st.tuples(st.sampled_from(["map", "odom", "/odom", "base_link"]),
                           st.sampled_from(["odom", "base_link", "laser", "/laser"]),
                           st.integers(-3 * 10**8, 10**8)),  # stamp relative to receive time
                 min_size=1, max_size=4),
    ),
    max_size=120,
)


@needs_compiled
@settings(max_examples=60, deadline=None)
@given(_stream, st.integers(2, 6))
def test_random_streams_give_the_same_state_and_report(
    steps: list[tuple[int, str, str, list[tuple[str, str, int]]]], window: int
) -> None:
    t = T0
    records: list[Record] = []
    for step, topic, caller, links in steps:
        t += step
        records.append((t, topic, caller,
                        [tf(parent, child, max(t + rel, 0)) for parent, child, rel in links]))
    thresholds = Thresholds(rate_window=window, gap_min=0.05)
    assert state(feed(records, True, thresholds)) == state(feed(records, False, thresholds))


_PURE_SCRIPT = """
import sys
sys.path[:0] = [{tests!r}, {doctor!r}]
import test_compiled_accounting as t
from doctor_faults import FAULTS
assert t.COMPILED is None
streams = {{name: t._sorted(f()) for name, f in FAULTS.items()}}
streams["peer"] = t.peer_stream()
for name in sorted(streams):
    print(name, t.state(t.feed(streams[name], False)))
"""


@needs_compiled
def test_the_pure_python_core_gives_the_same_state_and_report() -> None:
    # the pure twin's own field classes (slots), in a process with TFBUS_PURE_PYTHON
    env = {**os.environ, "TFBUS_PURE_PYTHON": "1"}
    script = _PURE_SCRIPT.format(tests=str(HERE.parent), doctor=str(HERE))
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                         text=True, timeout=120, check=True).stdout
    pure = dict(line.split(" ", 1) for line in out.splitlines())
    streams = {name: _sorted(f()) for name, f in FAULTS.items()}
    streams["peer"] = peer_stream()
    assert sorted(pure) == sorted(streams)
    for name, records in streams.items():
        assert state(feed(records, True)) == pure[name], name
