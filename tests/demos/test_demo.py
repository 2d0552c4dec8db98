"""The seed demo, driven by ManualClock on asyncio and trio: the tutorial's line each
simulated second, the ERROR line before the broadcaster has sent anything, a 100 Hz
broadcast with zero jitter, and the summary line."""

from __future__ import annotations

import re

import anyio
import pytest
from event_loops import anyio_backend_with_uvloop  # noqa: F401  (the fixture)

from tfbus import Time
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.cli import main
from tfbus.clock import ManualClock
from tfbus.demos.tutorial import BroadcasterStatistics, broadcaster_node, listener_node, run_demo
from tfbus.listener import TransformListener

pytestmark = pytest.mark.anyio

START = Time(1248138527, 200_823_000)
INFO = re.compile(
    r"^\[ INFO\] (\d+\.\d{9}): base_laser: \(1\.00, 0\.20\. 0\.00\) -----> "
    r"base_link: \(1\.10, 0\.20, 0\.20\) at time (\d+\.\d\d)$"
)


async def test_demo_prints_the_tutorial_line_each_simulated_second() -> None:
    clock = ManualClock(START)
    lines: list[str] = []
    async with anyio.create_task_group() as tg:
        done = anyio.Event()

        async def demo() -> None:
            await run_demo(clock=clock, duration=10.5, out=lines.append)
            done.set()

        tg.start_soon(demo)
        await clock.advance(10.5)
        await done.wait()
    info, summary = lines[:-1], lines[-1]
    assert len(info) == 10
    for k, line in enumerate(info, start=1):
        m = INFO.match(line)
        assert m, line
        assert m.group(1) == f"{START.sec + k}.{START.nanosec:09d}"
        # Time(0) resolves to the newest broadcast. The listener went to sleep on this
        # deadline before the broadcaster did, so (ties wake in sleep order) it runs first
        # and sees the broadcast of 10 ms earlier — as in the tutorial's own output.
        assert m.group(2) == f"{(START.ns + k * 1_000_000_000 - 10_000_000) / 1e9:.2f}"
        assert m.group(2) == f"{START.sec + k}.19"
    assert summary == (
        "[ INFO] summary: 1050 transforms sent, broadcast rate 100.00 Hz, "
        "timer jitter p50 0.000 ms, p99 0.000 ms"
    )


