"""Zenoh configuration of a tfbus transport: loopback-only defaults, files, overrides.

Networking defaults (no arguments): mode ``peer``, **multicast scouting off**, listen on
``tcp/127.0.0.1:7448`` (the rendezvous port, :data:`DEFAULT_PORT`) and connect to it. The
first tfbus process on the machine takes the port; later ones listen on an ephemeral
127.0.0.1 port, connect to the first and learn about each other through Zenoh's gossip,
so every process reaches every other one and the mesh survives the first one exiting.
Nothing leaves 127.0.0.1.

Multi-host: pass ``listen=["tcp/0.0.0.0:7448"]`` on one host and
``connect=["tcp/<that host>:7448"]`` on the others, or a Zenoh JSON5 configuration
file (``config="zenoh.json5"``) -- then the file rules (the defaults above are not
applied; explicit ``connect=``/``listen=`` still override it). TLS and access control
are plain Zenoh configuration: see ``docs/zenoh.md``.

Zenoh's own errors (``zenoh.ZError``: an unreadable file, a rejected value) are raised
as :class:`~tfbus.errors.TransportError` (the ``ZError`` is its ``__cause__``).
"""

from __future__ import annotations

import json
import logging
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import anyio
import anyio.to_thread
import zenoh

from tfbus.errors import TransportError

__all__ = ["DEFAULT_PORT", "ZenohConfigSource", "default_name", "zenoh_config"]

DEFAULT_PORT: Final = 7448
"""The local rendezvous port of the no-configuration defaults (``tcp/127.0.0.1:7448``)."""

ZenohConfigSource = str | os.PathLike[str] | Mapping[str, Any] | zenoh.Config
"""What ``config=`` accepts: a JSON5 file path, a ``zenoh.Config``, or a mapping of
config paths to JSON values applied on top of the defaults."""


def _endpoint_list(value: str | Sequence[str]) -> list[str]:
    return [value] if isinstance(value, str) else list(value)


def zenoh_config(
    *,
    connect: str | Sequence[str] | None = None,
    listen: str | Sequence[str] | None = None,
    config: ZenohConfigSource | None = None,
    port: int = DEFAULT_PORT,
) -> tuple[zenoh.Config, zenoh.Config | None]:
    """Build the Zenoh configuration of a transport: ``(config, fallback)``.

    Without ``connect``, ``listen`` and ``config`` this is the one-machine default: peer
    mode, multicast scouting off, listen on and connect to ``tcp/127.0.0.1:{port}``;
    ``fallback`` (used when that port is taken by another tfbus process) listens on
    ``tcp/127.0.0.1:0`` instead. Otherwise ``fallback`` is None.

    Args:
        connect: Zenoh endpoints to connect to (``"tcp/10.0.0.2:7448"``); retried in the
            background until they answer.
        listen: endpoints to listen on (default with ``connect`` alone:
            ``tcp/127.0.0.1:0``).
        config: a Zenoh JSON5 file path, a ``zenoh.Config``, or a mapping of config
            paths to JSON values (``{"transport/link/tx/lease": 3000}``) applied on top
            of the defaults. With a file or ``zenoh.Config``, the tfbus defaults are not
            applied (only explicit ``connect``/``listen``).
        port: the rendezvous port of the default configuration.

    Raises:
        TransportError: if the file cannot be read or a value is rejected by Zenoh.
        ValueError: if an endpoint list is empty where one is required, or ``port`` is
            not a TCP port (1..65535).
    """
    if isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= 65535:
        raise ValueError(f"port must be a TCP port number in 1..65535, got {port!r}")
    base_given = config is not None and not isinstance(config, Mapping)

    def build(listen_eps: list[str] | None, connect_eps: list[str] | None) -> zenoh.Config:
        cfg: zenoh.Config  # (typed: zenoh's stubs leave these Any under Python 3.10)
        if isinstance(config, zenoh.Config):
            cfg = zenoh.Config.from_json5(str(config))
        elif config is not None and not isinstance(config, Mapping):
            cfg = zenoh.Config.from_file(os.fspath(config))
        else:
            cfg = zenoh.Config()
        if not base_given:
            cfg.insert_json5("mode", '"peer"')
            cfg.insert_json5("scouting/multicast/enabled", "false")
            # Return from open() at once; links come up (and are retried) in background.
            cfg.insert_json5("open/return_conditions/connect_scouted", "false")
            cfg.insert_json5(
                "connect/retry",
                '{"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}',
            )
        if listen_eps is not None:
            cfg.insert_json5("listen/endpoints", json.dumps(listen_eps))
        if connect_eps is not None:
            cfg.insert_json5("connect/endpoints", json.dumps(connect_eps))
        if isinstance(config, Mapping):
            for key, value in config.items():
                cfg.insert_json5(key, json.dumps(value))
        return cfg

    try:
        if connect is None and listen is None and not base_given:
            hub = f"tcp/127.0.0.1:{port}"
            return build([hub], [hub]), build(["tcp/127.0.0.1:0"], [hub])
        listen_eps = _endpoint_list(listen) if listen is not None else None
        connect_eps = _endpoint_list(connect) if connect is not None else None
        if listen_eps is None and not base_given:
            listen_eps = ["tcp/127.0.0.1:0"]
        if connect_eps is None and not base_given:
            connect_eps = []
        return build(listen_eps, connect_eps), None
    except zenoh.ZError as err:
        raise TransportError(f"invalid Zenoh configuration: {err}") from err


