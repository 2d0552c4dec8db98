"""Tests for tfbus/bus.py (Bus, Subscription, latching, statistics), tfbus/latch.py and
tfbus/transports/memory.py (MemoryTransport)."""

from __future__ import annotations

from typing import Any

import anyio
import anyio.abc
import anyio.lowlevel
import pytest
from event_loops import anyio_backend_with_uvloop  # noqa: F401  (the fixture)

from tfbus.bus import (
    TF_STATIC_TOPIC,
    TF_TOPIC,
    Bus,
    Subscription,
    SubscriptionStatistics,
    TopicStatistics,
    Transport,
)
from tfbus.clock import ManualClock, every
from tfbus.messages import Header, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Time
from tfbus.transports.memory import MemoryTransport

pytestmark = pytest.mark.anyio


def ts(child: str, x: float = 0.0, parent: str = "base_link", sec: int = 1) -> TransformStamped:
    return TransformStamped(
        Header(Time(sec), parent), child, Transform(translation=Vector3(x, 0.0, 0.0))
    )


async def test_publish_and_receive() -> None:
    async with Bus() as bus:
        with bus.subscribe("/chat") as sub:
            with pytest.raises(anyio.WouldBlock):
                sub.receive_nowait()
            await bus.publish("/chat", "hello")
            bus.publish_nowait("/chat", {"any": "object"})
            bus.publish_nowait("/other", "not for us")
            assert await sub.receive() == "hello"
            assert sub.receive_nowait() == {"any": "object"}
            assert sub.topic == "/chat"
            assert sub.queue_size == 100


async def test_receive_waits_for_publish() -> None:
    async with Bus() as bus, bus.subscribe("/chat") as sub, anyio.create_task_group() as tg:
        got: list[Any] = []

        async def consumer() -> None:
            got.append(await sub.receive())

        tg.start_soon(consumer)
        await anyio.wait_all_tasks_blocked()  # trio: instant; asyncio: fine here
        assert sub.statistics().tasks_waiting_receive == 1
        bus.publish_nowait("/chat", 42)
    assert got == [42]


async def test_drop_oldest_and_counters() -> None:
    async with Bus(queue_size=10) as bus:
        small = bus.subscribe("/n", queue_size=3)
        big = bus.subscribe("/n")
        for i in range(5):
            bus.publish_nowait("/n", i)
        assert [small.receive_nowait() for _ in range(3)] == [2, 3, 4]  # oldest dropped
        assert small.statistics() == SubscriptionStatistics(
            topic="/n",
            queue_size=3,
            queued=0,
            delivered=5,
            received=3,
            dropped=2,
            tasks_waiting_receive=0,
        )
        assert big.statistics().queued == 5
        assert big.statistics().dropped == 0
        assert bus.statistics()["/n"] == TopicStatistics(
            topic="/n", published=5, remote=0, delivered=10, dropped=2, subscribers=2
        )
        big.close()
        assert bus.statistics()["/n"].subscribers == 1


async def test_queue_size_validation() -> None:
    with pytest.raises(ValueError):
        Bus(queue_size=0)
    async with Bus() as bus:
        with pytest.raises(ValueError):
            bus.subscribe("/x", queue_size=0)


async def test_slow_subscriber_drops_but_publisher_keeps_100hz() -> None:
    clock = ManualClock(Time(1000))
    ticks = 0
    overruns = -1
    slow_got: list[int] = []
    fast_got: list[int] = []

    async def publisher(bus: Bus) -> None:
        nonlocal ticks, overruns
        async for tick in every(0.01, clock=clock):
            await bus.publish(TF_TOPIC, TFMessage((ts("laser", sec=tick.index + 1),)))
            ticks += 1
            overruns = tick.overruns

    async def slow(sub: Subscription[TFMessage]) -> None:
        async for msg in sub:
            slow_got.append(msg.transforms[0].header.stamp.sec)
            await clock.sleep(0.1)  # 10x slower than the publisher

    async def fast(sub: Subscription[TFMessage]) -> None:
        async for msg in sub:
            fast_got.append(msg.transforms[0].header.stamp.sec)

    async with Bus() as bus:
        slow_sub = bus.subscribe(TF_TOPIC, queue_size=2)
        fast_sub = bus.subscribe(TF_TOPIC)
        async with anyio.create_task_group() as tg:
            tg.start_soon(publisher, bus)
            tg.start_soon(slow, slow_sub)
            tg.start_soon(fast, fast_sub)
            await clock.advance(1.0)
            tg.cancel_scope.cancel()
        assert ticks == 100
        assert overruns == 0
        assert fast_got == list(range(1, 101))
        assert len(slow_got) < 15
        stats = slow_sub.statistics()
        assert stats.dropped > 80
        assert stats.delivered == stats.received + stats.dropped + stats.queued == 100
        assert bus.statistics()[TF_TOPIC].published == 100
        assert bus.statistics()[TF_TOPIC].dropped == stats.dropped


