"""Zenoh's own router with tfbus's defaults (``tfbus router``): fleets through one hub.

A router is a Zenoh session opened in ``router`` mode (eclipse-zenoh's router, the one
``zenohd`` runs; tfbus never routes anything itself). Robots, base stations and viewers
then open their buses in client mode, connected to it::

    tfbus router --listen tcp/127.0.0.1:7447          # one hub
    tfbus echo map base_link --bus "zenoh:mode=client&connect=tcp/127.0.0.1:7447"

Defaults (no config file): listen on ``tcp/127.0.0.1:7447`` (Zenoh's router port,
:data:`ROUTER_PORT`), multicast and gossip scouting off -- nothing leaves 127.0.0.1
unless told with ``listen=``. With a JSON5 ``config`` file the file rules (its mode is
set to ``router``; explicit ``listen``/``connect`` still override it). TLS and access
control are Zenoh configuration: ``docs/zenoh.md``.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Sequence
from typing import Final

import anyio
import zenoh

from tfbus.errors import TransportError

__all__ = ["ROUTER_PORT", "ZenohRouter", "router_config"]

ROUTER_PORT: Final = 7447
"""Zenoh's router port, the default of ``tfbus router`` (``tcp/127.0.0.1:7447``)."""


def router_config(
    *,
    listen: str | Sequence[str] | None = None,
    connect: str | Sequence[str] | None = None,
    config: str | os.PathLike[str] | None = None,
) -> zenoh.Config:
    """The Zenoh configuration of a router with tfbus's defaults (module doc).

    Args:
        listen: endpoints to listen on (default ``tcp/127.0.0.1:7447``).
        connect: other routers to connect to (default none).
        config: a Zenoh JSON5 file; then its settings rule (mode forced to ``router``).

    Raises:
        TransportError: if the file cannot be read or Zenoh rejects a value.
    """
    try:
        cfg: zenoh.Config
        if config is not None:
            cfg = zenoh.Config.from_file(os.fspath(config))
        else:
            cfg = zenoh.Config()
            cfg.insert_json5("scouting/multicast/enabled", "false")
            cfg.insert_json5("scouting/gossip/enabled", "false")
            if listen is None:
                listen = f"tcp/127.0.0.1:{ROUTER_PORT}"
        cfg.insert_json5("mode", '"router"')
        for key, value in (("listen", listen), ("connect", connect)):
            if value is not None:
                endpoints = [value] if isinstance(value, str) else list(value)
                cfg.insert_json5(f"{key}/endpoints", json.dumps(endpoints))
        return cfg
    except zenoh.ZError as err:
        raise TransportError(f"invalid Zenoh router configuration: {err}") from err


class ZenohRouter:
    """A Zenoh router session, open inside ``async with ZenohRouter(...) as router:``.

    Args: as :func:`router_config`.

    Raises:
        TransportError: (on enter) the configuration is invalid or a listen endpoint
            cannot be bound (e.g. the port is taken); the ``ZError`` is the cause.
    """

    def __init__(
        self,
        *,
        listen: str | Sequence[str] | None = None,
        connect: str | Sequence[str] | None = None,
        config: str | os.PathLike[str] | None = None,
    ) -> None:
        self._config = router_config(listen=listen, connect=connect, config=config)
        self._session: zenoh.Session | None = None

    @property
    def zid(self) -> str:
        """The router's Zenoh id (hex) while open, else ``""``."""
        return "" if self._session is None else str(self._session.zid())

    @property
    def endpoints(self) -> list[str]:
        """The endpoints the router listens on, as configured."""
        value = json.loads(self._config.get_json("listen/endpoints"))
        if isinstance(value, dict):  # per-mode form {"router": [...], ...}
            value = value.get("router", [])
        return [str(v) for v in value]

    def peers(self) -> list[str]:
        """The Zenoh ids of the clients and peers linked to the router now."""
        session = self._session
        if session is None:
            return []
        info = session.info
        return [str(z) for z in (*info.peers_zid(), *info.routers_zid())]

    async def __aenter__(self) -> ZenohRouter:
        def open_session() -> zenoh.Session:
            try:
                return zenoh.open(self._config)
            except zenoh.ZError as err:
                raise TransportError(f"cannot start the Zenoh router: {err}") from err

        if self._session is not None:
            raise RuntimeError("this ZenohRouter is already open")
        self._session = await anyio.to_thread.run_sync(open_session)
        return self

    async def __aexit__(self, *exc: object) -> None:
        session, self._session = self._session, None
        if session is not None:
            with anyio.CancelScope(shield=True), contextlib.suppress(Exception):
                await anyio.to_thread.run_sync(session.close)
