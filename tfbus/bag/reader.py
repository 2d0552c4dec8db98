"""Reading a bag's ``/tf`` and ``/tf_static`` messages in bag-time order.

Which library reads what:

* ROS 1 ``.bag``: chunk by chunk through its chunk-info records (:mod:`tfbus.bag.stream`),
  in memory bounded by a chunk rather than by the message count;
* ROS 2 bag folders / ``.db3`` files: rosbags' indexed reader;
* a bare ``.mcap`` file: the format's own ``mcap`` package (``SeekingReader`` through the
  summary; a file written without a summary is read from the start).

When the index or summary is unreadable (a truncated file), reading falls back to
:mod:`tfbus.bag.salvage`, which returns everything before the damage. A ``.db3`` file
shorter than its sqlite3 header says (which sqlite would read as zero-filled pages) is
read up to its first damaged page of messages, in bag-time order, then reported as
truncated; a timestamp that is not an integer or goes backwards is damage too. Whatever goes
wrong, the caller gets every readable message first, then one :class:`BagReadError`
naming the file, the byte offset where known and the last bag time read.
"""

from __future__ import annotations

import contextlib
import logging
import mmap
import sqlite3
from collections.abc import Callable, Collection, Iterator, Sequence
from heapq import heappop, heappush
from itertools import count
from os import PathLike
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Final, cast

from tfbus.bag.decode import RawItem, Source, cdr_decoder, ros1_decoder
from tfbus.bag.formats import (
    DEFAULT_TOPICS,
    MCAP_MAGIC,
    ROS2_AUTHORITY,
    TF_MSGTYPES,
    TF_STATIC_TOPIC,
    BagFormat,
    BagMessage,
    detect_format,
    fmt_time,
)
from tfbus.bag.salvage import mcap_channel_source, mcap_chunk_records, scan_mcap, scan_ros1
from tfbus.bag.stream import read_ros1_chunks
from tfbus.errors import BagError, BagFormatError, BagNotFoundError, BagReadError, ScanError
from tfbus.messages import TFMessage
from tfbus.time import Time

if TYPE_CHECKING:
    from rosbags.interfaces import Connection

