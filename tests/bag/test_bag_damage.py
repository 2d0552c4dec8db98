"""Damaged bags (records that do not parse, bags cut short, and the bag-reading fuzz test).

Whatever the damage, a read returns every readable message first, then raises one
``BagReadError`` naming the file and the byte offset where reading stopped; no other
exception escapes (``ValueError``, ``UnicodeDecodeError``, rosbags' ``TypesysError`` did).
"""

from __future__ import annotations

import random
import struct
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("rosbags")
pytest.importorskip("mcap")

from tfbus.bag import (
    BagError,
    BagMessage,
    BagReadError,
    load_buffer,
    read_messages,
    summarize,
    write_bag,
)
from tfbus.time import Time

DATA = Path(__file__).resolve().parents[1] / "data"
TURTLE = DATA / "webviz_turtle_tf_example.bag"
TURTLE_MESSAGES = 2689


def read_all(path: Path) -> tuple[list[BagMessage], BaseException | None]:
    """Every message a read yields, and the exception that ended it (or ``None``)."""
    got: list[BagMessage] = []
    try:
        for rec in read_messages(path):
            got.append(rec)
    except Exception as err:
        return got, err
    return got, None


def ros1_records(
    data: bytes, start: int = len(b"#ROSBAG V2.0\n"), stop: int | None = None
) -> Iterator[tuple[int, int, dict[str, bytes]]]:
    """(offset, end, header fields) of each record of a ROS 1 bag v2.0 in
    ``data[start:stop]``, parsed here from the format description
    (wiki.ros.org/Bags/Format/2.0), independently of tfbus."""
    off = start
    while off < (len(data) if stop is None else stop):
        (hlen,) = struct.unpack_from("<I", data, off)
        raw = data[off + 4 : off + 4 + hlen]
        fields: dict[str, bytes] = {}
        i = 0
        while i < len(raw):
            (n,) = struct.unpack_from("<I", raw, i)
            name, _, value = raw[i + 4 : i + 4 + n].partition(b"=")
            fields[name.decode()] = value
            i += 4 + n
        (dlen,) = struct.unpack_from("<I", data, off + 4 + hlen)
        end = off + 8 + hlen + dlen
        yield off, end, fields
        off = end


def tfbus_bags(tmp_path: Path, messages: list[BagMessage]) -> dict[str, Path]:
    """A ROS 1 .bag, a bare .db3 and a bare .mcap written by tfbus's own writer."""
    write_bag(tmp_path / "w.bag", messages, format="ros1")
    write_bag(tmp_path / "d", messages, format="sqlite3")
    write_bag(tmp_path / "m", messages, format="mcap")
    return {
        "ros1": tmp_path / "w.bag",
        "sqlite3": next((tmp_path / "d").glob("*.db3")),
        "mcap": next((tmp_path / "m").glob("*.mcap")),
    }


