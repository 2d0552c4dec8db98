"""Fuzzing every way a user reads a recording: damaged ROS 1 bags, .db3 files and MCAP files.

Small valid files are written first (tfbus's own writer, rosbags' bz2 ROS 1 writer,
``mcap``'s writer with zstd and lz4 chunks), then damaged the ways files are damaged: cut
at any byte, bits flipped, an absurd value written into a length field of a record
(ROS 1 record header and data lengths, header field lengths, a chunk's uncompressed size;
MCAP record lengths, a chunk's uncompressed size, compression name and records length,
the footer's offsets; a .db3 header's page size and page count), records duplicated or
swapped (.db3: pages). Each damaged file goes through one of the library's readers
(:func:`~tfbus.bag.read_messages`, :func:`~tfbus.bag.load_buffer`,
:func:`~tfbus.bag.summarize`, :func:`~tfbus.bag.read_window`,
:func:`~tfbus.bag.iter_windows`) under a bound on the address space, so an absurd length
that is allocated fails the test rather than the machine.

Whatever the damage: only a :class:`~tfbus.bag.BagError` escapes, in one line naming the
file; no allocation fails (a MemoryError turned into a BagReadError counts as one);
what is read before the damage of a cut file, or of a file with one bad length, is a
prefix of the intact file's messages; every message read is well formed. A few fixed
damaged files go through the commands (``tfbus bag-info``, ``doctor``, ``echo``,
``lookup --bag``) as subprocesses: status not 0, one-line warnings or errors, no traceback.

Hypothesis runs derandomized (the same examples on every run) and bounded
(``max_examples``), so the suite stays deterministic and short.
"""

from __future__ import annotations

import contextlib
import resource
import struct
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

pytest.importorskip("rosbags")
pytest.importorskip("mcap")

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from tfbus.bag import (
    DEFAULT_TOPICS,
    BagError,
    BagMessage,
    BagReadError,
    iter_windows,
    load_buffer,
    read_messages,
    read_window,
    summarize,
    write_bag,
)
from tfbus.time import Time

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
TURTLE = DATA / "webviz_turtle_tf_example.bag"
NAV2 = DATA / "nav2_like.mcap"
ROS1_MAGIC = b"#ROSBAG V2.0\n"
MCAP_MAGIC = b"\x89MCAP0\r\n"

FUZZ = settings(max_examples=80, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

ABSURD_U32 = [0xFFFFFFFF, 0x80000000, 0x7FFFFFFF, 0x10000000, 0]
ABSURD_U64 = [2**64 - 1, 2**63, 2**63 - 1, 2**40, 2**32, 0]
ADDRESS_SPACE = 768 << 20
"""Bytes of address space a read may add to the process's (an absurd length allocated
fails with MemoryError inside the bound)."""


# ------------------------------------------------------------------ the valid files

def _rosbags_ros1(path: Path, source: Path, compression: str) -> Path:
    """A ROS 1 bag with ``compression`` (BZ2 / LZ4) chunks of ~2 KiB, written by
    rosbags' Writer with ``source``'s tf messages."""
    from rosbags.rosbag1 import Reader, Writer

    writer = Writer(path)
    writer.set_compression(Writer.CompressionFormat[compression])
    writer.chunk_threshold = 2048
    with Reader(source) as reader, writer:
        tf = [c for c in reader.connections if c.topic in ("/tf", "/tf_static")]
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data,
                                             md5sum=c.digest, callerid=c.ext.callerid,
                                             latching=c.ext.latching) for c in tf}
        for conn, t, raw in reader.messages(connections=tf):
            writer.write(conns[conn.id], t, raw)
    return path