async def test_listener_without_broadcaster_prints_the_error_line() -> None:
    clock = ManualClock(START)
    lines: list[str] = []
    buffer = Buffer(clock=clock)
    async with (
        Bus() as bus,
        TransformListener(buffer, bus, clock=clock),
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(listener_node, buffer, clock, 1.0, lines.append)
        await clock.advance(1.0)
        assert lines == [
            "[ERROR] 1248138528.200823000: Received an exception trying to transform a "
            'point from "base_laser" to "base_link": "base_link" passed to '
            "lookupTransform argument target_frame does not exist. "
        ]
        stats = BroadcasterStatistics()
        tg.start_soon(broadcaster_node, bus, clock, 100.0, stats)
        await clock.advance(1.0)
        assert INFO.match(lines[-1]), lines[-1]
        assert stats.sent == 101  # immediate first tick, then every 10 ms
        tg.cancel_scope.cancel()


async def test_broadcaster_counts_the_ticks_its_timer_skipped_when_late() -> None:
    """A loop late by over a period (time jumps 35 ms while it does not run) gets the
    latest passed tick at once and the older ones skipped, counted in ``skipped``
    (``PeriodicTimer``'s overrun policy, ``rcl_timer``'s)."""
    clock = ManualClock(START)
    stats = BroadcasterStatistics()
    async with Bus() as bus, anyio.create_task_group() as tg:
        tg.start_soon(broadcaster_node, bus, clock, 100.0, stats)
        await anyio.wait_all_tasks_blocked()
        assert (stats.sent, stats.skipped) == (1, 0)  # the immediate first tick
        clock.advance_nowait(0.035)  # the 10, 20 and 30 ms deadlines pass unseen
        await anyio.wait_all_tasks_blocked()
        assert (stats.sent, stats.skipped) == (2, 2)  # 30 ms fired, 10 and 20 skipped
        await clock.advance(0.005)  # 40 ms: on schedule again
        assert (stats.sent, stats.skipped) == (3, 2)
        tg.cancel_scope.cancel()


def test_main_rejects_bad_rates(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--rate", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("tfbus demo: error: ") and "--rate" in err


# -- the tutorial's terminals: one node per bus (two linked in-memory buses stand in for
#    two processes; tests/cli/test_three_terminals.py runs them over Zenoh for real)


async def test_run_listener_and_run_broadcaster_on_two_linked_buses() -> None:
    from tfbus import MemoryTransport
    from tfbus.demos.tutorial import run_broadcaster, run_listener

    clock = ManualClock(START)
    a, b = MemoryTransport.pair()
    lines: list[str] = []
    bsummary: list[str] = []
    async with (
        Bus(transport=a) as listener_bus,
        Bus(transport=b) as broadcaster_bus,
        anyio.create_task_group() as tg,
    ):
        done = anyio.Event()

        async def listener() -> None:
            await run_listener(listener_bus, clock=clock, duration=4.5, out=lines.append)
            done.set()

        tg.start_soon(listener)
        await clock.advance(2.0)  # the listener alone: two ERROR lines
        assert [line[:7] for line in lines] == ["[ERROR]", "[ERROR]"]
        tg.start_soon(
            lambda: run_broadcaster(
                broadcaster_bus, clock=clock, duration=2.0, out=bsummary.append
            )
        )
        await clock.advance(2.5)
        await done.wait()
    assert [line[:7] for line in lines[:4]] == ["[ERROR]"] * 2 + ["[ INFO]"] * 2
    for line in lines[2:4]:
        assert INFO.match(line), line
    assert lines[-1] == "[ INFO] summary: 4 lookups, 2 transformed, 2 failed"
    assert bsummary == [
        "[ INFO] summary: 200 transforms sent, broadcast rate 100.00 Hz, "
        "timer jitter p50 0.000 ms, p99 0.000 ms"
    ]


def test_main_roles_wire_the_runners(monkeypatch: pytest.MonkeyPatch) -> None:
    import tfbus.cli._bus_spec as sources
    import tfbus.demos.tutorial as demo
    from tfbus.transports.spec import BusSpec

    opened: list[tuple[str, str | None]] = []
    calls: list[tuple[str, dict[str, object]]] = []

    def fake_open_spec_transport(spec: BusSpec, *, name: str, use_sim_time: bool = False) -> None:
        opened.append((spec.text, name))
        return None  # an in-process bus

    async def fake_broadcaster(bus: Bus, **kwargs: object) -> BroadcasterStatistics:
        calls.append(("broadcaster", kwargs))
        return BroadcasterStatistics()

    async def fake_listener(bus: Bus, **kwargs: object) -> object:
        calls.append(("listener", kwargs))
        return None

    monkeypatch.setattr(sources, "open_spec_transport", fake_open_spec_transport)
    monkeypatch.setattr(demo, "run_broadcaster", fake_broadcaster)
    monkeypatch.setattr(demo, "run_listener", fake_listener)
    assert main(["demo", "broadcaster", "--rate", "50", "--duration", "3"]) == 0
    assert main(["demo", "listener", "--bus", "zenoh?port=9000", "--backend", "trio"]) == 0
    # (a --bus given is also opened once as "tfbus-cli" when parsed, to check its config)
    nodes = [o for o in opened if o[1] != "tfbus-cli"]
    assert nodes == [("zenoh", "robot_tf_publisher"), ("zenoh?port=9000", "robot_tf_listener")]
    assert [c[0] for c in calls] == ["broadcaster", "listener"]
    assert calls[0][1]["rate"] == 50.0 and calls[0][1]["duration"] == 3.0
    assert calls[0][1]["handle_signals"] is True
    assert calls[1][1]["listen_rate"] == 1.0 and calls[1][1]["duration"] is None


def test_main_rejects_a_bad_bus(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("zenoh")
    assert main(["demo", "listener", "--bus", "carrier-pigeon"]) == 2
    assert "unsupported bus" in capsys.readouterr().err


def test_open_bus_names_the_node_unless_the_spec_does() -> None:
    pytest.importorskip("zenoh")
    from tfbus.demos.tutorial import LISTENER_NAME
    from tfbus.transports.spec import open_bus

    named = open_bus("zenoh", default_name=LISTENER_NAME).transport
    assert getattr(named, "name", None) == "robot_tf_listener"
    assert getattr(open_bus("zenoh?name=mine", default_name="x").transport, "name", None) == "mine"
