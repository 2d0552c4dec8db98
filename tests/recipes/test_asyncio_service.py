"""The asyncio.run recipe (examples/asyncio_service.py) as its own process: start-up,
awaited lookups, asyncio.timeout, and SIGTERM shutdown with nothing left waiting."""

from __future__ import annotations

import re
import sys

import pytest

from .proc import Child

pytestmark = pytest.mark.skipif(sys.version_info < (3, 11), reason="TaskGroup: Python 3.11+")


def test_service_answers_and_shuts_down_on_sigterm() -> None:
    child = Child("examples/asyncio_service.py")
    try:
        assert child.expect("gripper:") == "gripper: no transform within 0.5 s (known: False)"
        child.expect("ready")
        xs = []
        for _ in range(3):
            line = child.expect("base_link: x = ")
            found = re.search(r"x = (-?\d+\.\d+) m", line)
            assert found is not None
            xs.append(float(found.group(1)))
        assert xs == sorted(xs) and xs[0] >= 0.05  # 0.1 s ahead of a robot moving +x
        assert child.terminate() == 0
        child.expect("pending waits: 0")
        child.expect("closed")
        assert not any("Traceback" in line for line in child.seen), child.seen
    finally:
        child.kill()