def _mcap_compressed(path: Path, source: Path, compression: str) -> Path:
    """``source``'s messages rewritten by the ``mcap`` package's Writer with
    ``compression`` (zstd / lz4) chunks of ~2 KiB and a full summary."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with source.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        items = list(reader.iter_messages())
        with path.open("wb") as out:
            w = Writer(out, chunk_size=2048, compression=CompressionType[compression.upper()])
            w.start("ros2", "tfbus-test")
            schemas = {sid: w.register_schema(s.name, s.encoding, s.data)
                       for sid, s in summary.schemas.items()}
            channels = {cid: w.register_channel(c.topic, c.message_encoding,
                                                schemas[c.schema_id], c.metadata)
                        for cid, c in summary.channels.items()}
            for _schema, channel, m in items:
                w.add_message(channels[channel.id], m.log_time, m.data, m.publish_time)
            w.finish()
    return path


class Recording:
    """A valid file, its bytes and the messages a read of it gives."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.data = path.read_bytes()
        self.messages = list(read_messages(path))
        assert self.messages
        self.suffix = path.suffix

    def __repr__(self) -> str:
        return f"Recording({self.path.name})"


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Recording]:
    d = tmp_path_factory.mktemp("valid")
    base = list(read_messages(TURTLE))[:80]
    write_bag(d / "plain.bag", base, format="ros1")
    write_bag(d / "db", base, format="sqlite3")
    write_bag(d / "mc", base, format="mcap")
    mcap = next((d / "mc").glob("*.mcap"))
    files = {
        "ros1": d / "plain.bag",
        "ros1_bz2": _rosbags_ros1(d / "bz2.bag", d / "plain.bag", "BZ2"),
        "ros1_lz4": _rosbags_ros1(d / "lz4.bag", d / "plain.bag", "LZ4"),
        "db3": next((d / "db").glob("*.db3")),
        "mcap": mcap,
        "mcap_zstd": _mcap_compressed(d / "zstd.mcap", mcap, "zstd"),
        "mcap_lz4": _mcap_compressed(d / "lz4.mcap", mcap, "lz4"),
    }
    out = {name: Recording(p) for name, p in files.items()}
    for name, rec in out.items():
        assert rec.messages == out["ros1"].messages or name.startswith(("db3", "mcap")), name
    return out


# ------------------------------------------------------------------ where the fields are

def _ros1_records(data: bytes, start: int, stop: int) -> Iterator[tuple[int, int, int]]:
    """(offset, header length, data length) of each ROS 1 record in ``data[start:stop]``
    (wiki.ros.org/Bags/Format/2.0), parsed here independently of tfbus."""
    off = start
    while off + 8 <= stop:
        (hlen,) = struct.unpack_from("<I", data, off)
        if off + 8 + hlen > stop:
            return
        (dlen,) = struct.unpack_from("<I", data, off + 4 + hlen)
        yield off, hlen, dlen
        off += 8 + hlen + dlen


def _ros1_fields(data: bytes, off: int, hlen: int) -> Iterator[tuple[int, bytes, int]]:
    """(offset of the field's length, name, offset of its value) of a record header."""
    i = off + 4
    while i + 4 <= off + 4 + hlen:
        (n,) = struct.unpack_from("<I", data, i)
        name = data[i + 4:i + 4 + n].partition(b"=")[0]
        yield i, name, i + 4 + len(name) + 1
        i += 4 + n


def ros1_layout(data: bytes) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """The length fields ``(offset, width)`` of a ROS 1 bag, and its records' spans
    ``(start, end)`` (top level and inside uncompressed chunks)."""
    lengths: list[tuple[int, int]] = []
    spans: list[tuple[int, int]] = []

    def walk(start: int, stop: int) -> None:
        for off, hlen, dlen in _ros1_records(data, start, stop):
            lengths.extend([(off, 4), (off + 4 + hlen, 4)])
            spans.append((off, off + 8 + hlen + dlen))
            fields = {}
            for at, name, value in _ros1_fields(data, off, hlen):
                lengths.append((at, 4))
                fields[name] = value
            if b"size" in fields:  # a chunk's uncompressed size (drawn 8 times as often)
                lengths.extend([(fields[b"size"], 4)] * 8)
            for name in (b"index_pos", b"chunk_pos"):
                if name in fields:
                    lengths.append((fields[name], 8))
            if b"count" in fields:
                lengths.append((fields[b"count"], 4))
            if b"compression" in fields and data[fields[b"compression"]:].startswith(b"none"):
                walk(off + 8 + hlen, off + 8 + hlen + dlen)

    walk(len(ROS1_MAGIC), len(data))
    return lengths, spans


