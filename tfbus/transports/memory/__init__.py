"""Two buses in one process, linked by memory object streams (no optional dependency).

* :mod:`~tfbus.transports.memory.transport` -- :class:`MemoryTransport` (also
  ``tfbus.MemoryTransport``);
* :mod:`~tfbus.transports.memory.options` -- the ``memory`` bus spec.
"""

from tfbus.transports.memory.transport import MemoryTransport

__all__ = ["MemoryTransport"]
