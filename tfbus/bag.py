"""Read, replay and record ``/tf`` and ``/tf_static`` in ROS bags (layer 4).

Formats, all through `rosbags <https://gitlab.com/ternaris/rosbags>`_ (pure Python):

* ROS 1 ``.bag`` (v2.0; message types ``tf2_msgs/TFMessage`` and the legacy
  ``tf/tfMessage``, which has the same layout and MD5),
* ROS 2 sqlite3 (a bag folder with ``metadata.yaml``, or a bare ``.db3`` file),
* MCAP (a bag folder or a bare ``.mcap`` file).

Reading::

    for rec in read_messages("turtle.bag"):          # bag time, topic, TFMessage, authority
        print(rec.time, rec.topic, len(rec.message.transforms))
    core = load_buffer("turtle.bag")                 # BufferCore with every transform
    core.lookup_transform("world", "turtle1", Time(0))

Replaying onto a :class:`~tfbus.bus.Bus` while a :class:`~tfbus.clock.ManualClock` follows
bag time (``await replay(path, bus, clock=clock, rate=2.0)``), and recording a bus to a bag
that the ROS tools read (``async with BagRecorder(bus, "out.bag", clock=clock): ...``).

Speed: a ``TFMessage`` has had the same wire layout since ROS 1 Hydro, so when a
connection's type hash (ROS 1 MD5, ROS 2 RIHS01) is the standard one it is decoded by a
dedicated :mod:`struct` decoder (several times faster than a generic deserializer);
anything else goes through rosbags' typestore.

Damage: rosbags needs a bag's index (ROS 1) or summary (MCAP), which a truncated file lacks.
For those, this module scans the file record by record and returns everything before the
damage, then raises :class:`BagReadError` saying where reading stopped (byte offset and the
last bag time read). Every error this module raises is a :class:`BagError`.
"""

from __future__ import annotations

import gc
import importlib
import logging
import math
import sqlite3
import struct
import zlib
from collections.abc import Awaitable, Callable, Collection, Iterator, Sequence
from contextlib import suppress
from dataclasses import dataclass, field
from enum import StrEnum
from os import PathLike
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Final, Literal, NamedTuple

from tfbus.errors import BagError, BagFormatError, BagNotFoundError, BagReadError
from tfbus.messages import (
    Header,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import NSEC_PER_SEC, Time

if TYPE_CHECKING:
    from rosbags.interfaces import Connection
    from rosbags.typesys.store import Typestore

    from tfbus.bus import Bus, Subscription
    from tfbus.clock import ManualClock
    from tfbus.core import BufferCore

__all__ = [
    "DEFAULT_TOPICS",
    "ROS2_AUTHORITY",
    "TF_MSGTYPES",
    "TF_STATIC_TOPIC",
    "TF_TOPIC",
    "AuthoritySummary",
    "BagError",
    "BagFormat",
    "BagFormatError",
    "BagMessage",
    "BagNotFoundError",
    "BagReadError",
    "BagRecorder",
    "BagSummary",
    "FrameSummary",
    "detect_format",
    "load_buffer",
    "read_messages",
    "replay",
    "summarize",
    "write_bag",
]

log = logging.getLogger(__name__)

TF_TOPIC: Final = "/tf"
TF_STATIC_TOPIC: Final = "/tf_static"
DEFAULT_TOPICS: Final = (TF_TOPIC, TF_STATIC_TOPIC)

#: Message types carried on /tf and /tf_static (rosbags' normalised names).
TF_MSGTYPES: Final = frozenset({"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"})
#: ROS 1 MD5 of TFMessage (identical for tf2_msgs/TFMessage and tf/tfMessage).
_ROS1_TF_MD5: Final = "94810edda583a504dfda3829e70d7eec"
#: ROS 2 RIHS01 type hash of tf2_msgs/msg/TFMessage.
_ROS2_TF_RIHS01: Final = (
    "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
)
#: tf2_ros (ROS 2) has no per-message publisher: its listener uses this authority.
ROS2_AUTHORITY: Final = "Authority undetectable"

_ROS1_MAGIC: Final = b"#ROSBAG V2.0\n"
_MCAP_MAGIC: Final = b"\x89MCAP0\r\n"
_SQLITE_MAGIC: Final = b"SQLite format 3\x00"


# --------------------------------------------------------------------------- errors


def _fmt_time(t: Time) -> str:
    return f"{t.sec}.{t.nanosec:09d}"


# --------------------------------------------------------------------------- records


class BagMessage(NamedTuple):
    """One ``/tf`` or ``/tf_static`` message read from a bag.

    ``time`` is the bag (receive) time, ``topic`` the topic name, ``message`` the
    :class:`~tfbus.messages.TFMessage` as tfbus values, ``authority`` who sent it (ROS 1:
    the publisher's caller id; ROS 2: ``"Authority undetectable"`` as tf2_ros says).
    """

    time: Time
    topic: str
    message: TFMessage
    authority: str = ROS2_AUTHORITY

    @property
    def is_static(self) -> bool:
        """True for ``/tf_static`` (latched / transient-local) messages."""
        return self.topic == TF_STATIC_TOPIC


class BagFormat(StrEnum):
    """On-disk formats: ``ros1`` (.bag), ``sqlite3`` (ROS 2 .db3), ``mcap``."""

    ROS1 = "ros1"
    SQLITE3 = "sqlite3"
    MCAP = "mcap"


def detect_format(path: str | PathLike[str]) -> BagFormat:
    """Tell a bag's format from its magic bytes (a folder: from the files inside it).

    Raises:
        BagNotFoundError: the path does not exist.
        BagFormatError: not a ROS 1 bag, ROS 2 sqlite3 bag or MCAP file.
    """
    p = Path(path)
    if not p.exists():
        raise BagNotFoundError(f"{p}: no such file or directory", p)
    if p.is_dir():
        if not (p / "metadata.yaml").exists():
            raise BagFormatError(
                f"{p}: a folder but not a ROS 2 bag (no metadata.yaml)", p
            )
        files = sorted(x for x in p.iterdir() if x.suffix in (".db3", ".mcap"))
        if not files:
            raise BagFormatError(f"{p}: ROS 2 bag folder without .db3 or .mcap files", p)
        return detect_format(files[0])
    try:
        with p.open("rb") as f:
            head = f.read(16)
    except OSError as err:
        raise BagFormatError(f"{p}: cannot read: {err.strerror}", p) from None
    if head.startswith(_ROS1_MAGIC):
        return BagFormat.ROS1
    if head.startswith(_MCAP_MAGIC):
        return BagFormat.MCAP
    if head.startswith(_SQLITE_MAGIC):
        return BagFormat.SQLITE3
    if head.startswith(b"#ROSBAG"):
        raise BagFormatError(f"{p}: unsupported ROS bag version {head[:12]!r} (need V2.0)", p)
    raise BagFormatError(
        f"{p}: unknown format (not a ROS 1 .bag, ROS 2 .db3 or .mcap file)", p
    )


# --------------------------------------------------------------------------- decoding

_U32 = struct.Struct("<I")
_ROS1_HEAD = struct.Struct("<IIII")  # seq, sec, nsec, len(frame_id)
_F7LE = struct.Struct("<7d")
_F7BE = struct.Struct(">7d")

Decoder = Callable[[bytes | memoryview], list[TransformStamped]]


def _ts(
    ns: int, frame: str, child: str, v: tuple[float, ...]
) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), frame),
        child,
        Transform(Vector3(v[0], v[1], v[2]), Quaternion(v[3], v[4], v[5], v[6])),
    )


