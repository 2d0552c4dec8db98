"""TCPROS subscriber side, in process: a connection's frames (the publisher's header, then
``TFMessage`` frames) fed to its handler as the read callback feeds them, no socket.

Once the header is accepted, each message frame is decoded by the codec's compiled
decoder and delivered in few Python calls; the messages, their publisher's authority, the
counts, and a malformed frame's error and the frames before it are those of the general
frame handler."""

from __future__ import annotations

import struct
import sys
from types import FrameType
from typing import Any

import pytest
from event_loops import anyio_backend_with_uvloop  # noqa: F401  (the fixture)

from tfbus import Bus, Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.codecs import ros1 as ros1_codec
from tfbus.errors import WireDecodeError
from tfbus.messages import TFMessage
from tfbus.transports.ros1 import TF_MD5SUM, Ros1Transport, TFCodec, encode_header
from tfbus.transports.ros1 import transport as ros1_transport
from tfbus.transports.ros1.tcpros import FrameSplitter, frame

pytestmark = pytest.mark.anyio

# Python functions entered from the splitter's feed until the bus's callback: feed, the
# TFMessage frame handler, Bus.deliver_nowait, its counters look-up and the bus's delivery
# (Bus._deliver_each; C code with the compiled core, so one fewer there).
# The general handler entered 9: feed, _frame, TFCodec.decode, _decode_transforms,
# _decode_ros1_compiled_or_struct, TFMessage's __new__ and the three of the bus.
CALLS_BEFORE_CALLBACK = 5


def _ts(i: int, stamp: Time) -> TransformStamped:
    return TransformStamped(
        Header(stamp, "base_link"),
        f"bench_{i}",
        Transform(Vector3(float(i), 0.5 * i, -1.0), Quaternion(0.0, 0.0, 0.6, 0.8)),
    )


def _message(k: int, n: int = 3) -> list[TransformStamped]:
    return [_ts(i, Time(1_700_000_000 + k, 250_000_000)) for i in range(n)]


def _header(callerid: str = "/bench_pub") -> bytes:
    return encode_header(
        {"callerid": callerid, "md5sum": TF_MD5SUM, "type": "tf2_msgs/TFMessage",
         "topic": "/tf"}
    )  # fmt: skip


def _link(bus: Bus) -> Any:
    node = Ros1Transport("http://127.0.0.1:9", node_name="/receive_path_test")
    return node, ros1_transport._Inbound(node, bus, "/tf", "http://127.0.0.1:1/")


async def test_messages_arrive_whole_in_order_with_the_publishers_authority() -> None:
    codec = TFCodec()
    got: list[Any] = []
    async with Bus() as bus:
        node, link = _link(bus)
        with bus.subscribe_callback("/tf", got.append):
            # The header and two messages in one read, a third cut across two reads.
            third = frame(codec.encode(_message(2)))
            data = (
                _header()
                + frame(codec.encode(_message(0)))
                + frame(codec.encode(_message(1, n=50)))
                + third[:7]
            )
            link.splitter.feed(memoryview(data))
            link.splitter.feed(memoryview(third[7:]))
    assert [list(m.transforms) for m in got] == [_message(0), _message(1, n=50), _message(2)]
    assert all(type(m.transforms) is tuple for m in got)
    assert all(isinstance(m, TFMessage) and type(m).authority == "/bench_pub" for m in got)
    assert got[0] == TFMessage(tuple(_message(0)))
    stats = node.statistics()
    assert (stats.received, stats.delivered) == (3, 3)
    assert link.callerid == "/bench_pub"


async def test_a_malformed_frame_raises_the_codecs_error_after_the_frames_before_it() -> None:
    codec = TFCodec()
    short = codec.encode(_message(1))[:-5]
    with pytest.raises(WireDecodeError) as expected:
        codec.decode(short)
    got: list[Any] = []
    async with Bus() as bus:
        node, link = _link(bus)
        with bus.subscribe_callback("/tf", got.append):
            data = _header() + frame(codec.encode(_message(0))) + frame(short)
            with pytest.raises(WireDecodeError) as raised:
                link.splitter.feed(memoryview(data))
    assert str(raised.value) == str(expected.value)
    assert [list(m.transforms) for m in got] == [_message(0)]
    stats = node.statistics()
    assert (stats.received, stats.delivered) == (2, 1)


@pytest.mark.skipif(
    ros1_codec._compiled_ros1 is None, reason="no compiled ROS 1 decoder (pure-Python core)"
)
async def test_a_tf_frame_reaches_the_callback_in_few_python_calls() -> None:
    codec = TFCodec()
    got: list[Any] = []
    entered: list[str] = []
    reached = False

    def record(message: Any) -> None:
        got.append(message)

    def profile(frame_: FrameType, event: str, arg: Any) -> None:
        nonlocal reached
        if event == "call" and not reached:
            if frame_.f_code is record.__code__:
                reached = True
            else:
                entered.append(frame_.f_code.co_name)

    async with Bus() as bus:
        _, link = _link(bus)
        with bus.subscribe_callback("/tf", record):
            link.splitter.feed(memoryview(_header() + frame(codec.encode(_message(0)))))
            data = memoryview(frame(codec.encode(_message(1, n=50))))
            sys.setprofile(profile)
            try:
                link.splitter.feed(data)
            finally:
                sys.setprofile(None)
    assert reached
    assert entered[0] == "feed"
    assert len(entered) <= CALLS_BEFORE_CALLBACK, entered
    assert list(got[-1].transforms) == _message(1, n=50)


def test_the_splitters_sink_may_be_replaced_by_the_first_frames_call() -> None:
    """Frames after the one whose call replaced the sink go to the new sink, also those
    of the same read."""
    first: list[bytes] = []
    later: list[bytes] = []

    def on_header(raw: bytes | memoryview) -> None:
        first.append(bytes(raw))
        splitter.sink = lambda raw: later.append(bytes(raw))

    splitter = FrameSplitter(on_header, 100, 100)
    payloads = [b"head", b"one", b"", b"three"]
    data = b"".join(struct.pack("<I", len(p)) + p for p in payloads)
    splitter.feed(data[:13])
    splitter.feed(data[13:])
    assert first == [b"head"]
    assert later == [b"one", b"", b"three"]
