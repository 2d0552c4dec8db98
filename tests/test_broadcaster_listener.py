"""Tests for tfbus/broadcaster.py and tfbus/listener.py (with the real BufferCore)."""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable

import anyio
import pytest
from event_loops import anyio_backend_with_uvloop  # noqa: F401  (the fixture)

from tfbus import MemoryTransport
from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import TF_STATIC_TOPIC, TF_TOPIC, Bus
from tfbus.clock import Clock, ManualClock, every
from tfbus.core import BatchResult, BufferCore
from tfbus.errors import ExtrapolationException, InvalidArgumentException, LookupException
from tfbus.listener import ListenerStatistics, TransformListener
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Duration, Time

pytestmark = pytest.mark.anyio


T0 = Time(1_248_138_528)
IDENTITY = Quaternion()


def ts(
    child: str,
    x: float = 0.1,
    parent: str = "base_link",
    stamp: Time = T0,
    rotation: Quaternion = IDENTITY,
) -> TransformStamped:
    return TransformStamped(Header(stamp, parent), child, Transform(Vector3(x, 0.0, 0.2), rotation))


async def settle(clock: ManualClock) -> None:
    """Let every task run until blocked (advance(0) does exactly that, on both backends)."""
    await clock.advance(0)


async def test_broadcaster_publishes_one_tfmessage_per_call() -> None:
    async with Bus() as bus:
        sub = bus.subscribe(TF_TOPIC)
        br = TransformBroadcaster(bus)
        assert br.bus is bus
        await br.send_transform(ts("laser"))
        br.send_transform_nowait([ts("a"), ts("b")])
        br.send_transform_nowait(t for t in [ts("c")])  # any iterable
        br.send_transform_nowait([])  # nothing
        await br.send_transform(())
        msgs = [sub.receive_nowait() for _ in range(3)]
        assert all(isinstance(m, TFMessage) for m in msgs)
        assert [[t.child_frame_id for t in m.transforms] for m in msgs] == [
            ["laser"],
            ["a", "b"],
            ["c"],
        ]
        with pytest.raises(anyio.WouldBlock):
            sub.receive_nowait()
        assert br.sent == 4
        with pytest.raises(TypeError):
            br.send_transform_nowait([ts("a"), "not a transform"])  # type: ignore[list-item]
        with pytest.raises(TypeError):
            await br.send_transform(42)  # type: ignore[arg-type]
        assert bus.statistics()[TF_TOPIC].published == 3


async def test_static_broadcaster_is_latched() -> None:
    async with Bus() as bus:
        sbr = StaticTransformBroadcaster(bus)
        await sbr.send_transform(ts("laser", 1.0))
        sbr.send_transform_nowait([ts("laser", 2.0), ts("camera")])
        assert TF_TOPIC not in bus.statistics()
        late = bus.subscribe(TF_STATIC_TOPIC)
        msg = late.receive_nowait()
        assert {t.child_frame_id: t.transform.translation.x for t in msg.transforms} == {
            "laser": 2.0,
            "camera": 0.1,
        }


async def test_listener_feeds_buffer() -> None:
    clock = ManualClock(T0)
    core = BufferCore()
    async with Bus() as bus, TransformListener(core, bus, clock=clock) as listener:
        await TransformBroadcaster(bus).send_transform(ts("base_laser"))
        await StaticTransformBroadcaster(bus).send_transform(ts("base_link", parent="odom"))
        await settle(clock)
        out = core.lookup_transform("base_link", "base_laser", Time(0))
        assert out.transform.translation == Vector3(0.1, 0.0, 0.2)
        assert core.can_transform("odom", "base_link", T0 + Duration(100))  # static
        assert listener.statistics() == ListenerStatistics(
            messages=2, stored=2, refused=0, invalid=0, malformed=0, dropped=0
        )
        assert listener.buffer is core
        assert "default_authority" in core.all_frames_as_yaml()


async def test_latched_statics_are_stored_before_aenter_returns() -> None:
    core = BufferCore()
    async with Bus() as bus:
        StaticTransformBroadcaster(bus).send_transform_nowait([ts("base_laser"), ts("camera", 0.5)])
        async with TransformListener(core, bus, authority="me") as listener:
            # no checkpoint needed: the latched message was handled inside __aenter__
            assert core.can_transform("base_link", "camera", Time(0))
            assert core.can_transform("base_link", "base_laser", Time(0))
            assert listener.statistics().stored == 2
        assert "me" in core.all_frames_as_yaml()