def _decode_ros1(raw: bytes | memoryview) -> list[TransformStamped]:
    """Decode a ROS 1 serialized TFMessage (little endian, Header with seq)."""
    buf = bytes(raw)
    (n,) = _U32.unpack_from(buf, 0)
    off = 4
    out: list[TransformStamped] = []
    append = out.append
    head = _ROS1_HEAD.unpack_from
    u32 = _U32.unpack_from
    f7 = _F7LE.unpack_from
    for _ in range(n):
        _seq, sec, nsec, flen = head(buf, off)
        off += 16
        frame = buf[off : off + flen].decode()
        off += flen
        (clen,) = u32(buf, off)
        off += 4
        child = buf[off : off + clen].decode()
        off += clen
        v = f7(buf, off)
        off += 56
        append(_ts(sec * NSEC_PER_SEC + nsec, frame, child, v))
    if off > len(buf):
        raise struct.error("message shorter than its contents")
    return out


def _decode_cdr(raw: bytes | memoryview) -> list[TransformStamped]:
    """Decode a CDR (ROS 2) serialized tf2_msgs/msg/TFMessage, either byte order."""
    buf = bytes(raw)
    little = buf[1] == 1
    e = "<" if little else ">"
    u32 = struct.Struct(e + "I").unpack_from
    ii = struct.Struct(e + "iII").unpack_from  # sec, nanosec, len(frame_id)
    f7 = (_F7LE if little else _F7BE).unpack_from
    (n,) = u32(buf, 4)
    off = 8  # absolute; CDR alignment is relative to byte 4
    out: list[TransformStamped] = []
    append = out.append
    for _ in range(n):
        off += -(off - 4) % 4
        sec, nsec, flen = ii(buf, off)
        off += 12
        frame = buf[off : off + flen - 1].decode()
        off += flen
        off += -(off - 4) % 4
        (clen,) = u32(buf, off)
        off += 4
        child = buf[off : off + clen - 1].decode()
        off += clen
        off += -(off - 4) % 8
        v = f7(buf, off)
        off += 56
        append(_ts(sec * NSEC_PER_SEC + nsec, frame, child, v))
    if off > len(buf):
        raise struct.error("message shorter than its contents")
    return out


def _from_rosbags(msg: Any) -> list[TransformStamped]:
    """Convert a rosbags-deserialized TFMessage object to tfbus values."""
    out = []
    for t in msg.transforms:
        st = t.header.stamp
        tr = t.transform.translation
        q = t.transform.rotation
        out.append(
            _ts(
                int(st.sec) * NSEC_PER_SEC + int(st.nanosec),
                str(t.header.frame_id),
                str(t.child_frame_id),
                (tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w),
            )
        )
    return out