async def test_tf_topics_require_tfmessage() -> None:
    async with Bus() as bus:
        with pytest.raises(TypeError):
            bus.publish_nowait(TF_TOPIC, [ts("a")])
        with pytest.raises(TypeError):
            await bus.publish(TF_STATIC_TOPIC, ts("a"))


async def test_late_subscriber_gets_latched_statics_per_child() -> None:
    async with Bus() as bus:
        early = bus.subscribe(TF_STATIC_TOPIC)
        assert bus.latched_statics() == TFMessage(())
        bus.publish_nowait(TF_STATIC_TOPIC, TFMessage((ts("laser", 1.0), ts("camera", 2.0))))
        bus.publish_nowait(TF_STATIC_TOPIC, TFMessage((ts("laser", 3.0),)))  # replaces laser
        bus.publish_nowait(TF_STATIC_TOPIC, TFMessage((ts("imu", 4.0),)))
        assert early.statistics().queued == 3  # early subscribers see every message

        late = bus.subscribe(TF_STATIC_TOPIC)
        msg = late.receive_nowait()  # at once, before any further publish
        assert isinstance(msg, TFMessage)
        by_child = {t.child_frame_id: t.transform.translation.x for t in msg.transforms}
        assert by_child == {"laser": 3.0, "camera": 2.0, "imu": 4.0}
        assert len(msg.transforms) == 3
        with pytest.raises(anyio.WouldBlock):
            late.receive_nowait()
        # /tf is not latched
        tf_sub = bus.subscribe(TF_TOPIC)
        bus.publish_nowait(TF_TOPIC, TFMessage((ts("x"),)))
        assert bus.subscribe(TF_TOPIC).statistics().queued == 0
        assert tf_sub.statistics().queued == 1
        stats = bus.statistics()[TF_STATIC_TOPIC]
        assert stats.published == 3
        assert stats.delivered == 3 + 1  # early x3, late's snapshot x1
        assert stats.subscribers == 2


async def test_statistics_lists_every_topic() -> None:
    async with Bus() as bus:
        bus.subscribe("/a")
        bus.publish_nowait("/b", 1)
        stats = bus.statistics()
        assert set(stats) == {"/a", "/b"}
        assert stats["/a"].subscribers == 1
        assert stats["/b"] == TopicStatistics("/b", 1, 0, 0, 0, 0)


async def test_cancellation_leaves_no_subscription_behind() -> None:
    async with Bus() as bus:

        async def waiter_async_with() -> None:
            async with bus.subscribe("/x") as sub:
                await sub.receive()

        async def waiter_iter() -> None:
            with bus.subscribe("/x") as sub:
                async for _ in sub:
                    pass

        async with anyio.create_task_group() as tg:
            for _ in range(100):
                tg.start_soon(waiter_async_with)
                tg.start_soon(waiter_iter)
            await anyio.wait_all_tasks_blocked()
            assert bus.statistics()["/x"].subscribers == 200
            tg.cancel_scope.cancel()
        assert bus.statistics()["/x"].subscribers == 0
        with anyio.move_on_after(0):
            async with bus.subscribe("/y") as sub:
                await sub.receive()
        assert bus.statistics()["/y"].subscribers == 0


async def test_close_wakes_receiver_and_ends_iteration() -> None:
    async with Bus() as bus:
        sub = bus.subscribe("/x")
        bus.publish_nowait("/x", 1)
        sub.close()
        sub.close()  # idempotent
        assert sub.closed
        with pytest.raises(anyio.ClosedResourceError):
            sub.receive_nowait()
        assert [m async for m in sub] == []

        sub2 = bus.subscribe("/x")
        outcome: list[str] = []

        async def receiver() -> None:
            try:
                await sub2.receive()
            except anyio.ClosedResourceError:
                outcome.append("closed")

        async with anyio.create_task_group() as tg:
            tg.start_soon(receiver)
            await anyio.wait_all_tasks_blocked()
            await sub2.aclose()
        assert outcome == ["closed"]