async def test_listener_stores_valid_transforms_beside_invalid_ones(
    caplog: pytest.LogCaptureFixture,
) -> None:
    clock = ManualClock(T0)
    core = BufferCore()
    caplog.set_level(logging.WARNING, logger="tfbus.listener")
    async with Bus() as bus, TransformListener(core, bus, clock=clock) as listener:
        bad = [
            ts("nan_frame", math.nan),
            ts("bad_quat", rotation=Quaternion(0.0, 0.0, 0.0, 2.0)),
            ts("base_link"),  # self transform
        ]
        # Published as a peer that does not check would (a broadcaster refuses them).
        await bus.publish(TF_TOPIC, TFMessage([ts("a"), bad[0], ts("b"), bad[1], bad[2], ts("c")]))
        await settle(clock)
        for child in ("a", "b", "c"):
            assert core.can_transform("base_link", child, T0)
        for child in ("nan_frame", "bad_quat"):
            with pytest.raises((LookupException, ExtrapolationException)):
                core.lookup_transform("base_link", child, T0)
        stats = listener.statistics()
        assert stats.stored == 3
        assert stats.invalid == 3
        # rate-limited: one warning for the burst of invalid transforms
        warnings = [r for r in caplog.records if r.name == "tfbus.listener"]
        assert len(warnings) == 1
        assert "nan_frame" in warnings[0].getMessage()

        # after the log period, the next one is logged and mentions the suppressed ones
        await clock.advance(10.0)
        await bus.publish(TF_TOPIC, TFMessage([ts("nan2", math.inf)]))
        await settle(clock)
        warnings = [r for r in caplog.records if r.name == "tfbus.listener"]
        assert len(warnings) == 2
        assert "2 more like this suppressed" in warnings[1].getMessage()
        assert listener.statistics().invalid == 4


async def test_listener_counts_refused_old_and_repeated_data() -> None:
    clock = ManualClock(T0)
    core = BufferCore(cache_time=10.0)
    async with Bus() as bus, TransformListener(core, bus, clock=clock) as listener:
        br = TransformBroadcaster(bus)
        br.send_transform_nowait(ts("laser", stamp=T0 + Duration(20)))
        br.send_transform_nowait(
            [
                ts("laser", stamp=T0 + Duration(20)),  # repeated stamp
                ts("laser", stamp=T0),  # older than cache_time: TF_OLD_DATA
                ts("laser", stamp=T0 + Duration(21)),  # fine
            ]
        )
        await settle(clock)
        stats = listener.statistics()
        assert (stats.stored, stats.refused, stats.invalid) == (2, 2, 0)


async def test_listener_survives_junk_on_the_topics(caplog: pytest.LogCaptureFixture) -> None:
    clock = ManualClock(T0)
    core = BufferCore()
    caplog.set_level(logging.WARNING, logger="tfbus.listener")
    async with Bus() as bus, TransformListener(core, bus, clock=clock) as listener:
        bus.deliver_nowait(TF_TOPIC, "not a TFMessage")  # e.g. a confused transport
        bus.deliver_nowait(TF_STATIC_TOPIC, {"transforms": []})
        bus.deliver_nowait(TF_TOPIC, TFMessage(42))  # type: ignore[arg-type]
        bus.deliver_nowait(TF_TOPIC, TFMessage(("junk", ts("ok"))))  # type: ignore[arg-type]
        broken = TransformStamped(Header(T0, "base_link"), "weird", "no transform")  # type: ignore[arg-type]
        bus.deliver_nowait(TF_TOPIC, TFMessage((broken,)))
        await settle(clock)
        TransformBroadcaster(bus).send_transform_nowait(ts("later", stamp=T0 + Duration(1)))
        await settle(clock)
        assert core.can_transform("base_link", "ok", T0)
        assert core.can_transform("base_link", "later", T0 + Duration(1))
        stats = listener.statistics()
        # "junk" and four non-TFMessages are malformed; a TransformStamped whose transform
        # field has the wrong type is an invalid transform.
        assert stats.malformed == 4
        assert stats.invalid == 1
        assert stats.stored == 2
        assert stats.messages == 6