__all__ = ["read_messages", "read_window"]

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
        path: a ROS 1 ``.bag``, a ROS 2 bag folder, or a ``.db3`` / ``.mcap`` file; or
            an fsspec URL of an ``.mcap`` file (``http(s)://``, ``s3://``,
            ``memory://``; ``file://`` is a local path), read by range requests through
            its chunk index, not downloaded whole (needs fsspec: the ``table`` extra).
        topics: topic names to read; only ``tf2_msgs/TFMessage`` and ``tf/tfMessage``
            connections on them are used, every other topic is ignored.
        start: first bag time to yield (inclusive); ``None`` from the beginning.
        stop: bag time to stop at (exclusive); ``None`` to the end.
        latched: with ``start``, also yield the ``/tf_static`` messages recorded before
            ``start`` (stamped with their own bag time, first), as a latched /
            transient-local subscriber joining at ``start`` would receive them.

    Yields:
        :class:`BagMessage` (bag time, topic, TFMessage, authority); in a ROS 1 bag,
        equal bag times in connection order, then file order (as rosbags' reader). A
        damaged file (truncated, or with no index) is read in file order up to the
        damage. A ROS 1 bag or an MCAP file is read one chunk at a time: memory does not
        grow with the message count.

    Raises:
        BagNotFoundError: the path does not exist.
        BagFormatError: not a bag format tfbus reads.
        BagReadError: truncated or corrupt; raised after every readable message has been
            yielded, saying where reading stopped (byte offset, last bag time). No other
            exception escapes a read.
    """
    topics = frozenset(topics)
    lo = None if start is None else start.ns
    hi = None if stop is None else stop.ns
    url = remote_url(path)
    if url is not None:
        if lo is not None and latched and TF_STATIC_TOPIC in topics:
            yield from _read_url(url, frozenset({TF_STATIC_TOPIC}), None, lo)
        yield from _read_url(url, topics, lo, hi)
        return
    p = _local(path)
    fmt = detect_format(p)
    if lo is not None and latched and TF_STATIC_TOPIC in topics:
        yield from _read(p, fmt, frozenset({TF_STATIC_TOPIC}), None, lo)
    yield from _read(p, fmt, topics, lo, hi)


# --------------------------------------------------------------------------- URLs

REMOTE_BLOCK_SIZE: Final = 64 * 1024
"""Bytes of the read-ahead of a recording read through fsspec: each range request asks
for what the reader needs plus this much."""


def remote_url(path: str | PathLike[str]) -> str | None:
    """``path`` when it is a URL that fsspec opens (``scheme://...``) other than
    ``file://`` (a local path, read as one), else None."""
    if isinstance(path, str) and "://" in path and not path.startswith("file://"):
        return path
    return None


def _local(path: str | PathLike[str]) -> Path:
    """A local path; a ``file://`` URL as its path."""
    if isinstance(path, str) and path.startswith("file://"):
        from urllib.parse import unquote, urlparse

        return Path(unquote(urlparse(path).path))
    return Path(path)


def _read_url(
    url: str, topics: frozenset[str], lo: int | None, hi: int | None
) -> Iterator[BagMessage]:
    """The tf messages of an MCAP file at an fsspec URL (``http(s)://``, ``s3://``,
    ``memory://`` ...), in log-time order, read by range requests through the summary's
    chunk index: the footer and summary, then only the chunks that meet ``[lo, hi)``.

    Raises:
        ImportError: fsspec (or the protocol's package) is not installed.
        BagNotFoundError: nothing at the URL.
        BagFormatError: not an MCAP file, or one without a chunk index (over a URL only
            indexed MCAP files are read; ROS 1 and .db3 files need a local copy).
        BagReadError: the file cannot be read or decoded, after what was read.
    """
    try:
        import fsspec
    except ImportError:
        from tfbus._extras import missing_extra

        raise missing_extra("tfbus.bag (a URL)", "fsspec", "table") from None
    count = 0
    last: int | None = None
    try:
        # The block size and cache are the file's options (``fs.open``), not the
        # filesystem's: ``fsspec.open(url, **kw)`` hands ``kw`` to the filesystem, which
        # s3fs passes on to botocore's session (a TypeError there).
        fs, fs_path = fsspec.core.url_to_fs(url)
        f = fs.open(fs_path, "rb", block_size=REMOTE_BLOCK_SIZE, cache_type="readahead")
    except FileNotFoundError:
        raise BagNotFoundError(f"{url}: no such file", url) from None
    except (OSError, ValueError) as err:
        raise BagReadError(f"cannot open: {describe(err)}", url, messages_read=0) from None
    try:
        head = f.read(16)
        if not head.startswith(MCAP_MAGIC):
            raise BagFormatError(f"{url}: over a URL only MCAP files are read (by range "
                                 "requests); copy a ROS 1 .bag or .db3 file locally", url)
        f.seek(0)
        try:
            items = _mcap_indexed(cast("IO[bytes]", f), int(f.size), topics, lo, hi)
        except BagError:
            raise
        except Exception as err:
            raise BagReadError(f"unreadable summary: {describe(err)}", url,
                               messages_read=0) from None
        if items is None:
            raise BagFormatError(f"{url}: an MCAP file without a chunk index cannot be read "
                                 "by range requests; copy it locally", url)
        while True:
            try:
                item = next(items, None)
            except BagError:
                raise
            except Exception as err:
                raise BagReadError(describe(err), url, messages_read=count,
                                   last_time=None if last is None else Time.from_ns(last)
                                   ) from None
            if item is None:
                return
            stamp, src, raw, _offset = item
            try:
                message = BagMessage(Time.from_ns(stamp), src.topic,
                                     TFMessage(src.decode(raw)), src.authority)
            except Exception as err:
                raise BagReadError(f"corrupt {src.topic} message at bag time {stamp} ns: "
                                   f"{describe(err)}", url, messages_read=count) from None
            yield message
            count += 1
            last = stamp
    finally:
        f.close()


def read_window(
    path: str | PathLike[str],
    *,
    start: Time | None = None,
    end: Time | None = None,
    topics: Collection[str] = DEFAULT_TOPICS,
) -> Iterator[BagMessage]:
    """A window of a bag: every ``/tf_static`` message of the whole file, then the other
    topics' messages with bag time in ``[start, end)``, each part in bag-time order.

    Statics are read over the whole file because a recording usually has them once, at
    its start (and a late static publisher's after it): a window in the middle needs them
    all. The window itself is read through each format's index, so only its part of the
    file is read and held: MCAP through the summary's chunk index (the chunks whose time
    range meets the window), ROS 1 through the bag's index records (rosbags), ROS 2
    ``.db3`` by ``WHERE timestamp`` on the messages table's timestamp index (rosbags).

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder, or a ``.db3`` / ``.mcap`` file.
        start: first bag time of the window (inclusive); ``None``: from the beginning.
        end: bag time the window ends at (exclusive); ``None``: to the end.
        topics: the topics to read (default ``/tf`` and ``/tf_static``).

    Yields:
        :class:`BagMessage`: the statics, then the window.

    Raises:
        BagNotFoundError, BagFormatError, BagReadError: as :func:`read_messages`.
        ValueError: ``end`` is before ``start``.
    """
    if start is not None and end is not None and end.ns < start.ns:
        raise ValueError(f"end ({end.ns} ns) is before start ({start.ns} ns)")
    wanted = frozenset(topics)
    if TF_STATIC_TOPIC in wanted:
        yield from read_messages(path, topics=(TF_STATIC_TOPIC,))
    dynamic = wanted - {TF_STATIC_TOPIC}
    if dynamic:
        yield from read_messages(path, topics=dynamic, start=start, stop=end, latched=False)


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
    cut: tuple[Path, int, int, int] | None = None
    if fmt is BagFormat.ROS1:
        reader = Reader1(p)
    else:
        if p.is_file() and p.suffix != ".db3":
            raise BagFormatError(f"{p}: a {fmt.value} file must be named *.db3", p)
        files = _db3_files(p)
        cuts = [c for c in map(_db3_cut, files) if c is not None]
        if cuts and len(files) > 1:
            f, size, _pages, _page_size = cuts[0]
            raise ScanError(f"{f.name} is truncated: {_cut_text(*cuts[0][1:])}", size)
        cut = cuts[0] if cuts else None
        reader = Reader2(p)
    if cut is not None:
        try:  # the connections (topics, definitions: the first pages) through rosbags
            with reader:
                srcs = {c.topic: _rosbags_source(c) for c in reader.connections
                        if c.topic in topics and c.msgtype in TF_MSGTYPES}
        except Exception as err:
            raise ScanError(f"truncated: {_cut_text(*cut[1:])} ({describe(err)})",
                            cut[1]) from None
        yield from _raw_db3_cut(cut, srcs, lo, hi)
        return
    with reader:
        conns: Sequence[Connection] = [
            c for c in reader.connections if c.topic in topics and c.msgtype in TF_MSGTYPES
        ]
        if not conns:  # rosbags: an empty filter means *every* message
            return
        sources = {id(c): _rosbags_source(c) for c in conns}
        for conn, stamp, raw in reader.messages(connections=conns, start=lo, stop=hi):
            yield stamp, sources[id(conn)], raw, None


# ------------------------------------------------------------- a truncated .db3 file
#
# sqlite reads the pages missing from a file cut short as zeros (a cut of 1-100 bytes
# returned the last page's first-stored rows as garbage without an error). The file's
# header says how long it must be (sqlite.org/fileformat2.html, "The Database Header":
# page size at offset 16, in-header database size in pages at 28, valid when the change
# counter at 24 equals the version-valid-for number at 92). A short file is read up to
# the damage: the rows of the messages table stored on leaf pages before the first
# damaged one (leaves in key order from sqlite's dbstat table, the last rowid of a leaf
# from its cell pointer array), in bag-time order without the timestamp index (which may
# be damaged too), then a ScanError says the file is truncated.


def _db3_cut(f: Path) -> tuple[Path, int, int, int] | None:
    """``(file, size, pages, page size)`` when ``f`` is shorter than its header says."""
    try:
        with f.open("rb") as fh:
            head = fh.read(100)
            size = fh.seek(0, 2)
    except OSError:
        return None
    if len(head) < 100:
        return (f, size, 1, 0)
    page_size = int.from_bytes(head[16:18], "big")
    page_size = 65536 if page_size == 1 else page_size
    pages = int.from_bytes(head[28:32], "big")
    if not pages or head[24:28] != head[92:96]:
        return None  # a header from an older writer: the page count is not kept there
    return (f, size, pages, page_size) if size < pages * page_size else None


def _cut_text(size: int, pages: int, page_size: int) -> str:
    if not page_size:
        return f"{size} bytes, less than the 100-byte sqlite3 header"
    return (f"{size} bytes of the {pages * page_size} its header gives ({pages} pages of "
            f"{page_size} bytes)")


def _varint(page: bytes, at: int) -> tuple[int, int]:
    """An sqlite varint at ``page[at]``: (value, offset after it)."""
    value = 0
    for i in range(8):
        byte = page[at + i]
        value = (value << 7) | (byte & 0x7F)
        if byte < 0x80:
            return value, at + i + 1
    return (value << 8) | page[at + 8], at + 9


def _db3_last_intact_rowid(db: sqlite3.Connection, f: Path, intact: int,
                           page_size: int) -> int | None:
    """The last rowid of the messages table stored before its first damaged leaf page
    (a page past ``intact``, or with an overflow page past it); None when there is none,
    -1 when no leaf is damaged."""
    leaves: list[tuple[str, int]] = []
    damaged_leaf: set[str] = set()
    for path, pageno, pagetype in db.execute(
            "SELECT path, pageno, pagetype FROM dbstat WHERE name = 'messages'"):
        if pagetype == "leaf":
            leaves.append((path, pageno))
        if pageno > intact:  # an overflow page belongs to the leaf its path starts with
            damaged_leaf.add(path.split("+")[0] if pagetype == "overflow" else path)
        if pagetype == "internal" and pageno > intact:
            return None
    first = next((i for i, (path, pageno) in enumerate(leaves) if path in damaged_leaf), None)
    if first is None:
        return -1
    if first == 0:
        return None
    pageno = leaves[first - 1][1]
    with f.open("rb") as fh:
        fh.seek((pageno - 1) * page_size)
        page = fh.read(page_size)
    h = 100 if pageno == 1 else 0
    ncell = int.from_bytes(page[h + 3 : h + 5], "big")
    if page[h] != 0x0D or not ncell:
        return None
    cell = int.from_bytes(page[h + 8 + 2 * (ncell - 1) : h + 10 + 2 * (ncell - 1)], "big")
    _payload, at = _varint(page, cell)
    return _varint(page, at)[0]


def _raw_db3_cut(
    cut: tuple[Path, int, int, int], sources: dict[str, Source], lo: int | None,
    hi: int | None,
) -> Iterator[RawItem]:
    """The messages of a truncated .db3 stored before the damage, in bag-time order,
    then a ScanError at the end of the file."""
    f, size, pages, page_size = cut
    reason = f"truncated: {_cut_text(size, pages, page_size)}"
    if not page_size:
        raise ScanError(reason, size)
    with contextlib.closing(sqlite3.connect(f"{f.resolve().as_uri()}?immutable=1",
                                            uri=True)) as db:
        try:
            last = _db3_last_intact_rowid(db, f, size // page_size, page_size)
        except (sqlite3.Error, IndexError):
            last = None  # the table's tree itself is damaged: nothing can be trusted
        if last is not None and sources:
            by_id = {tid: sources[name] for tid, name in
                     db.execute("SELECT id, name FROM topics") if name in sources}
            query = ["SELECT id FROM messages NOT INDEXED WHERE topic_id IN (",
                     ",".join("?" * len(by_id)), ")"]
            args: list[int] = list(by_id)
            for clause, value in (("id <= ?", None if last < 0 else last),
                                  ("timestamp >= ?", lo), ("timestamp < ?", hi)):
                if value is not None:
                    query.append(f" AND {clause}")
                    args.append(value)
            rowids = [r for (r,) in db.execute("".join(query) + " ORDER BY timestamp, id",
                                               args)]
            for rowid in rowids:
                tid, stamp, data = db.execute(
                    "SELECT topic_id, timestamp, data FROM messages WHERE id = ?",
                    (rowid,)).fetchone()
                yield stamp, by_id[tid], data, None
    raise ScanError(reason + ("" if last == -1 else "; the messages stored from there on "
                              "are lost"), size)


def _raw_mcap(
    p: Path, topics: Collection[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    """Raw tf messages of an MCAP file in log-time order, through its summary.

    ``mcap``'s SeekingReader reads the summary; the chunks that hold tf are read and
    decompressed (CRC checked) by ``mcap``'s ``Chunk.read`` / ``breakup_chunk`` (through
    :func:`~tfbus.bag.salvage.mcap_chunk_records`: memory bounded by the data), in order
    of their first log time, and merged by log time on a heap of plain tuples (ties: the
    order of the chunks, then of the records). This is the ordering SeekingReader's
    ``iter_messages(log_time_order=True)`` gives, at a third of its cost: its queue
    compares entries in Python. A file written without a summary (or with no chunk
    index) is read from the start by :func:`~tfbus.bag.salvage.scan_mcap`, which also
    stops at any damage it finds.
    """
    with p.open("rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        stream = cast("IO[bytes]", mm)

        def release(offset: int, length: int) -> None:
            # The chunk's bytes were copied out: drop its pages from this process's
            # resident memory (a walk over a whole file then holds no more of it than a
            # chunk; the kernel still caches the file).
            start = offset - offset % mmap.PAGESIZE
            with contextlib.suppress(OSError, ValueError, AttributeError):
                mm.madvise(mmap.MADV_DONTNEED, start, offset + length - start)

        items = _mcap_indexed(stream, len(mm), topics, lo, hi, release)
        if items is None:
            yield from scan_mcap(p, topics, lo, hi)
            return
        yield from items


def _mcap_indexed(
    stream: IO[bytes], size: int, topics: Collection[str], lo: int | None, hi: int | None,
    release: Callable[[int, int], None] | None = None,
) -> Iterator[RawItem] | None:
    """The tf messages of an MCAP file object in log-time order through its summary's
    chunk index (see :func:`_raw_mcap`): only the chunks that meet ``[lo, hi)`` and hold
    a channel on ``topics`` are read. None when the file has no summary or no chunk index
    (then it must be read from the start)."""
    from mcap.reader import SeekingReader

    summary = SeekingReader(stream, record_size_limit=size).get_summary()
    if summary is None or not summary.chunk_indexes:
        return None
    return _mcap_chunks(stream, summary, topics, lo, hi, release)


def _mcap_chunks(
    stream: IO[bytes], summary: Any, topics: Collection[str], lo: int | None, hi: int | None,
    release: Callable[[int, int], None] | None = None,
) -> Iterator[RawItem]:
    """The indexed read itself (:func:`_raw_mcap`), on any seekable file object;
    ``release(offset, length)`` is told each chunk record read once its bytes are
    copied out."""
    from mcap.data_stream import ReadDataStream
    from mcap.records import Chunk, Message

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
        stream.seek(index.chunk_start_offset + 9)  # opcode (1) + record length (8)
        chunk = Chunk.read(ReadDataStream(stream))
        if release is not None:
            release(index.chunk_start_offset, index.chunk_length)
        for record in mcap_chunk_records(chunk):
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
        return _raw_mcap(p, topics, lo, hi)
    if fmt is BagFormat.ROS1:
        return read_ros1_chunks(p, topics, lo, hi)
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
        if type(stamp) is not int:  # sqlite3: a damaged record or index (a flipped bit)
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