def _typestore_for(conn: Connection) -> Typestore:
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    data = conn.msgdef.data
    if not data:
        store = get_typestore(Stores.ROS1_NOETIC if _is_ros1(conn) else Stores.ROS2_HUMBLE)
        if conn.msgtype == "tf/msg/tfMessage":
            store.register(get_types_from_msg(_TF_MSGDEF, "tf/msg/tfMessage"))
        return store
    if conn.msgdef.format.name == "IDL":
        store.register(get_types_from_idl(data))
    else:
        store.register(get_types_from_msg(data, conn.msgtype))
    return store


_TF_MSGDEF: Final = "geometry_msgs/TransformStamped[] transforms\n"


def _is_ros1(conn: Connection) -> bool:
    return type(conn.ext).__name__ == "ConnectionExtRosbag1"


def _decoder_for(conn: Connection) -> Decoder:
    """The fastest correct decoder for one connection's messages."""
    if _is_ros1(conn):
        if conn.digest == _ROS1_TF_MD5:
            return _decode_ros1
        store = _typestore_for(conn)

        def ros1_generic(raw: bytes | memoryview) -> list[TransformStamped]:
            return _from_rosbags(store.deserialize_ros1(raw, conn.msgtype))

        return ros1_generic
    fmt = getattr(conn.ext, "serialization_format", "cdr")
    if fmt != "cdr":
        raise ValueError(f"unsupported serialization format {fmt!r} on {conn.topic}")
    digest = conn.digest
    store = _typestore_for(conn)
    if not digest:
        with suppress(Exception):
            digest = store.hash_rihs01(conn.msgtype)
    if digest == _ROS2_TF_RIHS01:
        return _decode_cdr

    def cdr_generic(raw: bytes | memoryview) -> list[TransformStamped]:
        return _from_rosbags(store.deserialize_cdr(raw, conn.msgtype))

    return cdr_generic


# --------------------------------------------------------------------------- reading


def _tf_connections(connections: Sequence[Connection], topics: Collection[str]) -> list[Any]:
    return [c for c in connections if c.topic in topics and c.msgtype in TF_MSGTYPES]


def _authority(conn: Connection) -> str:
    if _is_ros1(conn):
        return str(getattr(conn.ext, "callerid", "") or "unknown_publisher")
    return ROS2_AUTHORITY


class _Source(NamedTuple):
    topic: str
    authority: str
    decode: Decoder


RawItem = tuple[int, _Source, bytes | memoryview]


def _raw_rosbags(
    p: Path, fmt: BagFormat, topics: Collection[str], start: int | None, stop: int | None
) -> Iterator[RawItem]:
    """Yield raw tf messages in bag-time order through rosbags' indexed readers."""
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag2 import Reader as Reader2

    reader: Any
    if fmt is BagFormat.ROS1:
        reader = Reader1(p)
    else:
        if p.is_file() and p.suffix not in (".db3", ".mcap"):
            want = ".db3" if fmt is BagFormat.SQLITE3 else ".mcap"
            raise BagFormatError(f"{p}: a {fmt.value} file must be named *{want}", p)
        reader = Reader2(p)
    with reader:
        conns = _tf_connections(reader.connections, topics)
        if not conns:  # rosbags: an empty filter means *every* message
            return
        sources = {id(c): _Source(c.topic, _authority(c), _decoder_for(c)) for c in conns}
        for conn, stamp, raw in reader.messages(connections=conns, start=start, stop=stop):
            yield stamp, sources[id(conn)], raw


def read_messages(
    path: str | PathLike[str],
    *,
    topics: Collection[str] = DEFAULT_TOPICS,
    start: Time | None = None,
    stop: Time | None = None,
    latched: bool = True,
) -> Iterator[BagMessage]:
    """Iterate a bag's ``/tf`` and ``/tf_static`` messages in bag-time order.

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder, or a ``.db3`` / ``.mcap`` file.
        topics: topic names to read; only ``tf2_msgs/TFMessage`` and ``tf/tfMessage``
            connections on them are used, every other topic is ignored.
        start: first bag time to yield (inclusive); ``None`` from the beginning.
        stop: bag time to stop at (exclusive); ``None`` to the end.
        latched: with ``start``, also yield the ``/tf_static`` messages recorded before
            ``start`` (stamped with their own bag time, first), as a latched /
            transient-local subscriber joining at ``start`` would receive them.

    Yields:
        :class:`BagMessage` (bag time, topic, TFMessage, authority).

    Raises:
        BagNotFoundError: the path does not exist.
        BagFormatError: not a bag format tfbus reads.
        BagReadError: truncated or corrupt; raised after every readable message has been
            yielded, saying where reading stopped.
    """
    p = Path(path)
    fmt = detect_format(p)
    topics = frozenset(topics)
    lo = None if start is None else start.ns
    hi = None if stop is None else stop.ns
    if lo is not None and latched and TF_STATIC_TOPIC in topics:
        yield from _read(p, fmt, frozenset({TF_STATIC_TOPIC}), None, lo)
    yield from _read(p, fmt, topics, lo, hi)


