"""TCPROS (ROS 1) under mutated input: a subscriber connection's receive path in process,
then a live node on 127.0.0.1 fed hostile connection headers and frames.

In process (hypothesis, derandomized, bounded): a valid TCPROS stream as a publisher
sends it -- the connection header (``callerid``, ``topic``, ``md5sum``, ``type``, ...;
ROS wiki "ROS/Connection Header"), then length-prefixed ``tf2_msgs/TFMessage`` or
``rosgraph_msgs/Clock`` frames -- is mutated (bits flipped, cut, extended, an absurd value
written into a length field, two fields swapped, a field repeated) and fed, cut at random
points, to the node's handler of one publisher connection from a read buffer that is
overwritten after each read, as the asyncio pump reuses its buffer. Only ``ValueError``
(the codec's ``WireDecodeError`` is one) or ``TransportError`` (the publisher refused)
ends it; what is delivered before is exactly what the codec's reference decoder makes of
the frames before the bad one (by the pure-Python twin of the compiled decoder the
connection uses), and the counters say so.

Live (FakeMaster, two tfbus nodes, a raw TCP client and a raw TCPROS publisher, all on
127.0.0.1): hostile headers to the node's TCPROS server and hostile header/frame sessions
from a publisher it follows each close their connection only and are counted in
``malformed``; a valid subscriber and a valid publisher are served all along, and the
hostile publisher's own later valid session is delivered.

Pure parsers (``decode_header``, ``FrameSplitter``, the ROS 1 decoders) are fuzzed in
``tests/codecs/test_fuzz_decoders.py``; this file fuzzes the transport around them.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from typing import Any

import anyio
import anyio.abc
import pytest
from anyio.streams.buffered import BufferedByteReceiveStream
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st
from hypothesis.control import currently_in_test_context

pytest.importorskip("rosbags")

import itertools

from ros1_hostile import FakeMaster, HostilePeer, http_answer, send_raw, tcpros_answer

from tfbus import (
    Buffer,
    Bus,
    Header,
    Quaternion,
    Time,
    Transform,
    TransformBroadcaster,
    TransformListener,
    TransformStamped,
    Vector3,
)
from tfbus.codecs import ros1 as ros1_codec
from tfbus.errors import TransformException, TransportError
from tfbus.messages import Clock
from tfbus.transports.ros1 import TF_MD5SUM, Ros1Transport, encode_header
from tfbus.transports.ros1 import transport as ros1_transport
from tfbus.transports.ros1.tcpros import (
    MAX_HEADER_BYTES,
    FrameSplitter,
    decode_header,
    frame,
    read_frame,
)

FUZZ = settings(max_examples=300, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
ABSURD_U32 = [0, 1, 3, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, MAX_HEADER_BYTES,
              MAX_HEADER_BYTES + 1]
MAX_MESSAGE_BYTES = 64 * 1024
"""The node's ``max_message_bytes`` here: a frame announcing more ends the connection."""
FRAME_IDS = ["map", "base_link", "", "ü/ñ", "a" * 300]
TOPICS = {"/tf": (TF_MD5SUM, "tf2_msgs/TFMessage"),
          "/clock": (ros1_codec.CLOCK_MD5SUM, ros1_codec.CLOCK_TYPE)}


def _ts(parent: str, child: str, ns: int, x: float) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), parent), child,
        Transform(Vector3(x, -x, 0.5), Quaternion(0.0, 0.0, 0.6, 0.8)),
    )


def _header_fields(topic: str, callerid: str = "/talker") -> dict[str, str]:
    md5, msg_type = TOPICS[topic]
    return {"callerid": callerid, "topic": topic, "md5sum": md5, "type": msg_type,
            "message_definition": "# " + msg_type, "latching": "0"}


# ------------------------------------------------------------------ the streams


def _header_lengths(fields: dict[str, str]) -> list[int]:
    """Offsets, in the encoded header, of its total length and each field's length."""
    out, off = [0], 4
    for k, v in fields.items():
        out.append(off)
        off += 4 + len(f"{k}={v}".encode())
    return out


def _tf_lengths(raw: bytes) -> list[int]:
    """Offsets of the length fields of a ROS 1 TFMessage: its count, then each
    transform's frame_id and child_frame_id lengths."""
    (n,) = struct.unpack_from("<I", raw, 0)
    out, off = [0], 4
    for _ in range(n):
        out.append(off + 12)
        (flen,) = struct.unpack_from("<I", raw, off + 12)
        off += 16 + flen
        out.append(off)
        (clen,) = struct.unpack_from("<I", raw, off)
        off += 4 + clen + 56
    return out


