"""Transports that carry a :class:`~tfbus.bus.Bus` across processes and machines (layer 4).

* :mod:`tfbus.transports.memory` -- :class:`~tfbus.transports.memory.MemoryTransport`,
  two buses in one process (no dependency; also ``tfbus.MemoryTransport``).
* :mod:`tfbus.transports.zenoh` -- :class:`~tfbus.transports.zenoh.ZenohTransport`
  (needs the ``tfbus[zenoh]`` extra: ``eclipse-zenoh`` and ``msgspec``).
* :mod:`tfbus.transports.wire` -- the versioned msgspec wire format they share.
* :mod:`tfbus.transports.spec` -- ``--bus`` strings (``zenoh``, ``memory``, ...): one
  table of schemes, each transport module imported only when its scheme is used.

This package imports nothing optional itself: ``import tfbus.transports.zenoh`` is what
pulls in Zenoh.
"""

__all__: list[str] = []
