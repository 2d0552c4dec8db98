"""Transports that carry a :class:`~tfbus.bus.Bus` across processes and machines.

* :mod:`tfbus.transports.zenoh` -- :class:`~tfbus.transports.zenoh.ZenohTransport`
  (needs the ``tfbus[zenoh]`` extra: ``eclipse-zenoh`` and ``msgspec``).
* :mod:`tfbus.transports.wire` -- the versioned msgspec wire format they share.

This package imports nothing optional itself: ``import tfbus.transports.zenoh`` is what
pulls in Zenoh. The in-memory ``MemoryTransport`` lives in :mod:`tfbus.bus`.
"""

__all__: list[str] = []