@st.composite
def stream(draw: st.DrawFn, topic: str) -> bytes:
    """A publisher's TCPROS stream on ``topic``, valid or mutated."""
    fields = _header_fields(topic, draw(st.sampled_from(["/talker", "", "/" + "n" * 200])))
    fields["md5sum"] = draw(st.sampled_from([
        fields["md5sum"],
        "*",  # a subscriber's wildcard, accepted from a publisher too
        "f" * 5000,  # huge: refused in one short line
    ]))
    fields["type"] = draw(st.sampled_from([fields["type"], "t" * 5000]))
    if draw(st.integers(0, 9)) == 0:  # a refusal (TransportError), short or huge
        fields["error"] = draw(st.sampled_from(["no such topic", "e" * 5000]))
    header = encode_header(fields)
    parts: list[bytes] = [header]
    lengths = [(0, off) for off in _header_lengths(fields)]  # (part, offset in it)
    for _ in range(draw(st.integers(0, 3))):
        if topic == "/clock":
            sec = draw(st.sampled_from([0, 1, 2**31 - 1, 2**32 - 1]))
            nsec = draw(st.sampled_from([0, 999_999_999]))
            payload = ros1_codec.encode_clock(Clock(Time(sec, nsec)))
            offs = [0]
        else:
            payload = ros1_codec.encode_tf([
                _ts(draw(st.sampled_from(FRAME_IDS)), draw(st.sampled_from(FRAME_IDS)),
                    draw(st.sampled_from([0, 1, 1_700_000_000 * 10**9])), float(i))
                for i in range(draw(st.integers(1, 3)))
            ])
            offs = [4 + o for o in _tf_lengths(payload)]
        lengths += [(len(parts), 0)] + [(len(parts), o) for o in offs]
        parts.append(frame(payload))
    # absurd values into length fields, then whole fields (frames) swapped or repeated,
    # then bytes flipped, cut or added
    for _ in range(draw(st.integers(0, 2))):
        part, off = draw(st.sampled_from(lengths))
        absurd = draw(st.sampled_from(ABSURD_U32) | st.integers(0, 2**32 - 1))
        p = parts[part]
        parts[part] = p[:off] + struct.pack("<I", absurd) + p[off + 4:]
    for _ in range(draw(st.integers(0, 1))):
        if draw(st.booleans()):
            i, j = draw(st.integers(0, len(parts) - 1)), draw(st.integers(0, len(parts) - 1))
            parts[i], parts[j] = parts[j], parts[i]
        else:
            parts.insert(draw(st.integers(0, len(parts))), draw(st.sampled_from(parts)))
    raw = bytearray(b"".join(parts))
    for _ in range(draw(st.integers(0, 2))):
        op = draw(st.sampled_from(["flip", "cut", "extend"]))
        if op == "cut":
            del raw[draw(st.integers(0, len(raw))):]
        elif op == "extend":
            raw += draw(st.binary(max_size=16))
        elif raw:
            raw[draw(st.integers(0, len(raw) - 1))] ^= 1 << draw(st.integers(0, 7))
    return bytes(raw)


# ------------------------------------------------------------------ the model


def _reference(data: bytes, topic: str, uri: str) -> tuple[list[object], type[Exception] | None,
                                                            int]:
    """What one publisher connection must deliver from ``data``: the messages (by the
    codec's reference decoder), the error class that ends it (None: still open) and the
    message frames counted as received. Built from the split frames and tf2's rules
    (roscpp ``TransportPublisherLink::onHeaderReceived``: an ``error`` field is a refusal,
    the md5sum must match or be ``*``)."""
    frames: list[bytes] = []
    splitter = FrameSplitter(lambda raw: frames.append(bytes(raw)), MAX_HEADER_BYTES,
                             MAX_MESSAGE_BYTES)
    split_error: type[Exception] | None = None
    try:
        splitter.feed(data)
    except ValueError:
        split_error = ValueError
    if not frames:
        return [], split_error, 0
    try:
        header = decode_header(frames[0])
    except ValueError:
        return [], ValueError, 0
    if "error" in header:
        return [], TransportError, 0
    if header.get("md5sum") not in (TOPICS[topic][0], "*"):
        return [], ValueError, 0
    authority = header.get("callerid") or uri
    out: list[object] = []
    received = 0
    for raw in frames[1:]:
        received += 1
        try:
            if topic == "/clock":
                out.append(ros1_codec.decode_clock(raw))
            else:
                out.append((authority, ros1_codec.decode_ros1_struct(raw)))
        except ValueError:
            return out, ValueError, received
    return out, split_error, received


