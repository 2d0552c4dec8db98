"""A full fleet makes room for the living: when ``max_robots`` robots are kept, a newly
announced robot takes the place of the one gone the longest; a live robot is refused only
when every kept robot is alive.

The liveliness events a peer-aware transport delivers (:class:`PeerEvent` on
``PEERS_TOPIC``) are published on an in-process bus, so thousands of announced names run
in well under a second; time is a ManualClock (no wall-clock wait).
"""

from __future__ import annotations

import gc
import tracemalloc

import pytest

from tfbus.bus import MAX_IDLE_TOPICS, Bus
from tfbus.clock import ManualClock
from tfbus.fleet import FleetBuffer
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from tfbus.time import Time
from tfbus.topics import PEERS_TOPIC
from tfbus.transports._base import PeerEvent

pytestmark = pytest.mark.anyio


async def announce(bus: Bus, node_id: str, name: str, *, alive: bool = True) -> None:
    await bus.publish(PEERS_TOPIC, PeerEvent(alive, node_id, name))


async def flood(bus: Bus, names: range, prefix: str = "spoof") -> None:
    """Each name announced by one node that leaves at once (announced-then-gone)."""
    for i in names:
        await announce(bus, f"n{i}", f"{prefix}{i}/node")
        await announce(bus, f"n{i}", f"{prefix}{i}/node", alive=False)


async def test_names_announced_then_gone_cannot_keep_a_live_robot_out() -> None:
    """2 000 names announced and gone (as a peer spoofing names does) against
    max_robots=1000: 1 000 kept, each new one released the longest gone; then a live
    robot is followed at once, taking the place of the oldest gone name."""
    clock = ManualClock(Time(1000))
    async with Bus() as bus, FleetBuffer(bus, max_robots=1000, forget_after=300,
                                         clock=clock) as fleet:
        await flood(bus, range(2000))
        stats = fleet.statistics()
        assert (len(fleet), stats.gone, stats.evicted, stats.robots_refused) == (
            1000, 2000, 1000, 0)
        assert "spoof1000" in fleet and "spoof1999" in fleet  # the latest 1 000 names
        assert "spoof999" not in fleet and "spoof0" not in fleet  # the oldest ones went
        await announce(bus, "live", "robot7/driver")
        assert "robot7" in fleet and fleet.robots()["robot7"].alive
        assert "spoof1000" not in fleet  # gone the longest (same clock time: first gone)
        stats = fleet.statistics()
        assert (len(fleet), stats.evicted, stats.robots_refused, stats.released) == (
            1000, 1001, 0, 0)
        t = TransformStamped(Header(Time(1000), "map"), "base_link",
                             Transform(Vector3(1.0, 0.0, 0.0), Quaternion()))
        await bus.publish("/robot7/tf", TFMessage([t]))
        got = fleet["robot7"].lookup_transform("map", "base_link", Time(0))
        assert got.transform.translation.x == 1.0


async def test_the_robot_gone_the_longest_goes_first_and_the_living_stay() -> None:
    clock = ManualClock(Time(1000))
    async with Bus() as bus, FleetBuffer(bus, max_robots=3, forget_after=300,
                                         clock=clock) as fleet:
        for name in ("a", "b", "c"):
            await announce(bus, f"id-{name}", f"{name}/node")
        # Every kept robot alive: the fourth is refused and counted.
        await announce(bus, "id-d", "d/node")
        assert sorted(fleet) == ["a", "b", "c"] and "d" not in fleet
        assert (fleet.statistics().robots_refused, fleet.statistics().evicted) == (1, 0)
        with pytest.raises(RuntimeError, match="max_robots=3"):
            fleet.add_robot("manual")
        # c goes at 1010 s, a at 1020 s: c has been gone the longest.
        clock.advance_nowait(10.0)
        await announce(bus, "id-c", "c/node", alive=False)
        clock.advance_nowait(10.0)
        await announce(bus, "id-a", "a/node", alive=False)
        await announce(bus, "id-e", "e/node")
        assert sorted(fleet) == ["a", "b", "e"]
        await announce(bus, "id-f", "f/node")
        assert sorted(fleet) == ["b", "e", "f"]
        assert (fleet.statistics().evicted, fleet.statistics().robots_refused) == (2, 1)
        assert all(info.alive for info in fleet.robots().values())
        # All alive again: refused; a robot added by hand follows the same rule.
        await announce(bus, "id-g", "g/node")
        assert "g" not in fleet and fleet.statistics().robots_refused == 2
        await announce(bus, "id-b", "b/node", alive=False)
        fleet.add_robot("manual")
        assert sorted(fleet) == ["e", "f", "manual"]
        assert fleet.statistics().evicted == 3
        # forget_after still releases on time (counted apart from evictions).
        await announce(bus, "id-e", "e/node", alive=False)
        clock.advance_nowait(300.0)
        await announce(bus, "id-h", "h/node")
        assert sorted(fleet) == ["f", "h", "manual"]
        assert (fleet.statistics().released, fleet.statistics().evicted) == (1, 3)


async def test_a_flood_of_names_holds_memory_at_max_robots() -> None:
    """The memory a fleet and its bus hold after 2 000 announced-then-gone names is what
    they hold after 2 500 more: bounded by max_robots (and the bus's MAX_IDLE_TOPICS
    counters of topics no one subscribes to any more), not by what peers announce."""
    clock = ManualClock(Time(1000))
    async with Bus() as bus, FleetBuffer(bus, max_robots=500, forget_after=300,
                                         clock=clock) as fleet:
        await flood(bus, range(500))
        tracemalloc.start()
        try:
            await flood(bus, range(500, 2000), prefix="warm")
            gc.collect()  # a released robot's buffer holds reference cycles
            base = tracemalloc.get_traced_memory()[0]
            await flood(bus, range(2000, 4500), prefix="more")
            gc.collect()
            grown = tracemalloc.get_traced_memory()[0] - base
        finally:
            tracemalloc.stop()
        assert len(fleet) == 500 and fleet.statistics().evicted == 4000
        assert len(bus.statistics()) <= 2 * 500 + MAX_IDLE_TOPICS + 1
        assert grown < 100_000, grown  # bytes: a few robots' worth at most, not 2 500