def mcap_layout(data: bytes) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """The length fields ``(offset, width)`` of an MCAP file (mcap.dev/spec), and its
    top-level records' spans."""
    lengths: list[tuple[int, int]] = []
    spans: list[tuple[int, int]] = []

    def walk(start: int, stop: int, top: bool) -> None:
        off = start
        while off + 9 <= stop:
            op = data[off]
            (n,) = struct.unpack_from("<Q", data, off + 1)
            lengths.append((off + 1, 8))
            body = off + 9
            if top:
                spans.append((off, min(body + n, stop)))
            if op == 0x06 and body + 32 <= stop:  # Chunk
                # uncompressed size (drawn 8 times as often), compression name length
                lengths.extend([(body + 16, 8)] * 8 + [(body + 28, 4)])
                (clen,) = struct.unpack_from("<I", data, body + 28)
                rec = body + 32 + clen
                compression = data[body + 32:rec]
                lengths.append((rec, 8))
                if compression == b"" and rec + 8 <= stop:
                    (rlen,) = struct.unpack_from("<Q", data, rec)
                    walk(rec + 8, min(rec + 8 + rlen, stop), False)
            elif op in (0x03, 0x04) and body + 6 <= stop:  # Schema, Channel: a string length
                lengths.append((body + (2 if op == 0x03 else 4), 4))
            elif op == 0x02:  # Footer: summary start and summary offset start
                lengths.extend([(body, 8), (body + 8, 8)])
            if op == 0x02 or n > stop:
                return
            off = body + n

    walk(len(MCAP_MAGIC), len(data), True)
    return lengths, spans


def db3_layout(data: bytes) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """The sqlite3 header's size fields (page size, in-header page count, first freelist
    page, freelist count, schema format) and the file's pages past the first."""
    lengths = [(16, 2), (28, 4), (32, 4), (36, 4), (44, 4)]
    page = int.from_bytes(data[16:18], "big")
    spans = [(i, i + page) for i in range(page, len(data) - page + 1, page)]
    return lengths, spans


LAYOUT: dict[str, Callable[[bytes], tuple[list[tuple[int, int]], list[tuple[int, int]]]]] = {
    ".bag": ros1_layout, ".mcap": mcap_layout, ".db3": db3_layout}


# ------------------------------------------------------------------ damage

class Damaged(bytes):
    """Damaged file contents, shown by their size (not their bytes) in reports."""

    def __repr__(self) -> str:
        return f"<{len(self)} bytes>"


@st.composite
def damage(draw: st.DrawFn, rec: Recording,
           kinds: tuple[str, ...] = ("cut", "flip", "length", "length", "duplicate", "swap"),
           ) -> tuple[str, bytes, int]:
    """(kind, damaged bytes, offset of the first damaged byte)."""
    data = rec.data
    lengths, spans = LAYOUT[rec.suffix](data)
    kind = draw(st.sampled_from(kinds))
    if kind == "cut":
        at = draw(st.integers(0, len(data) - 1))
        return kind, data[:at], at
    if kind == "flip":
        b = bytearray(data)
        flips = draw(st.lists(st.tuples(st.integers(0, len(b) - 1), st.integers(0, 7)),
                              min_size=1, max_size=8))
        for pos, bit in flips:
            b[pos] ^= 1 << bit
        return kind, bytes(b), min(p for p, _ in flips)
    if kind == "length":
        at, width = draw(st.sampled_from(lengths))
        value = draw(st.sampled_from(ABSURD_U32 if width == 4 else
                                     ABSURD_U64 if width == 8 else [0, 1, 3, 0xFFFF]) |
                     st.sampled_from([len(data), len(data) + 1, len(data) * 2]))
        value %= 1 << (8 * width)
        order = "big" if rec.suffix == ".db3" else "little"
        patched = data[:at] + value.to_bytes(width, order) + data[at + width:]
        return kind, patched, at
    i = draw(st.integers(0, len(spans) - 2))
    (a0, a1), (b0, b1) = spans[i], spans[i + 1]
    if kind == "duplicate":
        return kind, data[:a1] + data[a0:a1] + data[a1:], a1
    if rec.suffix == ".db3":  # swap two pages
        j = draw(st.integers(0, len(spans) - 1))
        (b0, b1) = spans[j]
        if b0 < a0:
            (a0, a1), (b0, b1) = (b0, b1), (a0, a1)
        if a0 == b0:
            return kind, data, len(data)
        return kind, data[:a0] + data[b0:b1] + data[a1:b0] + data[a0:a1] + data[b1:], a0
    return kind, data[:a0] + data[b0:b1] + data[a0:a1] + data[b1:], a0


