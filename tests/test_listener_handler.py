"""A ``TransformListener``'s two message handlers, the compiled one
(``tfbus._clistener.InlineHandler``: a message of one transform stored with no Python
frame) and the listener's own ``_handle`` (the pure-Python path), do the same: the same
transforms stored under the same authorities, the same counts, the same warnings, the
same clock reads, for every kind of message a bus can carry."""

from __future__ import annotations

import logging
import math
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass

import pytest
from event_loops import anyio_backend_with_uvloop  # noqa: F401  (the fixture)

import tfbus.listener
from tfbus.buffer import Buffer
from tfbus.bus import TF_STATIC_TOPIC, TF_TOPIC, Bus
from tfbus.clock import ManualClock, SystemClock
from tfbus.core import BufferCore
from tfbus.listener import ListenerStatistics, TransformListener
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Duration, Time

pytestmark = pytest.mark.anyio

T0 = Time(1_700_000_000)
COMPILED = tfbus.listener._HANDLER


def ts(child: str, stamp: Time = T0, x: float = 0.1, parent: str = "base_link",
       rotation: Quaternion | None = None) -> TransformStamped:
    return TransformStamped(
        Header(stamp, parent), child,
        Transform(Vector3(x, 0.0, 0.2), Quaternion() if rotation is None else rotation))


class _NamedMessage(TFMessage):
    """A TFMessage subclass naming its publisher (what the ROS 1 transport delivers)."""

    authority = "/ros1_publisher"


@dataclass
class Outcome:
    statistics: ListenerStatistics
    warnings: list[str]
    frames: str
    clock_reads: int


class _CountingClock(ManualClock):
    """A ManualClock that counts its ``now_ns`` reads."""

    reads = 0

    def now_ns(self) -> int:
        self.reads += 1
        return super().now_ns()


def _deliveries() -> Iterator[tuple[str, object]]:
    """Every kind of message, in an order where refusals and authorities matter."""
    yield TF_TOPIC, TFMessage((ts("a"),))  # stored
    yield TF_TOPIC, TFMessage((ts("a"),))  # repeated stamp: refused
    yield TF_TOPIC, TFMessage((ts("a", T0 + Duration(1)),))  # stored
    yield TF_TOPIC, TFMessage((ts("a", T0 - Duration(20)),))  # older than the cache: refused
    yield TF_TOPIC, TFMessage((ts("nan", x=math.nan),))  # invalid
    yield TF_TOPIC, TFMessage((ts("q", rotation=Quaternion(0.0, 0.0, 0.0, 2.0)),))  # invalid
    yield TF_TOPIC, TFMessage(("junk",))  # type: ignore[arg-type]  # malformed item
    yield TF_TOPIC, TFMessage((ts("b"), ts("c"), ts("b")))  # a batch: 2 stored, 1 refused
    yield TF_TOPIC, TFMessage((ts("i"), ts("nan2", x=math.nan)))  # a batch: 1 stored, 1 invalid
    yield TF_TOPIC, _NamedMessage((ts("j"), ts("k", T0 + Duration(1))))  # batch, publisher's
    yield TF_TOPIC, TFMessage(())  # nothing
    yield TF_TOPIC, TFMessage([ts("d")])  # a list of one: the batch path, stored
    yield TF_TOPIC, _NamedMessage((ts("e"),))  # the publisher's authority
    yield TF_TOPIC, "not a TFMessage"  # malformed message
    yield TF_TOPIC, TFMessage(42)  # type: ignore[arg-type]  # not iterable: malformed
    yield TF_STATIC_TOPIC, TFMessage((ts("fixed", parent="a"),))  # static, stored
    yield TF_STATIC_TOPIC, TFMessage((ts("fixed2", x=math.inf, parent="a"),))  # invalid
    yield TF_STATIC_TOPIC, TFMessage((ts("g", parent="fixed"), ts("h", parent="fixed")))