def mcap_with(path: Path, source: Path, log_times: list[int], schema_text: bytes | None = None,
              ) -> Path:
    """An MCAP file (written with the ``mcap`` package) holding the first /tf payloads of
    ``source`` at the given log times; ``schema_text`` replaces the stored definition."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with source.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        (schema,) = [s for s in summary.schemas.values() if s.name == "tf2_msgs/msg/TFMessage"]
        payloads = [m.data for _s, c, m in reader.iter_messages(topics=["/tf"])]
    with path.open("wb") as out:
        w = Writer(out)
        w.start("ros2", "tfbus-test")
        sid = w.register_schema(schema.name, schema.encoding, schema_text or schema.data)
        cid = w.register_channel("/tf", "cdr", sid)
        for t, payload in zip(log_times, payloads, strict=False):
            w.add_message(cid, t, payload, t)
        w.finish()
    return path


# ------------------------------------------------------------ records that do not parse


def test_log_time_beyond_int64_is_a_bag_read_error(tmp_path: Path) -> None:
    """An MCAP log time >= 2**63 ns raised ValueError (Time range) out of the
    read; now the three messages before it are returned, then a BagReadError."""
    bags = tfbus_bags(tmp_path, list(read_messages(TURTLE))[:10])
    bad = mcap_with(tmp_path / "huge.mcap", bags["mcap"], [10**18, 10**18 + 1, 10**18 + 2,
                                                           2**64 - 1])
    got, err = read_all(bad)
    assert len(got) == 3
    assert isinstance(err, BagReadError), repr(err)
    assert err.messages_read == 3 and "huge.mcap" in str(err) and err.offset is not None
    assert "\n" not in str(err)


def test_unreadable_schema_is_a_bag_read_error(tmp_path: Path) -> None:
    """A cut MCAP whose stored definition is mangled raised rosbags'
    TypesysError; now a BagReadError naming the file and the offset."""
    bags = tfbus_bags(tmp_path, list(read_messages(TURTLE))[:40])
    data = bags["mcap"].read_bytes()
    sep = b"=" * 80
    assert sep in data
    mangled = data.replace(sep, b"=" * 14 + b"<" + b"=" * 65, 1)
    cut = tmp_path / "schema.mcap"
    cut.write_bytes(mangled[: len(mangled) * 9 // 10])
    got, err = read_all(cut)
    assert got == []
    assert isinstance(err, BagReadError), repr(err)
    assert err.offset is not None and 0 < err.offset < len(mangled) and "schema.mcap" in str(err)


@pytest.mark.parametrize("cut", [True, False])
def test_unparsable_schema_is_one_short_line(tmp_path: Path, cut: bool) -> None:
    """``tfbus bag-info`` on an MCAP whose stored schema does not parse
    printed the whole schema twice in one ~1500-character warning; now one short line:
    the file, the byte offset, the schema's name and its first bad line (line 2 of the
    stored definition, the mangled separator), whether or not the file has a summary
    (a complete file is then read record by record: no usable topic hash here)."""
    from click.testing import CliRunner

    from tfbus.cli import cli

    source = tfbus_bags(tmp_path, list(read_messages(TURTLE))[:40])["mcap"]
    text = "geometry_msgs/TransformStamped[] transforms\n=====<=====\n" + "=" * 80 + "\n"
    whole = mcap_with(tmp_path / "bad.mcap", source, [10**18 + i for i in range(5)],
                      schema_text=text.encode() + b"MSG: geometry_msgs/TransformStamped\n")
    path = whole
    if cut:
        path = tmp_path / "badcut.mcap"
        data = whole.read_bytes()
        path.write_bytes(data[: len(data) * 9 // 10])
    result = CliRunner().invoke(cli, ["bag-info", str(path)], catch_exceptions=False)
    (line,) = result.stderr.splitlines()
    assert line.startswith(f"tfbus bag-info: warning: {path}: schema "
                           "'tf2_msgs/msg/TFMessage' does not parse at line 2: '=====<====='")
    assert "; reading stopped (byte " in line
    offset = int(line.split("(byte ")[1].split(",")[0])
    assert 0 < offset < path.stat().st_size
    assert len(line) < 100 + len(str(path)) + 60
    assert "MSG:" not in line and "transforms" not in line  # the schema is not quoted


def test_non_utf8_connection_header_is_a_bag_read_error(tmp_path: Path) -> None:
    """A ROS 1 bag without index whose connection topic is not UTF-8 raised
    UnicodeDecodeError; now a BagReadError at that record's offset."""
    path = tmp_path / "w.bag"
    write_bag(path, list(read_messages(TURTLE))[:40])
    data = bytearray(path.read_bytes())
    conn = next(off for off, _end, f in ros1_records(bytes(data)) if f.get("op") == b"\x05")
    at = data.index(b"topic=/tf", conn)
    data[at + 6] = 0xFF  # "topic=\xfftf"
    chunk_end = next(end for off, end, f in ros1_records(bytes(data)) if f.get("op") == b"\x05")
    cut = tmp_path / "utf8.bag"
    cut.write_bytes(bytes(data[:chunk_end]))
    got, err = read_all(cut)
    assert got == [] and isinstance(err, BagReadError), repr(err)
    assert err.offset is not None and conn < err.offset < at
    assert "utf8.bag" in str(err)


