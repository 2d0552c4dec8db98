"""Who may read and drive ``tfbus view``'s page: the ``Host`` and ``Origin`` of every
request are checked against what the server serves, so that another web site the user
visits cannot read the frames or drive the bag's playback (a cross-site WebSocket, or DNS
rebinding: a name of the attacker's that resolves to 127.0.0.1).

* ``Host`` must be one of the names the page is served as (``localhost``, ``127.0.0.1``,
  ``[::1]`` and the ``--host`` given, with the port): a rebound name is refused (RFC 9110
  section 7.2; the check every local development server makes against rebinding).
* ``Origin``, when the browser sends one (it always does for a WebSocket, RFC 6455
  section 10.2, and for a cross-site request), must be ``http://`` one of those names.
  A client that is not a browser sends none and is let in.
* With a ``token`` (opt-in, for remote use: ``--host 0.0.0.0 --token SECRET``), a
  request that carries it (``?token=SECRET``, or the cookie set by the first such request)
  is let in whatever its ``Host``, as long as its ``Origin`` is the page's own (the same
  host and port as ``Host``); one without it is refused.

A refused request gets ``403 Forbidden`` and is counted (:attr:`PageGuard.refused`). A
connection that fails its opening handshake (opened and closed, not HTTP) and a
WebSocket that sends a message the page cannot read are counted
(:attr:`PageGuard.failed_handshakes`, :attr:`PageGuard.bad_messages`) and closed; each
kind is logged as one line at most every :data:`LOG_PERIOD` seconds, never as a
traceback.

The page is viser's server (websockets' asyncio server); :func:`install` wraps its
``serve`` once, in viser's module only: every viser server started afterwards checks
its requests with the :class:`PageGuard` registered for its port (none registered:
refused).
"""

from __future__ import annotations

import hmac
import http
import logging
import socket
import threading
import time
import types
import urllib.parse
from collections.abc import Callable, Iterable
from typing import Any, Final

from tfbus.errors import PortInUseError
from tfbus.ratelimit import RateLimitedLog

__all__ = ["COOKIE", "LOG_PERIOD", "LOOPBACK_NAMES", "PageGuard", "install"]

LOOPBACK_NAMES: Final = ("localhost", "127.0.0.1", "[::1]")
"""Names a page on this machine is always served as."""
COOKIE: Final = "tfbus_view_token"
"""The cookie holding the token once a request carried it in ``?token=``."""
LOG_PERIOD: Final = 5.0
"""Seconds between two lines about the same kind of refused or failed connection."""
_WILDCARDS: Final = ("", "0.0.0.0", "::", "[::]")

_log = RateLimitedLog(logging.getLogger("tfbus.view"), period=LOG_PERIOD)
_guards: dict[int, PageGuard] = {}
_lock = threading.Lock()


def _name(host: str) -> str:
    host = host.strip().lower()
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


class PageGuard:
    """The ``Host`` / ``Origin`` / token check of one page (module docstring).

    Args:
        host: the address served (``--host``); a wildcard (``0.0.0.0``, ``::``) adds no
            name: from another machine the page is reached with the token only.
        port: the TCP port served.
        token: the secret a remote browser must carry (None: no token, loopback only).
        origins: other origins let in (``https://app.foxglove.dev`` for the Foxglove
            server: Foxglove's web app is another origin by design).

    Raises:
        ValueError: ``token`` is empty, longer than 256 characters or not printable
            ASCII without spaces, ``;``, ``,`` or ``"`` (it goes in a cookie and a URL).
    """

    def __init__(self, host: str, port: int, token: str | None = None,
                 origins: Iterable[str] = ()) -> None:
        if token is not None and not (
            0 < len(token) <= 256
            and all(0x21 <= ord(c) < 0x7F and c not in ';,"\\' for c in token)
        ):
            raise ValueError("token must be 1-256 printable ASCII characters without "
                             f"spaces, ';', ',', '\"' or '\\\\', got {token!r:.40}")
        self.port = port
        self.token = token
        names = list(LOOPBACK_NAMES)
        if _name(host) not in _WILDCARDS and _name(host) not in names:
            names.append(_name(host))
        self.hosts: frozenset[str] = frozenset(f"{n}:{port}" for n in names)
        self.origins = frozenset(o.lower() for o in origins)
        """The ``Host`` values accepted without the token (name:port)."""
        self.refused = 0
        """Requests refused: a foreign ``Host`` or ``Origin``, no or a wrong token."""
        self.failed_handshakes = 0
        """Connections that failed their opening handshake (closed early, not HTTP)."""
        self.bad_messages = 0
        """WebSockets closed for a message the page could not read."""

    def _has_token(self, path: str, cookie: str) -> bool:
        if self.token is None:
            return False
        query = urllib.parse.parse_qs(urllib.parse.urlsplit(path).query)
        given = query.get("token", [])
        jar = {k.strip(): v.strip() for k, _, v in (c.partition("=") for c in cookie.split(";"))}
        if COOKIE in jar:
            given.append(jar[COOKIE])
        return any(hmac.compare_digest(g.encode(), self.token.encode()) for g in given)

    def check(self, host: str | None, origin: str | None, path: str = "/",
              cookie: str = "") -> str | None:
        """Why a request with these headers is refused, None when it may go on."""
        h = (host or "").strip().lower()
        if origin is not None and origin.lower() in self.origins:
            origin = None  # an origin let in: as a client that sends none
        if self._has_token(path, cookie):
            if origin is not None and origin != f"http://{h}" and origin != f"https://{h}":
                return f"Origin {origin!r:.80} is not the page's own"
            return None
        if self.token is not None and h not in self.hosts:
            return f"no token and Host {host!r:.80} is not this machine's"
        if h not in self.hosts:
            return f"Host {host!r:.80} is not a name this page is served as"
        if origin is not None and origin.lower() not in {f"http://{n}" for n in self.hosts}:
            return f"Origin {origin!r:.80} is another site"
        return None

    def note(self, kind: str, detail: str) -> None:
        """Count and log (one line per kind per :data:`LOG_PERIOD`) a refused request
        (``refused``), failed handshake or unreadable message."""
        setattr(self, kind, getattr(self, kind) + 1)
        _log.log(time.monotonic(), logging.WARNING,
                 f"tfbus view: {kind.replace('_', ' ')} on port %d (%s; %d so far)",
                 self.port, detail, getattr(self, kind))


