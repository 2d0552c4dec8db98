"""Writing tf messages to new bags that the ROS tools read, and recording a bus.

Through rosbags' writers: ROS 1 ``.bag`` (``rosbags.rosbag1.Writer``) and ROS 2 bag
folders with sqlite3 or MCAP storage (``rosbags.rosbag2.Writer``, bag version 8).
"""

from __future__ import annotations

import logging
import struct
import time as _wallclock
from collections.abc import Collection, Iterator, Sequence
from os import PathLike
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

from tfbus.bag.formats import DEFAULT_TOPICS, TF_STATIC_TOPIC, BagFormat, BagMessage
from tfbus.bag.reader import describe
from tfbus.codecs.ros1 import ROSBAGS_TF_TYPE, tf_typestore, to_rosbags
from tfbus.errors import BagError, BagFormatError
from tfbus.messages import TFMessage
from tfbus.ratelimit import CountLimitedLog
from tfbus.time import NSEC_PER_SEC, Time

if TYPE_CHECKING:
    from tfbus.bus import Bus, Subscription
    from tfbus.clock import Clock

__all__ = ["BagRecorder", "write_bag"]

_ROS1_MAX_SEC = 0xFFFF_FFFF  # a ROS 1 bag's record times are uint32 seconds
_log = CountLimitedLog(logging.getLogger(__name__), 1, period=5.0, clock=_wallclock.monotonic)


def _qos(static: bool) -> list[Any]:
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    never = QosTime(sec=9223372036, nsec=854775807)
    return [
        Qos(
            history=QosHistory.KEEP_LAST,
            depth=1 if static else 100,
            reliability=QosReliability.RELIABLE,
            durability=QosDurability.TRANSIENT_LOCAL if static else QosDurability.VOLATILE,
            deadline=never,
            lifespan=never,
            liveliness=QosLiveliness.AUTOMATIC,
            liveliness_lease_duration=never,
            avoid_ros_namespace_conventions=False,
        )
    ]


class _Writer:
    """Synchronous bag writer for TFMessages: ROS 1 .bag or ROS 2 (sqlite3 / mcap)."""

    def __init__(
        self,
        path: Path,
        fmt: BagFormat,
        callerid: str,
    ) -> None:
        self.path = path
        self.fmt = fmt
        self.ros1 = fmt is BagFormat.ROS1
        self.store = tf_typestore(ros1=self.ros1)
        self.callerid = callerid
        self.conns: dict[str, Any] = {}
        self.writer: Any = None
        self.count = 0

    def open(self) -> None:
        try:
            if self.ros1:
                from rosbags.rosbag1 import Writer as Writer1

                self.writer = Writer1(self.path)
            else:
                from rosbags.rosbag2 import StoragePlugin
                from rosbags.rosbag2 import Writer as Writer2

                plugin = (
                    StoragePlugin.MCAP if self.fmt is BagFormat.MCAP else StoragePlugin.SQLITE3
                )
                self.writer = Writer2(self.path, version=8, storage_plugin=plugin)
            self.writer.open()
        except Exception as err:
            raise BagError(f"{self.path}: cannot create bag: {describe(err)}", self.path) from None

    def _conn(self, topic: str) -> Any:
        conn = self.conns.get(topic)
        if conn is None:
            typ = ROSBAGS_TF_TYPE
            static = topic == TF_STATIC_TOPIC
            if self.ros1:
                conn = self.writer.add_connection(
                    topic, typ, typestore=self.store, callerid=self.callerid,
                    latching=1 if static else 0,
                )
            else:
                conn = self.writer.add_connection(
                    topic, typ, typestore=self.store, offered_qos_profiles=_qos(static)
                )
            self.conns[topic] = conn
        return conn

    def write(self, time: Time, topic: str, message: TFMessage) -> None:
        """Write one message at bag time ``time``.

        Raises:
            ValueError: a header stamp or ``time`` the format cannot hold (message
                stamps: int32 seconds as rosbags serializes them; a ROS 1 bag's times:
                uint32 seconds); nothing was written.
        """
        s = self.store
        msg = to_rosbags(s, message.transforms, ros1=self.ros1)
        typ = ROSBAGS_TF_TYPE
        try:
            raw = s.serialize_ros1(msg, typ) if self.ros1 else s.serialize_cdr(msg, typ)
        except (struct.error, OverflowError) as exc:
            raise ValueError(f"a stamp does not fit a {self.fmt.value} message: {exc}") from None
        # checked before rosbags' ROS 1 writer indexes the time (it would fail only later,
        # then again when closing the bag)
        if self.ros1 and time.ns // NSEC_PER_SEC > _ROS1_MAX_SEC:
            raise ValueError(f"bag time {time.ns // NSEC_PER_SEC} s is past a ROS 1 bag's "
                             "(uint32 seconds)")
        self.writer.write(self._conn(topic), time.ns, raw)
        self.count += 1

    def close(self) -> None:
        self.writer.close()


