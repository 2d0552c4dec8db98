"""The Textual recipe (examples/textual_app.py) driven by Textual's own App.run_test()
(asyncio: Textual runs on asyncio only)."""

from __future__ import annotations

import re

import anyio
import pytest

pytest.importorskip("textual")

from examples.textual_app import FramesApp


async def _until(predicate: object, pilot: object, limit: float = 30.0) -> None:
    with anyio.fail_after(limit):
        while not predicate():  # type: ignore[operator]
            await pilot.pause(0.05)  # type: ignore[attr-defined]


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_live_readout_timeout_message_and_shutdown(anyio_backend: str) -> None:
    app = FramesApp()
    async with app.run_test() as pilot:
        pose = app.query_one("#pose")
        status = app.query_one("#status")
        await _until(lambda: "base_link: x = " in str(pose.render()), pilot)
        x = float(re.search(r"x = (-?\d+\.\d+) m", str(pose.render())).group(1))  # type: ignore[union-attr]
        assert 0.05 <= x <= 60.0

        await pilot.press("g")
        await _until(lambda: "no transform within" in str(status.render()), pilot)
        assert str(status.render()) == "gripper: no transform within 0.5 s (frame known: False)"
        session = app.session
        assert not session.closed
        await pilot.press("q")
    # Quitting cancelled the workers' waits and closed the session from on_unmount.
    assert session.closed
    assert session.buffer.pending_waits == 0