def register(guard: PageGuard) -> None:
    """Check the requests reaching ``guard.port`` with ``guard``."""
    with _lock:
        _guards[guard.port] = guard


def unregister(guard: PageGuard) -> None:
    """Forget ``guard`` (its page was closed)."""
    with _lock:
        if _guards.get(guard.port) is guard:
            del _guards[guard.port]


def _guard_of(connection: Any) -> PageGuard | None:
    try:
        port = int(connection.local_address[1])
    except Exception:
        return None
    return _guards.get(port)


class _Drop(logging.Filter):
    """websockets' own records of a failed connection: counted, one line, no traceback."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < logging.ERROR:
            return False
        conn = getattr(record, "websocket", None)
        guard = _guard_of(conn) if conn is not None else None
        err = record.exc_info[1] if record.exc_info else None
        detail = f"{type(err).__name__}" if err is not None else record.getMessage()
        if guard is not None:
            guard.note("failed_handshakes", detail[:80])
        else:
            _log.log(time.monotonic(), logging.WARNING, "tfbus view: %s", detail[:80])
        return False


_ws_logger = logging.getLogger("tfbus.view.websocket")
_ws_logger.addFilter(_Drop())
_ws_logger.propagate = False


def _serve(real: Callable[..., Any]) -> Callable[..., Any]:
    def serve(handler: Callable[[Any], Any], host: Any = None, port: Any = None,
              **kw: Any) -> Any:
        inner = kw.pop("process_request", None)
        inner_response = kw.pop("process_response", None)

        def process_request(connection: Any, request: Any) -> Any:
            guard = _guard_of(connection)
            headers = request.headers
            why = "no page registered on this port" if guard is None else guard.check(
                headers.get("Host"), headers.get("Origin"), request.path,
                ", ".join(headers.get_all("Cookie")))
            if why is not None:
                if guard is not None:
                    guard.note("refused", why)
                return connection.respond(http.HTTPStatus.FORBIDDEN, "Forbidden\n")
            return inner(connection, request) if inner is not None else None

        def process_response(connection: Any, request: Any, response: Any) -> Any:
            guard = _guard_of(connection)
            if guard is not None and guard.token is not None and \
                    guard._has_token(request.path, ""):
                response.headers["Set-Cookie"] = (
                    f"{COOKIE}={guard.token}; Path=/; HttpOnly; SameSite=Strict")
            if inner_response is not None:
                return inner_response(connection, request, response)
            return None

        async def guarded(connection: Any) -> None:
            try:
                await handler(connection)
            except Exception as err:  # a message the page could not read
                guard = _guard_of(connection)
                if guard is not None:
                    guard.note("bad_messages", type(err).__name__)

        return real(guarded, host, port, process_request=process_request,
                    process_response=process_response, logger=_ws_logger, **kw)

    return serve


class _Shim(types.ModuleType):
    """A module forwarding every attribute to ``target`` but those given."""

    def __init__(self, target: types.ModuleType, **overrides: Any) -> None:
        super().__init__(target.__name__)
        self._target = target
        self.__dict__.update(overrides)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._target, name)


def install(modules: Iterable[types.ModuleType] = ()) -> None:
    """Make viser's page server (``viser.infra._infra``) check every request with the
    :class:`PageGuard` of its port; once (later calls do nothing)."""
    import websockets
    import websockets.asyncio.server as ws_server

    targets = list(modules)
    if not targets:
        from viser.infra import _infra

        targets = [_infra]
    for mod in targets:
        if isinstance(getattr(mod, "websockets", None), _Shim):
            continue
        server = _Shim(ws_server, serve=_serve(ws_server.serve))
        aio = _Shim(websockets.asyncio, server=server)
        mod.websockets = _Shim(websockets, asyncio=aio)  # type: ignore[attr-defined]


def check_port(host: str, port: int) -> None:
    """Bind ``host:port`` once and let it go, so that a server started on it next fails
    with one clear line rather than a traceback from inside its library (port 0: an
    ephemeral port, nothing to check).

    Raises:
        PortInUseError: the port is taken, or ``host`` is not an address of this machine
            (the message names both and the system's reason).
    """
    if port == 0:
        return
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
        try:
            s.bind((host, port))
        except OSError as err:
            raise PortInUseError(f"cannot serve on {host}:{port}: {err.strerror or err}") from None
