"""Fixtures shared by the ``tfbus view`` tests (tests/view/)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from tfbus.view.server import TfPage


@pytest.fixture(scope="session")
def chromium() -> str:
    """Debian's headless Chromium (installed by ``scripts/install/install_chromium.sh``
    when missing; a failure under ``CI=true``, a skip naming the script elsewhere): the
    path of its executable."""
    import shutil

    from peer_install import require

    require("chromium", "install_chromium.sh", timeout=2400)
    exe = shutil.which("chromium")
    assert exe is not None, "install_chromium.sh said ready, but chromium is not on PATH"
    return exe


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
