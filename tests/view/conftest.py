"""Fixtures shared by the ``tfbus view`` tests (tests/view/)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from tfbus.view.server import TfPage


@pytest.fixture
def page() -> Iterator[TfPage]:
    """A viser page on 127.0.0.1 at a free port, stopped after the test (needs the
    ``tfbus[view]`` extra: skipped without viser)."""
    pytest.importorskip("viser")
    from tfbus.view.server import TfPage

    p = TfPage("127.0.0.1", 0)
    try:
        yield p
    finally:
        p.close()
