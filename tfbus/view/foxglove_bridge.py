"""``tfbus view --foxglove PORT``: the same transforms over the Foxglove WebSocket protocol
(the ``foxglove-sdk`` package; subprotocol ``foxglove.sdk.v1``), for Foxglove's 3D panel.

``/tf`` (and ``/tf_static``) go out as ``foxglove.FrameTransforms`` (parent, child,
translation, rotation x y z w, the header stamp as timestamp), scans as
``foxglove.LaserScan`` in their own frame, bag time as the server time (the ``time``
capability: Foxglove's timeline follows the bag), and each frame tf cannot place as a
warning status message (tf2's text), cleared when it can be placed again.

Who may connect: foxglove-sdk's server checks neither ``Origin`` nor ``Host``, so it
listens on a free port of 127.0.0.1 only, behind a front (:class:`_Front`) on ``host``:
``port`` that reads each connection's request head (at most :data:`MAX_HEAD` bytes in
:data:`HEAD_TIMEOUT` seconds, :data:`MAX_CONNECTIONS` at once) and checks it as the page
does (:class:`~tfbus.view.guard.PageGuard`, Foxglove's web app
``https://app.foxglove.dev`` let in too); a refused one gets ``403`` and is counted in
:attr:`FoxgloveBridge.guard`, the others are relayed byte for byte.

The SDK's own port is not a way around the front: the SDK serves it with TLS only
(``start_server(tls_cert=, tls_key=)``), with a key and a self-signed certificate made
for this run (:func:`_identity`) that only the front trusts. A page of another site that
finds the port cannot open it: ``ws://`` gets no WebSocket (the server speaks TLS) and
``wss://`` fails the browser's certificate check (no authority vouches for it; a browser
offers no way past that for a WebSocket). foxglove-sdk offers no hook that could refuse a
client by its headers (its ``ServerListener`` is called on subscriptions, not
connections) and no client authentication: a program running on this machine that skips
certificate checks can still connect to the port, as it could read the process's memory.
The SDK's error line for each such dropped connection becomes a count and one line every
:data:`~tfbus.view.guard.LOG_PERIOD` seconds at most.

Foxglove's ``Timestamp`` has uint32 seconds: a transform or scan stamped at or after
2**32 s (a Zenoh peer may send stamps up to 2**63 ns) is not sent, counted in
:attr:`FoxgloveBridge.dropped` and logged; the others are sent.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import ssl
import threading
import time
from collections.abc import Iterable
from typing import Any, Final

from tfbus.messages import TransformStamped
from tfbus.ratelimit import CountLimitedLog, RateLimitedLog
from tfbus.sensor_msgs import LaserScan
from tfbus.time import Time
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC
from tfbus.view.guard import LOG_PERIOD, PageGuard
from tfbus.view.scene import Scene

__all__ = ["FOXGLOVE_APP", "HEAD_TIMEOUT", "INNER_HOST", "MAX_CONNECTIONS", "MAX_HEAD",
           "FoxgloveBridge"]

FOXGLOVE_APP: Final = "https://app.foxglove.dev"
"""The origin of Foxglove's web app, let in by default."""
MAX_HEAD: Final = 16_384
"""Bytes of request head read at most before a connection is refused."""
HEAD_TIMEOUT: Final = 10.0
"""Seconds a connection has to send its request head."""
MAX_CONNECTIONS: Final = 64
"""Connections relayed at once; more are closed at once."""
INNER_HOST: Final = "127.0.0.1"
"""Where foxglove-sdk's own server listens (TLS only, behind the front)."""

_MAX_SEC: Final = 0xFFFF_FFFF  # foxglove.Timestamp.sec is a uint32
_log = CountLimitedLog(logging.getLogger("tfbus.view"), 1, period=5.0, clock=time.monotonic)


