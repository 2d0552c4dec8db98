"""A ``SimClock`` fed mutated ``/clock`` samples (hypothesis, derandomized, bounded), on
asyncio and trio.

Each example is a run of samples as the three middlewares carry them (tfbus's Zenoh wire
format, CDR, ROS 1), valid ones at edge times (0, the int32 and uint32 second limits,
steps back, repeats, stalls) among mutated ones (bits flipped, cut, extended); what decodes
is published on ``/clock`` of a bus, with objects that are not a Clock at all. Whatever
comes, the clock never raises into the publisher, its time is always that of the last
accepted sample (``Time(0)`` before any), every sample is counted as accepted or dropped,
a step back is counted as a jump (rclpy's ``TimeSource`` reports it to jump callbacks),
and a task sleeping on simulated time still wakes when a later valid sample arrives.
"""

from __future__ import annotations

from typing import Any

import anyio
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from tfbus import Bus, SimClock
from tfbus.clock import every
from tfbus.codecs import cdr, native, ros1
from tfbus.errors import WireError
from tfbus.messages import Clock
from tfbus.time import TIME_MAX_NS, Time
from tfbus.topics import CLOCK_TOPIC

CODECS = {"native": native, "cdr": cdr, "ros1": ros1}
EDGE_SECONDS = [0, 1, 2, 59, 60, 2**31 - 2, 2**31 - 1, 2**32 - 1]


@st.composite
def sample(draw: st.DrawFn) -> tuple[str, bytes]:
    """One ``/clock`` sample on the wire of one codec: valid or mutated."""
    name = draw(st.sampled_from(sorted(CODECS)))
    codec = CODECS[name]
    sec = draw(st.sampled_from(EDGE_SECONDS) | st.integers(0, 2**31 - 1))
    nsec = draw(st.sampled_from([0, 1, 999_999_999]) | st.integers(0, 999_999_999))
    try:
        raw = bytearray(codec.encode_clock(Clock(Time(sec, nsec))))
    except WireError:  # a time this middleware cannot carry
        raw = bytearray(ros1.encode_clock(Clock(Time(sec % 2**31, nsec))))
        name = "ros1"
    for _ in range(draw(st.integers(0, 2))):
        op = draw(st.sampled_from(["flip", "cut", "extend", "byte"]))
        if op == "cut":
            del raw[draw(st.integers(0, len(raw))):]
        elif op == "extend":
            raw += draw(st.binary(max_size=8))
        elif raw:
            at = draw(st.integers(0, len(raw) - 1))
            if op == "flip":
                raw[at] ^= 1 << draw(st.integers(0, 7))
            else:
                raw[at] = draw(st.sampled_from([0, 0x7F, 0x80, 0xFF]))
    return name, bytes(raw)


JUNK: list[Any] = [None, 5, "1.5", Clock(None), Clock(12.5), object()]  # type: ignore[arg-type]