def default_name() -> str:
    """``"<program>-<pid>"``: the node name a transport uses when none is given."""
    prog = Path(sys.argv[0]).stem if sys.argv and sys.argv[0] else "python"
    return f"{prog or 'python'}-{os.getpid()}"


UNREACHABLE: Final = "Unable to connect to any of"
"""Zenoh's error text when none of the ``connect`` endpoints answers (a client whose
router is not up): the one error :func:`open_waiting` waits out."""
CONNECT_RETRY_FIRST: Final = 0.25
"""Seconds before the first retry to open a session whose endpoints did not answer."""
CONNECT_RETRY_MAX: Final = 2.0
"""Longest wait between two retries, seconds."""
CONNECT_LOG_PERIOD: Final = 5.0
"""Seconds between two "waiting for a Zenoh router" log lines."""


def connect_endpoints(config: zenoh.Config) -> str:
    """The ``connect`` endpoints of ``config``, for a log line."""
    try:
        endpoints = json.loads(config.get_json("connect/endpoints"))
        return ", ".join(str(e) for e in endpoints) or "no endpoint"
    except (zenoh.ZError, ValueError, TypeError):
        return "the configured endpoints"


async def open_waiting(
    open_session: Callable[[], zenoh.Session],
    config: zenoh.Config,
    connect_timeout: float | None,
    log: logging.Logger,
) -> zenoh.Session:
    """Open a session with ``open_session`` (run in a worker thread; it raises
    :class:`~tfbus.errors.TransportError` with Zenoh's text), retrying while no ``connect``
    endpoint of ``config`` answers, as rmw_zenoh waits for its router: the first retry after
    :data:`CONNECT_RETRY_FIRST` s, then doubling up to :data:`CONNECT_RETRY_MAX` s, one
    warning line every :data:`CONNECT_LOG_PERIOD` s (none for a router that answers within
    the first retry), until ``connect_timeout`` seconds (None: for ever). Each attempt
    fails within milliseconds and the waits between them are cancellable (Ctrl-C ends a
    waiting command at once).

    Raises:
        TransportError: any other error of ``open_session``, or no endpoint answered
            within ``connect_timeout`` (the message names the option).
    """
    deadline = None if connect_timeout is None else anyio.current_time() + connect_timeout
    delay = CONNECT_RETRY_FIRST
    next_log = anyio.current_time() + CONNECT_RETRY_FIRST  # not for a router racing us
    while True:
        try:
            return await anyio.to_thread.run_sync(open_session)
        except TransportError as err:
            if UNREACHABLE not in str(err):
                raise
            now = anyio.current_time()
            if deadline is not None and now >= deadline:
                raise TransportError(
                    f"no Zenoh router or peer answered within {connect_timeout:g} s"
                    f" (connect_timeout): {err}"
                ) from err.__cause__
            if now >= next_log:
                next_log = now + CONNECT_LOG_PERIOD
                log.warning(
                    "waiting for a Zenoh router or peer at %s (is `tfbus router` running?);"
                    " still trying", connect_endpoints(config)
                )
            await anyio.sleep(delay if deadline is None else min(delay, deadline - now))
            delay = min(delay * 2, CONNECT_RETRY_MAX)
