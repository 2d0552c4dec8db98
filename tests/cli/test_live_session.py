"""The live session every ``--bus`` command runs in (``tfbus.cli._live_session.live``):
what the process made before it is left out of the cyclic garbage collector while the
session runs, and put back when it ends."""

from __future__ import annotations

import gc

import pytest

from tfbus.cli._bus_source import BusSource
from tfbus.cli._live_session import live


class _Cycle:
    """An object in a reference cycle with itself (freed only by the cyclic collector)."""

    def __init__(self) -> None:
        self.me = self


@pytest.mark.anyio
async def test_a_session_leaves_what_came_before_it_out_of_collections() -> None:
    """Inside: the objects made before are frozen (``gc.get_freeze_count``), and a
    garbage cycle made by the session is still collected; after: none frozen. A process
    that froze objects itself keeps exactly its own freeze."""
    assert gc.get_freeze_count() == 0
    seen: list[int] = []
    collected: list[int] = []

    async def body() -> None:
        seen.append(gc.get_freeze_count())
        _Cycle()  # garbage at once: only a collection frees it
        before = len(gc.get_objects())
        collected.append(gc.collect())
        assert len(gc.get_objects()) < before

    await live(BusSource("memory"), None, body)
    assert seen[0] > 1000 and collected[0] >= 1  # the modules, at least
    assert gc.get_freeze_count() == 0
    gc.freeze()
    try:
        count = gc.get_freeze_count()
        made = [[] for _ in range(10_000)]  # made after the process's own freeze
        seen.clear()
        await live(BusSource("memory"), None, body)
        # the session froze nothing more (``made`` would count) and unfroze nothing
        assert seen[0] <= count and 0 < gc.get_freeze_count() <= count
        assert len(made) == 10_000
    finally:
        gc.unfreeze()
