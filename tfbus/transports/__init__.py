"""Transports that carry a :class:`~tfbus.bus.Bus` across processes and machines.

* :mod:`tfbus.transports.zenoh` -- :class:`~tfbus.transports.zenoh.ZenohTransport`
  (needs the ``tfbus[zenoh]`` extra: ``eclipse-zenoh`` and ``msgspec``).
* :mod:`tfbus.transports.wire` -- the versioned msgspec wire format they share.
* :mod:`tfbus.transports.ros2` -- :class:`~tfbus.transports.ros2.Ros2Transport`: ``/tf``
  and ``/tf_static`` to and from ROS 2 nodes over DDS (needs the ``tfbus[ros2]`` extra:
  ``cyclonedds``); :mod:`tfbus.transports.ros2_wire` -- ROS 2's TFMessage on the DDS wire.

This package imports nothing optional itself: ``import tfbus.transports.zenoh`` is what
pulls in Zenoh (``import tfbus.transports.ros2``: cyclonedds). The in-memory
``MemoryTransport`` lives in :mod:`tfbus.bus`.
"""

__all__: list[str] = []