def _frame(frames: str, child: str) -> str:
    """``child``'s entry in ``all_frames_as_yaml``: its line and the indented ones below."""
    lines = frames.split("\n")
    start = next(i for i, line in enumerate(lines) if line.rstrip() == f"{child}:")
    end = next((i for i in range(start + 1, len(lines))
                if lines[i] and not lines[i].startswith(" ")), len(lines))  # fmt: skip
    return "\n".join(lines[start:end])


async def _run(handler: object, sink_kind: str, monkeypatch: pytest.MonkeyPatch,
               caplog: pytest.LogCaptureFixture) -> Outcome:
    monkeypatch.setattr(tfbus.listener, "_HANDLER", handler)
    caplog.clear()
    clock = _CountingClock(T0)
    sink = Buffer(cache_time=10.0, clock=clock) if sink_kind == "Buffer" else BufferCore(10.0)
    with caplog.at_level(logging.WARNING, logger="tfbus.listener"):
        async with Bus() as bus, TransformListener(sink, bus, clock=clock, log_period=1e-9) \
                as listener:
            for i, (topic, message) in enumerate(_deliveries()):
                await clock.advance(0.001)  # each message its own time: every warning shown
                if i % 2:
                    bus.deliver_nowait(topic, message)  # as a transport delivers
                else:
                    await bus.publish(topic, message)
            reads = clock.reads
            frames = sink.all_frames_as_yaml(T0 + Duration(1))
    if isinstance(sink, Buffer):
        sink.close()
    return Outcome(listener.statistics(),
                   [r.getMessage() for r in caplog.records if r.name == "tfbus.listener"],
                   frames, reads)


@pytest.mark.skipif(COMPILED is None, reason="the compiled handler is not built (a pure-"
                    "Python install, or TFBUS_PURE_PYTHON): only the listener's own runs")
