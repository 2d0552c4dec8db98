"""Shared fixtures: every async test runs on asyncio and on trio (anyio's pytest plugin)."""

from __future__ import annotations

import pytest

from tfbus import _backend


def pytest_report_header() -> str:
    """Which core the run uses (``TFBUS_PURE_PYTHON=1`` selects the pure-Python one)."""
    kind = "compiled" if _backend.COMPILED else "pure-Python"
    return f"tfbus core: {kind} ({_backend.IMPLEMENTATION.__name__}), COMPILED={_backend.COMPILED}"


@pytest.fixture(params=["asyncio", "trio"], scope="module")
def anyio_backend(request: pytest.FixtureRequest) -> str:
    """The anyio backend of ``pytest.mark.anyio`` tests: each runs once per backend.

    Module scope, so module-scoped async fixtures (as in ``test_bag.py``) may use it.
    """
    return str(request.param)
