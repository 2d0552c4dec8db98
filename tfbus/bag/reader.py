"""Reading a bag's ``/tf`` and ``/tf_static`` messages in bag-time order.

Which library reads what:

* ROS 1 ``.bag`` and ROS 2 bag folders / ``.db3`` files: rosbags' indexed readers;
* a bare ``.mcap`` file: the format's own ``mcap`` package (``SeekingReader`` through the
  summary; a file written without a summary is read from the start).

When the index or summary is unreadable (a truncated file), reading falls back to
:mod:`tfbus.bag.salvage`, which returns everything before the damage. Whatever goes
wrong, the caller gets every readable message first, then one :class:`BagReadError`
naming the file, the byte offset where known and the last bag time read.
"""

from __future__ import annotations

import contextlib
import logging
import mmap
import sqlite3
from collections.abc import Collection, Iterator, Sequence
from heapq import heappop, heappush
from itertools import count
from os import PathLike
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, cast

from tfbus.bag.decode import RawItem, Source, cdr_decoder, ros1_decoder
from tfbus.bag.formats import (
    DEFAULT_TOPICS,
    ROS2_AUTHORITY,
    TF_MSGTYPES,
    TF_STATIC_TOPIC,
    BagFormat,
    BagMessage,
    detect_format,
    fmt_time,
)
from tfbus.bag.salvage import ScanError, mcap_channel_source, scan_mcap, scan_ros1
from tfbus.errors import BagError, BagFormatError, BagReadError
from tfbus.messages import TFMessage
from tfbus.time import Time

if TYPE_CHECKING:
    from rosbags.interfaces import Connection

__all__ = ["read_messages"]

log = logging.getLogger(__name__)


def describe(err: BaseException) -> str:
    """One line saying what went wrong, for a :class:`BagReadError`'s reason."""
    if isinstance(err, sqlite3.DatabaseError):
        return f"sqlite3: {err}"
    if isinstance(err, ScanError):
        return err.reason
    text = " ".join(str(err).split()) or type(err).__name__
    return text.rstrip(".")


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
        :class:`BagMessage` (bag time, topic, TFMessage, authority). A damaged file
        (truncated, or with no index) is read in file order up to the damage.

    Raises:
        BagNotFoundError: the path does not exist.
        BagFormatError: not a bag format tfbus reads.
        BagReadError: truncated or corrupt; raised after every readable message has been
            yielded, saying where reading stopped (byte offset, last bag time). No other
            exception escapes a read.
    """
    p = Path(path)
    fmt = detect_format(p)
    topics = frozenset(topics)
    lo = None if start is None else start.ns
    hi = None if stop is None else stop.ns
    if lo is not None and latched and TF_STATIC_TOPIC in topics:
        yield from _read(p, fmt, frozenset({TF_STATIC_TOPIC}), None, lo)
    yield from _read(p, fmt, topics, lo, hi)


# --------------------------------------------------------------------------- sources


def _is_ros1(conn: Connection) -> bool:
    return type(conn.ext).__name__ == "ConnectionExtRosbag1"


def _rosbags_source(conn: Connection) -> Source:
    """How to decode one rosbags connection (ROS 1 or ROS 2)."""
    if _is_ros1(conn):
        callerid = str(getattr(conn.ext, "callerid", "") or "unknown_publisher")
        return Source(conn.topic, callerid, ros1_decoder(conn.msgtype, conn.digest,
                                                         conn.msgdef.data))
    fmt = getattr(conn.ext, "serialization_format", "cdr")
    if fmt != "cdr":
        raise ValueError(f"unsupported serialization format {fmt!r} on {conn.topic}")
    decode = cdr_decoder(conn.msgtype, conn.msgdef.data,
                         idl=conn.msgdef.format.name == "IDL", digest=conn.digest)
    return Source(conn.topic, ROS2_AUTHORITY, decode)


def _raw_rosbags(
    p: Path, fmt: BagFormat, topics: Collection[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    """Raw tf messages in bag-time order through rosbags' indexed readers."""
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag2 import Reader as Reader2

    reader: Any
    if fmt is BagFormat.ROS1:
        reader = Reader1(p)
    else:
        if p.is_file() and p.suffix != ".db3":
            raise BagFormatError(f"{p}: a {fmt.value} file must be named *.db3", p)
        reader = Reader2(p)
    with reader:
        conns: Sequence[Connection] = [
            c for c in reader.connections if c.topic in topics and c.msgtype in TF_MSGTYPES
        ]
        if not conns:  # rosbags: an empty filter means *every* message
            return
        sources = {id(c): _rosbags_source(c) for c in conns}
        for conn, stamp, raw in reader.messages(connections=conns, start=lo, stop=hi):
            yield stamp, sources[id(conn)], raw, None


