"""SimClock: simulated time from /clock on a bus (ROS use_sim_time), in process.

The tests publish ``rosgraph_msgs/Clock`` messages themselves: nothing waits on wall time
except the ``wall_timeout`` guard's own tests, which need wall time to pass.
"""

from __future__ import annotations

import hashlib
import logging

import anyio
import pytest

from tfbus import Buffer, Bus, SimClock, TransformListener
from tfbus._aio import wait_all_tasks_blocked
from tfbus.clock import Clock, SimClockStatistics, every
from tfbus.codecs import native, ros1
from tfbus.errors import SimTimeStalled, TimeoutException, WireDecodeError, WireEncodeError
from tfbus.messages import (
    Clock as ClockMessage,
)
from tfbus.messages import (
    Header,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import Time
from tfbus.topics import CLOCK_TOPIC

pytestmark = pytest.mark.anyio


def tick(bus: Bus, sec: float) -> None:
    bus.publish_nowait(CLOCK_TOPIC, ClockMessage(Time.from_sec(sec)))


def tf(child: str, sec: float, x: float) -> TFMessage:
    return TFMessage(
        (TransformStamped(Header(Time.from_sec(sec), "map"), child, Transform(Vector3(x, 0, 0))),)
    )


async def test_time_is_zero_until_the_first_clock_then_follows_it() -> None:
    async with Bus() as bus, SimClock(bus) as clock:
        assert isinstance(clock, Clock)
        assert clock.now() == Time(0) and clock.now_ns() == 0
        tick(bus, 120.25)
        assert clock.now() == Time.from_sec(120.25)
        tick(bus, 121)
        assert clock.now_ns() == 121_000_000_000
        assert (clock.received, clock.accepted, clock.dropped, clock.jumps) == (2, 2, 0, 0)
    tick_after = Time.from_sec(121)
    assert clock.now() == tick_after  # left: keeps the last time read


async def test_clock_made_before_its_bus_drives_a_buffer_once_attached() -> None:
    clock = SimClock()
    buffer = Buffer(clock=clock)  # built before the bus exists, as a CLI's source is
    with pytest.raises(RuntimeError, match="no bus"):
        await clock.__aenter__()
    async with Bus() as bus, clock.attach(bus), TransformListener(buffer, bus):
        assert clock.now() == Time(0)
        bus.publish_nowait("/tf", tf("base", 120.0, 1.5))
        tick(bus, 120.0)
        assert clock.now() == Time(120)
        t = await buffer.lookup_transform_async("map", "base", clock.now(), timeout=1.0)
        assert t.transform.translation.x == 1.5
        with pytest.raises(RuntimeError, match="already follows a bus"):
            SimClock(bus).attach(bus)
        with pytest.raises(RuntimeError, match="entered"):
            clock.attach(bus)


async def test_sleep_advances_only_with_clock_and_a_pause_pauses_it() -> None:
    woke: list[Time] = []
    async with Bus() as bus, SimClock(bus) as clock, anyio.create_task_group() as tg:

        async def sleeper() -> None:
            await clock.sleep(2.0)  # from t = 0: until /clock reaches 2 s
            woke.append(clock.now())

        tg.start_soon(sleeper)
        await wait_all_tasks_blocked()
        for sec in (0.5, 1.0, 1.0, 1.0, 1.999999999):  # a paused simulation repeats 1.0
            tick(bus, sec)
            await wait_all_tasks_blocked()
            assert woke == []
        tick(bus, 2.5)  # the message that passes the deadline wakes it
        await wait_all_tasks_blocked()
        assert woke == [Time.from_sec(2.5)]


async def test_sleep_until_deadlines_call_later_and_every_run_on_sim_time() -> None:
    events: list[tuple[str, float]] = []
    async with Bus() as bus, SimClock(bus) as clock, anyio.create_task_group() as tg:
        tick(bus, 10.0)

        async def until() -> None:
            await clock.sleep_until(Time(12))
            events.append(("until", clock.now().to_sec()))

        async def scoped() -> None:
            with clock.move_on_after(1.5) as scope:
                await anyio.sleep_forever()
            events.append(("move_on_after", clock.now().to_sec()))
            assert scope.cancelled_caught
            with pytest.raises(TimeoutError), clock.fail_after(1.0):
                await anyio.sleep_forever()
            events.append(("fail_after", clock.now().to_sec()))

        async def timer() -> None:
            async for t in every(1.0, clock=clock):
                events.append(("every", t.expected.to_sec()))
                if len([e for e in events if e[0] == "every"]) == 3:
                    return

        tg.start_soon(until)
        tg.start_soon(scoped)
        tg.start_soon(timer)
        await wait_all_tasks_blocked()
        clock.call_later(0.75, lambda: events.append(("call_later", clock.now().to_sec())))
        # Deadlines due at one /clock wake in the same delivery (in no fixed order on
        # trio, which shuffles a batch): compare what each message woke.
        woken: dict[float, list[tuple[str, float]]] = {}
        for sec in (10.5, 11.0, 11.5, 12.0, 12.5, 13.0, 13.5):
            before = len(events)
            tick(bus, sec)
            await wait_all_tasks_blocked()
            woken[sec] = sorted(events[before:])
        assert woken == {
            10.5: [],
            11.0: [("call_later", 11.0), ("every", 11.0)],
            11.5: [("move_on_after", 11.5)],
            12.0: [("every", 12.0), ("until", 12.0)],
            12.5: [("fail_after", 12.5)],
            13.0: [("every", 13.0)],
            13.5: [],
        }


async def test_jump_back_calls_callbacks_and_clears_a_listeners_buffer(
    caplog: pytest.LogCaptureFixture,
) -> None:
    jumps: list[tuple[Time, Time]] = []
    async with Bus() as bus, SimClock(bus) as clock:
        buffer = Buffer(clock=clock)
        async with TransformListener(buffer, bus):
            clock.on_jump(lambda old, new: jumps.append((old, new)))
            tick(bus, 100.0)
            bus.publish_nowait("/tf", tf("base", 100.0, 1.0))
            found = buffer.lookup_transform("map", "base", Time.from_sec(100.0))
            assert found.transform.translation.x == 1.0
            with caplog.at_level(logging.WARNING):
                tick(bus, 5.0)  # a looping bag starts again
            assert jumps == [(Time.from_sec(100.0), Time.from_sec(5.0))]
            assert clock.jumps == 1 and clock.now() == Time.from_sec(5.0)
            assert not buffer.can_transform("map", "base", Time(0))  # cleared, as tf2_ros
            assert "Clearing TF buffer" in caplog.text
            assert "jumped back from 100.000000000 s to 5.000000000 s" in caplog.text
            bus.publish_nowait("/tf", tf("base", 5.0, 2.0))  # filled again
            found = buffer.lookup_transform("map", "base", Time.from_sec(5.0))
            assert found.transform.translation.x == 2.0
            # two publishers interleaving: one jump per backward step
            for sec in (6.0, 5.5, 6.5, 6.0):
                tick(bus, sec)
            assert clock.jumps == 3 and clock.now() == Time.from_sec(6.0)


async def test_two_clock_publishers_are_counted_and_logged_a_looping_bag_is_not(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with Bus() as bus, SimClock(bus) as clock:
        with caplog.at_level(logging.WARNING, logger="tfbus.clock"):
            # a bag of 100..102 s played in a loop (rosbag play -l): jumps back, runs on
            for _ in range(3):
                for k in range(21):
                    tick(bus, 100.0 + k * 0.1)
            assert clock.statistics() == SimClockStatistics(
                received=63, accepted=63, dropped=0, jumps=2, interleaved=0
            )
            assert not any("several publishers" in r.getMessage() for r in caplog.records)
            # a simulator at 200 s (100 Hz) beside the looping bag at 100 s (10 Hz):
            # each bag message jumps back, the simulator's next one leaps forward again
            for k in range(40):
                tick(bus, 200.0 + k * 0.01)
                if k % 10 == 9:
                    tick(bus, 100.0 + k * 0.01)
            # a simulator at 50 s (100 Hz) beside a bag at 300 s (10 Hz): each simulator
            # message after a bag's jumps back, the bag's next one leaps forward
            for k in range(40):
                tick(bus, 50.0 + k * 0.01)
                if k % 10 == 9:
                    tick(bus, 300.0 + k * 0.01)
        stats = clock.statistics()
        # jumps back: 2 loops, 4 bag messages at 100 s, the simulator's first at 50 s and
        # its 3 after a bag message at 300 s; each bag message at 300 s undoes a jump,
        # and so does the simulator's next one after a bag message at 100 s (3)
        assert (stats.received, stats.accepted, stats.jumps) == (151, 151, 10)
        assert stats.interleaved == 7 and clock.now() == Time.from_sec(300.39)
        lines = [r.getMessage() for r in caplog.records if "several publishers" in r.getMessage()]
        assert lines == [
            "several publishers on /clock? simulated time jumped back from 200.090000000 s "
            "and returned to 200.100000000 s in one step from 100.090000000 s"
        ]
        with pytest.raises(AttributeError):
            stats.jumps = 0  # type: ignore[misc]


async def test_bad_clock_messages_are_counted_dropped_and_logged_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with Bus() as bus, SimClock(bus, max_forward_step=1e6) as clock:
        tick(bus, 50.0)
        with caplog.at_level(logging.WARNING, logger="tfbus.clock"):
            for _ in range(5):
                bus.publish_nowait(CLOCK_TOPIC, ClockMessage(-1))  # type: ignore[arg-type]
                bus.publish_nowait(CLOCK_TOPIC, ClockMessage(51.0))  # type: ignore[arg-type]
                bus.publish_nowait(CLOCK_TOPIC, {"clock": 52})
                bus.publish_nowait(CLOCK_TOPIC, ClockMessage(Time.from_sec(50.0 + 2e6)))
            tick(bus, 51.0)  # the valid one beside them is kept
        assert clock.now() == Time.from_sec(51.0)
        assert (clock.received, clock.accepted, clock.dropped, clock.jumps) == (22, 2, 20, 0)
        lines = [r.getMessage() for r in caplog.records if r.name == "tfbus.clock"]
        assert len(lines) == 2, lines  # one per kind: malformed, too far ahead
        assert "expected a rosgraph_msgs/Clock of a Time" in lines[0]
        assert "more than 1e+06 s ahead of the simulated time 50.000000000 s" in lines[1]


async def test_first_clock_is_accepted_at_any_time() -> None:
    async with Bus() as bus, SimClock(bus, max_forward_step=10.0) as clock:
        tick(bus, 1.7e9)  # a bag recorded on wall time
        tick(bus, 1.7e9 + 11)  # then more than 10 s ahead in one step: dropped
        assert clock.now() == Time.from_sec(1.7e9) and clock.dropped == 1


async def test_lookup_timeout_runs_on_sim_time() -> None:
    async with Bus() as bus, SimClock(bus) as clock:
        buffer = Buffer(clock=clock)
        async with TransformListener(buffer, bus), anyio.create_task_group() as tg:
            tick(bus, 20.0)
            outcome: list[object] = []

            async def lookup(child: str) -> None:
                try:
                    t = await buffer.lookup_transform_async("map", child, Time(21), timeout=2.0)
                    outcome.append((child, t.transform.translation.x, clock.now().to_sec()))
                except TimeoutException:
                    outcome.append((child, "timeout", clock.now().to_sec()))

            tg.start_soon(lookup, "arm")
            tg.start_soon(lookup, "leg")
            await wait_all_tasks_blocked()
            tick(bus, 21.0)
            await wait_all_tasks_blocked()
            assert outcome == []  # no data yet, 1 s of the 2 s timeout passed
            bus.publish_nowait("/tf", tf("arm", 21.0, 3.0))
            await wait_all_tasks_blocked()
            assert outcome == [("arm", 3.0, 21.0)]
            tick(bus, 21.999)
            await wait_all_tasks_blocked()
            assert len(outcome) == 1
            tick(bus, 22.0)
            await wait_all_tasks_blocked()
            assert outcome[1] == ("leg", "timeout", 22.0)


async def test_wall_timeout_raises_sim_time_stalled_when_clock_stops() -> None:
    async with Bus() as bus, SimClock(bus, wall_timeout=0.3) as clock:
        tick(bus, 1.0)
        with anyio.fail_after(30):  # the guard, not this bound, must end each wait
            with pytest.raises(SimTimeStalled) as info:
                await clock.sleep(1.0)
            assert isinstance(info.value, TimeoutError)
            assert "no /clock message for 0.3 s of wall time" in str(info.value)
            with pytest.raises(SimTimeStalled), clock.move_on_after(5.0):
                await anyio.sleep_forever()
            buffer = Buffer(clock=clock)
            with pytest.raises(SimTimeStalled):
                await buffer.lookup_transform_async("map", "base", Time(2), timeout=1.0)
        assert clock.now() == Time.from_sec(1.0)


async def test_wall_timeout_is_renewed_by_each_clock_message() -> None:
    # /clock every 0.05 s of wall time for 1.5 s (paused at 1.0 s of sim time: alive):
    # a 1 s wall bound must not fire; the sim-time deadline ends the wait.
    async with Bus() as bus, SimClock(bus, wall_timeout=1.0) as clock:
        tick(bus, 1.0)
        done: list[float] = []
        with anyio.fail_after(30):
            async with anyio.create_task_group() as tg:

                async def sleeper() -> None:
                    await clock.sleep(5.0)
                    done.append(clock.now().to_sec())

                tg.start_soon(sleeper)
                for _ in range(30):
                    await anyio.sleep(0.05)  # the publisher's pace, wall time
                    tick(bus, 1.0)
                tick(bus, 6.0)
        assert done == [6.0]


async def test_body_exception_leaves_as_itself() -> None:
    async with Bus() as bus:
        with pytest.raises(KeyError):
            async with SimClock(bus):
                raise KeyError("body")


def test_bad_arguments_name_the_field() -> None:
    bus = Bus()
    with pytest.raises(ValueError, match="wall_timeout"):
        SimClock(bus, wall_timeout=0)
    with pytest.raises(TypeError, match="wall_timeout"):
        SimClock(bus, wall_timeout="1")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="max_forward_step"):
        SimClock(bus, max_forward_step=float("nan"))


def test_clock_codecs_native_and_ros1() -> None:
    codec = native.WireCodec()
    msg = ClockMessage(Time(123, 456))
    assert codec.decode(codec.encode(msg, sender=1, seq=1)).message == msg
    assert hashlib.md5(b"time clock").hexdigest() == ros1.CLOCK_MD5SUM
    assert ros1.CLOCK_TYPE == "rosgraph_msgs/Clock"
    raw = ros1.encode_clock(msg)
    assert raw == bytes([123, 0, 0, 0, 0xC8, 0x01, 0, 0])
    assert ros1.decode_clock(raw) == msg
    for bad in (raw[:7], raw + b"\0", (5).to_bytes(4, "little") + (10**9).to_bytes(4, "little")):
        with pytest.raises(WireDecodeError):
            ros1.decode_clock(bad)
    with pytest.raises(WireEncodeError):
        ros1.encode_clock(ClockMessage(Time(2**32)))
