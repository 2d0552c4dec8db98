"""Transports that carry a :class:`~tfbus.bus.Bus` across processes and machines.

Every transport is a package of the same shape (``docs/architecture.md``, "Adding a
transport"): ``transport.py`` (the class), ``options.py`` (its ``--bus`` spec) and its own
parts. What they share is in :mod:`tfbus.transports._base`; their message codecs are in
:mod:`tfbus.codecs`.

* :mod:`tfbus.transports.memory` -- :class:`~tfbus.transports.memory.MemoryTransport`,
  two buses in one process (no dependency; also ``tfbus.MemoryTransport``).
* :mod:`tfbus.transports.zenoh` -- :class:`~tfbus.transports.zenoh.ZenohTransport`
  (needs the ``tfbus[zenoh]`` extra: ``eclipse-zenoh`` and ``msgspec``); its wire format
  is :mod:`tfbus.codecs.native`.
* :mod:`tfbus.transports.ros2` -- :class:`~tfbus.transports.ros2.Ros2Transport`: ``/tf``
  and ``/tf_static`` to and from ROS 2 nodes over DDS (needs the ``tfbus[ros2]`` extra:
  ``cyclonedds``); samples coded by :mod:`tfbus.codecs.cdr`.
* :mod:`tfbus.transports.ros1` -- :class:`~tfbus.transports.ros1.Ros1Transport`: tfbus as
  a ROS 1 node, TCPROS and the master's XML-RPC (needs ``tfbus[ros1]``: ``rosbags``);
  messages coded by :mod:`tfbus.codecs.ros1`.
* :mod:`tfbus.transports.spec` -- ``--bus`` strings (``zenoh``, ``memory``, ``ros2``,
  ``ros1``, ...): the one parser and opener, one table of schemes, each transport's
  ``options`` module imported only when its scheme is used.

This package imports nothing optional itself: ``import tfbus.transports.zenoh`` is what
pulls in Zenoh (``import tfbus.transports.ros2``: cyclonedds).
"""

__all__: list[str] = []
