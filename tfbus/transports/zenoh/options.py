"""The ``zenoh`` bus spec: :class:`ZenohOptions` for command lines and scripts.

Forms (parsed by :func:`tfbus.transports.spec.parse_bus_spec`, the one ``--bus`` parser;
this module only turns a parsed :class:`~tfbus.transports.spec.BusSpec` into a transport)::

    zenoh                                   one machine, no configuration
    zenoh:tcp/10.0.0.2:7448                 shorthand for connect=...
    zenoh:connect=tcp/10.0.0.2:7448,tcp/10.0.0.3:7448&name=planner
    zenoh?listen=tcp/0.0.0.0:7448&namespace=robot1
    zenoh?config=/etc/tfbus/zenoh.json5&name=planner

Keys: ``connect``, ``listen`` (endpoint lists), ``config`` (JSON5 file), ``prefix``,
``namespace`` (``*``: every robot, a fleet listener), ``name``, ``port`` (rendezvous
port), ``express`` (``1``/``true``), ``congestion_control`` (``drop``, the default, or
``block``: :class:`ZenohTransport`), ``mode`` (``peer`` or ``client``: ``client`` goes
through a Zenoh router, ``tfbus router``; with ``config`` the file's mode rules),
``connect_timeout`` (seconds to wait for the ``connect`` endpoints, e.g. a router not up
yet; default: wait as long as it takes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from tfbus.transports.spec import BusSpec
from tfbus.transports.zenoh.config import DEFAULT_PORT
from tfbus.transports.zenoh.keys import DEFAULT_PREFIX
from tfbus.transports.zenoh.transport import ZenohTransport

__all__ = ["ZenohOptions", "transport_from_spec"]


@dataclass(frozen=True, slots=True)
class ZenohOptions:
    """Everything a command line needs to build a Zenoh-backed bus (from a ``--bus`` spec).

    Attributes mirror :class:`ZenohTransport`'s arguments of the same names.
    """

    connect: tuple[str, ...] | None = None
    listen: tuple[str, ...] | None = None
    config: str | None = None
    prefix: str = DEFAULT_PREFIX
    namespace: str = ""
    name: str | None = None
    port: int = DEFAULT_PORT
    express: bool = False
    congestion_control: str = "drop"
    mode: str | None = None
    connect_timeout: float | None = None

    @classmethod
    def from_spec(cls, spec: BusSpec) -> ZenohOptions:
        """The options of a parsed ``zenoh`` spec.

        Raises:
            ValueError: if the scheme is not ``zenoh`` or a value is not understood.
        """
        if spec.scheme != "zenoh":
            raise ValueError(
                f"unsupported bus {spec.text or spec.scheme!r}: expected 'zenoh' or "
                "'zenoh?key=value&...'"
            )
        return cls(
            connect=spec.values("connect"),
            listen=spec.values("listen"),
            config=spec.value("config"),
            prefix=spec.value("prefix") or DEFAULT_PREFIX,
            namespace=spec.value("namespace") or "",
            name=spec.value("name"),
            port=spec.integer("port", DEFAULT_PORT, minimum=1, maximum=65535),
            express=spec.boolean("express"),
            congestion_control=_congestion(spec.value("congestion_control")),
            mode=_mode(spec.value("mode")),
            connect_timeout=_seconds(spec.value("connect_timeout")),
        )

    def transport(self, **overrides: Any) -> ZenohTransport:
        """A new :class:`ZenohTransport` from these options (``overrides`` win).

        Raises:
            ValueError: for an invalid prefix, namespace or name.
            TransportError: for an unreadable or invalid config file.
        """
        kwargs: dict[str, Any] = {
            "connect": self.connect,
            "listen": self.listen,
            "config": self.config,
            "prefix": self.prefix,
            "namespace": self.namespace,
            "name": self.name,
            "port": self.port,
            "express": self.express,
            "congestion_control": self.congestion_control,
            "connect_timeout": self.connect_timeout,
        }
        if self.mode is not None and self.config is None:
            kwargs["config"] = {"mode": self.mode}
        kwargs.update(overrides)
        return ZenohTransport(**kwargs)


def _mode(value: str | None) -> str | None:
    if value is not None and value not in _MODES:
        raise ValueError(f"mode must be one of {', '.join(_MODES)}, got {value!r}")
    return value


_MODES = ("peer", "client")


def _seconds(value: str | None) -> float | None:
    if value is None:
        return None
    try:
        seconds = float(value)
    except ValueError:
        seconds = math.nan
    if not 0 <= seconds < math.inf:
        raise ValueError(f"connect_timeout must be finite seconds >= 0, got {value!r}")
    return seconds


def _congestion(value: str | None) -> str:
    if value is None:
        return "drop"
    if value not in ("drop", "block"):
        raise ValueError(f"congestion_control must be drop or block, got {value!r}")
    return value


def transport_from_spec(spec: BusSpec, **overrides: Any) -> ZenohTransport:
    """The ``zenoh`` row of the scheme table (:func:`tfbus.transports.spec.open_transport`).

    Raises:
        ValueError: an option value that is not understood.
        TransportError: an unreadable or invalid config file.
    """
    return ZenohOptions.from_spec(spec).transport(**overrides)