def _identity() -> tuple[bytes, bytes]:
    """A fresh TLS identity for one run of the SDK's server: a P-256 key (PKCS#8 PEM, as
    foxglove-sdk's ``tls_key`` wants) and a self-signed X.509 certificate (PEM) for
    ``127.0.0.1``, without a well-defined expiration date (RFC 5280 section 4.1.2.5:
    ``99991231235959Z``). Only the front trusts it; the key never leaves the process."""
    import datetime
    import ipaddress

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "tfbus view (one run)")])
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(datetime.datetime(2000, 1, 1, tzinfo=datetime.timezone.utc))
            .not_valid_after(datetime.datetime(9999, 12, 31, 23, 59, 59,
                                               tzinfo=datetime.timezone.utc))
            .add_extension(x509.SubjectAlternativeName(
                [x509.IPAddress(ipaddress.ip_address(INNER_HOST))]), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .sign(key, hashes.SHA256()))
    return (cert.public_bytes(serialization.Encoding.PEM),
            key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                              serialization.NoEncryption()))


def _trusting(cert_pem: bytes) -> ssl.SSLContext:
    """A TLS client context that trusts ``cert_pem`` and nothing else (the system's
    certificate authorities are not loaded), for ``127.0.0.1``."""
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)  # verifies the chain and the name
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    ctx.load_verify_locations(cadata=cert_pem.decode("ascii"))
    return ctx


_SDK_LINES: Final = (
    # (foxglove-sdk's line starts with, and contains) -> what it means here
    (("Dropping client", "handshake failed"),
     "dropped a connection not made through its front (no TLS with this run's certificate)"),
    (("Dropping client", ""), "dropped a client"),
    (("Error receiving from client", ""), "lost a client's connection"),
)
_SDK_LOGGERS: Final = ("foxglove.websocket.server", "foxglove.websocket.connected_client.poller")


class _SdkLog(logging.Filter):
    """foxglove-sdk logs an error line for each connection it drops (a client that does
    not complete the TLS handshake: one that went around the front) or loses (closed
    without a WebSocket close); they are counted in :data:`sdk_lines` and logged as one
    line per kind every :data:`~tfbus.view.guard.LOG_PERIOD` seconds at most instead."""

    def filter(self, record: logging.LogRecord) -> bool:
        msg = record.getMessage()
        for (start, part), meaning in _SDK_LINES:
            if msg.startswith(start) and part in msg:
                sdk_lines[meaning] = sdk_lines.get(meaning, 0) + 1
                _sdk_log.log(time.monotonic(), logging.WARNING,
                             f"tfbus view: foxglove server {meaning} (%s; %d so far)",
                             msg[:200], sdk_lines[meaning])
                return False
        return True


sdk_lines: dict[str, int] = {}
"""How many of foxglove-sdk's per-connection error lines this process counted instead of
printing, by meaning (``"dropped a connection not made through its front (...)"``,
``"dropped a client"``, ``"lost a client's connection"``)."""
_sdk_log = RateLimitedLog(logging.getLogger("tfbus.view"), period=LOG_PERIOD)
_sdk_filter = _SdkLog()


