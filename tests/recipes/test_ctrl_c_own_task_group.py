"""Ctrl-C (a real SIGINT to the program's PID) in a program with its own anyio task group
inside ``Bus`` and ``TransformListener`` (``examples/ctrl_c_own_task_group.py``): with
``except* KeyboardInterrupt`` the program catches it on asyncio and on trio; a plain
``except KeyboardInterrupt`` catches it on asyncio and misses it on trio, where the
application's own task group leaves ``BaseExceptionGroup([KeyboardInterrupt()])``."""

from __future__ import annotations

import signal
import sys

import pytest

from .proc import Child

pytestmark = pytest.mark.skipif(sys.version_info < (3, 11),
                                reason="the example uses except* (Python 3.11+)")

EXAMPLE = "examples/ctrl_c_own_task_group.py"


def _interrupted(backend: str, mode: str) -> list[str]:
    if backend == "trio":
        pytest.importorskip("trio")
    child = Child(EXAMPLE, backend, mode)
    try:
        child.expect("READY")
        child.proc.send_signal(signal.SIGINT)
        assert child.proc.wait(60) == 0
        return child.rest()
    finally:
        child.kill()


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_except_star_catches_ctrl_c_on_both_backends(backend: str) -> None:
    lines = _interrupted(backend, "star")
    assert "stopped by Ctrl-C (except* KeyboardInterrupt)" in lines
    assert not any("Traceback" in line for line in lines), lines


def test_a_plain_except_catches_ctrl_c_on_asyncio() -> None:
    lines = _interrupted("asyncio", "plain")
    assert "stopped by Ctrl-C (except KeyboardInterrupt)" in lines


def test_a_plain_except_misses_ctrl_c_grouped_by_the_application_s_task_group_on_trio() -> None:
    lines = _interrupted("trio", "plain")
    assert any(line.startswith("not caught by except KeyboardInterrupt: BaseExceptionGroup(")
               and line.endswith("[KeyboardInterrupt()])") for line in lines), lines
