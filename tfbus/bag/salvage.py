"""Salvage of damaged recordings: read record by record up to the damage, then say where.

Indexed readers need what a damaged file lacks: rosbags reads a ROS 1 bag through its
index (written when ``rosbag record`` closes the file), the ``mcap`` reader seeks through an
MCAP file's summary (after the data section). A recording cut short by a crash or a full
disk has neither, so these readers walk the file from the start, return every complete
message and raise :class:`ScanError` with the byte offset where reading stopped.

* MCAP: the format's own library (``mcap``, its ``StreamReader``) reads the records in
  order, with chunk CRCs checked; this module only tracks offsets and sorts each chunk's
  messages by log time.
* ROS 1: no library on PyPI reads a bag without its index (rosbags refuses it: "Bag
  index looks damaged"; ``rosbag reindex`` and the ``rosbag`` module bagpy wraps are ROS
  1's own code, installed with ROS, not from PyPI), so the ROS 1 bag v2.0 records
  (``http://wiki.ros.org/Bags/Format/2.0``) are parsed here: bag header, chunks (none /
  bz2 / lz4), connections and message data; index records are skipped. A bag that ends
  at a record boundary but has no index (``index_pos`` 0 or past the end) is truncated
  or was never closed: that is reported too, after its messages.
"""

from __future__ import annotations

import bz2
import importlib
import mmap
import struct
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import IO, TYPE_CHECKING, cast

from tfbus.bag.decode import RawItem, Source, cdr_decoder, ros1_decoder
from tfbus.bag.formats import MCAP_MAGIC, ROS1_MAGIC, ROS2_AUTHORITY, TF_MSGTYPES
from tfbus.errors import ScanError
from tfbus.time import NSEC_PER_SEC

if TYPE_CHECKING:
    from mcap.records import Channel, Schema

__all__ = ["mcap_channel_source", "scan_mcap", "scan_ros1"]

_U32 = struct.Struct("<I")
# ROS 1 record ops (header field ``op``): message data, bag header, chunk, connection.
_OP_MSG, _OP_HEADER, _OP_CHUNK, _OP_CONN = b"\x02", b"\x03", b"\x05", b"\x07"


def _in_window(stamp: int, lo: int | None, hi: int | None) -> bool:
    return (lo is None or stamp >= lo) and (hi is None or stamp < hi)


# --------------------------------------------------------------------------- ROS 1


def _ros1_header(data: bytes) -> dict[str, bytes]:
    """The ``name=value`` fields of a ROS 1 record header (or connection header)."""
    fields: dict[str, bytes] = {}
    off = 0
    while off < len(data):
        (n,) = _U32.unpack_from(data, off)
        off += 4
        if off + n > len(data):
            raise struct.error("header field longer than its header")
        name, _, value = data[off : off + n].partition(b"=")
        fields[name.decode()] = value
        off += n
    return fields


def _ros1_records(
    buf: bytes | mmap.mmap, base: int, start: int = 0
) -> Iterator[tuple[int, int, dict[str, bytes], bytes]]:
    """(record offset, data offset, header fields, data) of each record in ``buf`` from
    ``start``; only each record's own bytes are copied (``buf`` may map a whole file).

    ``base`` is the file offset of ``buf``. A record cut short raises :class:`ScanError`,
    except that an uncompressed chunk cut short is yielded first with the part present
    (its complete records are salvaged).
    """
    off = start
    while off < len(buf):
        if off + 4 > len(buf):
            raise ScanError("truncated record header", base + off)
        (hlen,) = _U32.unpack_from(buf, off)
        if off + 4 + hlen + 4 > len(buf):
            raise ScanError("truncated record header", base + off)
        try:
            head = _ros1_header(buf[off + 4 : off + 4 + hlen])
        except (struct.error, UnicodeDecodeError):
            raise ScanError("corrupt record header", base + off) from None
        (dlen,) = _U32.unpack_from(buf, off + 4 + hlen)
        dstart = off + 8 + hlen
        if dstart + dlen > len(buf):
            if head.get("op") == b"\x05" and head.get("compression") == b"none":
                yield base + off, base + dstart, head, buf[dstart:]
            raise ScanError("truncated record data", base + off)
        yield base + off, base + dstart, head, buf[dstart : dstart + dlen]
        off = dstart + dlen