# ------------------------------------------------------------------ reading

@contextlib.contextmanager
def bounded_address_space() -> Iterator[None]:
    """At most :data:`ADDRESS_SPACE` more bytes of address space while inside."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/status") as f:
        vm = next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmSize:"))
    limit = vm + ADDRESS_SPACE
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _collect(it: Iterator[BagMessage], got: list[BagMessage]) -> None:
    for m in it:
        got.append(m)


def _read_messages(p: Path, got: list[BagMessage]) -> None:
    _collect(read_messages(p), got)


def _load_buffer(p: Path, got: list[BagMessage]) -> None:
    try:
        core = load_buffer(p)
    except BagReadError as err:
        assert err.partial is not None
        raise
    core.all_frames_as_string()


def _summarize(p: Path, got: list[BagMessage]) -> None:
    s = summarize(p)
    if s.error is not None:
        raise s.error


def _read_window(p: Path, got: list[BagMessage]) -> None:
    _collect(read_window(p, start=Time(1396293888, 200_000_000),
                                 end=Time(1396293888, 500_000_000)), got)


def _iter_windows(p: Path, got: list[BagMessage]) -> None:
    for w in iter_windows(p, 0.1, margin=0.05):
        assert w.buffer is not None


READERS: dict[str, Callable[[Path, list[BagMessage]], None]] = {
    "read_messages": _read_messages,
    "load_buffer": _load_buffer,
    "summarize": _summarize,
    "read_window": _read_window,
    "iter_windows": _iter_windows,
}


def _memory_errors(err: BaseException | None) -> list[BaseException]:
    out = []
    seen: set[int] = set()
    while err is not None and id(err) not in seen:
        seen.add(id(err))
        if isinstance(err, MemoryError):
            out.append(err)
        err = err.__context__ or err.__cause__
    return out


def read_damaged(path: Path, reader: str) -> tuple[list[BagMessage], BaseException | None]:
    got: list[BagMessage] = []
    try:
        with bounded_address_space():
            READERS[reader](path, got)
    except Exception as err:
        return got, err
    return got, None


def check(rec: Recording, kind: str, damaged: bytes, at: int, reader: str) -> None:
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"damaged{rec.suffix}"
        path.write_bytes(damaged)
        got, err = read_damaged(path, reader)
    event(f"{kind}: {type(err).__name__}")
    assert err is None or isinstance(err, BagError), (kind, at, reader, repr(err))
    assert not _memory_errors(err), (kind, at, reader, "an absurd length was allocated")
    if err is not None:
        text = str(err)
        assert "\n" not in text and str(path) in text, text
    for m in got:
        assert isinstance(m, BagMessage) and m.topic in DEFAULT_TOPICS
        assert 0 <= m.time.ns < 2**63
    if kind == "cut" and reader == "read_messages":
        assert err is not None, (kind, at)
        assert got == rec.messages[: len(got)], (kind, at)
    if kind == "length" and reader == "read_messages":
        assert got == (rec.messages[: len(got)] if err else rec.messages), (kind, at)
    if kind in ("duplicate", "swap") and reader == "read_messages":
        assert all(m in rec.messages for m in got), (kind, at)


def _fuzz(name: str) -> Callable[..., None]:
    @FUZZ
    @given(data=st.data())
    def test(recordings: dict[str, Recording], data: st.DataObject) -> None:
        rec = recordings[name]
        kind, damaged, at = data.draw(damage(rec).map(lambda d: (d[0], Damaged(d[1]), d[2])),
                                      label="damage")
        reader = data.draw(st.sampled_from(list(READERS)), label="reader")
        check(rec, kind, damaged, at, reader)

    test.__doc__ = (f"{name}: cut, flipped, absurd lengths, duplicated and swapped records "
                    "through every reader: only a one-line BagError naming the file, no "
                    "allocation failing, a prefix of the intact file's messages when cut "
                    "or with one bad length.")
    return test


test_fuzz_ros1 = _fuzz("ros1")
test_fuzz_ros1_bz2 = _fuzz("ros1_bz2")
test_fuzz_ros1_lz4 = _fuzz("ros1_lz4")
test_fuzz_db3 = _fuzz("db3")
test_fuzz_mcap = _fuzz("mcap")
test_fuzz_mcap_zstd = _fuzz("mcap_zstd")
test_fuzz_mcap_lz4 = _fuzz("mcap_lz4")


@settings(max_examples=12, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(data=st.data())
def test_fuzz_recorded_files(data: st.DataObject) -> None:
    """The turtle bag (rosbag record, 850 KB) and nav2_like.mcap (220 KB) cut and with an
    absurd length, read whole: only a BagError, the intact file's first messages."""
    rec = data.draw(st.sampled_from([TURTLE_REC, NAV2_REC]), label="file")
    kind, damaged, at = data.draw(damage(rec, ("cut", "length")),
                                  label="damage")
    check(rec, kind, damaged, at, "read_messages")


