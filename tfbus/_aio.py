"""Every shortcut tfbus takes through CPython's asyncio (one file to review per Python
release; anyio keeps its own in ``anyio/_backends/_asyncio.py``).

Each is used only when the running anyio backend is asyncio (callers check with
``tfbus.clock._base.running_asyncio_loop()``); trio and any other backend take the
portable anyio path. Sections by user; the lead merges the sections of the parallel
redesign helpers into this one file.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import cast

import anyio

__all__ = ["BufferedReadPump", "open_pumped_connection"]

_READ_SIZE = 65536
"""Bytes read per ``recv_into`` by a :class:`BufferedReadPump`."""


# -- transports: a TCP connection read in the event loop's callback (ROS 1 TCPROS) ---------


class BufferedReadPump(asyncio.BufferedProtocol):
    """Feeds a connection's bytes to a :class:`FrameSplitter` from asyncio's read
    callback; the first error (or the end) is kept in ``error`` and sets ``events``.

    A buffered protocol: the loop reads into one buffer kept for the connection
    (``recv_into``), where a plain :class:`asyncio.Protocol` gets a new ``bytes`` per read
    that asyncio allocates at its ``max_size`` of 256 KiB and then shrinks (measured here:
    ~16 us more per read of a 4.6 kB message). Used by the ROS 1 transport's TCPROS
    subscriber connections (``tfbus/transports/ros1/transport.py``)."""

    def __init__(self, feed: Callable[[memoryview], None], *events: anyio.Event) -> None:
        self._feed = feed
        self._events = events
        self._buffer = memoryview(bytearray(_READ_SIZE))
        self._transport: asyncio.Transport | None = None
        self.error: BaseException | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast("asyncio.Transport", transport)

    def get_buffer(self, sizehint: int) -> memoryview:
        return self._buffer

    def buffer_updated(self, nbytes: int) -> None:
        if self.error is not None:
            return
        try:
            # A view, not a copy: the splitter reads it (and copies only an incomplete
            # frame) before the loop reads into the buffer again.
            self._feed(self._buffer[:nbytes])
        except Exception as exc:  # malformed input or a refusal: this connection only
            self._end(exc)
            if self._transport is not None:
                self._transport.abort()

    def eof_received(self) -> bool:
        self._end(anyio.EndOfStream())
        return False

    def connection_lost(self, exc: Exception | None) -> None:
        self._end(exc if exc is not None else anyio.EndOfStream())

    def _end(self, exc: BaseException) -> None:
        if self.error is None:
            self.error = exc
        for event in self._events:
            event.set()


async def open_pumped_connection(
    loop: asyncio.AbstractEventLoop,
    host: str,
    port: int,
    feed: Callable[[memoryview], None],
    *events: anyio.Event,
) -> tuple[asyncio.Transport, BufferedReadPump]:
    """Connect to ``host:port`` with a :class:`BufferedReadPump` feeding ``feed`` from the
    loop's read callback (``loop.create_connection``); ``events`` are set when the
    connection ends or ``feed`` raises.

    Raises:
        OSError: the connection is refused or fails.
    """
    transport, pump = await loop.create_connection(
        lambda: BufferedReadPump(feed, *events), host, port
    )
    return transport, pump