def _read(
    p: Path, fmt: BagFormat, topics: frozenset[str], lo: int | None, hi: int | None
) -> Iterator[BagMessage]:
    count = 0
    last: int | None = None

    def fail(reason: str, offset: int | None = None) -> BagReadError:
        return BagReadError(
            reason,
            p,
            offset=offset,
            last_time=None if last is None else Time.from_ns(last),
            messages_read=count,
        )

    raw_iter: Iterator[RawItem]
    try:
        raw_iter = _raw_rosbags(p, fmt, topics, lo, hi)
        first = next(raw_iter, None)
    except BagError:
        raise
    except Exception as err:
        # No usable index/summary (truncated ROS 1 or MCAP): scan record by record.
        if fmt is BagFormat.ROS1:
            raw_iter = _scan_ros1(p, topics, lo, hi)
        elif fmt is BagFormat.MCAP and p.is_file():
            raw_iter = _scan_mcap(p, topics, lo, hi)
        else:
            raise fail(_describe(err)) from None
        log.info("%s: index unreadable (%s); scanning records", p, _describe(err))
        first = None
        try:
            first = next(raw_iter, None)
        except _ScanError as scan_err:
            raise fail(scan_err.reason, scan_err.offset) from None
    if first is None:
        return
    item: RawItem | None = first
    while item is not None:
        stamp, src, raw = item
        try:
            transforms = src.decode(raw)
        except Exception as err:
            raise fail(f"corrupt {src.topic} message at bag time "
                       f"{_fmt_time(Time.from_ns(stamp))}: {_describe(err)}") from None
        yield BagMessage(Time.from_ns(stamp), src.topic, TFMessage(transforms), src.authority)
        count += 1
        last = stamp
        try:
            item = next(raw_iter, None)
        except _ScanError as err:
            raise fail(err.reason, err.offset) from None
        except BagError:
            raise
        except Exception as err:
            raise fail(_describe(err)) from None


def _describe(err: BaseException) -> str:
    if isinstance(err, sqlite3.DatabaseError):
        return f"sqlite3: {err}"
    text = str(err).strip() or type(err).__name__
    return text.rstrip(".")


# ----------------------------------------------------------- salvage (no index / summary)


class _ScanError(Exception):
    def __init__(self, reason: str, offset: int) -> None:
        super().__init__(reason)
        self.reason = reason
        self.offset = offset


def _ros1_header(data: bytes) -> dict[str, bytes]:
    fields: dict[str, bytes] = {}
    off = 0
    while off < len(data):
        (n,) = _U32.unpack_from(data, off)
        off += 4
        name, _, value = data[off : off + n].partition(b"=")
        fields[name.decode()] = value
        off += n
    return fields


