"""A ROS 1 bag read chunk by chunk, in memory bounded by a chunk, not by the message count.

rosbags' ``Reader`` loads every connection's index (one entry per message, about 150 B
each) before it yields the first message: a 1 GB bag of 1 kB messages holds about 150 MB
of index. This reader keeps only what the ROS 1 bag v2.0 format
(``http://wiki.ros.org/Bags/Format/2.0``) puts in its index section once per connection
and once per chunk: the connection records and the chunk-info records (chunk position,
first and last message time, message count per connection). The chunks that hold a tf
connection and meet the time window are then read one at a time, in order of their first
message time, each decompressed (none / bz2 / lz4) to the size its header states; its tf
messages go on a heap that releases every message older than the next chunk's first
time.

Order: the messages come in bag-time order, ties by connection id, then by position in
the file, the order rosbags' ``Reader.messages`` gives (a ``heapq.merge`` of the
per-connection indexes, each sorted by time). ``rosbag record`` writes chunks in time
order, so the heap holds at most one chunk's tf messages; chunks whose time ranges
overlap (a bag merged from several recordings) are merged exactly too, the heap then
holding the tf messages of the chunks that overlap.
"""

from __future__ import annotations

import contextlib
import mmap
import struct
from collections.abc import Collection, Iterator
from heapq import heappop, heappush
from pathlib import Path
from typing import NamedTuple

from tfbus.bag.decode import RawItem, Source, ros1_decoder
from tfbus.bag.formats import ROS1_MAGIC, TF_MSGTYPES
from tfbus.bag.salvage import _decompress_ros1_chunk, _ros1_header, _ros1_records
from tfbus.errors import ScanError
from tfbus.time import NSEC_PER_SEC

__all__ = ["ChunkInfo", "read_ros1_chunks"]

_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_TIME = struct.Struct("<II")
_OP_MSG, _OP_HEADER, _OP_CHUNK_INFO, _OP_CONN = b"\x02", b"\x03", b"\x06", b"\x07"


class ChunkInfo(NamedTuple):
    """A ROS 1 chunk-info record (op 0x06): where a chunk is and what it holds."""

    chunk_pos: int
    """Byte offset of the chunk record in the file."""
    start_time: int
    """Bag time of the chunk's first message, ns."""
    end_time: int
    """Bag time of the chunk's last message, ns."""
    connections: frozenset[int]
    """Ids of the connections with messages in the chunk."""


def _time(value: bytes) -> int:
    sec, nsec = _TIME.unpack(value)
    return int(sec * NSEC_PER_SEC + nsec)


def _source(topic: str, body: bytes, topics: Collection[str]) -> Source | None:
    """The :class:`Source` of a connection record on a tf topic, else None."""
    fields = _ros1_header(body)
    msgtype = fields.get("type", b"").decode()
    if "/msg/" not in msgtype:
        msgtype = msgtype.replace("/", "/msg/", 1)
    if topic not in topics or msgtype not in TF_MSGTYPES:
        return None
    decode = ros1_decoder(msgtype, fields.get("md5sum", b"").decode(),
                          fields.get("message_definition", b"").decode())
    return Source(topic, fields.get("callerid", b"").decode() or "unknown_publisher", decode)