@pytest.mark.parametrize("sink_kind", ["Buffer", "BufferCore"])
async def test_the_compiled_handler_does_what_the_listener_does(
    sink_kind: str, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    compiled = await _run(COMPILED, sink_kind, monkeypatch, caplog)
    python = await _run(None, sink_kind, monkeypatch, caplog)
    assert compiled == python


@pytest.mark.parametrize("handler", ["compiled", "python"])
async def test_each_handler_counts_stores_and_warns_as_tf2_ros_would(
    handler: str, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    if handler == "compiled" and COMPILED is None:
        pytest.skip("the compiled handler is not built (pure-Python install or core)")
    got = await _run(COMPILED if handler == "compiled" else None, "Buffer", monkeypatch,
                     caplog)
    # 18 deliveries, all counted as messages; stored: a, a@+1, b, c, i, j, k, d, e, fixed,
    # g, h; refused: a repeated, a too old, b repeated; invalid: nan, q, nan2, fixed2;
    # malformed: the "junk" item, the str, TFMessage(42).
    assert got.statistics == ListenerStatistics(
        messages=18, stored=12, refused=3, invalid=4, malformed=3, dropped=0)
    assert got.clock_reads == 18  # one clock read a message (tf2_ros ROS 1 listener)
    warned = "\n".join(got.warnings)
    for word in ("nan", "'q'", "nan2", "fixed2", "malformed transform on /tf: TypeError",
                 "ignoring a str on /tf", "/tf_static"):
        assert word in warned, (word, warned)
    for child in ("e", "j", "k"):  # the subclass's authority, kept (one and a batch)
        assert "broadcaster: '/ros1_publisher'" in _frame(got.frames, child), child
    for child in ("a", "b", "c", "i", "d", "fixed", "g", "h"):
        assert "broadcaster: 'default_authority'" in _frame(got.frames, child), child
    for child in ("a", "b", "c", "d", "e", "i", "j", "k", "fixed", "g", "h"):
        assert f"\n{child}:" in f"\n{got.frames}", (child, got.frames)
    for child in ("nan", "q", "nan2", "fixed2"):
        assert f"\n{child}:" not in f"\n{got.frames}"


async def test_the_compiled_handler_serves_only_a_store_of_one_transform(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A sink without the core's one-transform store (here a BufferCore subclass that
    overrides ``set_transforms``) is fed by the listener's own handler, compiled core or
    not: its batches are what it overrides."""
    seen: list[int] = []

    class _Batching(BufferCore):
        def set_transforms(self, transforms, authority="default", is_static=False):  # type: ignore[no-untyped-def, override]
            items = list(transforms)
            seen.append(len(items))
            return super().set_transforms(items, authority, is_static)

    clock = ManualClock(T0)
    async with Bus() as bus, TransformListener(_Batching(), bus, clock=clock) as listener:
        await bus.publish(TF_TOPIC, TFMessage((ts("a"),)))
        assert listener._handlers == []
    assert seen == [1]
    assert listener.statistics().stored == 1


@pytest.mark.skipif(COMPILED is None, reason="the compiled handler is not built (a pure-"
                    "Python install, or TFBUS_PURE_PYTHON)")
async def test_the_compiled_handler_stores_batches_and_named_messages_itself() -> None:
    """Messages of several transforms and a publisher's TFMessage subclass (the ROS 1
    transport's) are stored by the compiled handler, not handed to ``_handle``; a list of
    transforms and a message that is not a TFMessage are."""
    clock = ManualClock(T0)
    buffer = Buffer(cache_time=10.0, clock=clock)
    async with Bus() as bus, TransformListener(buffer, bus, clock=clock) as listener:
        handed: list[object] = []
        handle = listener._handle

        def spy(static: bool, message: object) -> None:
            handed.append(message)
            handle(static, message)

        listener._handle = spy  # type: ignore[method-assign]
        batch = TFMessage((ts("a"), ts("b")))
        named = _NamedMessage((ts("c"), ts("d")))
        listed = TFMessage([ts("e")])
        bus.deliver_nowait(TF_TOPIC, batch)
        bus.deliver_nowait(TF_TOPIC, named)
        bus.deliver_nowait(TF_TOPIC, _NamedMessage((ts("f"),)))
        bus.deliver_nowait(TF_TOPIC, listed)
        bus.deliver_nowait(TF_TOPIC, "junk")
        assert handed == [listed, "junk"]
        assert sum(h.messages for h in listener._handlers) == 3
        assert sum(h.stored for h in listener._handlers) == 5
        assert listener.statistics().stored == 6
    buffer.close()


@pytest.mark.parametrize("handler", ["compiled", "python"])
async def test_a_system_clock_is_read_per_message_with_its_jump_back_reported(
    handler: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The compiled handler reads a SystemClock's wall clock in C: the same reading
    (``time.time_ns``'s clock), recorded as the clock's latest, and a time earlier than
    the latest fires the clock's jump callbacks with (latest, now), as ``now_ns`` does."""
    if handler == "compiled" and COMPILED is None:
        pytest.skip("the compiled handler is not built (pure-Python install or core)")
    monkeypatch.setattr(tfbus.listener, "_HANDLER", COMPILED if handler == "compiled" else None)
    clock = SystemClock()
    jumps: list[tuple[Time, Time]] = []
    clock.on_jump(lambda old, new: jumps.append((old, new)))
    buffer = Buffer(cache_time=10.0, clock=clock)
    async with Bus() as bus, TransformListener(buffer, bus, clock=clock) as listener:
        assert len(listener._handlers) == (handler == "compiled") * 2  # /tf, /tf_static
        entered: list[str] = []
        before = time.time_ns()
        sys.setprofile(lambda frame, event, _arg: entered.append(frame.f_code.co_name)
                       if event == "call" else None)
        try:
            bus.deliver_nowait(TF_TOPIC, TFMessage((ts("a", Time.from_ns(before)),)))
        finally:
            sys.setprofile(None)
        after = time.time_ns()
        assert before <= clock._latest_ns <= after and jumps == []
        assert ("now_ns" in entered) == (handler == "python"), entered
        ahead = after + 3600 * 10**9  # as if read an hour ahead, then the clock stepped back
        clock._latest_ns = ahead
        await bus.publish(TF_TOPIC, TFMessage((ts("a", Time.from_ns(after + 1)),)))
        assert len(jumps) == 1 and jumps[0][0] == Time.from_ns(ahead)
        assert after <= jumps[0][1].ns == clock._latest_ns <= time.time_ns()
        assert listener.statistics().messages == 2
    buffer.close()
