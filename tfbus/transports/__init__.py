"""Transports that carry a :class:`~tfbus.bus.Bus` across processes and machines (layer 4).

* :mod:`tfbus.transports.memory` -- :class:`~tfbus.transports.memory.MemoryTransport`,
  two buses in one process (no dependency; also ``tfbus.MemoryTransport``).
* :mod:`tfbus.transports.zenoh` -- :class:`~tfbus.transports.zenoh.ZenohTransport`
  (needs the ``tfbus[zenoh]`` extra: ``eclipse-zenoh`` and ``msgspec``).
* :mod:`tfbus.transports.wire` -- the versioned msgspec wire format Zenoh carries.
* :mod:`tfbus.transports.ros2` -- :class:`~tfbus.transports.ros2.Ros2Transport`: ``/tf``
  and ``/tf_static`` to and from ROS 2 nodes over DDS (needs the ``tfbus[ros2]`` extra:
  ``cyclonedds``); :mod:`tfbus.transports.ros2_wire` -- ROS 2's TFMessage on the DDS wire.
* :mod:`tfbus.transports.ros1` -- :class:`~tfbus.transports.ros1.Ros1Transport`: tfbus as
  a ROS 1 node, TCPROS and the master's XML-RPC (needs ``tfbus[ros1]``: ``rosbags``).
* :mod:`tfbus.transports.spec` -- ``--bus`` strings (``zenoh``, ``memory``, ``ros2``,
  ``ros1``, ...): one table of schemes, each transport module imported only when its
  scheme is used.

This package imports nothing optional itself: ``import tfbus.transports.zenoh`` is what
pulls in Zenoh (``import tfbus.transports.ros2``: cyclonedds).
"""

__all__: list[str] = []
