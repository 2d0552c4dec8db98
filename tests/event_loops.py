"""The event loops an async test runs on.

Every ``pytest.mark.anyio`` test runs on asyncio and on trio (``anyio_backend`` in
``conftest.py``). A module whose code under test takes asyncio shortcuts that depend on
the loop's implementation (its timers, its transports' writes; :mod:`tfbus._aio`) runs on
uvloop as well, by importing this module's fixture, whose name is ``anyio_backend``::

    from event_loops import anyio_backend_with_uvloop  # noqa: F401  (the fixture)

uvloop's timers count whole milliseconds and its transports are not ``asyncio.Transport``
subclasses: the two differences tfbus handles (:func:`tfbus._aio.timer_delay`,
:func:`tfbus._aio.asyncio_transport_of`). uvloop is in the ``test`` extra (CPython off
Windows, where it builds); elsewhere its runs are skipped, saying so. A test that asks
which backend runs reads ``anyio_backend_name`` (``"asyncio"`` on uvloop too).
"""

from __future__ import annotations

import importlib.util

import pytest

__all__ = ["UVLOOP", "anyio_backend_with_uvloop", "backends_with_uvloop", "uvloop_backend"]

UVLOOP = ("asyncio", {"use_uvloop": True})
"""anyio's asyncio backend on uvloop's event loop (anyio's ``use_uvloop`` option)."""


def backends_with_uvloop() -> list[object]:
    """The ``anyio_backend`` parameters of a module that also runs on uvloop: asyncio,
    trio and :data:`UVLOOP` (test id ``uvloop``)."""
    return ["asyncio", "trio", pytest.param(UVLOOP, id="uvloop")]


def uvloop_backend(param: object) -> object:
    """``param`` as the ``anyio_backend`` fixture's value; the uvloop run is skipped
    (saying why) where uvloop is not installed."""
    if param == UVLOOP and importlib.util.find_spec("uvloop") is None:
        pytest.skip("uvloop is not installed (the test extra installs it on CPython off Windows)")
    return param


@pytest.fixture(params=backends_with_uvloop(), scope="module", name="anyio_backend")
def anyio_backend_with_uvloop(request: pytest.FixtureRequest) -> object:
    """The ``anyio_backend`` of a module that imports it: asyncio, trio and uvloop
    (:func:`uvloop_backend`), each for the whole module."""
    return uvloop_backend(request.param)