def _raw_mcap(
    p: Path, topics: Collection[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    """Raw tf messages of an MCAP file in log-time order, through its summary.

    ``mcap``'s SeekingReader reads the summary; the chunks that hold tf are read and
    decompressed (CRC checked) by ``mcap``'s ``Chunk.read`` / ``breakup_chunk``, in order
    of their first log time, and merged by log time on a heap of plain tuples (ties: the
    order of the chunks, then of the records). This is the ordering SeekingReader's
    ``iter_messages(log_time_order=True)`` gives, at a third of its cost: its queue
    compares entries in Python. A file written without a summary (or with no chunk
    index) is read from the start by :func:`~tfbus.bag.salvage.scan_mcap`, which also
    stops at any damage it finds.
    """
    from mcap.data_stream import ReadDataStream
    from mcap.reader import SeekingReader
    from mcap.records import Chunk, Message
    from mcap.stream_reader import breakup_chunk

    with p.open("rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        stream = cast("IO[bytes]", mm)
        summary = SeekingReader(stream, record_size_limit=len(mm)).get_summary()
        if summary is None or not summary.chunk_indexes:
            yield from scan_mcap(p, topics, lo, hi)
            return
        sources: dict[int, Source] = {}
        for channel in summary.channels.values():
            schema = summary.schemas.get(channel.schema_id)
            src = mcap_channel_source(channel, schema, topics)
            if src is not None:
                sources[channel.id] = src
        if not sources:
            return
        chunks = sorted(
            (
                c for c in summary.chunk_indexes
                if (lo is None or c.message_end_time >= lo)
                and (hi is None or c.message_start_time < hi)
                and (not c.message_index_offsets or not sources.keys().isdisjoint(
                    c.message_index_offsets))
            ),
            key=lambda c: (c.message_start_time, c.chunk_start_offset),
        )
        heap: list[tuple[int, int, int, bytes]] = []
        seq = count()
        for index in chunks:
            # Nothing in this chunk or a later one is older than its first log time.
            while heap and heap[0][0] < index.message_start_time:
                t, _n, cid, data = heappop(heap)
                yield t, sources[cid], data, None
            mm.seek(index.chunk_start_offset + 9)  # opcode (1) + record length (8)
            chunk = Chunk.read(ReadDataStream(stream))
            for record in breakup_chunk(chunk, validate_crc=True):
                if (
                    isinstance(record, Message)
                    and record.channel_id in sources
                    and (lo is None or record.log_time >= lo)
                    and (hi is None or record.log_time < hi)
                ):
                    heappush(heap, (record.log_time, next(seq), record.channel_id, record.data))
        while heap:
            t, _n, cid, data = heappop(heap)
            yield t, sources[cid], data, None


# --------------------------------------------------------------------------- reading


def _indexed(
    p: Path, fmt: BagFormat, topics: frozenset[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    if fmt is BagFormat.MCAP and p.is_file():
        if p.suffix != ".mcap":
            raise BagFormatError(f"{p}: an mcap file must be named *.mcap", p)
        return _raw_mcap(p, topics, lo, hi)
    return _raw_rosbags(p, fmt, topics, lo, hi)


def _salvage(
    p: Path, fmt: BagFormat, topics: frozenset[str], lo: int | None, hi: int | None
) -> Iterator[RawItem] | None:
    """The record-by-record reader for ``p``, or ``None`` when there is none."""
    if fmt is BagFormat.ROS1:
        return scan_ros1(p, topics, lo, hi)
    if fmt is BagFormat.MCAP:
        files = [p] if p.is_file() else sorted(
            p.glob("*.mcap"), key=lambda x: (len(x.name), x.name)
        )
        return _chain_mcap(files, topics, lo, hi)
    return None


def _chain_mcap(
    files: list[Path], topics: frozenset[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    for f in files:
        try:
            yield from scan_mcap(f, topics, lo, hi)
        except ScanError as err:
            if len(files) > 1:
                raise ScanError(f"{f.name}: {err.reason}", err.offset) from None
            raise


def locate_damage(p: Path, fmt: BagFormat) -> int | None:
    """Byte offset of the first damage a record-by-record read finds, if any."""
    scan = _salvage(p, fmt, frozenset(), None, None)
    if scan is None:
        return None
    try:
        for _ in scan:
            pass
    except ScanError as err:
        return err.offset
    except Exception:
        return None
    return None


def locate_message(
    p: Path, fmt: BagFormat, topics: frozenset[str], stamp: int, raw: bytes | memoryview
) -> int | None:
    """Byte offset of the message with bag time ``stamp`` and payload ``raw``, found by a
    record-by-record read (a compressed ROS 1 chunk gives the chunk's offset)."""
    scan = _salvage(p, fmt, topics, stamp, stamp + 1)
    if scan is None:
        return None
    want = bytes(raw)
    try:
        for _stamp, _src, data, offset in scan:
            if bytes(data) == want:
                return offset
    except Exception:
        return None
    return None


def _kind(value: object) -> str:
    """What a damaged bag time is, for a message: ``a BLOB b'\\x01'``, ``a REAL 2.5``."""
    kind = {bytes: "a BLOB", float: "a REAL", str: "a TEXT", type(None): "NULL"}.get(
        type(value), f"a {type(value).__name__}")
    text = repr(value)
    return kind if value is None else f"{kind} {text[:40]}{'...' if len(text) > 40 else ''}"


def _db3_files(p: Path) -> list[Path]:
    """The sqlite3 files of a ROS 2 bag: ``p`` itself, or the ``*.db3`` in its folder."""
    return [p] if p.is_file() else sorted(p.glob("*.db3"))


def _sqlite_record(p: Path, fmt: BagFormat, stamp: object, raw: bytes | memoryview) -> str:
    """`` (messages row N of FILE)``: the sqlite3 row holding the message with bag time
    ``stamp`` and payload ``raw``, or ``""`` when it is not found (or not sqlite3)."""
    if fmt is not BagFormat.SQLITE3:
        return ""
    want = bytes(raw)
    for f in _db3_files(p):
        try:
            with contextlib.closing(sqlite3.connect(f"{f.resolve().as_uri()}?immutable=1",
                                                    uri=True)) as db:
                rows = db.execute("SELECT id, data FROM messages WHERE timestamp IS ? LIMIT 100",
                                  (stamp,)).fetchall() or db.execute(
                    "SELECT id, data FROM messages WHERE data = ? LIMIT 1", (want,)).fetchall()
        except (sqlite3.Error, OSError, ValueError, OverflowError):
            continue
        for rowid, data in rows:
            if data == want:
                return f" (messages row {rowid} of {f.name})"
    return ""


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

    items = _indexed(p, fmt, topics, lo, hi)
    salvaging = False
    # One .db3 is read in timestamp order (an ORDER BY on its index): a time going
    # backwards is damage. (Several files are read one after the other; bags written
    # record by record are read in file order.)
    ordered = fmt is BagFormat.SQLITE3 and len(_db3_files(p)) == 1
    while True:
        try:
            item = next(items, None)
        except (BagError, ImportError):
            raise  # an optional package missing is not damage: the caller names the extra
        except ScanError as err:
            raise fail(err.reason, err.offset) from None
        except Exception as err:
            reason = describe(err)
            fallback = None if salvaging or count else _salvage(p, fmt, topics, lo, hi)
            if fallback is None:
                raise fail(reason, locate_damage(p, fmt)) from None
            # No usable index / summary (a truncated file): read record by record.
            log.info("%s: index unreadable (%s); reading record by record", p, reason)
            items, salvaging, ordered = fallback, True, False
            continue
        if item is None:
            return
        stamp, src, raw, offset = item
        if type(stamp) is not int:  # sqlite3: a damaged record or index (issue 21, item 8)
            raise fail(f"corrupt {src.topic} message: its bag time is {_kind(stamp)}, not an "
                       f"integer{_sqlite_record(p, fmt, stamp, raw)}", offset) from None
        if ordered and last is not None and stamp < last:
            raise fail(f"corrupt {src.topic} message: bag time {stamp} ns is earlier than "
                       f"the previous message's, {last} ns, in a time-ordered read (a damaged "
                       f"timestamp index)"
                       f"{_sqlite_record(p, fmt, stamp, raw)}", offset) from None
        try:
            message = BagMessage(Time.from_ns(stamp), src.topic, TFMessage(src.decode(raw)),
                                 src.authority)
        except ImportError:
            raise
        except Exception as err:
            when = fmt_time(Time.from_ns(stamp)) if 0 <= stamp < 2**63 else f"{stamp} ns"
            if offset is None:
                offset = locate_message(p, fmt, topics, stamp, raw)
            raise fail(f"corrupt {src.topic} message at bag time {when}: {describe(err)}",
                       offset) from None
        yield message
        count += 1
        last = stamp