def test_every_bag_error_leaves_the_cli_helpers_one_line(tmp_path: Path) -> None:
    """load_buffer and summarize on a damaged file: a BagReadError / a summary with its
    error, never another exception."""
    bags = tfbus_bags(tmp_path, list(read_messages(TURTLE))[:10])
    bad = mcap_with(tmp_path / "huge.mcap", bags["mcap"], [10**18, 2**64 - 1])
    with pytest.raises(BagReadError) as e:
        load_buffer(bad)
    assert e.value.partial is not None
    s = summarize(bad)
    assert s.error is not None and s.messages == {"/tf": 1}


# --------------------------------------------------------------------------- bags cut short


def test_ros1_cut_exactly_after_a_chunk_is_truncated(tmp_path: Path) -> None:
    """A 20 000-message bag cut right after a chunk (and its index records)
    returned the first chunks' messages with no error; the missing index now says the
    bag is truncated, after those messages."""
    base = list(read_messages(TURTLE))
    dyn = [m for m in base if m.topic == "/tf"]
    t0 = dyn[0].time.ns
    messages = [base[0]] + [
        dyn[i % len(dyn)]._replace(time=Time.from_ns(t0 + i * 1_000_000)) for i in range(19_999)
    ]
    path = tmp_path / "big.bag"
    assert write_bag(path, messages) == 20_000
    data = path.read_bytes()
    records = list(ros1_records(data))
    chunks = [i for i, (_o, _e, f) in enumerate(records) if f.get("op") == b"\x05"]
    assert len(chunks) >= 2
    # After the first chunk come its index-data records (op 0x04); cut after them.
    i = chunks[0] + 1
    while records[i][2].get("op") == b"\x04":
        i += 1
    cut_at = records[i - 1][1]
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[:cut_at])
    got, err = read_all(cut)
    assert isinstance(err, BagReadError), repr(err)
    assert 0 < len(got) < 20_000 and got == list(read_messages(path))[: len(got)]
    assert err.offset == cut_at and "truncated" in err.reason


def test_version_line_alone_is_not_an_empty_bag(tmp_path: Path) -> None:
    """The 13-byte file ``#ROSBAG V2.0\\n`` read as an empty bag; it is an error."""
    path = tmp_path / "v.bag"
    path.write_bytes(b"#ROSBAG V2.0\n")
    got, err = read_all(path)
    assert got == [] and isinstance(err, BagReadError) and err.offset == 13


# --------------------------------------------------------------------------- fuzz


def ros1_tf_message_ends(data: bytes) -> list[int]:
    """File offset where each /tf or /tf_static message record ends, in file order, for
    a bag with uncompressed chunks (parsed independently of tfbus)."""
    tf_conns: set[bytes] = set()
    ends = []
    for _off, end, fields in ros1_records(data):
        if fields.get("op") != b"\x05":
            continue
        assert fields["compression"] == b"none"
        body = end - int.from_bytes(fields["size"], "little")
        for _o, e, f in ros1_records(data, body, end):
            if f.get("op") == b"\x07" and f["topic"] in (b"/tf", b"/tf_static"):
                tf_conns.add(f["conn"])
            elif f.get("op") == b"\x02" and f["conn"] in tf_conns:
                ends.append(e)
    return ends


def _variants(data: bytes, rng: random.Random, n: int) -> Iterator[tuple[str, bytes]]:
    for k in range(n):
        if k % 2:
            yield "cut", data[: rng.randrange(len(data))]
        else:
            b = bytearray(data)
            for _ in range(rng.choice((1, 1, 2, 8))):
                b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
            yield "flip", bytes(b)