async def test_bus_close_ends_subscriptions_after_draining() -> None:
    got: list[int] = []
    async with Bus() as bus:
        sub = bus.subscribe("/x")
        bus.publish_nowait("/x", 1)
        bus.publish_nowait("/x", 2)
    async for m in sub:
        got.append(m)
    assert got == [1, 2]
    with pytest.raises(anyio.EndOfStream):
        sub.receive_nowait()
    with pytest.raises(anyio.ClosedResourceError):
        bus.publish_nowait("/x", 3)
    with pytest.raises(anyio.ClosedResourceError):
        bus.subscribe("/x")
    with pytest.raises(RuntimeError):
        await bus.__aenter__()


async def test_bus_must_be_open() -> None:
    bus = Bus()
    with pytest.raises(RuntimeError):
        bus.publish_nowait("/x", 1)
    with pytest.raises(RuntimeError):
        bus.subscribe("/x")
    with pytest.raises(RuntimeError):
        bus.deliver_nowait("/x", 1)


async def test_memory_transport_links_two_buses() -> None:
    a_end, b_end = MemoryTransport.pair()
    assert isinstance(a_end, Transport)
    async with Bus(transport=a_end) as a, Bus(transport=b_end) as b:
        assert a.transport is a_end
        a_sub = a.subscribe(TF_TOPIC)
        b_sub = b.subscribe(TF_TOPIC)
        msg = TFMessage((ts("laser"),))
        a.publish_nowait(TF_TOPIC, msg)
        with anyio.fail_after(5):
            assert await b_sub.receive() is msg
        assert a_sub.receive_nowait() is msg
        # delivered remote messages are not sent back out: nothing echoes to a
        a_chat = a.subscribe("/chat")
        b.publish_nowait("/chat", "from b")
        b.publish_nowait("/chat", "again")
        with anyio.fail_after(5):
            assert await a_chat.receive() == "from b"
            assert await a_chat.receive() == "again"
        await anyio.wait_all_tasks_blocked()
        assert a.statistics()[TF_TOPIC].published == 1
        assert b.statistics()[TF_TOPIC] == TopicStatistics(TF_TOPIC, 1, 1, 1, 0, 1)
        assert a_end.sent == 1 and b_end.sent == 2
        assert a_end.delivered == 2 and b_end.delivered == 1
        assert a_sub.statistics().queued == 0

        # statics delivered remotely are latched on the receiving bus
        a.publish_nowait(TF_STATIC_TOPIC, TFMessage((ts("camera", 5.0),)))
        b_static = b.subscribe("/tf_static/probe")  # any topic: just to wait for delivery
        a.publish_nowait("/tf_static/probe", None)
        with anyio.fail_after(5):
            await b_static.receive()
        late = b.subscribe(TF_STATIC_TOPIC)
        assert late.receive_nowait().transforms[0].child_frame_id == "camera"


async def test_memory_transport_drops_when_full_and_unlinked() -> None:
    lonely = MemoryTransport()
    lonely.send_nowait("/x", 1)
    assert lonely.dropped == 1
    a_end, b_end = MemoryTransport.pair(max_buffer_size=2)
    async with Bus(transport=a_end) as a:  # b's bus never opens: its buffer fills up
        for i in range(5):
            a.publish_nowait("/x", i)
    assert a_end.sent == 2
    assert a_end.dropped == 3
    del b_end


async def test_deliver_many_nowait() -> None:
    async with Bus() as bus:
        sub = bus.subscribe("/x")
        bus.deliver_many_nowait("/x", [1, 2, 3])
        bus.deliver_nowait(TF_STATIC_TOPIC, "junk is delivered, not latched")
        assert [sub.receive_nowait() for _ in range(3)] == [1, 2, 3]
        assert bus.statistics()["/x"].remote == 3
        assert bus.latched_statics() == TFMessage(())


async def test_remote_delivery_while_closing_is_dropped_not_raised() -> None:
    """A transport whose task still runs once after the bus began closing (on asyncio,
    anyio does not cancel a task whose awaited future is already done) delivers into a
    closed bus: dropped, no ClosedResourceError that would fail the bus's task group (seen
    with the ROS 2 transport at the end of ``tfbus frames --bus ros2``). Before opening,
    delivery is still a usage error."""
    bus = Bus()
    with pytest.raises(RuntimeError, match="not open"):
        bus.deliver_nowait("/x", 0)
    with pytest.raises(RuntimeError, match="not open"):
        bus.deliver_many_nowait("/x", [0])
    async with bus:
        sub = bus.subscribe("/x")
        bus.deliver_nowait("/x", 1)
    bus.deliver_nowait("/x", 2)
    bus.deliver_many_nowait("/x", [3, 4])
    bus.deliver_nowait(TF_STATIC_TOPIC, TFMessage(()))
    assert bus.statistics()["/x"].remote == 1
    assert sub.statistics().queued <= 1