class _ExplodingBuffer:
    """A sink of the listener's protocol (set_transforms + clear) with a bug: a batch
    holding "boom" raises instead of reporting."""

    def __init__(self) -> None:
        self.stored: list[str] = []
        self.cleared = 0

    def set_transforms(
        self, transforms: Iterable[TransformStamped], authority: str, is_static: bool
    ) -> BatchResult:
        batch = list(transforms)
        if any(t.child_frame_id == "boom" for t in batch):
            raise RuntimeError("buffer bug")
        self.stored.extend(t.child_frame_id for t in batch)
        return BatchResult(len(batch), 0, [])

    def clear(self) -> None:
        self.cleared += 1


async def test_listener_accepts_any_sink_and_survives_its_errors() -> None:
    clock = ManualClock(T0)
    buf = _ExplodingBuffer()
    async with Bus() as bus, TransformListener(buf, bus, clock=clock) as listener:
        br = TransformBroadcaster(bus)
        br.send_transform_nowait([ts("a")])
        br.send_transform_nowait([ts("boom"), ts("x")])
        br.send_transform_nowait([ts("b")])
        await settle(clock)
    assert buf.stored == ["a", "b"]
    assert listener.statistics().malformed == 1
    assert buf.cleared == 0


async def test_listener_exit_and_cancellation_leave_no_subscription_behind() -> None:
    core = BufferCore()
    async with Bus() as bus:
        async with TransformListener(core, bus):
            stats = bus.statistics()
            assert stats[TF_TOPIC].subscribers == 1
            assert stats[TF_STATIC_TOPIC].subscribers == 1
        stats = bus.statistics()
        assert stats[TF_TOPIC].subscribers == 0
        assert stats[TF_STATIC_TOPIC].subscribers == 0

        async def listen_forever() -> None:
            async with TransformListener(core, bus):
                await anyio.sleep_forever()

        async with anyio.create_task_group() as tg:
            for _ in range(20):
                tg.start_soon(listen_forever)
            await anyio.wait_all_tasks_blocked()
            assert bus.statistics()[TF_TOPIC].subscribers == 20
            tg.cancel_scope.cancel()
        stats = bus.statistics()
        assert stats[TF_TOPIC].subscribers == 0
        assert stats[TF_STATIC_TOPIC].subscribers == 0

        listener = TransformListener(core, bus)
        async with listener:
            pass
        with pytest.raises(RuntimeError):
            await listener.__aenter__()


async def test_listener_ends_quietly_when_the_bus_closes_first() -> None:
    core = BufferCore()
    bus_open = anyio.Event()
    close_bus = anyio.Event()
    bus_closed = anyio.Event()
    bus = Bus()

    async def run_bus() -> None:
        async with bus:
            bus_open.set()
            await close_bus.wait()
        bus_closed.set()

    async with anyio.create_task_group() as tg:
        tg.start_soon(run_bus)
        await bus_open.wait()
        async with TransformListener(core, bus) as listener:
            TransformBroadcaster(bus).send_transform_nowait(ts("laser"))
            close_bus.set()
            await bus_closed.wait()
            await anyio.wait_all_tasks_blocked()
    assert core.can_transform("base_link", "laser", T0)
    assert listener.statistics().stored == 1


async def test_slow_listener_drops_oldest_but_broadcaster_keeps_100hz() -> None:
    clock = ManualClock(T0)
    sent = 0

    class SlowCore(BufferCore):
        pass

    core = SlowCore()

    async def broadcaster(bus: Bus) -> None:
        nonlocal sent
        br = TransformBroadcaster(bus)
        async for tick in every(0.01, clock=clock):
            await br.send_transform(ts("base_laser", stamp=tick.expected))
            sent += 1

    async with Bus() as bus, TransformListener(core, bus, clock=clock, queue_size=5) as listener:
        async with anyio.create_task_group() as tg:
            tg.start_soon(broadcaster, bus)
            # Hog: a subscriber that never reads must not slow anyone down either.
            hog = bus.subscribe(TF_TOPIC, queue_size=1)
            await clock.advance(1.0)
            tg.cancel_scope.cancel()
        assert sent == 100
        assert listener.statistics().stored == 100  # the listener keeps up
        assert hog.statistics().dropped == 99
        latest = core.lookup_transform("base_link", "base_laser", Time(0))
        assert latest.header.stamp == T0 + Duration(1)