def test_fuzz_damaged_bags_raise_only_bag_errors(tmp_path: Path) -> None:
    """Byte flips and truncations of the turtle bag and of tfbus-written .bag, .db3 and
    .mcap files (seeded, bounded: 16 reads of the 850 KB turtle bag, 3 x 50 of the small
    ones): only BagError escapes; a truncated file
    returns a prefix of the intact file's messages, a longer cut never fewer, and the
    intact length reads whole without error."""
    bags = {"turtle": TURTLE, **tfbus_bags(tmp_path, list(read_messages(TURTLE))[:150])}
    rng = random.Random(20261122)
    for name, src in bags.items():
        data = src.read_bytes()
        full = list(read_messages(src))
        ends = ros1_tf_message_ends(data) if src.suffix == ".bag" else None
        assert ends is None or len(ends) == len(full)
        cuts: list[tuple[int, int]] = []
        for kind, damaged in _variants(data, rng, 16 if name == "turtle" else 50):
            f = tmp_path / f"fuzz{src.suffix}"
            f.write_bytes(damaged)
            got, err = read_all(f)
            assert err is None or isinstance(err, BagError), (name, kind, repr(err))
            if kind == "cut":
                assert err is not None, (name, len(damaged))
                assert got == full[: len(got)], (name, len(damaged))
                if ends is not None:
                    assert len(got) == sum(e <= len(damaged) for e in ends), (name, len(damaged))
                cuts.append((len(damaged), len(got)))
        cuts.sort()
        counts = [n for _size, n in cuts]
        assert counts == sorted(counts), name  # a later cut never returns fewer
    whole = tmp_path / "whole.bag"
    whole.write_bytes(TURTLE.read_bytes())
    assert read_all(whole) == (list(read_messages(TURTLE)), None)


@pytest.mark.parametrize("compression", ["BZ2", "LZ4"])
def test_compressed_ros1_bag_cut_is_salvaged(tmp_path: Path, compression: str) -> None:
    """A ROS 1 bag with bz2 / lz4 chunks (written by rosbags' Writer), cut: the complete
    chunks before the cut are read record by record, the same messages as the intact
    file, then a BagReadError at the cut chunk."""
    from rosbags.rosbag1 import Reader, Writer

    path = tmp_path / f"{compression}.bag"
    writer = Writer(path)
    writer.set_compression(Writer.CompressionFormat[compression])
    writer.chunk_threshold = 16 * 1024  # several chunks (rosbags: 1 MiB by default)
    with Reader(TURTLE) as reader, writer:
        conns = {}
        tf = [c for c in reader.connections if c.topic in ("/tf", "/tf_static")]
        for c in tf:
            conns[c.id] = writer.add_connection(
                c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest,
                callerid=c.ext.callerid, latching=c.ext.latching,
            )
        for conn, t, raw in reader.messages(connections=tf):
            writer.write(conns[conn.id], t, raw)
    full = list(read_messages(path))
    assert full == list(read_messages(TURTLE))
    data = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) // 2])
    got, err = read_all(cut)
    assert isinstance(err, BagReadError), repr(err)
    assert len(full) // 4 < len(got) < len(full) and got == full[: len(got)]
    assert err.offset is not None and err.offset < len(data) // 2


# --------------------------------------- flipped .db3 bits, salvage memory, chunk sizes


def _index_entry_flipped(tmp_path: Path, row: int, bit: int) -> tuple[Path, list[BagMessage]]:
    """A 20-message .db3 whose timestamp index entry for messages row ``row`` has bit
    ``bit`` of its timestamp's serial type flipped. The entry is found in the file as the
    second copy of the row's 8-byte big-endian timestamp (the first is in the table row),
    preceded by the record header ``[size, type of timestamp, type of rowid]`` (sqlite's
    file format, sqlite.org/fileformat2.html#record_format)."""
    import sqlite3

    path = tfbus_bags(tmp_path, list(read_messages(TURTLE))[:20])["sqlite3"]
    messages = list(read_messages(path))
    with sqlite3.connect(path) as db:
        (stamp,) = db.execute("SELECT timestamp FROM messages WHERE id = ?", (row,)).fetchone()
    data = bytearray(path.read_bytes())
    raw = stamp.to_bytes(8, "big")
    first = data.index(raw)
    entry = data.index(raw, first + 1)
    assert data[entry - 2] == 6  # serial type 6: a 64-bit integer
    data[entry - 2] ^= 1 << bit
    bad = tmp_path / "flipped.db3"
    bad.write_bytes(bytes(data))
    return bad, messages


