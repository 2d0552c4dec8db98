"""The ``ros1`` bus spec: ``ros1``, ``ros1:http://127.0.0.1:11311`` (master),
``ros1:master=http://127.0.0.1:11311&name=/planner&host=127.0.0.1&remote=1``.

The spec is parsed and its keys checked by :func:`tfbus.transports.spec.parse_bus_spec`
(the one ``--bus`` parser); this module turns its values into a :class:`Ros1Transport`.
Keys: ``master`` (master URI), ``name`` (node name), ``host`` (address to bind and
advertise), ``remote`` (a boolean: contact publishers outside loopback).
"""

from __future__ import annotations

import os
from typing import Any

from tfbus.transports.ros1.transport import Ros1Transport
from tfbus.transports.spec import BusSpec

__all__ = ["transport_from_spec"]


def transport_from_spec(spec: BusSpec, **overrides: Any) -> Ros1Transport:
    """The ``ros1`` row of the scheme table (:func:`tfbus.transports.spec.open_transport`).

    ``overrides`` may carry ``name`` (a CLI's default node name; ``-`` becomes ``_`` and
    the process id is appended), used when the spec gives none, and ``scan_topics``
    (:class:`Ros1Transport`'s: ``sensor_msgs/LaserScan`` topics to subscribe to) and
    ``clock_topic`` (:class:`Ros1Transport`'s: ``"/clock"`` for ``--use-sim-time``).

    Raises:
        ValueError: a value that is not understood (named: ``remote`` not a boolean, a bad
            node name or master URI).
        TypeError: an override other than ``name``, ``scan_topics`` and ``clock_topic``.
    """
    unknown = set(overrides) - {"name", "scan_topics", "clock_topic"}
    if unknown:
        raise TypeError(f"unexpected ros1 transport override(s): {', '.join(sorted(unknown))}")
    name = spec.value("name")
    default_name = overrides.get("name")
    if name is None and isinstance(default_name, str) and default_name:
        name = f"{default_name.replace('-', '_')}_{os.getpid()}"
    remote = spec.value("remote") or "0"
    if remote not in ("0", "1"):
        raise ValueError(f"ros1 option remote must be 0 or 1, got {remote!r}")
    return Ros1Transport(
        master_uri=spec.value("master"),
        node_name=name,
        host=spec.value("host"),
        allow_remote=remote == "1",
        scan_topics=tuple(overrides.get("scan_topics", ())),
        clock_topic=overrides.get("clock_topic"),
    )
