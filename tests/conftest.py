"""Shared fixtures: every async test runs on asyncio and on trio (anyio's pytest plugin)."""

from __future__ import annotations

import pytest


@pytest.fixture(params=["asyncio", "trio"], scope="module")
def anyio_backend(request: pytest.FixtureRequest) -> str:
    """The anyio backend of ``pytest.mark.anyio`` tests: each runs once per backend.

    Module scope, so module-scoped async fixtures (as in ``test_bag.py``) may use it.
    """
    return str(request.param)