def test_db3_timestamp_read_as_a_blob_is_a_bag_read_error(tmp_path: Path) -> None:
    """One flipped bit makes a timestamp a 1-byte BLOB (serial type 14):
    read_messages leaked TypeError ('<=' between int and bytes); now the 9 messages
    before it in time order, then a BagReadError naming the file and the row."""
    bad, messages = _index_entry_flipped(tmp_path, 10, 3)
    got, err = read_all(bad)
    assert isinstance(err, BagReadError), repr(err)
    assert got == messages[:9]
    assert "flipped.db3" in str(err) and "messages row 10 of flipped.db3" in err.reason
    assert "BLOB" in err.reason and "\n" not in str(err)


def test_db3_timestamp_out_of_order_is_a_bag_read_error(tmp_path: Path) -> None:
    """A flip making the timestamp a 32-bit integer (serial type 4) read
    the message "cleanly" at bag time 325100004 ns, out of order; a time-ordered read
    going backwards is now damage."""
    bad, messages = _index_entry_flipped(tmp_path, 10, 1)
    got, err = read_all(bad)
    assert isinstance(err, BagReadError), repr(err)
    assert got == messages[:9] and "earlier than the previous message" in err.reason


@pytest.mark.parametrize("command", [["bag-info"], ["echo", "world", "turtle1"], ["monitor"]])
def test_cli_on_a_flipped_db3_is_one_line(tmp_path: Path,
                                                         command: list[str]) -> None:
    """bag-info, echo and monitor on the flipped file printed a traceback; now one line
    naming the file (exit status 1), after what was readable."""
    from click.testing import CliRunner

    from tfbus.cli import cli

    bad, _ = _index_entry_flipped(tmp_path, 10, 3)
    args = [command[0], str(bad), *command[1:]] if command[0] == "bag-info" else [
        command[0], "--bag", str(bad), *command[1:]]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert "Traceback" not in result.stderr
    lines = [x for x in result.stderr.splitlines() if "flipped.db3" in x]
    assert len(lines) == 1 and "messages row 10" in lines[0], result.stderr
    assert result.exit_code == 1


