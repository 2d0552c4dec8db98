"""MemoryTransport: two buses in one process, linked by memory object streams.

The in-memory :class:`~tfbus.bus.Transport` of the tests and the examples (httpx's
``MockTransport`` pattern): ``a, b = MemoryTransport.pair()``, then
``Bus(transport=a)`` and ``Bus(transport=b)`` see each other's publishes. It needs no
optional dependency (anyio only). Also re-exported as ``tfbus.MemoryTransport``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import anyio
import anyio.abc

if TYPE_CHECKING:
    from tfbus.transports._base import BusLike

__all__ = ["MemoryTransport"]


class MemoryTransport:
    """An in-memory transport: one end of a linked pair (httpx ``MockTransport``-style).

    ``a, b = MemoryTransport.pair()``; ``Bus(transport=a)`` and ``Bus(transport=b)``
    then see each other's publishes. Each end buffers messages for its peer in a memory
    object stream of ``max_buffer_size``; when that is full, ``send_nowait`` drops the
    message and counts it in :attr:`dropped` (it never blocks). Messages sent before the
    peer's bus opens wait in the buffer.
    """

    def __init__(self, max_buffer_size: float = math.inf) -> None:
        """Create an unlinked end; use :meth:`pair` (or :meth:`link`)."""
        send, receive = anyio.create_memory_object_stream[tuple[str, object]](max_buffer_size)
        self._inbox_send = send
        self._inbox_receive = receive
        self._peer: MemoryTransport | None = None
        self._running = False
        self.sent = 0
        """Messages handed to the peer."""
        self.dropped = 0
        """Messages dropped because the peer's buffer was full or closed."""
        self.delivered = 0
        """Messages injected into this end's bus."""

    @classmethod
    def pair(cls, max_buffer_size: float = math.inf) -> tuple[MemoryTransport, MemoryTransport]:
        """Two linked ends."""
        a, b = cls(max_buffer_size), cls(max_buffer_size)
        a.link(b)
        return a, b

    def link(self, peer: MemoryTransport) -> None:
        """Link this end and ``peer`` both ways."""
        self._peer = peer
        peer._peer = self

    async def run(
        self,
        bus: BusLike,
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Inject messages from the peer into ``bus`` until cancelled.

        Raises:
            RuntimeError: if this end is already running.
        """
        if self._running:
            raise RuntimeError("this MemoryTransport end is already running")
        self._running = True
        try:
            task_status.started()
            receive = self._inbox_receive
            while True:
                topic, message = await receive.receive()
                self.delivered += 1
                bus.deliver_nowait(topic, message)
        finally:
            self._running = False

    def send_nowait(self, topic: str, message: object) -> None:
        """Hand ``message`` to the peer's buffer; drop and count it if that is full."""
        peer = self._peer
        if peer is None:
            self.dropped += 1
            return
        try:
            peer._inbox_send.send_nowait((topic, message))
        except (anyio.WouldBlock, anyio.BrokenResourceError, anyio.ClosedResourceError):
            self.dropped += 1
        else:
            self.sent += 1

    def __repr__(self) -> str:
        return (
            f"<MemoryTransport sent={self.sent} delivered={self.delivered} dropped={self.dropped}>"
        )