async def test_end_to_end_across_a_memory_transport() -> None:
    clock = ManualClock(T0)
    a_end, b_end = MemoryTransport.pair()
    core = BufferCore()
    async with (
        Bus(transport=a_end) as a,
        Bus(transport=b_end) as b,
        TransformListener(core, b, clock=clock),
    ):
        await StaticTransformBroadcaster(a).send_transform(ts("camera", parent="base_laser"))
        await TransformBroadcaster(a).send_transform(ts("base_laser"))
        await settle(clock)
        out = core.lookup_transform("base_link", "camera", Time(0))
        assert out.transform.translation.x == pytest.approx(0.2)


class _ProtocolOnlyClock:
    """A Clock with nothing beyond the protocol, over a ManualClock (a third-party Clock)."""

    def __init__(self, inner: ManualClock) -> None:
        self.inner = inner
        self.now = inner.now
        self.now_ns = inner.now_ns
        self.sleep_until = inner.sleep_until
        self.sleep = inner.sleep
        self.on_jump = inner.on_jump
        self.move_on_after = inner.move_on_after
        self.fail_after = inner.fail_after
        self.call_later = inner.call_later


@pytest.mark.parametrize("protocol_only", [False, True])
async def test_listener_clears_the_buffer_when_its_clock_jumps_back(
    caplog: pytest.LogCaptureFixture, protocol_only: bool
) -> None:
    """The listener reads the clock on each message, as tf2_ros's
    TransformListener does, so a clock stepped back clears the buffer (here a BufferCore,
    which has no clock of its own: only the listener can notice). The listener reads the
    Clock protocol's ``now_ns()`` (no Time built), of a tfbus clock or any other."""
    clock = ManualClock(T0)
    listened: Clock = _ProtocolOnlyClock(clock) if protocol_only else clock
    assert isinstance(listened, Clock)
    core = BufferCore()
    caplog.set_level(logging.WARNING, logger="tfbus.listener")
    async with Bus() as bus, TransformListener(core, bus, clock=listened):
        br = TransformBroadcaster(bus)
        StaticTransformBroadcaster(bus).send_transform_nowait([ts("fixed")])
        br.send_transform_nowait([ts("laser")])
        await settle(clock)
        assert core.can_transform("base_link", "laser", T0)
        clock.set_nowait(Time(T0.sec - 3600))  # the wall clock is stepped back 1 h
        br.send_transform_nowait([ts("other", stamp=Time(T0.sec - 3600))])
        await settle(clock)
        assert not core.can_transform("base_link", "laser", T0)  # cleared
        assert core.can_transform("base_link", "fixed", T0)  # statics stay (tf2 clear)
        assert core.can_transform("base_link", "other", Time(T0.sec - 3600))
    assert any("jump back in time" in r.getMessage() for r in caplog.records)


async def test_listener_on_a_buffer_reads_the_buffers_clock() -> None:
    """With ``Buffer()`` + ``TransformListener`` (the README set-up) the
    listener reads the buffer's own clock on each message; a jump back seen there clears
    the buffer once (the Buffer's own jump handler)."""
    clock = ManualClock(T0)
    buf = Buffer(clock=clock)
    async with Bus() as bus, TransformListener(buf, bus):
        br = TransformBroadcaster(bus)
        br.send_transform_nowait([ts("laser")])
        await settle(clock)
        assert buf.can_transform("base_link", "laser", T0)
        clock.set_nowait(Time(T0.sec - 3600))
        br.send_transform_nowait([ts("other", stamp=Time(T0.sec - 3600))])
        await settle(clock)
        assert not buf.can_transform("base_link", "laser", T0)
    buf.close()