def test_ros1_salvage_does_not_read_the_file_into_memory(tmp_path: Path) -> None:
    """Salvaging a ROS 1 bag read the whole file (Path.read_bytes, then a copy without
    its first line): Python memory grew by twice the file. It is now mapped and read a
    record at a time: the traced peak while reading a 9 MB bag cut at 90 % stays
    under a third of the file, with the same messages as before."""
    import tracemalloc

    base = list(read_messages(TURTLE))
    dyn = [m for m in base if m.topic == "/tf"]
    t0 = dyn[0].time.ns
    messages = [base[0]] + [
        dyn[i % len(dyn)]._replace(time=Time.from_ns(t0 + i * 1_000_000)) for i in range(59_999)
    ]
    path = tmp_path / "big.bag"
    assert write_bag(path, messages) == 60_000
    data = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) * 9 // 10])
    size = len(data)
    ends = ros1_tf_message_ends(data)
    del data
    tracemalloc.start()
    try:
        got = 0
        with pytest.raises(BagReadError) as err:
            for _ in read_messages(cut):
                got += 1
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < size // 3, (peak, size)
    assert got == sum(e <= size * 9 // 10 for e in ends) and "truncated" in err.value.reason


def test_compressed_chunk_without_its_size_is_refused(tmp_path: Path) -> None:
    """A bz2 chunk whose header lacks "size" (the uncompressed size, a required field)
    was decompressed without any bound; it is now a BagReadError at that chunk, after
    the messages before it."""
    from rosbags.rosbag1 import Reader, Writer

    path = tmp_path / "bz2.bag"
    writer = Writer(path)
    writer.set_compression(Writer.CompressionFormat.BZ2)
    writer.chunk_threshold = 16 * 1024
    with Reader(TURTLE) as reader, writer:
        tf = [c for c in reader.connections if c.topic in ("/tf", "/tf_static")]
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data,
                                             md5sum=c.digest, callerid=c.ext.callerid,
                                             latching=c.ext.latching) for c in tf}
        for conn, t, raw in reader.messages(connections=tf):
            writer.write(conns[conn.id], t, raw)
    full = list(read_messages(path))
    data = bytearray(path.read_bytes())
    chunks = [(off, end, f) for off, end, f in ros1_records(bytes(data)) if f.get("op") == b"\x05"]
    assert len(chunks) > 3
    off, _end, _f = chunks[2]
    at = data.index(b"size=", off)
    data[at : at + 5] = b"sizz="  # same length: the record layout is unchanged
    bad = tmp_path / "nosize.bag"
    bad.write_bytes(bytes(data[: len(data) // 2]))  # no index: read record by record
    got, err = read_all(bad)
    assert isinstance(err, BagReadError), repr(err)
    assert err.offset == off and "no uncompressed size" in err.reason
    assert 0 < len(got) < len(full) and got == full[: len(got)]


@pytest.mark.parametrize("short", [1, 37, 100])
def test_db3_cut_short_is_truncated(tmp_path: Path, short: int) -> None:
    """A .db3 cut short by 1-100 bytes read "cleanly", its last page
    zero-filled by sqlite (message 476 of 500 came back with garbage values). The short
    file is now detected from its header (page count x page size) and reported as
    truncated, after the messages stored on the intact pages: here the 476 on the leaf
    pages before the cut one, the same as in the intact file."""
    import sqlite3

    path = tfbus_bags(tmp_path, list(read_messages(TURTLE))[:500])["sqlite3"]
    full = list(read_messages(path))
    data = path.read_bytes()
    page_size = int.from_bytes(data[16:18], "big")
    assert len(data) == int.from_bytes(data[28:32], "big") * page_size
    with sqlite3.connect(path) as db:  # rows before the last page of the messages table
        (last_leaf_rows,) = db.execute(
            "SELECT ncell FROM dbstat WHERE name = 'messages' AND pageno = ?",
            (len(data) // page_size,)).fetchone()
    cut = tmp_path / "cut.db3"
    cut.write_bytes(data[:-short])
    got, err = read_all(cut)
    assert isinstance(err, BagReadError), repr(err)
    assert "truncated" in err.reason and err.offset == len(data) - short
    assert f"{len(data) - short} bytes of the {len(data)}" in err.reason
    assert got == full[: len(full) - last_leaf_rows] and len(got) == 476


def _first_chunk(data: bytes) -> tuple[int, int]:
    """Byte offset and length field of the first CHUNK record (opcode 0x06) of an MCAP
    file: records are opcode (1 byte), length (uint64 little-endian), body."""
    pos = 8  # the magic
    while data[pos] != 0x06:
        pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
    return pos, struct.unpack_from("<Q", data, pos + 1)[0]


@pytest.mark.parametrize("how", ["cut", "patched"])
def test_mcap_record_longer_than_the_file_names_the_file_and_the_damage(
    tmp_path: Path, how: str
) -> None:
    """mcap's "CHUNK record has length 161977 that exceeds limit 100000" (its record size
    limit is the file's size) reached the user as is: the error names the file, the
    record, its length and the file's size, and says the file is cut short or damaged."""
    data = (DATA / "nav2_like.mcap").read_bytes()
    at, length = _first_chunk(data)
    data = data[:100_000]  # a copy stopped part-way: no summary, the first chunk cut
    if how == "patched":  # and the first chunk's length field damaged
        length = 2**40
        data = data[:at + 1] + struct.pack("<Q", length) + data[at + 9:]
    bad = tmp_path / f"{how}.mcap"
    bad.write_bytes(data)
    messages, err = read_all(bad)
    assert messages == []
    assert isinstance(err, BagReadError)
    assert err.offset == at and err.path == bad
    assert str(err) == (
        f"{bad}: the CHUNK record at byte {at} says it is {length} bytes long, more than "
        f"the whole file ({len(data)} bytes): the file is cut short (copied or downloaded "
        f"in part, or still being written) or damaged at that record; reading stopped "
        f"(byte {at}, 0 tf message(s) read)")