class Recorder:
    """The bus as the connection sees it (``BusLike``): records what is delivered."""

    def __init__(self) -> None:
        self.got: list[tuple[str, object]] = []

    def deliver_nowait(self, topic: str, message: object) -> None:
        self.got.append((topic, message))

    def deliver_many_nowait(self, topic: str, messages: Any) -> None:
        self.got.extend((topic, m) for m in messages)

    def reaches(self, topic: str) -> bool:
        return True


_NODE: list[Ros1Transport] = []


def _node() -> Ros1Transport:
    """One node for every example (its codec compiles rosbags' deserialisers once); never
    run: its connections' handlers are driven directly."""
    if not _NODE:
        _NODE.append(Ros1Transport("http://127.0.0.1:9", node_name="/fuzz_receiver",
                                   clock_topic="/clock", max_message_bytes=MAX_MESSAGE_BYTES))
    return _NODE[0]


@contextmanager
def _counted(node: Ros1Transport) -> Iterator[Callable[[], tuple[int, int]]]:
    before = node.statistics()
    yield lambda: (node.statistics().received - before.received,
                   node.statistics().delivered - before.delivered)


def _feed(topic: str, data: bytes, cuts: list[int]) -> None:
    """Feed ``data`` to one publisher connection's handler in reads cut at ``cuts``, each
    a view of one reused read buffer (overwritten after the read), and check it against
    :func:`_reference`."""
    node = _node()
    uri = "http://127.0.0.1:1/"
    bus = Recorder()
    link = ros1_transport._Inbound(node, bus, topic, uri)  # type: ignore[arg-type]
    buf = bytearray(max(len(data), 1))
    error: Exception | None = None
    with _counted(node) as counted:
        bounds = sorted({0, len(data), *(c for c in cuts if 0 < c < len(data))})
        for lo, hi in itertools.pairwise(bounds):
            buf[: hi - lo] = data[lo:hi]
            try:
                link.splitter.feed(memoryview(buf)[: hi - lo])
            except (ValueError, TransportError) as exc:  # ends the connection
                error = exc
                break
            finally:
                buf[:] = b"\xaa" * len(buf)  # the pump reuses its read buffer
        if topic == "/clock":  # queued by the clock connection's sink: the loop's drain
            node._bus = bus  # type: ignore[assignment]
            try:
                node._drain_clock(True)
            finally:
                node._bus = None
        received, delivered = counted()
    expected, expected_error, expected_received = _reference(data, topic, uri)
    if topic == "/clock":
        got: list[object] = [m for _, m in bus.got]
    else:
        got = [(type(m).authority, m.transforms) for _, m in bus.got]  # type: ignore[attr-defined]
        expected = [(a, tuple(t)) for a, t in expected]  # type: ignore[misc]
    if currently_in_test_context():  # what the examples covered (--hypothesis-show-statistics)
        event(f"ended by {type(error).__name__}" if error else "still open")
        event(f"{min(len(expected), 2)}+ messages delivered")
    assert got == expected
    assert (error is None) == (expected_error is None), (error, expected_error)
    if error is not None:
        assert isinstance(error, expected_error)  # type: ignore[arg-type]
        assert "\n" not in str(error) and len(str(error)) < 400  # one clear line
    assert (received, delivered) == (expected_received, len(expected))
    for _, message in bus.got:
        if topic == "/clock":
            assert isinstance(message, Clock) and 0 <= message.clock.ns < 2**32 * 10**9


@pytest.mark.parametrize("topic", sorted(TOPICS))
@FUZZ
@given(data=st.data())
def test_a_mutated_publisher_stream_delivers_what_decodes_then_ends_with_one_error(
    topic: str, data: st.DataObject
) -> None:
    raw = data.draw(stream(topic), label="stream")
    cuts = data.draw(st.lists(st.integers(0, len(raw)), max_size=6), label="cuts")
    _feed(topic, raw, cuts)


# ------------------------------------------------------------------ connection headers