TURTLE_REC = Recording(TURTLE)
NAV2_REC = Recording(NAV2)


# ------------------------------------------------------------------ the commands

def _cli(*args: str) -> tuple[int, str]:
    out = subprocess.run([sys.executable, "-m", "tfbus.cli", *args], capture_output=True,
                         text=True, timeout=120, env={"PYTHONPATH": str(ROOT),
                                                      "PATH": "/usr/bin:/bin"})
    return out.returncode, out.stderr


def _damaged_files(d: Path, recordings: dict[str, Recording]) -> dict[str, Path]:
    out = {}
    ros1 = recordings["ros1"].data
    lengths, _ = ros1_layout(ros1)
    at = lengths[len(lengths) // 2][0]  # a length in the middle of the bag: absurd
    out["bag"] = d / "length.bag"
    out["bag"].write_bytes(ros1[:at] + b"\xff\xff\xff\xff" + ros1[at + 4:])
    z = recordings["mcap_zstd"].data
    # the first chunk's uncompressed size (24 bytes past its length field): 2^63
    chunk = next(o for o, w in mcap_layout(z)[0] if w == 8 and z[o - 1] == 0x06)
    out["mcap"] = d / "size.mcap"
    out["mcap"].write_bytes(z[:chunk + 24] + struct.pack("<Q", 2**63) + z[chunk + 32:])
    db = recordings["db3"].data
    out["db3"] = d / "cut.db3"
    out["db3"].write_bytes(db[: len(db) * 2 // 3])
    return out


@pytest.mark.parametrize(("command", "file"), [
    ("bag-info {}", "mcap"),
    ("doctor --bag {}", "db3"),
    ("echo world turtle1 --bag {} -n 3", "bag"),
    ("lookup --bag {} --target world --source turtle1 --every 1 -o {out} --quiet", "mcap"),
])
def test_commands_on_damaged_files(tmp_path: Path, recordings: dict[str, Recording],
                                   command: str, file: str) -> None:
    """Each command a user reads a recording with, on a damaged file: exit status not 0,
    every stderr line a ``tfbus CMD: warning:`` / ``error:`` line, the first naming the
    file, no traceback."""
    path = _damaged_files(tmp_path, recordings)[file]
    code, err = _cli(*command.format(path, out=tmp_path / "o.parquet").split())
    assert code != 0, err
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    name = command.split()[0]
    if name == "doctor":  # the damage is in the report (stdout), not in a warning
        assert lines == [], err
        return
    assert lines and all(line.startswith(f"tfbus {name}: ") for line in lines), err
    assert str(path) in lines[0], err
    assert all(": warning: " in line or ": error: " in line for line in lines), err


def test_absurd_lengths_of_the_fuzz_are_set_in_files() -> None:
    """The length fields the fuzz writes are where the formats put them: the first
    record of each file read back with the offsets above."""
    data = TURTLE.read_bytes()
    lengths, spans = ros1_layout(data)
    (hlen,) = struct.unpack_from("<I", data, len(ROS1_MAGIC))
    assert lengths[0] == (len(ROS1_MAGIC), 4) and spans[0][0] == len(ROS1_MAGIC)
    (dlen,) = struct.unpack_from("<I", data, len(ROS1_MAGIC) + 4 + hlen)
    assert spans[0][1] == len(ROS1_MAGIC) + 8 + hlen + dlen
    assert data[spans[1][0] + 4:spans[1][0] + 40].find(b"op=") >= 0  # the next record
    assert lengths[1] == (len(ROS1_MAGIC) + 4 + hlen, 4)
    nav = NAV2.read_bytes()
    lengths, spans = mcap_layout(nav)
    assert spans[0][0] == len(MCAP_MAGIC) and nav[spans[-1][0]] == 0x02  # ends at the footer
    assert spans[-1][1] == len(nav) - len(MCAP_MAGIC)


# ------------------------------------------------------------ minimal failing inputs

def _second_chunk_size(data: bytes) -> int:
    """Offset of the ``size`` value in the header of a ROS 1 bag's second chunk."""
    starts = [off for off, hlen, _ in _ros1_records(data, len(ROS1_MAGIC), len(data))
              if any(name == b"op" and data[v] == 0x05
                     for _, name, v in _ros1_fields(data, off, hlen))]
    assert len(starts) >= 2
    off = starts[1]
    (hlen,) = struct.unpack_from("<I", data, off)
    return next(v for _, name, v in _ros1_fields(data, off, hlen) if name == b"size")


@pytest.mark.parametrize(("compression", "size"), [
    ("bz2", 0), ("lz4", 0), ("bz2", 1), ("lz4", 1), ("bz2", "one less"), ("lz4", "one less"),
    ("lz4", 2**30), ("lz4", 2**32 - 1)])
def test_ros1_chunk_size_that_does_not_match_its_data(
        tmp_path: Path, recordings: dict[str, Recording], compression: str,
        size: int | str) -> None:
    """Found by the fuzz tests above: a compressed ROS 1 chunk whose header gives
    ``size`` 0 was read as holding no record, its messages dropped with no error (79 of
    80 messages, silently); an lz4 chunk whose ``size`` says 1 GiB or 4 GiB had a buffer
    that large allocated (lz4's ``max_length``). Now the chunk's data must decompress to
    exactly its size, in memory bounded by the data: the messages before the chunk, then
    a BagReadError at the chunk naming the compression, and nothing allocated."""
    rec = recordings[f"ros1_{compression}"]
    at = _second_chunk_size(rec.data)
    real = int.from_bytes(rec.data[at:at + 4], "little")
    value = real - 1 if size == "one less" else int(size)
    bad = tmp_path / "size.bag"
    bad.write_bytes(rec.data[:at] + value.to_bytes(4, "little") + rec.data[at + 4:])
    got, err = read_damaged(bad, "read_messages")
    assert isinstance(err, BagReadError), repr(err)
    assert not _memory_errors(err)
    assert f"corrupt {compression} chunk" in err.reason and str(bad) in str(err)
    assert 0 < len(got) < len(rec.messages) and got == rec.messages[: len(got)]
    assert err.offset is not None and err.offset < at  # the chunk's record holds `at`


def _first_chunk_without_content_size(data: bytes, size: int) -> bytes:
    """``data`` (a zstd MCAP file) up to its first chunk, that chunk rewritten with its
    records compressed by zstd without the frame's content size and ``size`` as its
    uncompressed size; the file ends there (cut short: no summary)."""
    import zstandard

    _, spans = mcap_layout(data)
    start = next(a for a, _ in spans if data[a] == 0x06)
    body = start + 9
    (clen,) = struct.unpack_from("<I", data, body + 28)
    rec = body + 32 + clen
    assert data[body + 32:rec] == b"zstd"
    (rlen,) = struct.unpack_from("<Q", data, rec)
    records = zstandard.ZstdDecompressor().decompress(data[rec + 8:rec + 8 + rlen])
    packed = zstandard.ZstdCompressor(write_content_size=False).compress(records)
    content = (data[body:body + 16] + struct.pack("<QI", size, 0) + struct.pack("<I", 4)
               + b"zstd" + struct.pack("<Q", len(packed)) + packed)
    return data[:start] + b"\x06" + struct.pack("<Q", len(content)) + content


@pytest.mark.parametrize("size", [2**32, 2**40, 2**63, 2**64 - 1, 1])
def test_mcap_chunk_size_that_does_not_match_its_data(
        tmp_path: Path, recordings: dict[str, Recording], size: int) -> None:
    """Found by the fuzz tests above: an MCAP zstd chunk whose uncompressed size says
    2^63 stopped the read with "Python int too large to convert to C ssize_t"; zstd data
    written without its content size had a buffer of the header's size allocated (4 GiB,
    1 TiB). Now a BagReadError says the chunk's data decompresses to another size than
    its header gives, and nothing that large is allocated."""
    data = _first_chunk_without_content_size(recordings["mcap_zstd"].data, size)
    bad = tmp_path / "size.mcap"
    bad.write_bytes(data)
    got, err = read_damaged(bad, "read_messages")
    assert isinstance(err, BagReadError), repr(err)
    assert not _memory_errors(err), "the chunk's size was allocated"
    assert got == []
    assert "corrupt zstd chunk: its data decompresses to" in err.reason, err.reason
    assert f"the {size} bytes its header gives" in err.reason, err.reason
    # the same chunk with its true size is read: the first chunk's messages
    true = tmp_path / "true.mcap"
    import zstandard

    records_size = len(zstandard.ZstdDecompressor().decompressobj().decompress(
        data[data.rindex(b"zstd") + 12:]))
    true.write_bytes(_first_chunk_without_content_size(recordings["mcap_zstd"].data,
                                                       records_size))
    got, err = read_damaged(true, "read_messages")
    assert isinstance(err, BagReadError) and "truncated" in err.reason, repr(err)
    assert got and got == recordings["mcap_zstd"].messages[: len(got)]


def _second_message_length(data: bytes) -> int:
    """Offset of the length field of the second message record inside an MCAP file's
    first (uncompressed) chunk."""
    _, spans = mcap_layout(data)
    start = next(a for a, _ in spans if data[a] == 0x06)
    body = start + 9
    (clen,) = struct.unpack_from("<I", data, body + 28)
    off = body + 32 + clen + 8
    seen = 0
    while True:
        op, length = struct.unpack_from("<BQ", data, off)
        if op == 0x05:
            seen += 1
            if seen == 2:
                return off + 1
        off += 9 + length


@pytest.mark.parametrize("length", [0, 1, 21, 2**32, 2**40, 2**63, 2**64 - 1])
@pytest.mark.parametrize("summary", [True, False])
def test_mcap_message_length_that_does_not_fit_its_chunk(
        tmp_path: Path, recordings: dict[str, Recording], length: int, summary: bool) -> None:
    """Found by the fuzz tests above: a message record in an MCAP chunk whose length is
    under a message header's 22 bytes, or past the chunk's end, was read (``mcap``'s
    ``read(length - 22)``) as one message holding the rest of the chunk: the read
    returned 1 of 80 messages and no error (2^64 - 1 stopped it with "cannot fit 'int'
    into an index-sized integer"). Now a BagReadError naming the record, after the
    messages of the chunks before it (none: it is in the first chunk; a chunk is read
    whole, as for a bad CRC), whether the file is read through its summary or, cut
    short, from the start."""
    data = recordings["mcap"].data
    at = _second_message_length(data)
    patched = data[:at] + struct.pack("<Q", length) + data[at + 8:]
    if not summary:  # cut after the first chunk: read record by record
        _, spans = mcap_layout(data)
        patched = patched[:next(b for a, b in spans if data[a] == 0x06)]
    bad = tmp_path / "length.mcap"
    bad.write_bytes(patched)
    got, err = read_damaged(bad, "read_messages")
    assert isinstance(err, BagReadError), repr(err)
    assert got == []
    assert "corrupt chunk: its" in err.reason and str(bad) in str(err), err.reason
    assert ("more than the" in err.reason) if length >= 22 else \
        ("less than a message's 22-byte header" in err.reason), err.reason