def _format_for(path: Path, fmt: str | BagFormat | None) -> BagFormat:
    if fmt is not None:
        try:
            return BagFormat(fmt)
        except ValueError:
            raise BagFormatError(
                f"unknown bag format {fmt!r} (use ros1, sqlite3 or mcap)", path
            ) from None
    if path.suffix == ".bag":
        return BagFormat.ROS1
    if path.suffix == ".mcap":
        return BagFormat.MCAP
    return BagFormat.SQLITE3


def write_bag(
    path: str | PathLike[str],
    messages: Iterator[BagMessage] | Sequence[BagMessage],
    *,
    format: str | BagFormat | None = None,
    callerid: str = "/tfbus_record",
) -> int:
    """Write tf messages to a new bag that ROS tools read.

    ``/tf_static`` is written latched (ROS 1 ``latching=1``) / transient-local with depth
    1 (ROS 2); ``/tf`` volatile, depth 100. The type is ``tf2_msgs/msg/TFMessage`` with
    the standard message definition and hashes.

    Args:
        path: ``*.bag`` for ROS 1; otherwise a ROS 2 bag folder to create (``format``
            ``"sqlite3"``, the default, or ``"mcap"``).
        messages: :class:`BagMessage` records (time = bag time to write).
        format: ``"ros1"``, ``"sqlite3"`` or ``"mcap"``; default from the path's suffix.
        callerid: ROS 1 caller id stored on the connections.

    Returns:
        The number of messages written.

    Raises:
        BagError: the path exists already or cannot be created.
        BagFormatError: unknown ``format``.
        ValueError: a header stamp or bag time the format cannot hold (message stamps
            are int32 seconds; a ROS 1 bag's times uint32 seconds); the messages before
            it are written and the bag closed.
    """
    p = Path(path)
    w = _Writer(p, _format_for(p, format), callerid)
    w.open()
    try:
        for rec in messages:
            w.write(rec.time, rec.topic, rec.message)
    finally:
        w.close()
    return w.count


class BagRecorder:
    """Record a bus's ``/tf`` and ``/tf_static`` to a bag while the ``async with`` lasts.

    Each message is written with the receive time read from ``clock`` (or the header
    stamp of its first transform when no clock is given). A message with a stamp or
    receive time the format cannot hold (message stamps are int32 seconds; a ROS 1 bag's
    times uint32 seconds) is counted in :attr:`dropped`, logged and not written. On exit
    the messages already delivered to the recorder are written and the bag is closed::

        async with Bus() as bus, BagRecorder(bus, "session.bag", clock=clock) as rec:
            ...
        print(rec.count)

    Args:
        bus: the bus to record.
        path: ``*.bag`` (ROS 1) or a ROS 2 bag folder (``format`` ``"sqlite3"``/``"mcap"``).
        clock: receive-time source; only its ``now()`` is read.
        format: ``"ros1"``, ``"sqlite3"`` or ``"mcap"``; default from the suffix.
        topics: the topics to record.
        queue_size: subscription queue per topic (a full queue drops its oldest message).

    Raises:
        BagError: the path exists already or cannot be created (on entry).
    """

    def __init__(
        self,
        bus: Bus,
        path: str | PathLike[str],
        *,
        clock: Clock | None = None,
        format: str | BagFormat | None = None,
        topics: Collection[str] = DEFAULT_TOPICS,
        callerid: str = "/tfbus_record",
        queue_size: int = 10_000,
    ) -> None:
        self.bus = bus
        self.queue_size = queue_size
        self.path = Path(path)
        self.clock = clock
        self.topics = tuple(topics)
        self._writer = _Writer(self.path, _format_for(self.path, format), callerid)
        self._subs: list[Subscription[Any]] = []
        self.dropped = 0
        """Messages not written: a stamp or receive time the bag format cannot hold."""

    @property
    def count(self) -> int:
        """Messages written so far."""
        return self._writer.count

    async def __aenter__(self) -> BagRecorder:
        import anyio

        self._writer.open()
        self._subs = [self.bus.subscribe(t, queue_size=self.queue_size) for t in self.topics]
        self._tg = anyio.create_task_group()
        await self._tg.__aenter__()
        for sub in self._subs:
            self._tg.start_soon(self._pump, sub)
        return self

    async def _pump(self, sub: Subscription[Any]) -> None:
        async for msg in sub:
            self._write(sub.topic, msg)

    def _write(self, topic: str, msg: Any) -> None:
        if not isinstance(msg, TFMessage):
            return
        if self.clock is not None:
            t = self.clock.now()
        elif msg.transforms:
            t = msg.transforms[0].header.stamp
        else:
            return
        try:
            self._writer.write(t, topic, msg)
        except ValueError as exc:  # only this message cannot be written
            self.dropped += 1
            _log.log(logging.WARNING, "%s: not recording a message on %s: %s", self.path,
                     topic, exc)

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        import anyio

        try:
            self._tg.cancel_scope.cancel()
            await self._tg.__aexit__(None, None, None)
            # Write what was delivered but not yet taken by the pumps.
            for sub in self._subs:
                while True:
                    try:
                        msg = sub.receive_nowait()
                    except (anyio.WouldBlock, anyio.EndOfStream, anyio.ClosedResourceError):
                        break
                    self._write(sub.topic, msg)
        finally:
            for sub in self._subs:
                sub.close()
            self._writer.close()
        return None