async def _pipe(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
    while data := await src.read(65536):
        dst.write(data)
        await dst.drain()


class _Front:
    """The listening socket on ``host:port`` in front of the SDK's loopback server: an
    asyncio loop in its own thread checks each connection's request head, then relays
    it to the SDK's server over TLS that trusts only this run's certificate."""

    def __init__(self, host: str, port: int, inner: int, guard_of: Any,
                 tls: ssl.SSLContext) -> None:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.sock = socket.socket(family, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.sock.bind((host, port))
        except OSError:
            self.sock.close()
            raise
        self.sock.listen(64)
        self.port: int = int(self.sock.getsockname()[1])
        self.inner = inner
        self._tls = tls
        self._guard_of = guard_of
        self._active: set[asyncio.Task[None]] = set()
        self._loop = asyncio.new_event_loop()
        self._started = threading.Event()
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=self._loop.run_until_complete,
                                        args=(self._main(),), name="tfbus-foxglove-front",
                                        daemon=True)
        self._error: BaseException | None = None
        self._thread.start()
        if not self._started.wait(30.0) or self._error is not None:
            self.close()
            raise OSError(f"the front did not start: {self._error!r}")

    async def _main(self) -> None:
        self._stop = asyncio.Event()
        try:
            server = await asyncio.start_server(self._accept, sock=self.sock, limit=MAX_HEAD)
        except Exception as err:  # reported by __init__
            self._error = err
            self._started.set()
            return
        self._started.set()
        try:
            await self._stop.wait()
        finally:
            server.close()
            for task in list(self._active):
                task.cancel()
            if self._active:
                await asyncio.wait(list(self._active), timeout=5.0)

    async def _accept(self, reader: asyncio.StreamReader,
                      writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if len(self._active) >= MAX_CONNECTIONS or task is None:
            writer.close()
            return
        self._active.add(task)
        try:
            await self._serve(reader, writer)
        except (OSError, asyncio.IncompleteReadError) as err:
            self._guard_of().note("failed_handshakes", type(err).__name__)
        except asyncio.CancelledError:
            # the front closing: the connection's task ends, not cancelled (asyncio's
            # streams would print the cancellation of a connection task as a traceback)
            pass
        finally:
            self._active.discard(task)
            writer.close()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        guard: PageGuard = self._guard_of()
        try:
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), HEAD_TIMEOUT)
        except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, asyncio.TimeoutError,
                OSError):
            guard.note("failed_handshakes", "no HTTP request head")
            return
        lines = head[:-4].decode("latin-1").split("\r\n")
        fields: dict[str, list[str]] = {}
        for line in lines[1:]:
            name, _, value = line.partition(":")
            fields.setdefault(name.strip().lower(), []).append(value.strip())
        parts = lines[0].split(" ")
        path = parts[1] if len(parts) == 3 else "/"

        def one(name: str) -> str | None:
            got = fields.get(name)
            return got[0] if got else None

        why = guard.check(one("host"), one("origin"), path, ", ".join(fields.get("cookie", [])))
        if why is not None:
            guard.note("refused", why)
            writer.write(b"HTTP/1.1 403 Forbidden\r\nContent-Length: 10\r\n"
                         b"Connection: close\r\n\r\nForbidden\n")
            await writer.drain()
            return
        try:
            up_reader, up_writer = await asyncio.wait_for(asyncio.open_connection(
                INNER_HOST, self.inner, ssl=self._tls, server_hostname=INNER_HOST,
                ssl_handshake_timeout=HEAD_TIMEOUT), HEAD_TIMEOUT)
        except (OSError, asyncio.TimeoutError) as err:  # ssl.SSLError is an OSError
            guard.note("failed_handshakes", f"foxglove server: {type(err).__name__}")
            return
        try:
            up_writer.write(head)
            ways = [asyncio.ensure_future(_pipe(reader, up_writer)),
                    asyncio.ensure_future(_pipe(up_reader, writer))]
            try:  # either side closing ends the relay (TLS has no half-close)
                await asyncio.wait(ways, return_when=asyncio.FIRST_COMPLETED)
            finally:
                for way in ways:
                    way.cancel()
                await asyncio.gather(*ways, return_exceptions=True)
        finally:
            up_writer.close()

    def close(self) -> None:
        stop = self._stop
        if stop is not None and not self._loop.is_closed():
            with contextlib.suppress(RuntimeError):  # its loop already ended
                self._loop.call_soon_threadsafe(stop.set)
        self._thread.join(timeout=10)
        if not self._thread.is_alive():
            self._loop.close()
        self.sock.close()


