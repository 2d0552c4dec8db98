"""Carry a :class:`~tfbus.bus.Bus`'s ``/tf`` and ``/tf_static`` (and, with ``clock_topic``,
``/clock``) to and from ROS 2 over DDS.

::

    from tfbus.bus import Bus
    from tfbus.transports.ros2 import Ros2Transport

    async with Bus(transport=Ros2Transport(domain_id=0)) as bus:   # this machine only
        ...

Needs the ``tfbus[ros2]`` extra (``cyclonedds``). One module per concern, as every
transport package (``docs/architecture.md``, "Adding a transport"):

* :mod:`~tfbus.transports.ros2.transport` -- :class:`Ros2Transport` and
  :class:`Ros2Statistics` (QoS, threads, receive path);
* :mod:`~tfbus.transports.ros2.options` -- the ``ros2`` bus spec
  (:func:`~tfbus.transports.ros2.options.transport_from_spec`);
* :mod:`~tfbus.transports.ros2.dds` -- DDS topic and type names, the ``IdlStruct`` types,
  :func:`cyclone_config`;
* :mod:`~tfbus.transports.ros2.action` -- tf2_ros's ``LookupTransform`` action over DDS
  (``buffer_server`` and ``BufferClient``) on the transport's participant: the
  :class:`~tfbus.transports._base.LookupServing` capability.

The samples are (de)serialised by :mod:`tfbus.codecs.cdr` and
:mod:`tfbus.codecs.lookup_action_cdr`.
"""

from tfbus._extras import require

require(__name__, "cyclonedds")

from tfbus.transports.ros2.dds import DOMAIN_ID_MAX, cyclone_config
from tfbus.transports.ros2.transport import (
    CLOCK_TYPE_HASH,
    TF_TYPE_HASH,
    Ros2Statistics,
    Ros2Transport,
)

__all__ = [
    "CLOCK_TYPE_HASH",
    "DOMAIN_ID_MAX",
    "TF_TYPE_HASH",
    "Ros2Statistics",
    "Ros2Transport",
    "cyclone_config",
]