class _FailingTransport:
    async def run(
        self, bus: Bus, *, task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED
    ) -> None:
        raise OSError("cannot connect")

    def send_nowait(self, topic: str, message: object) -> None:
        raise AssertionError("never called")


async def test_transport_failing_to_start_fails_bus_open() -> None:
    with pytest.raises(OSError, match="cannot connect"):
        async with Bus(transport=_FailingTransport()):
            pass


async def test_running_transport_end_twice_fails() -> None:
    a_end, _ = MemoryTransport.pair()
    async with Bus(transport=a_end):
        with pytest.raises(RuntimeError):
            async with Bus(transport=a_end):
                pass


def _with(t: TransformStamped, **fields: Any) -> TransformStamped:
    """``t`` with some of its translation/rotation/frame fields replaced."""
    tr = t.transform.translation._replace(**{k: v for k, v in fields.items() if k in "xyz"})
    rot = t.transform.rotation._replace(
        **{k[1:]: v for k, v in fields.items() if k in ("qx", "qy", "qz", "qw")}
    )
    header = t.header._replace(frame_id=fields.get("parent", t.header.frame_id))
    child = fields.get("child", t.child_frame_id)
    return TransformStamped(header, child, Transform(tr, rot))


async def test_latch_keeps_the_valid_static_when_an_invalid_one_is_resent() -> None:
    """A NaN static re-sent by any publisher replaced the valid latched
    /tf_static entry, so late joiners never got the valid one. The latch stores only
    transforms the core would store (same validation)."""
    good = ts("laser", 1.5)
    bad = [
        _with(good, x=float("nan")),
        _with(good, y=float("inf")),
        _with(good, qw=float("nan")),
        _with(good, qw=2.0),  # denormalised quaternion
        _with(good, parent="laser"),  # self transform
        _with(good, parent=""),
        _with(good, parent="/laser"),  # a self transform once the slash is stripped
    ]
    async with Bus() as bus:
        bus.publish_nowait(TF_STATIC_TOPIC, TFMessage((good,)))
        bus.publish_nowait(TF_STATIC_TOPIC, TFMessage(tuple(bad)))  # local publisher
        bus.deliver_nowait(TF_STATIC_TOPIC, TFMessage((bad[0],)))  # remote publisher
        bus.deliver_nowait(TF_STATIC_TOPIC, TFMessage((ts("cam", 2.0), "junk", None)))
        late = bus.subscribe(TF_STATIC_TOPIC)
        assert late.receive_nowait() == TFMessage((good, ts("cam", 2.0)))
        assert bus.latched_statics() == TFMessage((good, ts("cam", 2.0)))


async def test_latch_key_is_the_normalised_child_id() -> None:
    """``laser`` and ``/laser`` are one latched entry (tf2 strips the
    leading slash), the latest sent wins."""
    async with Bus() as bus:
        bus.publish_nowait(TF_STATIC_TOPIC, TFMessage((ts("laser", 1.0), ts("cam", 2.0))))
        bus.deliver_nowait(TF_STATIC_TOPIC, TFMessage((ts("/laser", 3.0),)))
        assert bus.latched_statics() == TFMessage((ts("/laser", 3.0), ts("cam", 2.0)))
        bus.publish_nowait(TF_STATIC_TOPIC, TFMessage((ts("laser", 4.0),)))
        assert bus.latched_statics() == TFMessage((ts("laser", 4.0), ts("cam", 2.0)))


def test_memory_transport_keeps_its_old_import_paths() -> None:
    """MemoryTransport lives in tfbus.transports.memory and is
    exported as tfbus.MemoryTransport; bus.py itself neither imports nor gets (there is
    no ``setattr`` into another module) anything of the transports layer."""
    import ast
    from pathlib import Path

    import tfbus
    import tfbus.bus

    assert tfbus.MemoryTransport is MemoryTransport
    assert not hasattr(tfbus.bus, "MemoryTransport")
    tree = ast.parse(Path(tfbus.bus.__file__).read_text())
    imported = [
        node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
    ] + [a.name for node in ast.walk(tree) if isinstance(node, ast.Import) for a in node.names]
    assert not [m for m in imported if m.startswith("tfbus.transports")]