def read_index(
    data: mmap.mmap, topics: Collection[str]
) -> tuple[dict[int, Source], list[ChunkInfo]]:
    """The tf connections and every chunk-info record of a ROS 1 bag mapped in ``data``.

    Raises:
        ValueError: not a ROS 1 bag, or its index is missing or damaged (``index_pos`` 0
            or past the end: a bag never closed; counts that differ from the bag
            header's; a record cut short or malformed).
    """
    if data[: len(ROS1_MAGIC)] != ROS1_MAGIC:
        raise ValueError("not a ROS 1 bag")
    records = _ros1_records(data, 0, len(ROS1_MAGIC))
    first = next(records, None)
    if first is None or first[2].get("op") != _OP_HEADER:
        raise ValueError("the first record is not the bag header")
    head = first[2]
    (index_pos,) = _U64.unpack(head["index_pos"])
    (conn_count,) = _U32.unpack(head["conn_count"])
    (chunk_count,) = _U32.unpack(head["chunk_count"])
    if not len(ROS1_MAGIC) < index_pos <= len(data):
        raise ValueError(f"bag header's index_pos {index_pos} is not inside the file "
                         "(the recording was never closed)")
    sources: dict[int, Source] = {}
    conns: set[int] = set()
    chunks: list[ChunkInfo] = []
    for _pos, _dpos, head, body in _ros1_records(data, 0, index_pos):
        op = head.get("op")
        if op == _OP_CONN:
            (conn,) = _U32.unpack(head["conn"])
            conns.add(conn)
            src = _source(head["topic"].decode(), body, topics)
            if src is not None:
                sources[conn] = src
        elif op == _OP_CHUNK_INFO:
            (ver,) = _U32.unpack(head["ver"])
            if ver != 1:
                raise ValueError(f"chunk-info version {ver} is not supported")
            (count,) = _U32.unpack(head["count"])
            if len(body) != 8 * count:
                raise ValueError(f"chunk-info record of {len(body)} bytes for {count} "
                                 "connections")
            ids = frozenset(_U32.unpack_from(body, 8 * k)[0] for k in range(count))
            chunks.append(ChunkInfo(_U64.unpack(head["chunk_pos"])[0],
                                    _time(head["start_time"]), _time(head["end_time"]), ids))
    if len(conns) != conn_count or len(chunks) != chunk_count:
        raise ValueError(f"index holds {len(conns)} connections and {len(chunks)} chunks; "
                         f"the bag header says {conn_count} and {chunk_count}")
    return sources, chunks


def read_ros1_chunks(
    p: Path, topics: Collection[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    """The tf messages of an indexed ROS 1 bag on ``topics`` with bag time in
    ``[lo, hi)``, in bag-time order (see the module's docstring), read chunk by chunk.

    Memory: the connection and chunk-info records, one decompressed chunk, and the tf
    messages of the chunks whose time ranges overlap; not one entry per message. The
    file is memory-mapped and each chunk's pages are dropped from this process's
    resident memory once its bytes are copied out.

    Raises:
        ValueError: the index is missing or damaged (see :func:`read_index`); a chunk
            record is cut short, does not decompress, or is not where its chunk-info
            says. (The caller then reads the bag record by record, as for rosbags'
            ``ReaderError``: :func:`tfbus.bag.salvage.scan_ros1` finds where.)
    """
    try:
        yield from _read_ros1_chunks(p, topics, lo, hi)
    except ScanError as err:
        raise ValueError(f"{err.reason} at byte {err.offset}") from None


def _read_ros1_chunks(
    p: Path, topics: Collection[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    with p.open("rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        sources, infos = read_index(mm, topics)
        if not sources:
            return
        chunks = sorted(
            (c for c in infos
             if not sources.keys().isdisjoint(c.connections)
             and (lo is None or c.end_time >= lo) and (hi is None or c.start_time < hi)),
            key=lambda c: (c.start_time, c.chunk_pos),
        )
        heap: list[tuple[int, int, int, int, bytes]] = []
        for info in chunks:
            while heap and heap[0][0] < info.start_time:
                t, conn, _cpos, _off, raw = heappop(heap)
                yield t, sources[conn], raw, None
            pos, dpos, head, body = next(_ros1_records(mm, 0, info.chunk_pos))
            if pos != info.chunk_pos or head.get("op") != b"\x05":
                raise ValueError(f"no chunk record at chunk_pos {info.chunk_pos}")
            inner = _decompress_ros1_chunk(head, body, pos)
            end = dpos + len(body)
            del body
            # The chunk's bytes were copied out: drop its pages from this process's
            # resident memory (the kernel still caches the file).
            start = pos - pos % mmap.PAGESIZE
            with contextlib.suppress(OSError, ValueError, AttributeError):
                mm.madvise(mmap.MADV_DONTNEED, start, end - start)
            for off, _idpos, ihead, ibody in _ros1_records(inner, 0):
                if ihead.get("op") != _OP_MSG:
                    continue
                (conn,) = _U32.unpack(ihead["conn"])
                if conn not in sources:
                    continue
                t = _time(ihead["time"])
                if (lo is None or t >= lo) and (hi is None or t < hi):
                    heappush(heap, (t, conn, info.chunk_pos, off, ibody))
        while heap:
            t, conn, _cpos, _off, raw = heappop(heap)
            yield t, sources[conn], raw, None
