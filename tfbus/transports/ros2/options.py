"""The ``ros2`` bus spec: ``ros2``, ``ros2:7`` (domain), ``ros2:domain=7&interfaces=eth0,wlan0``.

The spec is parsed and its keys checked by :func:`tfbus.transports.spec.parse_bus_spec`
(the one ``--bus`` parser); this module turns its values into a :class:`Ros2Transport`.
Keys: ``domain`` (0..232; default ``ROS_DOMAIN_ID`` or 0), ``config`` (a Cyclone XML
file), ``interfaces`` and ``peers`` (lists, ``,``-separated or the key repeated: a robot
network instead of loopback).
"""

from __future__ import annotations

from typing import Any

from tfbus.transports.ros2.transport import Ros2Transport
from tfbus.transports.spec import BusSpec

__all__ = ["transport_from_spec"]


def transport_from_spec(spec: BusSpec, **overrides: Any) -> Ros2Transport:
    """The ``ros2`` row of the scheme table (:func:`tfbus.transports.spec.open_transport`).

    ``overrides`` may carry ``name`` (a CLI's node name), which DDS has no use for, and
    ``clock_topic`` (``"/clock"``: carry ``rosgraph_msgs/msg/Clock`` for a
    :class:`~tfbus.clock.SimClock`, as :class:`Ros2Transport`'s argument).

    Raises:
        ValueError: a value that is not understood (named: ``domain`` not an integer or
            outside 0..232, an empty list, an unreadable ``config``).
        TypeError: an override other than ``name`` and ``clock_topic``.
    """
    unknown = set(overrides) - {"name", "clock_topic"}
    if unknown:
        raise TypeError(f"unexpected ros2 transport override(s): {', '.join(sorted(unknown))}")
    domain_text = spec.value("domain")
    domain_id: int | None = None
    if domain_text is not None:
        try:
            domain_id = int(domain_text)
        except ValueError:
            raise ValueError(
                f"ros2 bus option 'domain' must be an integer, got {domain_text!r}"
            ) from None
    interfaces = spec.values("interfaces")
    peers = spec.values("peers")
    return Ros2Transport(
        domain_id=domain_id,
        config=spec.value("config"),
        interfaces=list(interfaces) if interfaces else None,
        peers=list(peers) if peers else None,
        clock_topic=overrides.get("clock_topic"),
    )
