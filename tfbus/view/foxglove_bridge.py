"""``tfbus view --foxglove PORT``: the same transforms over the Foxglove WebSocket protocol
(the ``foxglove-sdk`` package; subprotocol ``foxglove.sdk.v1``), for Foxglove's 3D panel.

``/tf`` (and ``/tf_static``) go out as ``foxglove.FrameTransforms`` (parent, child,
translation, rotation x y z w, the header stamp as timestamp), scans as
``foxglove.LaserScan`` in their own frame, bag time as the server time (the ``time``
capability: Foxglove's timeline follows the bag), and each frame tf cannot place as a
warning status message (tf2's text), cleared when it can be placed again.

Foxglove's ``Timestamp`` has uint32 seconds: a transform or scan stamped at or after
2**32 s (a Zenoh peer may send stamps up to 2**63 ns) is not sent, counted in
:attr:`FoxgloveBridge.dropped` and logged; the others are sent.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable
from typing import Any, Final

from tfbus.messages import TransformStamped
from tfbus.ratelimit import CountLimitedLog
from tfbus.sensor_msgs import LaserScan
from tfbus.time import Time
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC
from tfbus.view.scene import Scene

__all__ = ["FoxgloveBridge"]

_MAX_SEC: Final = 0xFFFF_FFFF  # foxglove.Timestamp.sec is a uint32
_log = CountLimitedLog(logging.getLogger("tfbus.view"), 1, period=5.0, clock=time.monotonic)


class FoxgloveBridge:
    """A Foxglove WebSocket server with a ``/tf`` channel (and one per scan topic).

    Args:
        host: address to bind (``127.0.0.1``: this machine only; no authentication).
        port: TCP port (0: a free one; :attr:`port` says which).

    Raises:
        ImportError: ``foxglove-sdk`` is not installed (``pip install 'tfbus[view]'``).
        OSError: the port cannot be bound.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8765) -> None:
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

        try:
            self.server: Any = foxglove.start_server(
                name="tfbus view", host=host, port=port, capabilities=[Capability.Time],
                server_listener=_Listener(), context=self.context)
        except Exception as err:  # the SDK raises its own RuntimeError for a bind failure
            raise OSError(f"cannot serve Foxglove on {host}:{port}: {err}") from None
        self.port: int = int(self.server.port)
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
        """Stop the server."""
        self.server.stop()