def test_a_field_given_twice_keeps_its_last_value_as_in_roscpp() -> None:
    """roscpp's ``Header::parse`` stores each ``key=value`` into one map in order: the
    last ``md5sum`` decides whether the connection is accepted."""
    fields = _header_fields("/tf")
    body = encode_header(fields)[4:]
    good = struct.pack("<I", len(b"md5sum=" + TF_MD5SUM.encode())) + b"md5sum=" + \
        TF_MD5SUM.encode()
    bad = struct.pack("<I", len(b"md5sum=0123")) + b"md5sum=0123"
    assert decode_header(body + bad)["md5sum"] == "0123"
    assert decode_header(body + bad + good)["md5sum"] == TF_MD5SUM
    for tail, accepted in ((bad + good, True), (good + bad, False)):
        whole = struct.pack("<I", len(body + tail)) + body + tail
        frames = frame(ros1_codec.encode_tf([_ts("map", "a", 5, 1.0)]))
        if accepted:
            _feed("/tf", whole + frames, [])
        else:
            link = ros1_transport._Inbound(_node(), Recorder(), "/tf", "http://127.0.0.1:1/")  # type: ignore[arg-type]
            with pytest.raises(ValueError, match="sends md5sum '0123' on /tf"):
                link.splitter.feed(whole + frames)


@pytest.mark.parametrize(("field", "error"), [("md5sum", ValueError),
                                              ("error", TransportError)])
def test_a_huge_header_value_is_refused_in_one_short_line(field: str,
                                                          error: type[Exception]) -> None:
    """A publisher's 60 kB md5sum or error text ends the connection with an error (and a
    log line) naming the field in its first 80 or 200 characters (before: the whole
    value went into the message and the warning)."""
    fields = _header_fields("/tf") | {field: "f" * 60_000}
    link = ros1_transport._Inbound(_node(), Recorder(), "/tf", "http://127.0.0.1:1/")  # type: ignore[arg-type]
    with pytest.raises(error) as raised:
        link.splitter.feed(encode_header(fields))
    assert len(str(raised.value)) < 300
    assert ("sends md5sum 'fff" if field == "md5sum" else "refused /tf: fff") in str(raised.value)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (b"\x0c\x00\x00\x00no equals!!!",
         r"connection header: field b'no equals!!!' at byte 4 has no '='"),
        (b"\x0c\x00\x00\x00callerid=/\xff\xfe",
         r"connection header: field 'callerid' at byte 4 is not UTF-8 \(invalid start byte "
         r"at byte 14\)"),
        (b"\x06\x00\x00\x00\xffid=/x",
         r"connection header: the name of field b'\\xffid=/x' at byte 4 is not UTF-8"),
        (b"\xff\xff\xff\xffcallerid=/x",
         r"connection header: field of 4294967295 bytes at byte 4 runs past the end "
         r"\(11 bytes left\)"),
        (b"\x03\x00\x00\x00a=b\x01\x00",
         r"connection header: truncated field length at byte 7 \(2 bytes left, 4 needed\)"),
    ],
    ids=["no equals", "value not utf-8", "name not utf-8", "absurd length", "cut length"],
)
def test_a_bad_connection_header_names_the_field_and_where_it_is(body: bytes,
                                                                   message: str) -> None:
    with pytest.raises(ValueError, match=f"^{message}"):
        decode_header(body)


@FUZZ
@given(value=st.binary(max_size=64), name=st.sampled_from(["callerid", "md5sum", "type"]))
@example(value=b"\xff", name="callerid")
def test_a_field_that_is_not_utf8_is_named(value: bytes, name: str) -> None:
    body = struct.pack("<I", len(name) + 1 + len(value)) + name.encode() + b"=" + value
    try:
        text = value.decode()
    except UnicodeDecodeError:
        with pytest.raises(ValueError, match=f"^connection header: field '{name}' at byte 4 "):
            decode_header(body)
    else:
        assert decode_header(body) == {name: text}


# ------------------------------------------------------------------ live


_T0 = 1_000_000_000


async def _until(predicate: Callable[[], bool], timeout: float = 30.0) -> None:
    """Poll (bounded) until ``predicate()``."""
    with anyio.fail_after(timeout):
        while not predicate():
            await anyio.sleep(0.02)


async def _stamp_after(buffer: Buffer, child: str, ns: int, timeout: float = 30.0) -> None:
    """``map -> child`` reaches ``buffer`` stamped after ``ns`` (polled, bounded)."""
    with anyio.fail_after(timeout):
        while True:
            with suppress(TransformException):
                if buffer.get_latest_common_time("map", child).ns > ns:
                    return
            await anyio.sleep(0.02)


