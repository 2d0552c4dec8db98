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
from typing import IO, TYPE_CHECKING, Any, cast

from tfbus.bag.decode import RawItem, Source, cdr_decoder, ros1_decoder
from tfbus.bag.formats import MCAP_MAGIC, ROS1_MAGIC, ROS2_AUTHORITY, TF_MSGTYPES
from tfbus.errors import ScanError
from tfbus.time import NSEC_PER_SEC

if TYPE_CHECKING:
    from mcap.records import Channel, Chunk, Schema

__all__ = ["mcap_channel_source", "mcap_chunk_records", "scan_mcap", "scan_ros1"]

_U32 = struct.Struct("<I")
_STEP = 1 << 20  # bytes a chunk's decompressed data grows by at a time
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
    """A chunk's records, decompressed to the size its header states, never more.

    The output grows with what the data really holds, in steps of at most
    :data:`_STEP` bytes, and stops one byte past the header's size: an absurd size
    allocates nothing (lz4's ``max_length`` sizes its buffer by it at once). The data
    must end where its compressed stream ends, at exactly that size: a size too small
    (0 included) would otherwise drop the chunk's messages silently.
    """
    compression = head.get("compression", b"none").decode(errors="replace")
    if compression == "none":
        return body
    if len(head.get("size", b"")) != 4:
        # The format requires it (rosbag's ChunkHeader reads "size" as a required field);
        # without it nothing would bound what a small compressed chunk expands to.
        raise ScanError(f"corrupt {compression} chunk: no uncompressed size in its header",
                        pos)
    size = _U32.unpack(head["size"])[0]
    decompressor: Any
    try:
        if compression == "bz2":
            decompressor = bz2.BZ2Decompressor()
        elif compression == "lz4":
            decompressor = importlib.import_module("lz4.frame").LZ4FrameDecompressor()
        else:
            raise ScanError(f"unknown chunk compression {compression!r}", pos)
        inner = _bounded(decompressor, body, size)
    except ScanError:
        raise
    except Exception:
        raise ScanError(f"corrupt {compression} chunk", pos) from None
    if len(inner) > size:
        raise ScanError(f"corrupt {compression} chunk: its data decompresses to more than "
                        f"the {size} bytes its header gives", pos)
    if not decompressor.eof:
        raise ScanError(f"corrupt {compression} chunk: its data ends before its compressed "
                        "stream does", pos)
    if len(inner) != size:
        raise ScanError(f"corrupt {compression} chunk (size differs from its header: "
                        f"{len(inner)} bytes, not {size})", pos)
    return bytes(inner)


def _bounded(decompressor: Any, data: bytes, size: int) -> bytearray:
    """What ``decompressor`` (bz2's or lz4.frame's, which take ``max_length``) makes of
    ``data``, grown :data:`_STEP` bytes at a time and stopped one byte past ``size``:
    memory follows what the data holds, never a size field."""
    out = bytearray()
    while len(out) <= size:
        piece = decompressor.decompress(data, max_length=min(_STEP, size + 1 - len(out)))
        data = b""
        out += piece
        if decompressor.eof or not piece:
            break
    return out


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


def mcap_chunk_records(chunk: Chunk) -> list[Any]:
    """The records of an MCAP chunk (``mcap``'s ``breakup_chunk``, CRC checked), its data
    decompressed here with memory bounded by what the data holds.

    ``mcap`` hands the chunk's ``uncompressed_size`` to zstd as the output size: a damaged
    size of 2^63 raised "Python int too large to convert to C ssize_t", and zstd data
    written without its content size would have had a buffer of that size allocated. Here
    zstd and lz4 data are decompressed :data:`_STEP` bytes at a time up to one byte past
    that size, which they must fill exactly; then each record's length is checked
    against the chunk (:func:`_framed_records`) before ``mcap`` parses the records.

    Raises:
        ValueError: an unknown compression; data that decompresses to another size than
            the chunk's header gives, or does not decompress; a record whose length does
            not fit the chunk.
        Exception: what ``breakup_chunk`` raises on records that do not parse.
    """
    import dataclasses

    from mcap.stream_reader import breakup_chunk

    compression, size = chunk.compression, chunk.uncompressed_size
    if compression not in ("", "zstd", "lz4"):
        raise ValueError(f"unknown chunk compression {compression[:40]!r}")
    if compression:
        try:
            if compression == "zstd":
                zstandard = importlib.import_module("zstandard")
                reader = zstandard.ZstdDecompressor().stream_reader(
                    chunk.data, read_across_frames=True)
                inner = bytearray()
                while len(inner) <= size:
                    piece = reader.read(min(_STEP, size + 1 - len(inner)))
                    if not piece:
                        break
                    inner += piece
            else:
                lz4frame = importlib.import_module("lz4.frame")
                inner = _bounded(lz4frame.LZ4FrameDecompressor(), chunk.data, size)
        except ImportError:
            return list(breakup_chunk(chunk, validate_crc=True))  # mcap names the package
        except Exception as err:
            raise ValueError(f"corrupt {compression} chunk: {_describe(err)}") from None
        if len(inner) != size:
            more = "more than" if len(inner) > size else f"{len(inner)} bytes, not"
            raise ValueError(f"corrupt {compression} chunk: its data decompresses to {more} "
                             f"the {size} bytes its header gives")
        chunk = dataclasses.replace(chunk, compression="", data=bytes(inner))
    parsed = _framed_records(chunk.data)
    records = list(breakup_chunk(chunk, validate_crc=True))
    if len(records) != parsed:
        raise ValueError(f"corrupt chunk: {len(records)} records read where its framing "
                         f"holds {parsed} (a record's fields overrun its length)")
    return records


_RECORD = struct.Struct("<BQ")
_MESSAGE_HEADER = 22  # channel id (2), sequence (4), log time (8), publish time (8)


def _framed_records(data: bytes) -> int:
    """How many schema, channel and message records a chunk's (decompressed) records
    hold, each record's length checked against what is left of the chunk.

    ``mcap``'s ``breakup_chunk`` reads a message record's data with ``read(length -
    22)``: a length under 22 read everything left in the chunk as that message's data,
    a length past the chunk's end read what was left, and the chunk's later messages
    were dropped without an error.

    Raises:
        ValueError: a record header cut short, a length past the chunk's end, a message
            record shorter than a message's header.
    """
    off, end, known = 0, len(data), 0
    while off < end:
        if off + _RECORD.size > end:
            raise ValueError(f"corrupt chunk: a record header cut short at byte {off} of "
                             f"its {end} bytes of records")
        op, length = _RECORD.unpack_from(data, off)
        left = end - off - _RECORD.size
        if length > left:
            raise ValueError(f"corrupt chunk: its record at byte {off} (opcode 0x{op:02x}) "
                             f"says it is {length} bytes long, more than the {left} left in "
                             f"the chunk")
        if op == 0x05 and length < _MESSAGE_HEADER:
            raise ValueError(f"corrupt chunk: its message record at byte {off} is {length} "
                             f"bytes long, less than a message's {_MESSAGE_HEADER}-byte "
                             f"header")
        known += op in (0x03, 0x04, 0x05)
        off += _RECORD.size + length
    return known


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
    from mcap.stream_reader import StreamReader

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
                        inner = mcap_chunk_records(record)
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