async def test_a_jump_back_clears_a_sink_once_whoever_follows_the_clock(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The rule "clear on a jump back" has one owner (``clear_on_jump_back``): two
    listeners feeding one BufferCore, and a Buffer with its own listener, on one clock,
    clear each sink once per jump (one warning line), and stop following on exit."""
    from tfbus.buffer import clear_on_jump_back

    clock = ManualClock(T0)
    core = BufferCore()
    buf = Buffer(clock=clock)
    caplog.set_level(logging.WARNING)
    async with Bus() as bus:
        async with (
            TransformListener(core, bus, clock=clock),
            TransformListener(core, bus, clock=clock),
            TransformListener(buf, bus),
        ):
            TransformBroadcaster(bus).send_transform_nowait([ts("laser")])
            await settle(clock)
            assert core.can_transform("base_link", "laser", T0)
            assert buf.can_transform("base_link", "laser", T0)
            clock.set_nowait(Time(T0.sec - 60))
            jumps = [r for r in caplog.records if "jump back in time" in r.getMessage()]
            assert len(jumps) == 2  # one per sink
            assert not core.can_transform("base_link", "laser", T0)
            assert not buf.can_transform("base_link", "laser", T0)
        stop = clear_on_jump_back(core, clock)
        stop()
        stop()  # idempotent
        core.set_transform(ts("laser", stamp=Time(T0.sec - 60)), "x")
        clock.set_nowait(Time(T0.sec - 120))  # no listener follows core any more
        assert core.can_transform("base_link", "laser", Time(T0.sec - 60))
        assert not buf.can_transform("base_link", "laser", Time(T0.sec - 60))


@pytest.mark.parametrize(
    ("bad", "codes"),
    [
        (ts("nan_frame", math.nan), ("TF_NAN_INPUT",)),
        (ts("inf_frame", math.inf), ("TF_INF_INPUT",)),
        (ts("q", rotation=Quaternion(0.0, 0.0, 0.0, 2.0)), ("TF_DENORMALIZED_QUATERNION",)),
        (ts("base_link"), ("TF_SELF_TRANSFORM",)),
        (ts(""), ("TF_NO_CHILD_FRAME_ID",)),
    ],
)
@pytest.mark.parametrize("static", [False, True])
async def test_the_broadcaster_refuses_what_set_transform_refuses(
    bad: TransformStamped, codes: tuple[str, ...], static: bool
) -> None:
    """The sender raises the InvalidArgumentException BufferCore.set_transform raises (same
    codes, same wording), publishes nothing of the call, and the next valid send works."""
    with pytest.raises(InvalidArgumentException) as expected:
        BufferCore().set_transform(bad)
    async with Bus() as bus:
        sub = bus.subscribe(TF_STATIC_TOPIC if static else TF_TOPIC)
        br = (StaticTransformBroadcaster if static else TransformBroadcaster)(bus)
        with pytest.raises(InvalidArgumentException) as info:
            await br.send_transform([ts("a"), bad])
        with pytest.raises(InvalidArgumentException):
            br.send_transform_nowait(bad)
        assert info.value.codes == codes == expected.value.codes
        assert str(info.value).split(": ", 1)[1] == str(expected.value).split(": ", 1)[1]
        assert br.sent == 0
        assert sub.statistics().queued == 0
        await br.send_transform(ts("a", 1.5))
        assert (await sub.receive()).transforms[0].transform.translation.x == 1.5


async def test_the_broadcaster_sends_what_set_transform_accepts() -> None:
    """ints, a quaternion within tf2's 0.01 of unit norm, numpy-built transforms pass."""
    from tfbus.geometry import quaternion_from_euler

    async with Bus() as bus:
        core = BufferCore()
        async with TransformListener(core, bus):
            br = TransformBroadcaster(bus)
            await br.send_transform(
                [
                    ts("ints")._replace(
                        transform=Transform(Vector3(1, 2, 3), Quaternion(0, 0, 0, 1))
                    ),
                    ts("near", rotation=Quaternion(0.0, 0.0, 0.0, 1.004)),
                    ts("np", 2.0)._replace(
                        transform=Transform([2.0, 0.0, 0.0], quaternion_from_euler(0.0, 0.0, 1.0))
                    ),
                ]
            )
            assert br.sent == 3
            got = core.lookup_transform("base_link", "np", Time(0))
            assert got.transform.rotation.z == pytest.approx(math.sin(0.5), abs=1e-12)
            assert core.lookup_transform("base_link", "ints", Time(0)).transform.translation.z == 3