async def _run(samples: list[tuple[str, bytes] | int]) -> None:
    async with Bus() as bus, SimClock(bus) as clock:
        last: Time | None = None
        jumps = 0
        for item in samples:
            if isinstance(item, int):  # an object that is not a Clock
                before = (clock.accepted, clock.now())
                bus.publish_nowait(CLOCK_TOPIC, JUNK[item])
                assert (clock.accepted, clock.now()) == before
                continue
            name, raw = item
            try:
                message = CODECS[name].decode_clock(raw)
            except WireError:
                continue  # counted by the transport that read it; never reaches the bus
            accepted = clock.accepted
            bus.publish_nowait(CLOCK_TOPIC, message)
            if clock.accepted == accepted + 1:
                if last is not None and message.clock < last:
                    jumps += 1
                last = message.clock
            assert clock.now() == (last if last is not None else Time(0))
            assert 0 <= clock.now_ns() <= TIME_MAX_NS
        assert clock.received == clock.accepted + clock.dropped
        assert clock.jumps == jumps
        # After any of it, a task sleeping on simulated time wakes at a later sample.
        now = clock.now_ns()
        wake = Time.from_ns(min(now + 1_000_000_000, TIME_MAX_NS - 1))
        woke = anyio.Event()

        async def sleeper() -> None:
            await clock.sleep_until(wake)
            woke.set()

        async with anyio.create_task_group() as tg:
            tg.start_soon(sleeper)
            await anyio.wait_all_tasks_blocked()
            bus.publish_nowait(CLOCK_TOPIC, Clock(wake))
            with anyio.fail_after(10):
                await woke.wait()
        assert clock.now() == wake


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
@settings(max_examples=60, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(samples=st.lists(sample() | st.integers(0, len(JUNK) - 1), max_size=30))
def test_any_run_of_clock_samples_keeps_the_clock_consistent(
    backend: str, samples: list[tuple[str, bytes] | int]
) -> None:
    anyio.run(_run, samples, backend=backend)


# ------------------------------------------------------------------ timers and jump callbacks

PERIOD_NS = 1_000_000_000
MAX_STEP_NS = 10**18  # SimClock's default max_forward_step, 1e9 s
EDGE_NS = [0, 1, PERIOD_NS, 2**31 * 10**9 - 1, (2**32 - 1) * 10**9 + 999_999_999,
           TIME_MAX_NS - PERIOD_NS, TIME_MAX_NS - 1, TIME_MAX_NS]
"""Stamps at the edges of each middleware's time (ROS 2's int32 and ROS 1's uint32
seconds) and of :class:`~tfbus.time.Time` itself (int64 nanoseconds)."""

STEP = st.one_of(
    st.sampled_from(EDGE_NS),
    st.integers(0, TIME_MAX_NS),
    st.sampled_from(["same", "back", "forward", "junk"]),
)


async def _timer_run(steps: list[int | str], wall_timeout: float | None) -> None:
    """Publish ``steps`` on /clock with a 1 s timer and a jump callback running; check
    each against a model of SimClock (rclpy's TimeSource: a jump back is taken and
    reported; the first sample at any time; later ones more than max_forward_step ahead
    dropped), then that the timer still ticks on the next valid samples."""
    async with Bus() as bus, SimClock(bus, wall_timeout=wall_timeout) as clock:
        reported: list[tuple[int, int]] = []
        clock.on_jump(lambda old, new: reported.append((old.ns, new.ns)))
        ticks: list[Any] = []

        async def timer() -> None:
            async for tick in every(PERIOD_NS / 1e9, clock=clock):
                ticks.append((tick, clock.now_ns()))

        async with anyio.create_task_group() as tg:
            tg.start_soon(timer)
            await anyio.wait_all_tasks_blocked()
            now, accepted, jumps = 0, 0, []
            for step in steps:
                if step == "junk":
                    bus.publish_nowait(CLOCK_TOPIC, Clock(-1))  # type: ignore[arg-type]
                    continue
                ns = {"same": now, "back": max(now - PERIOD_NS, 0),
                      "forward": min(now + PERIOD_NS // 2, TIME_MAX_NS)}.get(step, step)
                assert isinstance(ns, int)
                bus.publish_nowait(CLOCK_TOPIC, Clock(Time.from_ns(ns)))
                if not accepted or ns - now <= MAX_STEP_NS:
                    if ns < now:
                        jumps.append((now, ns))
                    now, accepted = ns, accepted + 1
                await anyio.wait_all_tasks_blocked()  # the timer runs after each sample
                assert clock.now_ns() == now
            assert reported == jumps
            assert clock.jumps == len(jumps) and clock.accepted == accepted
            for tick, at in ticks:  # every tick at a deadline reached, read in range
                assert tick.expected.ns <= tick.actual.ns == at <= TIME_MAX_NS
            # After any of it, the timer ticks at the next valid samples (from a jump
            # back to 0 when there is no room left before the end of Time).
            if now + 2 * PERIOD_NS > TIME_MAX_NS:
                now = 0
                bus.publish_nowait(CLOCK_TOPIC, Clock(Time(0)))
                await anyio.wait_all_tasks_blocked()
            seen = len(ticks)
            for k in (1, 2):
                bus.publish_nowait(CLOCK_TOPIC, Clock(Time.from_ns(now + k * PERIOD_NS)))
                await anyio.wait_all_tasks_blocked()
            assert len(ticks) >= seen + 2
            assert ticks[-1][0].actual.ns == now + 2 * PERIOD_NS
            tg.cancel_scope.cancel()


@pytest.mark.parametrize("wall_timeout", [None, 600.0], ids=["unbounded", "wall_timeout"])
@pytest.mark.parametrize("backend", ["asyncio", "trio"])
@settings(max_examples=100, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(steps=st.lists(STEP, max_size=20))
@example(steps=[TIME_MAX_NS - 1])
def test_a_timer_and_jump_callbacks_follow_any_run_of_clock_samples(
    backend: str, wall_timeout: float | None, steps: list[int | str]
) -> None:
    anyio.run(_timer_run, steps, wall_timeout, backend=backend)


@pytest.mark.anyio
async def test_a_timer_within_one_period_of_the_end_of_time_waits_for_a_jump_back() -> None:
    """A /clock of 2**63 - 1 ns (the last Time; a sample a Zenoh peer may send) leaves no
    room for a timer's next deadline: the timer waits (before: a SimClock with a
    wall_timeout raised ValueError "Time beyond int64 nanoseconds" out of the timer),
    then ticks on from a jump back."""
    async with Bus() as bus, SimClock(bus, wall_timeout=600.0) as clock:
        bus.publish_nowait(CLOCK_TOPIC, Clock(Time.from_ns(TIME_MAX_NS)))
        ticks: list[Time] = []

        async def timer() -> None:
            async for tick in every(1.0, clock=clock):
                ticks.append(tick.expected)

        async with anyio.create_task_group() as tg:
            tg.start_soon(timer)
            await anyio.wait_all_tasks_blocked()
            assert ticks == []
            bus.publish_nowait(CLOCK_TOPIC, Clock(Time(100)))  # jump back: re-anchored
            await anyio.wait_all_tasks_blocked()
            bus.publish_nowait(CLOCK_TOPIC, Clock(Time(101)))
            await anyio.wait_all_tasks_blocked()
            assert ticks == [Time(101)]
            tg.cancel_scope.cancel()
        assert clock.jumps == 1


# ------------------------------------------------------------------ Zenoh: the newest-only stamp

def _native_clock(sender: int, seq: int, tag: str, stamp: object) -> bytes:
    """A tfbus wire payload of a ``Clock`` with any envelope values (msgpack)."""
    import msgspec

    return bytes([native.MAGIC, native.WIRE_VERSION]) + msgspec.msgpack.encode(
        [sender, seq, tag, [stamp]]
    )


ENVELOPE_INTS = st.sampled_from([0, 1, 2**63 - 1, 2**63, 2**64 - 1, -1, -(2**63)])


@st.composite
def native_clock_payload(draw: st.DrawFn) -> bytes:
    """A ``Clock`` payload of tfbus's Zenoh wire with edge envelope values, or a valid
    one mutated (bits flipped, cut, extended)."""
    stamp = draw(st.sampled_from([0, TIME_MAX_NS, TIME_MAX_NS + 1, -1, 2**64 - 1, 1.5, True])
                 | st.integers(0, TIME_MAX_NS))
    sender = draw(ENVELOPE_INTS | st.integers(1, 2**63 - 1))
    seq = draw(ENVELOPE_INTS | st.integers(1, 2**63 - 1))
    tag = draw(st.sampled_from(["Clock", "Clocj", "TFMessage", ""]))
    raw = bytearray(_native_clock(sender, seq, tag, stamp))
    for _ in range(draw(st.integers(0, 2))):
        op = draw(st.sampled_from(["flip", "cut", "extend"]))
        if op == "cut":
            del raw[draw(st.integers(0, len(raw))):]
        elif op == "extend":
            raw += draw(st.binary(max_size=8))
        elif raw:
            raw[draw(st.integers(0, len(raw) - 1))] ^= 1 << draw(st.integers(0, 7))
    return bytes(raw)


@settings(max_examples=400, deadline=None, derandomize=True, database=None)
@given(payload=native_clock_payload())
@example(payload=_native_clock(1, -1, "Clock", 5))
@example(payload=_native_clock(2**64 - 1, 1, "Clock", 5))
# another writer's encoding (the tag as a str 8): the schema reads it, not the C reader
@example(payload=bytes([native.MAGIC, native.WIRE_VERSION]) + b"\x94\x05\x07\xd9\x05Clock\x91"
         + b"\xcf" + (1_500_000_000).to_bytes(8, "big"))
def test_the_zenoh_newest_only_stamp_reads_exactly_the_clocks_the_decoder_accepts(
    payload: bytes,
) -> None:
    """Zenoh's thread reads each /clock's stamp with a light decoder to decide which
    sample to keep (``clock_stamp``, and ``NewestOnly.offer``, which reads it the same
    way inline); a sample it keeps replaces the one kept before. It gives a stamp exactly
    for the payloads the event loop's full decoder takes as a Clock, with the same stamp,
    so a sample that will be dropped never takes the place of a good one (before: a
    sender id or sequence number outside [1, 2**63) was read as a stamp, and the good
    sample it replaced was lost)."""
    pytest.importorskip("zenoh")
    from tfbus.transports.zenoh.transport import clock_stamp

    try:
        message = native.WireCodec().decode(payload).message
    except WireError:
        message = None
    expected = message.clock.ns if isinstance(message, Clock) else None
    assert clock_stamp(payload) == expected
    assert _stamp_offered(payload) == expected


class _Stats:
    coalesced = 0


class _Listeners:
    """A bus with no listener on ``/clock`` but the follower (``heard_beyond`` asks)."""

    def listeners(self, topic: str) -> int:
        return 0


class _Transport:
    """What ``NewestOnly.offer`` touches of its transport: the queue and the counters."""

    def __init__(self) -> None:
        self.pushed: list[object] = []
        self._stats = _Stats()
        self._bus = _Listeners()

    def _push(self, item: object) -> None:
        self.pushed.append(item)


def _stamp_offered(payload: bytes) -> int | None:
    """The stamp ``NewestOnly.offer`` reads from ``payload`` (its follower's ``due`` is
    asked with it), or None when it read none (then the sample is queued for the loop,
    which drops it: checked)."""
    from tfbus.transports.zenoh.transport import NewestOnly

    seen: list[int] = []
    transport = _Transport()
    newest = NewestOnly(transport, CLOCK_TOPIC, "tfbus/clock")  # type: ignore[arg-type]
    newest.follow(lambda ns: seen.append(ns) or False)
    newest.offer(payload)
    if seen:
        assert transport.pushed == [] and newest.kept_ns == seen[0]  # kept, not queued
        return seen[0]
    assert [item[2] for item in transport.pushed] == [payload]  # type: ignore[index]
    return None


@pytest.mark.anyio
async def test_a_sim_clock_on_zenoh_survives_mutated_clock_samples_from_a_raw_peer() -> None:
    """A raw Zenoh session (explicit 127.0.0.1 endpoint, scouting off) puts mutated
    ``/clock`` samples among valid ones on the key a SimClock's bus follows newest-only:
    the transport counts each it cannot decode, the clock drops the one too far ahead, a
    task sleeping on simulated time is woken by the valid sample that reaches it, and
    the clock goes on."""
    zenoh = pytest.importorskip("zenoh")
    import socket

    from tfbus.transports.zenoh import ZenohTransport
    from tfbus.transports.zenoh.config import zenoh_config

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    app = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="app")
    cfg, _ = zenoh_config(connect=f"tcp/127.0.0.1:{port}")
    codec = native.WireCodec()
    valid = codec.encode(Clock(Time(60)), sender=7, seq=2)
    bad = [
        _native_clock(7, -1, "Clock", 61 * 10**9),  # a sequence number the decoder refuses
        _native_clock(0, 3, "Clock", 61 * 10**9),  # a sender id it refuses
        _native_clock(7, 3, "Clock", TIME_MAX_NS + 1),  # past the end of Time
        _native_clock(7, 3, "Clock", -1),
        _native_clock(7, 3, "Clock", 61.5),
        valid[:-1],  # cut
        valid + b"\x00",  # extended
        b"\x00" + valid[1:],  # bad magic byte
        b"",
    ]
    async with Bus(transport=app) as bus, SimClock(bus) as clock:
        session = await anyio.to_thread.run_sync(zenoh.open, cfg)
        try:
            raw = session.declare_publisher(
                "tfbus/clock", congestion_control=zenoh.CongestionControl.BLOCK
            )
            with anyio.fail_after(30):
                while not raw.matching_status.matching:  # the app's subscriber is there
                    await anyio.sleep(0.02)
            woke = anyio.Event()

            async def sleeper() -> None:
                await clock.sleep_until(Time(100))
                woke.set()

            async with anyio.create_task_group() as tg:
                tg.start_soon(sleeper)
                raw.put(codec.encode(Clock(Time(50)), sender=7, seq=1))
                with anyio.fail_after(30):
                    while clock.now() != Time(50):
                        await anyio.sleep(0.02)
                raw.put(valid)
                for payload in bad:
                    raw.put(payload)
                raw.put(codec.encode(Clock(Time.from_ns(TIME_MAX_NS)), sender=7, seq=3))
                seq = 4
                with anyio.fail_after(30):
                    while not woke.is_set():  # repeated until read (Zenoh may drop)
                        raw.put(codec.encode(Clock(Time(100)), sender=7, seq=seq))
                        seq += 1
                        await anyio.sleep(0.05)
            stats = app.statistics()
            assert clock.now() == Time(100) and clock.jumps == 0
            assert stats.malformed == len(bad)
            assert clock.dropped == 1  # the one 2**63 - 1 ns: more than 1e9 s ahead
        finally:
            await anyio.to_thread.run_sync(session.close)


# ------------------------------------------------------------------ ROS 2: the newest-only queue


def _offer_all(stamps: list[int], dues: list[bool]) -> tuple[list[Clock], list[Clock], int]:
    """Offer ``/clock`` samples of ``stamps`` (ns) to a ROS 2 transport's newest-only
    clock, as Cyclone's listener thread does, the follower answering ``dues`` in turn;
    returns (offered, what the event loop then takes, coalesced)."""
    from tfbus.transports._newest import NewestClock
    from tfbus.transports.ros2.transport import Ros2Statistics

    newest = NewestClock()
    answers = iter(dues * (len(stamps) // max(len(dues), 1) + 1) or [False] * len(stamps))
    newest.dues = (lambda ns: next(answers, False),)
    stats = Ros2Statistics()
    offered = [Clock(Time.from_ns(ns)) for ns in stamps]
    for message in offered:
        with newest.lock:
            newest.offer(message, stats)
    with newest.lock:
        held = newest.take_all()
    return offered, held, stats.coalesced


def _is_ordered_subsequence(sub: list[Clock], of: list[Clock]) -> bool:
    it = iter(of)
    return all(any(x is y for y in it) for x in sub)


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(stamps=st.lists(st.sampled_from(EDGE_NS) | st.integers(0, 10**10), max_size=40),
       dues=st.lists(st.booleans(), max_size=8))
def test_ros2_newest_only_clock_hands_the_loop_samples_in_order_ending_with_the_newest(
    stamps: list[int], dues: list[bool]
) -> None:
    """Cyclone's thread keeps or queues each decoded /clock (a step back queues the one
    kept, then it): the event loop takes them in the order they came, the last one always
    among them, and every other is counted as coalesced."""
    pytest.importorskip("cyclonedds")
    offered, held, coalesced = _offer_all(stamps, dues)
    assert _is_ordered_subsequence(held, offered)
    assert len(held) + coalesced == len(offered)
    if offered:
        assert held[-1] is offered[-1]


def test_ros2_newest_only_clock_queue_is_bounded_under_steps_back() -> None:
    """A publisher stepping back at every other sample while the event loop is busy
    queues a sample per step; the queue keeps the newest NEWEST_MAX_QUEUED (besides the
    one kept) and counts the rest as coalesced (before: it grew without bound, one entry
    per step back)."""
    pytest.importorskip("cyclonedds")
    from tfbus.transports._newest import NEWEST_MAX_QUEUED

    n = 3 * NEWEST_MAX_QUEUED
    offered, held, coalesced = _offer_all([10**9 * (5 + i % 2 * 5) for i in range(n)], [False])
    assert NEWEST_MAX_QUEUED <= len(held) <= NEWEST_MAX_QUEUED + 1  # the queue, the one kept
    assert coalesced == n - len(held)
    assert all(a is b for a, b in zip(held, offered[-len(held):], strict=True))