def test_static_latch_api() -> None:
    """StaticLatch (tfbus/latch.py), the one latch of the bus and the transports."""
    from tfbus.latch import StaticLatch

    latch = StaticLatch()
    assert len(latch) == 0 and latch.message() == TFMessage(())
    assert latch.add("not a TFMessage") == 0
    assert latch.add(TFMessage((ts("laser", 1.0), ts("cam", 2.0), ts("bad", float("nan"))))) == 2
    assert "laser" in latch and "/laser" in latch and "bad" not in latch and 3 not in latch
    first = latch.message()
    assert latch.message() is first  # cached until the next change
    assert latch.add(TFMessage((ts("/cam", 5.0),))) == 1
    assert latch.message() == TFMessage((ts("laser", 1.0), ts("/cam", 5.0)))
    latch.clear()
    assert len(latch) == 0 and latch.message() == TFMessage(())


async def test_publish_checks_cancellation_before_publishing() -> None:
    async with Bus() as bus:
        got: list[object] = []
        with bus.subscribe_callback("/x", got.append):
            with anyio.CancelScope() as scope:
                scope.cancel()
                await bus.publish("/x", 1)
            assert scope.cancelled_caught
            assert got == []  # cancelled: not published


async def test_publish_never_raises_cancellation_after_publishing() -> None:
    """The checkpoint after a publish is cancel-shielded (on asyncio a yield on
    a done future, which anyio's cancel scopes do not interrupt; this holds anyio to it):
    a scope cancelled while the publisher yields cancels it at its next checkpoint, not
    inside the publish that already delivered the message."""
    async with Bus() as bus:
        got: list[object] = []
        delivered = anyio.Event()
        steps: list[str] = []

        def on_message(message: object) -> None:
            got.append(message)
            delivered.set()

        with bus.subscribe_callback("/x", on_message):
            async with anyio.create_task_group() as tg:
                scope = anyio.CancelScope()

                async def canceller() -> None:
                    await delivered.wait()  # runs while the publisher yields
                    scope.cancel()
                    steps.append("cancelled")

                async def publisher() -> None:
                    with scope:
                        await bus.publish("/x", 1)
                        steps.append("published")
                        await anyio.lowlevel.checkpoint()
                        steps.append("not reached")

                tg.start_soon(canceller)
                await anyio.wait_all_tasks_blocked()
                tg.start_soon(publisher)
            assert scope.cancelled_caught
            assert got == [1]
            assert "not reached" not in steps and "published" in steps
            # Cancelling from inside the delivery (the publisher's own task) as well.
            with anyio.CancelScope() as own:

                def cancel_own(message: object) -> None:
                    own.cancel()

                with bus.subscribe_callback("/y", cancel_own):
                    await bus.publish("/y", 2)
                    steps.append("own published")
                    await anyio.lowlevel.checkpoint()
                    steps.append("own not reached")
            assert own.cancelled_caught
            assert steps[-1] == "own published"


async def test_topics_no_one_uses_any_more_keep_a_bounded_record() -> None:
    """Subscribing to, publishing on and leaving 3 000 distinct topics (a fleet's robots
    coming and going) leaves the counters of the MAX_IDLE_TOPICS latest idle topics and
    of every topic still subscribed; a kept idle topic's counters go on when it is used
    again."""
    from tfbus.bus import MAX_IDLE_TOPICS

    async with Bus() as bus:
        kept = bus.subscribe("/kept")
        await bus.publish("/kept", 1)
        for i in range(3000):
            cb = bus.subscribe_callback(f"/r{i}/tf", lambda _m: None)
            sub = bus.subscribe(f"/r{i}/tf_static")
            await bus.publish(f"/r{i}/tf", i)
            cb.close()
            sub.close()
            await bus.publish(f"/nobody{i}", i)  # published with no subscriber
        stats = bus.statistics()
        assert len(stats) == MAX_IDLE_TOPICS + 1
        assert stats["/kept"].published == 1 and stats["/kept"].subscribers == 1
        assert "/r0/tf" not in stats and "/nobody2999" in stats
        assert stats["/r2999/tf"].published == 1 and stats["/r2999/tf"].subscribers == 0
        assert repr(bus).startswith(f"<Bus open topics={MAX_IDLE_TOPICS + 1} ")
        cb = bus.subscribe_callback("/r2999/tf", lambda _m: None)
        await bus.publish("/r2999/tf", 0)
        assert bus.statistics()["/r2999/tf"].published == 2
        assert bus.statistics()["/r2999/tf"].delivered == 2
        cb.close()
        assert kept.receive_nowait() == 1
