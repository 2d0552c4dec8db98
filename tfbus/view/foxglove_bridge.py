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

Foxglove's ``Timestamp`` has uint32 seconds: a transform or scan stamped at or after
2**32 s (a Zenoh peer may send stamps up to 2**63 ns) is not sent, counted in
:attr:`FoxgloveBridge.dropped` and logged; the others are sent.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading
import time
from collections.abc import Iterable
from typing import Any, Final

from tfbus.messages import TransformStamped
from tfbus.ratelimit import CountLimitedLog
from tfbus.sensor_msgs import LaserScan
from tfbus.time import Time
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC
from tfbus.view.guard import PageGuard
from tfbus.view.scene import Scene

__all__ = ["FOXGLOVE_APP", "HEAD_TIMEOUT", "MAX_CONNECTIONS", "MAX_HEAD", "FoxgloveBridge"]

FOXGLOVE_APP: Final = "https://app.foxglove.dev"
"""The origin of Foxglove's web app, let in by default."""
MAX_HEAD: Final = 16_384
"""Bytes of request head read at most before a connection is refused."""
HEAD_TIMEOUT: Final = 10.0
"""Seconds a connection has to send its request head."""
MAX_CONNECTIONS: Final = 64
"""Connections relayed at once; more are closed at once."""

_MAX_SEC: Final = 0xFFFF_FFFF  # foxglove.Timestamp.sec is a uint32
_log = CountLimitedLog(logging.getLogger("tfbus.view"), 1, period=5.0, clock=time.monotonic)


def _pump(src: socket.socket, dst: socket.socket) -> None:
    try:
        while data := src.recv(65536):
            dst.sendall(data)
    except OSError:
        pass
    finally:
        with contextlib.suppress(OSError):
            dst.shutdown(socket.SHUT_WR)


class _Front:
    """The listening socket on ``host:port`` in front of the SDK's loopback server."""

    def __init__(self, host: str, port: int, inner: int, guard_of: Any) -> None:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.sock = socket.socket(family, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.sock.bind((host, port))
        except OSError:
            self.sock.close()
            raise
        self.sock.listen(64)
        self.sock.settimeout(0.2)
        self.port: int = int(self.sock.getsockname()[1])
        self.inner = inner
        self._guard_of = guard_of
        self._stop = threading.Event()
        self._slots = threading.BoundedSemaphore(MAX_CONNECTIONS)
        self._thread = threading.Thread(target=self._accept, name="tfbus-foxglove-front",
                                        daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            if not self._slots.acquire(blocking=False):
                conn.close()
                continue
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        guard: PageGuard = self._guard_of()
        try:
            conn.settimeout(HEAD_TIMEOUT)
            head = b""
            while b"\r\n\r\n" not in head:
                chunk = conn.recv(4096)
                if not chunk or len(head) + len(chunk) > MAX_HEAD:
                    guard.note("failed_handshakes", "no HTTP request head")
                    return
                head += chunk
            lines = head.split(b"\r\n\r\n", 1)[0].decode("latin-1").split("\r\n")
            fields: dict[str, list[str]] = {}
            for line in lines[1:]:
                name, _, value = line.partition(":")
                fields.setdefault(name.strip().lower(), []).append(value.strip())
            parts = lines[0].split(" ")
            path = parts[1] if len(parts) == 3 else "/"

            def one(name: str) -> str | None:
                got = fields.get(name)
                return got[0] if got else None

            why = guard.check(one("host"), one("origin"), path,
                              ", ".join(fields.get("cookie", [])))
            if why is not None:
                guard.note("refused", why)
                conn.sendall(b"HTTP/1.1 403 Forbidden\r\nContent-Length: 10\r\n"
                             b"Connection: close\r\n\r\nForbidden\n")
                return
            conn.settimeout(None)
            with socket.create_connection(("127.0.0.1", self.inner), timeout=5) as up:
                up.settimeout(None)
                up.sendall(head)
                back = threading.Thread(target=_pump, args=(up, conn), daemon=True)
                back.start()
                _pump(conn, up)
                back.join()
        except OSError as err:
            guard.note("failed_handshakes", type(err).__name__)
        finally:
            conn.close()
            self._slots.release()

    def close(self) -> None:
        self._stop.set()
        self.sock.close()
        self._thread.join(timeout=5)


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
        try:
            self.server: Any = foxglove.start_server(
                name="tfbus view", host="127.0.0.1", port=0, capabilities=[Capability.Time],
                server_listener=_Listener(), context=self.context)
        except Exception as err:  # the SDK raises its own RuntimeError for a bind failure
            raise OSError(f"cannot serve Foxglove on {host}:{port}: {err}") from None
        try:
            self._front = _Front(host, port, int(self.server.port), lambda: self.guard)
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
