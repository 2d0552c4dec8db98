"""The ``memory`` bus spec (no options): an unlinked :class:`MemoryTransport` end.

The spec is parsed by :func:`tfbus.transports.spec.parse_bus_spec` (the one ``--bus``
parser); the scheme takes no key.
"""

from __future__ import annotations

from typing import Any

from tfbus.transports.memory.transport import MemoryTransport
from tfbus.transports.spec import BusSpec

__all__ = ["transport_from_spec"]


def transport_from_spec(spec: BusSpec, **overrides: Any) -> MemoryTransport:
    """The ``memory`` row of the scheme table (:func:`tfbus.transports.spec.open_transport`):
    an unlinked end, so the bus is private to this process (what it sends is counted in
    ``dropped``). ``overrides`` may give ``max_buffer_size``.

    Raises:
        TypeError: an override :class:`MemoryTransport` does not take.
    """
    return MemoryTransport(**overrides)