class FoxgloveBridge:
    """A Foxglove WebSocket server with a ``/tf`` channel (and one per scan topic).

    Args:
        host: address to bind (``127.0.0.1``: this machine only).
        port: TCP port (0: a free one; :attr:`port` says which).
        token: as the page's (:class:`~tfbus.view.guard.PageGuard`): lets a client in
            from any name when it carries ``?token=``.
        origins: browser origins let in besides this machine's (Foxglove's web app).

    Raises:
        ImportError: ``foxglove-sdk`` is not installed (``pip install 'tfbus[view]'``).
        OSError: the port cannot be bound.
        ValueError: a bad ``token``.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, *,
                 token: str | None = None,
                 origins: Iterable[str] = (FOXGLOVE_APP,)) -> None:
        import foxglove
        from foxglove.channels import FrameTransformsChannel
        from foxglove.websocket import Capability, ServerListener

        self._fg: Any = foxglove
        self.context: Any = foxglove.Context()
        self._static_wanted = threading.Event()
        wanted = self._static_wanted

        class _Listener(ServerListener):  # called on the SDK's thread
            def on_subscribe(self, _client: Any, channel: Any) -> None:
                if getattr(channel, "topic", None) == TF_STATIC_TOPIC:
                    wanted.set()

        origins = tuple(origins)
        self.guard: PageGuard = PageGuard(host, port, token, origins)  # bad token: no bind
        cert, key = _identity()
        for name in _SDK_LOGGERS:
            logging.getLogger(name).addFilter(_sdk_filter)  # once: the same filter
        try:
            self.server: Any = foxglove.start_server(
                name="tfbus view", host=INNER_HOST, port=0, capabilities=[Capability.Time],
                server_listener=_Listener(), context=self.context, tls_cert=cert,
                tls_key=key)
        except Exception as err:  # the SDK raises its own RuntimeError for a bind failure
            raise OSError(f"cannot serve Foxglove on {host}:{port}: {err}") from None
        self.inner_port: int = int(self.server.port)
        """The port of foxglove-sdk's own server on :data:`INNER_HOST` (TLS with this
        run's certificate: only the front can use it)."""
        try:
            self._front = _Front(host, port, self.inner_port, lambda: self.guard,
                                 _trusting(cert))
        except OSError as err:
            self.server.stop()
            raise OSError(f"cannot serve Foxglove on {host}:{port}: {err.strerror}") from None
        self.port: int = self._front.port
        self.guard = PageGuard(host, self.port, token, origins)  # port 0: the one bound
        """The ``Host`` / ``Origin`` / token check of the front and its counters."""
        self.tf: Any = FrameTransformsChannel(TF_TOPIC, context=self.context)
        self.tf_static: Any = None
        """The ``/tf_static`` channel, made by the first ``publish_transforms(static=True)``
        (a live bus; a bag's static transforms go out on ``/tf``)."""
        self.scans: dict[str, Any] = {}
        self._status: dict[str, str] = {}
        self.dropped = 0
        """Transforms and scans not sent: stamped at or after 2**32 s, which Foxglove's
        ``Timestamp`` (uint32 seconds) cannot carry."""

    @staticmethod
    def fits(stamp: Time) -> bool:
        """Whether Foxglove's ``Timestamp`` (uint32 seconds) can carry ``stamp``."""
        return stamp.sec <= _MAX_SEC

    def _drop(self, what: str, stamp: Time) -> None:
        self.dropped += 1
        _log.log(logging.WARNING, "foxglove: not sending %s stamped %d s (past uint32 "
                 "seconds)", what, stamp.sec)

    def publish_transforms(self, transforms: Iterable[TransformStamped], log_time_ns: int,
                           *, static: bool = False) -> None:
        """Send transforms on ``/tf`` (``/tf_static`` with ``static``) as one
        ``foxglove.FrameTransforms`` (log time: bag or receive time, nanoseconds); those
        that do not :meth:`fit <fits>` are left out and counted in :attr:`dropped`."""
        from foxglove.messages import (
            FrameTransform,
            FrameTransforms,
            Quaternion,
            Timestamp,
            Vector3,
        )

        out = []
        for t in transforms:
            if not self.fits(t.header.stamp):
                self._drop(f"the transform {t.header.frame_id!r:.80} -> "
                           f"{t.child_frame_id!r:.80}", t.header.stamp)
                continue
            v, q = t.transform.translation, t.transform.rotation
            out.append(FrameTransform(
                timestamp=Timestamp(sec=t.header.stamp.sec, nsec=t.header.stamp.nanosec),
                parent_frame_id=t.header.frame_id, child_frame_id=t.child_frame_id,
                translation=Vector3(x=v.x, y=v.y, z=v.z),
                rotation=Quaternion(x=q.x, y=q.y, z=q.z, w=q.w)))
        if not out:
            return
        channel = self.tf
        if static:
            self.advertise_static()
            channel = self.tf_static
        channel.log(FrameTransforms(transforms=out), log_time=log_time_ns)

    def advertise_static(self) -> None:
        """Advertise ``/tf_static`` now (before any static transform arrives), so a client
        can subscribe to it from the start."""
        if self.tf_static is None:
            from foxglove.channels import FrameTransformsChannel

            self.tf_static = FrameTransformsChannel(TF_STATIC_TOPIC, context=self.context)

    def take_static_request(self) -> bool:
        """Whether a client subscribed to ``/tf_static`` since the last call (the latest
        static transforms are then sent again: a late joiner gets them, as from a latched
        topic)."""
        if self._static_wanted.is_set():
            self._static_wanted.clear()
            return True
        return False

    def scan_channel(self, topic: str) -> Any:
        """The ``foxglove.LaserScan`` channel of ``topic``, advertised on first use."""
        from foxglove.channels import LaserScanChannel

        ch = self.scans.get(topic)
        if ch is None:
            ch = self.scans[topic] = LaserScanChannel(topic, context=self.context)
        return ch

    def publish_scan(self, topic: str, scan: LaserScan, log_time_ns: int) -> None:
        """Send a scan as ``foxglove.LaserScan`` in its own frame (identity pose, ranges
        and intensities as recorded, start/end angle = angle_min/angle_max); one that does
        not :meth:`fit <fits>` is not sent, counted in :attr:`dropped`."""
        from foxglove.messages import LaserScan as FgScan
        from foxglove.messages import Pose, Quaternion, Timestamp, Vector3

        ch = self.scan_channel(topic)
        s = scan.header.stamp
        if not self.fits(s):
            self._drop(f"a scan on {topic}", s)
            return
        ch.log(FgScan(
            timestamp=Timestamp(sec=s.sec, nsec=s.nanosec), frame_id=scan.header.frame_id,
            pose=Pose(position=Vector3(x=0.0, y=0.0, z=0.0),
                      orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
            start_angle=float(scan.angle_min), end_angle=float(scan.angle_max),
            ranges=[float(r) for r in scan.ranges],
            intensities=[float(i) for i in scan.intensities]), log_time=log_time_ns)

    def broadcast_time(self, time_ns: int) -> None:
        """The server time (bag time when playing a bag), nanoseconds."""
        self.server.broadcast_time(int(time_ns))

    def publish_errors(self, scene: Scene) -> None:
        """A warning status per frame tf cannot place (id: the frame id; tf2's message),
        sent when it changes; removed once the frame is placed again."""
        from foxglove.websocket import StatusLevel

        now = {f.frame_id: f"{f.frame_id}: {f.error}" for f in scene.frames
               if f.error is not None}
        for frame_id, message in now.items():
            if self._status.get(frame_id) != message:
                self.server.publish_status(message, StatusLevel.Warning, id=frame_id)
        gone = [k for k in self._status if k not in now]
        if gone:
            self.server.remove_status(gone)
        self._status = now

    def close(self) -> None:
        """Stop the server and its front."""
        self._front.close()
        self.server.stop()
