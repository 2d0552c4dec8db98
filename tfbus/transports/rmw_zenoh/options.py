"""The ``rmw_zenoh`` bus spec: ``rmw_zenoh``, ``rmw_zenoh:tcp/10.0.0.2:7447`` (connect),
``rmw_zenoh:domain=7&connect=tcp/127.0.0.1:7447&namespace=robot1``.

The spec is parsed and its keys checked by :func:`tfbus.transports.spec.parse_bus_spec`;
this module turns its values into a :class:`RmwZenohTransport`. Keys: ``connect``
(endpoints, default ``tcp/127.0.0.1:7447``), ``listen`` (with ``mode=peer``), ``mode``
(``client``, the default, or ``peer``), ``domain`` (0..232; default ``ROS_DOMAIN_ID`` or
0), ``namespace`` (the node's ROS 2 namespace; ``*`` a fleet listener), ``name`` (the
node's name), ``attachment`` (``positional``, the default, or ``labelled``: the older
Jazzy form), ``connect_timeout`` (seconds to wait for the router; default: as long as it
takes).
"""

from __future__ import annotations

import math
from typing import Any

from tfbus.transports.rmw_zenoh.transport import RmwZenohTransport
from tfbus.transports.rmw_zenoh.wire import DOMAIN_ID_MAX
from tfbus.transports.spec import BusSpec

__all__ = ["transport_from_spec"]


def transport_from_spec(spec: BusSpec, **overrides: Any) -> RmwZenohTransport:
    """The ``rmw_zenoh`` row of the scheme table (:func:`tfbus.transports.spec.open_transport`).

    ``overrides`` may carry ``name`` (a command's node name, used when the spec names
    none).

    Raises:
        ValueError: a value that is not understood (named: ``domain`` not an integer in
            0..232, ``mode`` not client/peer, ``connect_timeout`` not finite seconds >= 0,
            a namespace or name that is not a ROS 2 name).
        TypeError: an override other than ``name``.
    """
    unknown = set(overrides) - {"name"}
    if unknown:
        raise TypeError(
            f"unexpected rmw_zenoh transport override(s): {', '.join(sorted(unknown))}")
    domain: int | None = None
    if spec.value("domain") is not None:
        domain = spec.integer("domain", 0, minimum=0, maximum=DOMAIN_ID_MAX)
    timeout: float | None = None
    text = spec.value("connect_timeout")
    if text is not None:
        try:
            timeout = float(text)
        except ValueError:
            timeout = -1.0
        if not 0 <= timeout < math.inf:
            raise ValueError(f"bus option 'connect_timeout' must be finite seconds >= 0, "
                             f"got {text!r}")
    connect = spec.values("connect")
    listen = spec.values("listen")
    return RmwZenohTransport(
        connect=list(connect) if connect else None,
        listen=list(listen) if listen else None,
        mode=spec.value("mode") or "client",
        domain_id=domain,
        namespace=spec.value("namespace") or "",
        name=spec.value("name") or overrides.get("name"),
        attachment=spec.value("attachment") or "positional",
        connect_timeout=timeout,
    )
