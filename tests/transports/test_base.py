"""What every transport shares (``tfbus/transports/_base.py``): the thread-to-loop wake-up,
one statistics base with one meaning of ``received``, the ``PeerAware`` protocol the
command line asks instead of a scheme name, and the scheme table that agrees with it."""

from __future__ import annotations

import dataclasses
import importlib
import threading

import anyio
import pytest

from tfbus.bus import Bus
from tfbus.transports._base import BusLike, PeerAware, ThreadWakeup, TransportStatistics
from tfbus.transports.memory import MemoryTransport
from tfbus.transports.spec import schemes


@pytest.mark.anyio
async def test_a_thread_wakes_the_loop_once_per_burst() -> None:
    wakeup = ThreadWakeup()
    try:
        threads = [threading.Thread(target=wakeup.wake) for _ in range(50)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(10)
        assert wakeup._r.recv(4096) == b"\0"  # 50 wakes, one byte: one loop wake-up
        wakeup.wake()  # still pending (not re-armed): coalesced, nothing sent
        with pytest.raises(BlockingIOError):
            wakeup._r.recv(4096)
        wakeup.rearm()
        waker = threading.Thread(target=wakeup.wake)
        waker.start()
        with anyio.fail_after(10):  # a bound, not a timing: wakes as soon as the byte lands
            await wakeup.wait()
        waker.join(10)
        with pytest.raises(BlockingIOError):  # wait() consumed the signal
            wakeup._r.recv(4096)
    finally:
        wakeup.close()
    wakeup.wake()  # after close: ignored, no error


@pytest.mark.anyio
async def test_serve_drains_each_wake_up_then_in_batches_until_cancelled() -> None:
    """``ThreadWakeup.serve``: ``drain(True)`` once per wake-up from another thread, then
    ``drain(False)`` while it reports more; nothing after the watch is cancelled."""
    wakeup = ThreadWakeup()
    calls: list[bool] = []
    backlog = [0]  # batches still to drain after the current one
    drained = anyio.Event()

    def drain(woken: bool) -> bool:
        calls.append(woken)
        more = backlog[0] > 0
        if more:
            backlog[0] -= 1
        else:
            drained.set()
        return more

    try:
        async with anyio.create_task_group() as tg:
            tg.start_soon(wakeup.serve, drain)
            for backlog[0] in (0, 2):
                drained = anyio.Event()
                waker = threading.Thread(target=wakeup.wake)
                waker.start()
                with anyio.fail_after(10):  # a bound, not a timing
                    await drained.wait()
                waker.join(10)
            tg.cancel_scope.cancel()
        assert calls == [True, True, False, False]
        wakeup.wake()  # the watch is over: nothing drains it
        await anyio.lowlevel.checkpoint()
        assert calls == [True, True, False, False]
    finally:
        wakeup.close()


@pytest.mark.anyio
async def test_serve_raises_what_drain_raises() -> None:
    wakeup = ThreadWakeup()

    def drain(woken: bool) -> bool:
        raise LookupError("from drain")

    try:
        wakeup.wake()
        with anyio.fail_after(10), pytest.raises(LookupError, match="from drain"):
            await wakeup.serve(drain)
    finally:
        wakeup.close()


def test_serve_drains_in_the_asyncio_iteration_that_sees_the_wake_up() -> None:
    """On asyncio, ``drain`` runs in the loop's read callback of the socket: in the loop
    iteration whose poll reports it readable (the one after ``wake``), not one later in a
    task resumed by that callback, and outside any task."""
    import asyncio

    async def main() -> list[tuple[int, int, object]]:
        loop = asyncio.get_running_loop()
        wakeup = ThreadWakeup()
        tick = [0]  # event-loop iterations, counted by a callback that re-schedules itself
        woke_at = [0]
        seen: list[tuple[int, int, object]] = []
        drained = asyncio.Event()

        def ticker() -> None:
            tick[0] += 1
            if tick[0] == 5:  # the watch is registered by then
                woke_at[0] = tick[0]
                wakeup.wake()
            handle[0] = loop.call_soon(ticker)

        def drain(woken: bool) -> bool:
            seen.append((woke_at[0], tick[0], asyncio.current_task()))
            drained.set()
            return False

        server = asyncio.ensure_future(wakeup.serve(drain))
        handle = [loop.call_soon(ticker)]
        try:
            await asyncio.wait_for(drained.wait(), 10)
        finally:
            handle[0].cancel()
            server.cancel()
            with pytest.raises(asyncio.CancelledError):
                await server
            wakeup.close()
        return seen

    assert asyncio.run(main()) == [(5, 6, None)]


def _stats_classes() -> dict[str, type]:
    out: dict[str, type] = {}
    for module, name in (
        ("tfbus.transports.zenoh", "ZenohStatistics"),
        ("tfbus.transports.ros2", "Ros2Statistics"),
        ("tfbus.transports.ros1", "Ros1Statistics"),
        ("tfbus.transports.rmw_zenoh", "RmwZenohStatistics"),
    ):
        try:
            out[name] = getattr(importlib.import_module(module), name)
        except ImportError:  # the transport's extra is not installed
            continue
    return out


def test_every_transport_statistics_shares_the_base() -> None:
    classes = _stats_classes()
    assert classes, "no transport extra installed"
    base = [f.name for f in dataclasses.fields(TransportStatistics)]
    assert base == ["sent", "send_errors", "received", "delivered", "malformed"]
    for name, cls in classes.items():
        assert issubclass(cls, TransportStatistics), name
        assert [f.name for f in dataclasses.fields(cls)][: len(base)] == base, name
        stats = cls()
        stats.received += 2
        stats.delivered += 1
        stats.malformed += 1
        assert dataclasses.replace(stats) == stats


def test_peer_aware_is_what_the_scheme_table_says() -> None:
    """The CLI asks ``isinstance(transport, PeerAware)`` (and, before opening, the scheme
    row's ``peer_aware``): only Zenoh knows its peers."""
    from tfbus.transports.spec import open_transport

    assert not isinstance(MemoryTransport(), PeerAware)
    for name, row in schemes().items():
        if name == "memory":
            assert not row.peer_aware
            continue
        try:
            transport = open_transport(name)
        except Exception as exc:  # an extra not installed: TransportError
            if type(exc).__name__ != "TransportError":
                raise
            continue
        assert isinstance(transport, PeerAware) is row.peer_aware, name
    assert schemes()["zenoh"].peer_aware


def test_the_bus_is_bus_like() -> None:
    bus: BusLike = Bus()  # the protocol a transport's run() is typed with
    assert callable(bus.deliver_nowait) and callable(bus.deliver_many_nowait)