def _tf_frame(child: str, k: int) -> bytes:
    return frame(ros1_codec.encode_tf([_ts("map", child, _T0 + k * 10_000_000, float(k))]))


HOSTILE_HEADERS = {
    "no equals": struct.pack("<I", 16) + struct.pack("<I", 12) + b"no equals!!!",
    "absurd total": struct.pack("<I", 0xFFFFFFFF) + b"callerid=/x",
    "absurd field": struct.pack("<I", 15) + struct.pack("<I", 0x7FFFFFFF) + b"callerid=/x",
    "not utf-8": encode_header({"callerid": "/x", "topic": "/tf"})[:-1] + b"\xff",
}
"""Headers a raw client sends to the node's TCPROS server: each is counted in
``malformed`` and closes that connection."""

HOSTILE_SESSIONS = [
    # a header field without '=' (a valid header's "topic=/tf" with its '=' flipped)
    encode_header(_header_fields("/tf", "/hostile")).replace(b"topic=", b"topic\x3c"),
    # an absurd header length, then nothing
    struct.pack("<I", 0xFFFFFFFF),
    # a callerid that is not UTF-8
    encode_header(_header_fields("/tf", "/hostile")).replace(b"/hostile", b"/hostil\xff"),
    # a valid header and message, then a message frame announcing 2**31 bytes
    encode_header(_header_fields("/tf", "/hostile")) + _tf_frame("hostile", 1)
    + struct.pack("<I", 0x80000000),
    # a valid header and message, then one whose transform count exceeds its bytes
    encode_header(_header_fields("/tf", "/hostile")) + _tf_frame("hostile", 2)
    + frame(struct.pack("<I", 3) + ros1_codec.encode_tf([_ts("map", "x", _T0, 0.0)])[4:]),
]
"""What a hostile publisher the node follows sends, one per connection: each is counted
in ``malformed`` and ends that connection (the node reconnects, with back-off); then the
same publisher is valid and is delivered."""