def _decompress_ros1_chunk(head: dict[str, bytes], body: bytes, pos: int) -> bytes:
    """A chunk's records, decompressed to at most the size its header states."""
    compression = head.get("compression", b"none").decode(errors="replace")
    if compression == "none":
        return body
    if len(head.get("size", b"")) != 4:
        # The format requires it (rosbag's ChunkHeader reads "size" as a required field);
        # without it nothing would bound what a small compressed chunk expands to.
        raise ScanError(f"corrupt {compression} chunk: no uncompressed size in its header",
                        pos)
    size = limit = _U32.unpack(head["size"])[0]
    try:
        if compression == "bz2":
            inner = bz2.BZ2Decompressor().decompress(body, max_length=limit)
        elif compression == "lz4":
            lz4frame = importlib.import_module("lz4.frame")
            inner = lz4frame.LZ4FrameDecompressor().decompress(body, max_length=limit)
        else:
            raise ScanError(f"unknown chunk compression {compression!r}", pos)
    except ScanError:
        raise
    except Exception:
        raise ScanError(f"corrupt {compression} chunk", pos) from None
    if len(inner) != size:
        raise ScanError(f"corrupt {compression} chunk (size differs from its header)", pos)
    return bytes(inner)


def scan_ros1(
    p: Path, topics: Collection[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    """Read a ROS 1 bag record by record (chunks inline), in file (= recording) order.

    Yields the tf messages on ``topics`` with bag time in ``[lo, hi)``, then raises
    :class:`ScanError`: at the first damaged record, or at the end of the file when the
    bag has no index (truncated or never closed). A bag read to its end that has its
    index returns normally.

    The file is memory-mapped and read one record at a time (only the record being read
    is copied), never read into memory whole.
    """
    with p.open("rb") as f:
        if p.stat().st_size < len(ROS1_MAGIC):
            raise ScanError("not a ROS 1 bag", 0)
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            yield from _scan_ros1(mm, topics, lo, hi)


def _scan_ros1(
    data: mmap.mmap, topics: Collection[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    if data[: len(ROS1_MAGIC)] != ROS1_MAGIC:
        raise ScanError("not a ROS 1 bag", 0)
    sources: dict[int, Source | None] = {}
    index_pos: int | None = None

    def handle(pos: int, head: dict[str, bytes], body: bytes) -> Iterator[RawItem]:
        nonlocal index_pos
        op = head.get("op", b"")
        if op == _OP_HEADER:
            index_pos = struct.unpack("<Q", head["index_pos"])[0]
        elif op == _OP_CONN:
            conn_id = _U32.unpack(head["conn"])[0]
            if conn_id in sources:  # repeated after the chunks (index section)
                return
            topic = head["topic"].decode()
            fields = _ros1_header(body)
            msgtype = fields.get("type", b"").decode()
            if "/msg/" not in msgtype:
                msgtype = msgtype.replace("/", "/msg/", 1)
            if topic in topics and msgtype in TF_MSGTYPES:
                decode = ros1_decoder(
                    msgtype,
                    fields.get("md5sum", b"").decode(),
                    fields.get("message_definition", b"").decode(),
                )
                caller = fields.get("callerid", b"").decode() or "unknown_publisher"
                sources[conn_id] = Source(topic, caller, decode)
            else:
                sources[conn_id] = None
        elif op == _OP_MSG:
            src = sources.get(_U32.unpack(head["conn"])[0])
            if src is not None:
                sec, nsec = struct.unpack("<II", head["time"])
                stamp = sec * NSEC_PER_SEC + nsec
                if _in_window(stamp, lo, hi):
                    yield stamp, src, body, pos

    def guarded(pos: int, head: dict[str, bytes], body: bytes) -> Iterator[RawItem]:
        # A malformed field (missing, short, not UTF-8, bad definition) stops the scan here.
        try:
            yield from handle(pos, head, body)
        except ScanError:
            raise
        except Exception as err:
            op = head.get("op", b"?").hex()
            raise ScanError(f"corrupt record (op 0x{op}): {_describe(err)}", pos) from None

    for pos, dpos, head, body in _ros1_records(data, 0, len(ROS1_MAGIC)):
        if head.get("op") != _OP_CHUNK:
            yield from guarded(pos, head, body)
            continue
        inner = _decompress_ros1_chunk(head, body, pos)
        plain = head.get("compression", b"none") == b"none"
        # Inside a compressed chunk there are no file offsets: report the chunk's.
        for ipos, _idpos, ihead, ibody in _ros1_records(inner, dpos if plain else pos):
            yield from guarded(ipos if plain else pos, ihead, ibody)
    if not index_pos or index_pos >= len(data):
        raise ScanError(
            "no index: the bag is truncated or its recording was never closed", len(data)
        )


def _describe(err: BaseException) -> str:
    return (str(err).strip() or type(err).__name__).rstrip(".")


# --------------------------------------------------------------------------- MCAP


def mcap_channel_source(channel: Channel, schema: Schema | None, topics: Collection[str]) -> (
    Source | None
):
    """The :class:`Source` for an MCAP channel carrying tf, or ``None`` to skip it.

    Raises:
        Exception: the schema's definition cannot be parsed (see ``cdr_decoder``).
    """
    if (
        schema is None
        or channel.topic not in topics
        or schema.name not in TF_MSGTYPES
        or channel.message_encoding != "cdr"
    ):
        return None
    decode = cdr_decoder(
        schema.name,
        schema.data.decode(),
        idl=schema.encoding == "ros2idl",
        digest=channel.metadata.get("topic_type_hash", ""),
    )
    return Source(channel.topic, ROS2_AUTHORITY, decode)


def _longer_than_file(mm: mmap.mmap, start: int, size: int) -> str:
    """The reason of a record at byte ``start`` whose length field is more than the file's
    ``size`` (``mcap``'s RecordLengthLimitExceeded: its record size limit is the file
    size, the most any intact record can hold, so no setting could let it be read)."""
    opcode, length = mm[start], int.from_bytes(mm[start + 1:start + 9], "little")
    try:
        from mcap.opcode import Opcode

        name = Opcode(opcode).name
    except (ImportError, ValueError):
        name = f"opcode 0x{opcode:02x}"
    return (f"the {name} record at byte {start} says it is {length} bytes long, more "
            f"than the whole file ({size} bytes): the file is cut short (copied or "
            f"downloaded in part, or still being written) or damaged at that record")


def scan_mcap(
    p: Path, topics: Collection[str], lo: int | None, hi: int | None
) -> Iterator[RawItem]:
    """Read an MCAP file from its start with ``mcap``'s StreamReader, up to the footer.

    Messages come in file order, each chunk's sorted by log time. Yields the tf messages
    on ``topics`` with log time in ``[lo, hi)``; raises :class:`ScanError` at the first
    damaged record (cut short, bad CRC, bad compression, unknown schema or channel).
    """
    from mcap.records import Channel, Chunk, Message, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk

    with p.open("rb") as f:
        size = p.stat().st_size
        if size < len(MCAP_MAGIC):
            raise ScanError("not an MCAP file", 0)
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            stream = cast("IO[bytes]", mm)
            reader = StreamReader(
                stream, emit_chunks=True, validate_crcs=True, record_size_limit=size
            )
            schemas: dict[int, Schema] = {}
            sources: dict[int, Source | None] = {}

            def take(record: object, pos: int) -> Iterator[RawItem]:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    schema = schemas.get(record.schema_id)
                    if record.schema_id and schema is None:
                        raise ScanError(f"channel {record.id} names unknown schema", pos)
                    sources[record.id] = mcap_channel_source(record, schema, topics)
                elif isinstance(record, Message):
                    if record.channel_id not in sources:
                        raise ScanError(f"message on unknown channel {record.channel_id}", pos)
                    src = sources[record.channel_id]
                    if src is not None and _in_window(record.log_time, lo, hi):
                        yield record.log_time, src, record.data, pos

            pos = 0
            records = reader.records
            while True:
                try:
                    record = next(records, None)
                    if record is None:
                        return  # footer and closing magic read: complete
                    if isinstance(record, Chunk):
                        inner = breakup_chunk(record, validate_crc=True)
                        msgs = [m for r in inner for m in take(r, pos)]
                        msgs.sort(key=lambda m: m[0])
                    else:
                        msgs = list(take(record, pos))
                except ScanError:
                    raise
                except Exception as err:
                    reason = str(err).strip() or type(err).__name__
                    if type(err).__name__ == "EndOfFile":
                        reason = "truncated (file ends before the MCAP footer)"
                    elif type(err).__name__ == "RecordLengthLimitExceeded":
                        start = max(pos, len(MCAP_MAGIC))
                        raise ScanError(_longer_than_file(mm, start, size), start) from None
                    raise ScanError(reason, pos) from None
                yield from msgs
                pos = mm.tell()
