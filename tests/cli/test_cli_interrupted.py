"""Ctrl-C reaches the command line either as ``KeyboardInterrupt`` or, raised inside a
task group (trio delivers SIGINT to whichever task runs), grouped; both are Ctrl-C (exit
130, no traceback), anything else beside it is not."""

from __future__ import annotations

import sys

import pytest

from tfbus.cli._common import interrupted

if sys.version_info < (3, 11):
    from exceptiongroup import BaseExceptionGroup, ExceptionGroup


def test_a_grouped_keyboard_interrupt_is_ctrl_c() -> None:
    assert interrupted(KeyboardInterrupt())
    assert interrupted(BaseExceptionGroup("tasks", [KeyboardInterrupt()]))
    nested = BaseExceptionGroup("outer", [BaseExceptionGroup("inner", [KeyboardInterrupt()]),
                                          KeyboardInterrupt()])  # fmt: skip
    assert interrupted(nested)


@pytest.mark.parametrize(
    "err",
    [
        ValueError("x"),
        SystemExit(1),
        BaseExceptionGroup("tasks", [KeyboardInterrupt(), ValueError("x")]),
        ExceptionGroup("tasks", [ValueError("x")]),
    ],
)
def test_anything_else_is_not(err: BaseException) -> None:
    assert not interrupted(err)