@pytest.mark.anyio
async def test_a_node_under_hostile_tcpros_peers_counts_them_and_serves_valid_ones() -> None:
    sessions = iter(HOSTILE_SESSIONS)
    served = anyio.Event()  # the hostile publisher's valid session is under way

    async def hostile_publisher(conn: anyio.abc.SocketStream) -> None:
        """One TCPROS connection of the hostile publisher: to the node under test the
        next hostile session, then, once they are spent, a valid one (a message every
        20 ms); to any other subscriber (the good node follows /tf too) a valid one."""
        async with conn:
            with suppress(anyio.EndOfStream, anyio.IncompleteRead, anyio.BrokenResourceError,
                          OSError):
                with anyio.fail_after(30):
                    hello = decode_header(await read_frame(
                        BufferedByteReceiveStream(conn), MAX_HEADER_BYTES, "header"))
                under_test = hello.get("callerid") == "/under_test"
                session = next(sessions, None) if under_test else None
                if session is not None:
                    await conn.send(session)
                    with anyio.fail_after(30):
                        while await conn.receive():  # until the node closes it
                            pass
                    return
                await conn.send(encode_header(_header_fields("/tf", "/hostile")))
                if under_test:
                    served.set()
                for k in range(10, 3000):  # bounded: 60 s
                    await conn.send(_tf_frame("raw", k))
                    await anyio.sleep(0.02)

    listener = await anyio.create_tcp_listener(local_host="127.0.0.1")
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    peer = HostilePeer(send_raw(http_answer(tcpros_answer(f"<int>{port}</int>"))))
    with FakeMaster() as master, peer:
        master.extra_publishers.append(peer.uri)  # listed to /tf subscribers
        pub = Ros1Transport(master_uri=master.uri, node_name="/good",
                            master_check_period=0.2)
        async with listener, Bus(transport=pub) as pub_bus, \
                anyio.create_task_group() as tg:
            tg.start_soon(listener.serve, hostile_publisher)
            broadcaster = TransformBroadcaster(pub_bus)
            sent = [0]

            async def send() -> None:
                for _ in range(10_000):  # bounded: 100 s
                    sent[0] += 1
                    broadcaster.send_transform_nowait(_ts("map", "good", _T0 + sent[0] * 10**7,
                                                          0.0))
                    await anyio.sleep(0.01)

            tg.start_soon(send)
            await _until(lambda: pub._tcp_port != 0)
            # 1. hostile headers to the publisher's TCPROS server
            for raw in HOSTILE_HEADERS.values():
                with anyio.fail_after(30):
                    client = await anyio.connect_tcp("127.0.0.1", pub._tcp_port)
                    async with client:
                        await client.send(raw)
                        with suppress(anyio.EndOfStream, anyio.BrokenResourceError):
                            assert await client.receive() == b""  # closed, no answer
            # a huge md5sum: a well-formed header, refused with an error field
            with anyio.fail_after(30):
                client = await anyio.connect_tcp("127.0.0.1", pub._tcp_port)
                async with client:
                    await client.send(encode_header(
                        {"callerid": "/x", "topic": "/tf", "md5sum": "f" * 60_000}))
                    answer = b""
                    with suppress(anyio.EndOfStream, anyio.BrokenResourceError):
                        while len(answer) < 4096:  # until the server closes (bounded)
                            answer += await client.receive()
            refusal = decode_header(answer[4:])["error"]
            assert refusal.startswith("/good does not publish") or refusal.startswith(
                "md5sum mismatch: 'ffff")
            assert len(refusal) < 200  # one short line, not the 60 kB it was sent
            await _until(lambda: pub.statistics().malformed == len(HOSTILE_HEADERS))
            # 2. a subscriber node after it: served by the good publisher, and fed the
            # hostile publisher's sessions
            buffer = Buffer(cache_time=60.0)
            sub = Ros1Transport(master_uri=master.uri, node_name="/under_test",
                                master_check_period=0.2, max_message_bytes=MAX_MESSAGE_BYTES)
            async with Bus(transport=sub) as sub_bus, TransformListener(buffer, sub_bus):
                await _stamp_after(buffer, "good", _T0)
                await _until(lambda: sub.statistics().malformed >= len(HOSTILE_SESSIONS),
                             timeout=60.0)
                with anyio.fail_after(60):
                    await served.wait()
                await _stamp_after(buffer, "raw", _T0 + 10 * 10**7)  # the peer, now valid
                await _stamp_after(buffer, "good", _T0 + sent[0] * 10**7)  # still served
                stats = sub.statistics()
                assert stats.malformed == len(HOSTILE_SESSIONS)
                # the valid messages before the bad frames were delivered
                assert buffer.can_transform("map", "hostile", Time(0))
                # bounded: the connections that ended are gone, one per publisher remains
                assert sorted(c[1] for c in sub.bus_info() if c[4] == "/tf") == [
                    "/good", "/hostile"]
                assert stats.connections_opened - stats.connections_closed == len(
                    sub.bus_info())
            assert pub.statistics().malformed == len(HOSTILE_HEADERS)
            tg.cancel_scope.cancel()


class _Dropper(Recorder):
    """A bus whose subscribers keep nothing (only the count)."""

    def __init__(self) -> None:
        super().__init__()
        self.count = 0

    def deliver_nowait(self, topic: str, message: object) -> None:
        self.count += 1


@pytest.mark.skipif(
    ros1_codec._compiled_ros1 is None, reason="no compiled ROS 1 decoder (pure-Python core)"
)
def test_long_frame_ids_at_every_position_are_not_held_after_their_message() -> None:
    """A publisher sends message after message, each with one long ASCII frame id at a
    new position behind short non-ASCII ones; once delivered and dropped by the
    subscribers, nothing of them stays (before: the compiled decoder kept every ASCII id
    it decoded at each of its 4096 positions, whatever its length: about a message's
    worth of ids per position, here 6 MB after 200 messages of 30 kB)."""
    import tracemalloc

    long_id = "x" * 30_000
    data = encode_header(_header_fields("/tf", "/long_ids")) + b"".join(
        frame(ros1_codec.encode_tf(
            [_ts("ü", "ü", _T0, 0.0)] * k + [_ts(long_id + str(k), "c", _T0, 0.0)]
        ))
        for k in range(200)
    )
    node = _node()
    bus = _Dropper()
    link = ros1_transport._Inbound(node, bus, "/tf", "http://127.0.0.1:1/")  # type: ignore[arg-type]
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        link.splitter.feed(data)
        held = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert bus.count == 200
    assert held < 2_000_000, f"{held / 1e6:.1f} MB held after the messages were dropped"