def _scan_ros1(
    p: Path, topics: Collection[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    """Scan a ROS 1 bag record by record (chunks inline), for files without an index.

    Messages come in file order (= recording order for ``rosbag record``).
    """
    data = p.read_bytes()
    sources: dict[int, _Source | None] = {}

    def records(buf: bytes, base: int) -> Iterator[tuple[int, dict[str, bytes], bytes]]:
        off = 0
        while off < len(buf):
            if off + 4 > len(buf):
                raise _ScanError("truncated record header", base + off)
            (hlen,) = _U32.unpack_from(buf, off)
            if off + 4 + hlen + 4 > len(buf):
                raise _ScanError("truncated record header", base + off)
            try:
                head = _ros1_header(buf[off + 4 : off + 4 + hlen])
            except (struct.error, UnicodeDecodeError):
                raise _ScanError("corrupt record header", base + off) from None
            (dlen,) = _U32.unpack_from(buf, off + 4 + hlen)
            dstart = off + 8 + hlen
            if dstart + dlen > len(buf):
                if head.get("op") == b"\x05" and head.get("compression") == b"none":
                    # A cut uncompressed chunk: salvage its complete records first.
                    yield base + dstart, head, buf[dstart:]
                raise _ScanError("truncated record data", base + off)
            yield base + dstart, head, buf[dstart : dstart + dlen]
            off = dstart + dlen

    def handle(
        pos: int, head: dict[str, bytes], body: bytes
    ) -> Iterator[RawItem]:
        op = head.get("op", b"\x00")[0]
        if op == 0x07:  # connection
            conn_id = _U32.unpack_from(head["conn"])[0]
            topic = head["topic"].decode()
            cfields = _ros1_header(body)
            msgtype = cfields.get("type", b"").decode()
            md5 = cfields.get("md5sum", b"").decode()
            normalized = msgtype.replace("/", "/msg/", 1) if "/msg/" not in msgtype else msgtype
            if topic in topics and normalized in TF_MSGTYPES and md5 == _ROS1_TF_MD5:
                caller = cfields.get("callerid", b"").decode() or "unknown_publisher"
                sources[conn_id] = _Source(topic, caller, _decode_ros1)
            else:
                sources[conn_id] = None
        elif op == 0x02:  # message data
            conn_id = _U32.unpack_from(head["conn"])[0]
            src = sources.get(conn_id)
            if src is not None:
                sec, nsec = struct.unpack_from("<II", head["time"])
                stamp = sec * NSEC_PER_SEC + nsec
                if (lo is None or stamp >= lo) and (hi is None or stamp < hi):
                    yield stamp, src, body
        elif op == 0x05:  # chunk
            compression = head.get("compression", b"none").decode()
            if compression == "none":
                inner = body
            elif compression == "bz2":
                import bz2

                try:
                    inner = bz2.decompress(body)
                except (OSError, ValueError):
                    raise _ScanError("corrupt bz2 chunk", pos) from None
            elif compression == "lz4":
                try:
                    inner = importlib.import_module("lz4.frame").decompress(body)
                except Exception:
                    raise _ScanError("corrupt lz4 chunk", pos) from None
            else:
                raise _ScanError(f"unknown chunk compression {compression!r}", pos)
            for ipos, ihead, ibody in records(inner, pos):
                yield from handle(ipos, ihead, ibody)

    if not data.startswith(_ROS1_MAGIC):
        raise _ScanError("not a ROS 1 bag", 0)
    for pos, head, body in records(data[len(_ROS1_MAGIC) :], len(_ROS1_MAGIC)):
        yield from handle(pos, head, body)


def _scan_mcap(
    p: Path, topics: Collection[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    """Scan an MCAP file record by record, for files whose summary/footer is missing."""
    from rosbags.interfaces import (
        Connection,
        ConnectionExtRosbag2,
        MessageDefinition,
        MessageDefinitionFormat,
    )

    data = p.read_bytes()
    schemas: dict[int, tuple[str, str, str]] = {}  # id -> name, encoding, data
    sources: dict[int, _Source | None] = {}

    def string(buf: bytes, off: int) -> tuple[str, int]:
        (n,) = _U32.unpack_from(buf, off)
        return buf[off + 4 : off + 4 + n].decode(), off + 4 + n

    def handle(pos: int, op: int, rec: bytes) -> Iterator[RawItem]:
        if op == 0x03:  # schema
            (sid,) = struct.unpack_from("<H", rec, 0)
            name, off = string(rec, 2)
            enc, off = string(rec, off)
            (n,) = _U32.unpack_from(rec, off)
            schemas[sid] = (name, enc, rec[off + 4 : off + 4 + n].decode())
        elif op == 0x04:  # channel
            cid, sid = struct.unpack_from("<HH", rec, 0)
            topic, off = string(rec, 4)
            enc, off = string(rec, off)
            name, sdenc, sdata = schemas.get(sid, ("", "", ""))
            if topic in topics and name in TF_MSGTYPES and enc == "cdr":
                conn = Connection(
                    cid, topic, name,
                    MessageDefinition(
                        MessageDefinitionFormat.IDL if sdenc == "ros2idl"
                        else MessageDefinitionFormat.MSG, sdata),
                    "", 0, ConnectionExtRosbag2("cdr", []), None,
                )
                sources[cid] = _Source(topic, ROS2_AUTHORITY, _decoder_for(conn))
            else:
                sources[cid] = None
        elif op == 0x05:  # message
            cid, _seq, log_time, _pub = struct.unpack_from("<HIQQ", rec, 0)
            src = sources.get(cid)
            if src is not None and (lo is None or log_time >= lo) and (
                hi is None or log_time < hi
            ):
                yield log_time, src, rec[22:]
        elif op == 0x06:  # chunk
            _st, _et, usize, crc = struct.unpack_from("<QQQI", rec, 0)
            comp, off = string(rec, 28)
            (csize,) = struct.unpack_from("<Q", rec, off)
            body = rec[off + 8 : off + 8 + csize]
            try:
                if comp == "":
                    inner = body
                elif comp in ("zstd", "lz4"):
                    # rosbags' own MCAP chunk decompressors (zstd / lz4 frame).
                    from rosbags.rosbag2.storage_mcap import DECOMPRESSORS

                    inner = DECOMPRESSORS[comp](body, usize)
                else:
                    raise _ScanError(f"unknown chunk compression {comp!r}", pos)
            except _ScanError:
                raise
            except Exception:
                raise _ScanError(f"corrupt {comp} chunk", pos) from None
            if len(inner) != usize or (crc and zlib.crc32(inner) != crc):
                raise _ScanError("chunk checksum mismatch", pos)
            msgs: list[RawItem] = []
            for ipos, iop, irec in records(inner, pos):
                msgs.extend(handle(ipos, iop, irec))
            msgs.sort(key=lambda m: m[0])
            yield from msgs

    def records(buf: bytes, base: int) -> Iterator[tuple[int, int, bytes]]:
        off = 0
        while off < len(buf):
            if off + 9 > len(buf):
                raise _ScanError("truncated record", base + off)
            op = buf[off]
            (n,) = struct.unpack_from("<Q", buf, off + 1)
            if off + 9 + n > len(buf):
                raise _ScanError("truncated record", base + off)
            yield base + off, op, buf[off + 9 : off + 9 + n]
            off += 9 + n

    if not data.startswith(_MCAP_MAGIC):
        raise _ScanError("not an MCAP file", 0)
    for pos, op, rec in records(data[8:], 8):
        if op == 0x02:  # footer: done
            return
        try:
            yield from handle(pos, op, rec)
        except (struct.error, UnicodeDecodeError):
            raise _ScanError("corrupt record", pos) from None


# --------------------------------------------------------------------------- buffer


def load_buffer(
    path: str | PathLike[str],
    *,
    cache_time: float | None = None,
    topics: Collection[str] = DEFAULT_TOPICS,
    errors: Literal["raise", "warn"] = "raise",
) -> BufferCore:
    """Load every ``/tf`` and ``/tf_static`` transform of a bag into a new BufferCore.

    ``/tf_static`` transforms are stored with ``set_transform_static``, others with
    ``set_transform``; the authority is the publisher's caller id (ROS 1) or
    ``"Authority undetectable"`` (ROS 2).

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder, or a ``.db3`` / ``.mcap`` file.
        cache_time: cache length in seconds; default: the span of the recorded header
            stamps plus one second, so nothing is pruned and every sample can be looked up.
        topics: topics to read (default ``/tf`` and ``/tf_static``).
        errors: on a truncated / corrupt bag, ``"raise"`` raises :class:`BagReadError`
            whose ``partial`` holds the buffer with everything readable; ``"warn"`` logs a
            warning and returns that buffer.

    Raises:
        BagNotFoundError, BagFormatError: see :func:`read_messages`.
        BagReadError: truncated or corrupt bag (``errors="raise"``).
    """
    from tfbus.core import BufferCore

    statics: list[tuple[TransformStamped, str]] = []
    dynamics: list[tuple[list[TransformStamped], str]] = []
    lo_ns = hi_ns = None
    problem: BagReadError | None = None
    # Millions of small immutable objects and no cycles: the cyclic GC would rescan the
    # growing heap again and again (it tripled the load time), so pause it meanwhile.
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        for rec in read_messages(path, topics=topics):
            ts_list = list(rec.message.transforms)
            if rec.topic == TF_STATIC_TOPIC:
                statics.extend((ts, rec.authority) for ts in ts_list)
            elif ts_list:
                dynamics.append((ts_list, rec.authority))
                for ts in ts_list:
                    ns = ts.header.stamp.ns
                    if lo_ns is None or ns < lo_ns:
                        lo_ns = ns
                    if hi_ns is None or ns > hi_ns:
                        hi_ns = ns
        if cache_time is None:
            span = 0.0 if lo_ns is None or hi_ns is None else (hi_ns - lo_ns) / NSEC_PER_SEC
            cache_time = max(10.0, span + 1.0)
        core = BufferCore(cache_time=cache_time)
        _fill(core, statics, dynamics)
    except BagReadError as err:
        problem = err
        if cache_time is None:
            span = 0.0 if lo_ns is None or hi_ns is None else (hi_ns - lo_ns) / NSEC_PER_SEC
            cache_time = max(10.0, span + 1.0)
        core = BufferCore(cache_time=cache_time)
        _fill(core, statics, dynamics)
    finally:
        if gc_was_enabled:
            gc.enable()
    if problem is not None:
        problem.partial = core
        if errors == "raise":
            raise problem
        log.warning("%s", problem)
    return core


def _fill(
    core: BufferCore,
    statics: list[tuple[TransformStamped, str]],
    dynamics: list[tuple[list[TransformStamped], str]],
) -> None:
    from tfbus.errors import TransformException

    set_static = core.set_transform_static
    set_dynamic = core.set_transform
    bad = 0
    for ts, auth in statics:
        try:
            set_static(ts, auth)
        except TransformException:
            bad += 1
    for ts_list, auth in dynamics:
        for ts in ts_list:
            try:
                set_dynamic(ts, auth)
            except TransformException:
                bad += 1
    if bad:
        log.warning("%d invalid transform(s) in the bag were skipped", bad)


# --------------------------------------------------------------------------- summary


@dataclass
class FrameSummary:
    """Statistics of one child frame over a recording (or a live session).

    Stamps are header stamps in ns; ``delays`` are receive (bag) time minus header stamp
    in seconds, as tf_monitor measures them.
    """

    child: str
    parent: str
    static: bool
    authorities: dict[str, int] = field(default_factory=dict)
    count: int = 0
    first_stamp: int | None = None
    last_stamp: int | None = None
    delay_sum: float = 0.0
    delay_max: float = -math.inf

    @property
    def rate(self) -> float:
        """Average rate in Hz over the sample stamps (0.0 for static / single samples)."""
        if self.static or self.count < 2 or self.first_stamp is None or self.last_stamp is None:
            return 0.0
        span = (self.last_stamp - self.first_stamp) / NSEC_PER_SEC
        return (self.count - 1) / span if span > 0 else 0.0

    @property
    def authority(self) -> str:
        """The broadcaster that sent most of this frame's transforms."""
        return max(self.authorities, key=lambda a: self.authorities[a]) if self.authorities else ""

    @property
    def delay_avg(self) -> float:
        """Average receive delay, seconds (0.0 when nothing was counted)."""
        return self.delay_sum / self.count if self.count else 0.0

    @property
    def buffer_length(self) -> float:
        """Seconds between the oldest and the most recent sample."""
        if self.first_stamp is None or self.last_stamp is None:
            return 0.0
        return (self.last_stamp - self.first_stamp) / NSEC_PER_SEC


@dataclass
class AuthoritySummary:
    """Per broadcaster (authority): messages sent and their receive delays (seconds)."""

    authority: str
    messages: int = 0
    first: int | None = None
    last: int | None = None
    delay_sum: float = 0.0
    delay_count: int = 0
    delay_max: float = -math.inf

    @property
    def rate(self) -> float:
        """Messages per second of bag time (0.0 with fewer than two messages)."""
        if self.messages < 2 or self.first is None or self.last is None:
            return 0.0
        span = (self.last - self.first) / NSEC_PER_SEC
        return (self.messages - 1) / span if span > 0 else 0.0

    @property
    def delay_avg(self) -> float:
        """Average receive delay of its dynamic transforms, seconds."""
        return self.delay_sum / self.delay_count if self.delay_count else 0.0


@dataclass
class BagSummary:
    """What :func:`summarize` found: per-frame statistics and the recording's extent.

    ``start`` / ``end`` are bag times of the first and last tf message (``None`` if none),
    ``messages`` counts them per topic, ``frames`` maps child frame id to its summary.
    ``error`` is set when the bag was damaged (everything before it was summarised).
    """

    path: Path | None = None
    format: BagFormat | None = None
    start: Time | None = None
    end: Time | None = None
    messages: dict[str, int] = field(default_factory=dict)
    frames: dict[str, FrameSummary] = field(default_factory=dict)
    authorities: dict[str, AuthoritySummary] = field(default_factory=dict)
    error: BagReadError | None = None

    def add(self, rec: BagMessage) -> None:
        """Account for one message (from a bag or, later, a live bus)."""
        t = rec.time.ns
        if self.start is None or t < self.start.ns:
            self.start = rec.time
        if self.end is None or t > self.end.ns:
            self.end = rec.time
        self.messages[rec.topic] = self.messages.get(rec.topic, 0) + 1
        static = rec.topic == TF_STATIC_TOPIC
        auth = self.authorities.get(rec.authority)
        if auth is None:
            auth = self.authorities[rec.authority] = AuthoritySummary(rec.authority)
        auth.messages += 1
        if auth.first is None:
            auth.first = t
        auth.last = t
        frames = self.frames
        for ts in rec.message.transforms:
            child = ts.child_frame_id
            fs = frames.get(child)
            if fs is None or fs.static != static:
                fs = frames[child] = FrameSummary(child, ts.header.frame_id, static)
            fs.parent = ts.header.frame_id
            fs.count += 1
            fs.authorities[rec.authority] = fs.authorities.get(rec.authority, 0) + 1
            ns = ts.header.stamp.ns
            if fs.first_stamp is None or ns < fs.first_stamp:
                fs.first_stamp = ns
            if fs.last_stamp is None or ns > fs.last_stamp:
                fs.last_stamp = ns
            if not static:
                d = (t - ns) / NSEC_PER_SEC
                fs.delay_sum += d
                fs.delay_max = max(fs.delay_max, d)
                auth.delay_sum += d
                auth.delay_count += 1
                auth.delay_max = max(auth.delay_max, d)

    @property
    def duration(self) -> float:
        """Seconds between the first and last tf message (bag time)."""
        if self.start is None or self.end is None:
            return 0.0
        return (self.end.ns - self.start.ns) / NSEC_PER_SEC

    @property
    def transform_count(self) -> int:
        """Total number of transforms (every sample of every frame)."""
        return sum(f.count for f in self.frames.values())


def summarize(path: str | PathLike[str], *, topics: Collection[str] = DEFAULT_TOPICS) -> BagSummary:
    """Summarise a bag's tf data: frames, parents, rates, delays, span, static vs dynamic.

    A damaged bag is summarised up to the damage and the error stored in ``error``.

    Raises:
        BagNotFoundError, BagFormatError: see :func:`read_messages`.
    """
    summary = BagSummary(path=Path(path), format=detect_format(path))
    try:
        for rec in read_messages(path, topics=topics):
            summary.add(rec)
    except BagReadError as err:
        summary.error = err
    return summary


# --------------------------------------------------------------------------- replay


async def replay(
    path: str | PathLike[str],
    bus: Bus,
    *,
    clock: ManualClock | None = None,
    rate: float | None = 1.0,
    start: Time | None = None,
    stop: Time | None = None,
    topics: Collection[str] = DEFAULT_TOPICS,
    on_message: Callable[[BagMessage], object] | None = None,
    sleep: Callable[[float], Awaitable[object]] | None = None,
    monotonic: Callable[[], float] | None = None,
) -> int:
    """Publish a bag's tf messages on ``bus``, in order, at recorded timing times ``rate``.

    Before each message the ``clock`` (if given) is set to the message's bag time, so code
    awaiting on that clock (timers, ``Buffer`` timeouts) sees bag time, as ``rosbag play
    --clock`` does. Statics recorded before ``start`` are published first (latched).

    Args:
        path: the bag (see :func:`read_messages`).
        bus: where to publish (``/tf`` and ``/tf_static`` carry TFMessage).
        clock: a ManualClock to drive; it must not be ahead of the first bag time.
        rate: speed factor (2.0 = twice as fast); ``None`` or ``0`` = as fast as possible
            (still yielding to other tasks after every message).
        start, stop: bag-time window (``start`` inclusive, ``stop`` exclusive).
        topics: topics to replay.
        on_message: called after each message is published (progress bars).
        sleep, monotonic: wall-clock pacing, ``anyio.sleep`` and ``anyio.current_time``
            by default; tests inject fakes.

    Returns:
        The number of messages published.

    Raises:
        BagNotFoundError, BagFormatError: see :func:`read_messages`.
        BagReadError: damaged bag, raised after everything readable was published.
        ValueError: a negative ``rate``.
    """
    import anyio

    if rate is not None and rate < 0:
        raise ValueError(f"rate must be >= 0, got {rate}")
    pace = rate if rate else None
    do_sleep = sleep if sleep is not None else anyio.sleep
    now = monotonic if monotonic is not None else anyio.current_time
    t0_bag: int | None = None
    t0_wall = 0.0
    n = 0
    for rec in read_messages(path, topics=topics, start=start, stop=stop):
        if pace is not None:
            if t0_bag is None:
                t0_bag, t0_wall = rec.time.ns, now()
            due = t0_wall + (rec.time.ns - t0_bag) / NSEC_PER_SEC / pace
            delay = due - now()
            if delay > 0:
                await do_sleep(delay)
        if clock is not None and clock.now() < rec.time:
            await clock.set(rec.time)
        await bus.publish(rec.topic, rec.message)
        n += 1
        if on_message is not None:
            on_message(rec)
        if pace is None:
            await anyio.lowlevel.checkpoint()
    return n


# --------------------------------------------------------------------------- writing

_MCAP_OR_SQLITE = Literal["sqlite3", "mcap"]


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
        from rosbags.typesys import Stores, get_typestore

        self.path = path
        self.fmt = fmt
        self.ros1 = fmt is BagFormat.ROS1
        self.store = get_typestore(Stores.ROS1_NOETIC if self.ros1 else Stores.ROS2_HUMBLE)
        if "tf2_msgs/msg/TFMessage" not in self.store.types:  # ROS1_NOETIC lacks tf2_msgs
            from rosbags.typesys import get_types_from_msg

            self.store.register(get_types_from_msg(_TF_MSGDEF, "tf2_msgs/msg/TFMessage"))
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
            raise BagError(f"{self.path}: cannot create bag: {_describe(err)}", self.path) from None

    def _conn(self, topic: str) -> Any:
        conn = self.conns.get(topic)
        if conn is None:
            typ = "tf2_msgs/msg/TFMessage"
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
        s = self.store
        T = s.types
        Time_ = T["builtin_interfaces/msg/Time"]
        Header_ = T["std_msgs/msg/Header"]
        TS_ = T["geometry_msgs/msg/TransformStamped"]
        Tr_ = T["geometry_msgs/msg/Transform"]
        V_ = T["geometry_msgs/msg/Vector3"]
        Q_ = T["geometry_msgs/msg/Quaternion"]
        items = []
        for ts in message.transforms:
            st = ts.header.stamp
            stamp = Time_(sec=st.sec, nanosec=st.nanosec)
            head = (
                Header_(seq=0, stamp=stamp, frame_id=ts.header.frame_id)
                if self.ros1
                else Header_(stamp=stamp, frame_id=ts.header.frame_id)
            )
            tr, q = ts.transform.translation, ts.transform.rotation
            items.append(
                TS_(
                    header=head,
                    child_frame_id=ts.child_frame_id,
                    transform=Tr_(
                        translation=V_(x=float(tr.x), y=float(tr.y), z=float(tr.z)),
                        rotation=Q_(x=float(q.x), y=float(q.y), z=float(q.z), w=float(q.w)),
                    ),
                )
            )
        msg = T["tf2_msgs/msg/TFMessage"](transforms=items)
        typ = "tf2_msgs/msg/TFMessage"
        raw = s.serialize_ros1(msg, typ) if self.ros1 else s.serialize_cdr(msg, typ)
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
    stamp of its first transform when no clock is given). On exit the messages already
    delivered to the recorder are written and the bag is closed::

        async with Bus() as bus, BagRecorder(bus, "session.bag", clock=clock) as rec:
            ...
        print(rec.count)

    Args:
        bus: the bus to record.
        path: ``*.bag`` (ROS 1) or a ROS 2 bag folder (``format`` ``"sqlite3"``/``"mcap"``).
        clock: receive-time source (anything with ``now() -> Time``).
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
        clock: Any = None,
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
        self._writer.write(t, topic, msg)

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
