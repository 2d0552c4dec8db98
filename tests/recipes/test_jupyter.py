"""The Jupyter recipe (examples/jupyter_cells.py) run cell by cell in a real ipykernel.

A notebook runs each cell in its own task: a bus opened in one cell is closed in another,
the set-up cell is re-run, and a waiting cell is interrupted (SIGINT, Kernel > Interrupt).
"""

from __future__ import annotations

import re

import pytest

from .kernel import ROOT, cells, ipykernel

pytest.importorskip("ipykernel")
pytest.importorskip("jupyter_client")

CELLS = cells(ROOT / "examples" / "jupyter_cells.py")


def test_cells_are_the_recipes() -> None:
    assert list(CELLS) == ["setup", "lookup", "timeout", "interrupt", "after", "close"]


def test_a_session_opened_in_one_cell_is_used_and_closed_in_others() -> None:
    with ipykernel() as kernel:
        setup = kernel.run(CELLS["setup"])
        assert setup.status == "ok", setup
        assert "session open: <TransformSession name='robot' open>" in setup.stdout

        lookup = kernel.run(CELLS["lookup"])
        assert lookup.status == "ok", lookup
        # Driving at 1 m/s: the transform 0.2 s ahead is at x ~ 0.2 m plus the time
        # from the robot's start to the cell (bounded generously for a loaded machine).
        found = re.search(r"x = (-?\d+\.\d+) m", lookup.stdout)
        assert found is not None, lookup
        x = float(found.group(1))
        assert 0.15 <= x <= 30.0

        timeout = kernel.run(CELLS["timeout"])
        assert timeout.status == "ok", timeout
        assert "no transform within 0.5 s:" in timeout.stdout
        assert "gripper known to the buffer: False" in timeout.stdout

        # Re-running the set-up cell closes the old session (no second bus left open)
        # and the old robot task then ends on its closed bus.
        kernel.run("old = tf; old_robot = robot")
        again = kernel.run(CELLS["setup"])
        assert again.status == "ok", again
        check = kernel.run(
            "import asyncio\n"
            "await asyncio.wait([old_robot], timeout=10)\n"
            "print(old.closed, tf.closed, old is tf, old_robot.done(),"
            " old_robot.done() and old_robot.exception())"
        )
        # The old robot broadcast on its own session, so it ended quietly on that
        # session's closed bus (not on the new one the global ``tf`` now names).
        assert check.stdout.strip() == "True False False True None", check

        # Kernel > Interrupt while a lookup waits: the cell ends (ipykernel 7 cancels an
        # awaiting cell's task: CancelledError; older kernels raise KeyboardInterrupt),
        # the waiter is removed, and the session keeps answering.
        waiting = kernel.run(CELLS["interrupt"], interrupt_after="interrupt me")
        assert waiting.status == "error"
        assert waiting.ename in ("CancelledError", "KeyboardInterrupt"), waiting
        after = kernel.run(CELLS["after"])
        assert after.status == "ok", after
        assert "pending waits: 0 closed: False" in after.stdout
        assert "still live: x = " in after.stdout

        close = kernel.run(CELLS["close"])
        assert close.status == "ok", close
        assert close.stdout.strip() == "closed: True"
        # Closing twice is a no-op; the closed bus refuses new broadcasts clearly.
        twice = kernel.run(
            "await tf.aclose()\n"
            "try:\n"
            "    tf.broadcaster.send_transform_nowait(TransformStamped(Header(clock.now(), 'odom'),"
            " 'base_link', Transform(Vector3(0.0, 0.0, 0.0), Quaternion())))\n"
            "except Exception as exc:\n"
            "    print(type(exc).__name__)"
        )
        assert twice.status == "ok", twice
        assert twice.stdout.strip() == "ClosedResourceError"
