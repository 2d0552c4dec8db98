"""tfbus as a ROS 1 node, against the real ROS 1 (Debian's roscore, roscpp, tf, tf2_ros).

The ROS 1 scenarios, each a test: the tutorial's C++ broadcaster feeding a tfbus
listener and a tfbus broadcaster feeding the tutorial's C++ listener (and
``rostopic hz``), statics both ways with either side late, ``tf_monitor`` listing the
tfbus node, a master restarted under a running stream, a malformed TCPROS frame on one
connection. All on 127.0.0.1 (a free port per master). Waits are on data or output lines,
each with a bound.
"""

from __future__ import annotations

import contextlib
import functools
import re
import signal
import socket
import statistics
import struct
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path
from xmlrpc.server import SimpleXMLRPCRequestHandler, SimpleXMLRPCServer

import anyio
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ros1_harness import (  # noqa: F401  (the *_fixture names register fixtures)
    Master,
    Proc,
    assert_is_the_yaml_scan,
    master_fixture,
    ros1_fixture,
    rostopic_scan_publisher,
    tfbus_cli,
    tutorial_nodes_fixture,
)

from tfbus import (
    Buffer,
    Bus,
    Header,
    Quaternion,
    StaticTransformBroadcaster,
    Time,
    Transform,
    TransformBroadcaster,
    TransformListener,
    TransformStamped,
    Vector3,
)
from tfbus.clock import SystemClock
from tfbus.codecs.ros1 import decode_ros1_struct
from tfbus.demos.tutorial import (
    BroadcasterStatistics,
    broadcaster_node,
    run_broadcaster,
    run_listener,
)
from tfbus.errors import WireDecodeError
from tfbus.transports.ros1 import (
    TF_MD5SUM,
    Ros1Transport,
    TFCodec,
    decode_header,
    encode_header,
)
from tfbus.transports.ros1.tcpros import FrameSplitter
from tfbus.transports.spec import open_transport

pytestmark = pytest.mark.anyio

INFO = re.compile(
    r"^\[ INFO\] \d+\.\d{9}: base_laser: \(1\.00, 0\.20\. 0\.00\) -----> "
    r"base_link: \(1\.10, 0\.20, 0\.20\) at time \d+\.\d\d$"
)
CPP_INFO = (
    r"base_laser: \(1\.00, 0\.20\. 0\.00\) -----> base_link: \(1\.10, 0\.20, 0\.20\) at time \d+"
)


def _ts(parent: str, child: str, xyz: tuple[float, float, float], stamp: Time) -> TransformStamped:
    return TransformStamped(
        Header(stamp, parent), child, Transform(Vector3(*xyz), Quaternion(0.0, 0.0, 0.0, 1.0))
    )


# --------------------------------------------------------------------------- no ROS needed


def test_connection_header_round_trip() -> None:
    fields = {"callerid": "/a", "topic": "/tf", "md5sum": TF_MD5SUM, "message_definition": "x=y\n"}
    raw = encode_header(fields)
    assert struct.unpack_from("<I", raw)[0] == len(raw) - 4
    assert decode_header(raw[4:]) == fields


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200))
def test_connection_header_decoder_only_raises_value_error(raw: bytes) -> None:
    """Hostile header bytes: a dict or ValueError, nothing else."""
    try:
        out = decode_header(raw)
    except ValueError:
        return
    assert isinstance(out, dict)


@functools.cache
def _shared_codec() -> TFCodec:
    """One codec for the property tests (building one makes a rosbags typestore, ~0.5 s;
    its caches carried across examples are part of what those tests exercise)."""
    return TFCodec()


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_message_decoder_only_raises_value_error(raw: bytes) -> None:
    """Hostile message bytes: a list of TransformStamped or ValueError, nothing else."""
    codec = _shared_codec()
    try:
        out = codec.decode(raw)
    except ValueError:
        return
    assert all(isinstance(t, TransformStamped) for t in out)


_ids = st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=12)
_finite = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(
            _ids,
            _ids,
            st.integers(0, 2**31 - 1),
            st.integers(0, 999_999_999),
            st.tuples(*[_finite] * 7),
        ),
        max_size=8,
    )
)
def test_fast_decoder_equals_rosbags(
    items: list[tuple[str, str, int, int, tuple[float, ...]]],
) -> None:
    """The struct decoder used on the wire gives exactly what rosbags' generic one gives
    (and what was encoded)."""
    codec = _shared_codec()
    msg = [
        TransformStamped(
            Header(Time(sec, nsec), parent),
            child,
            Transform(Vector3(*v[:3]), Quaternion(*v[3:])),
        )
        for parent, child, sec, nsec, v in items
    ]
    raw = codec.encode(msg)
    assert codec.decode(raw) == codec.decode_generic(raw) == msg


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["base_link", "odom", "", "bäse"]),
            _ids,
            st.sampled_from([(0, 0), (1, 2), (2**31 - 1, 999_999_999)]),
            st.tuples(*[_finite] * 7),
        ),
        max_size=12,
    ),
    st.integers(0, 3),
)
def test_fast_decoder_shares_equal_headers_only(
    items: list[tuple[str, str, tuple[int, int], tuple[float, ...]]], seq: int
) -> None:
    """Runs of equal headers (few parents and stamps, so consecutive transforms often
    share one) decode as rosbags decodes them, whatever the seq numbers; a repeated
    message decodes the same from the string cache."""
    codec = _shared_codec()
    msg = [
        TransformStamped(
            Header(Time(*stamp), parent), child, Transform(Vector3(*v[:3]), Quaternion(*v[3:]))
        )
        for parent, child, stamp, v in items
    ]
    raw = bytearray(codec.encode(msg))
    off = 4
    for k in range(len(msg)):  # give some transforms a nonzero header.seq
        if k % 4 == seq:
            struct.pack_into("<I", raw, off, 0xFF if k == 0 else k + 1)
        (flen,) = struct.unpack_from("<I", raw, off + 12)
        off += 16 + flen
        (clen,) = struct.unpack_from("<I", raw, off)
        off += 4 + clen + 56
    assert codec.decode(bytes(raw)) == codec.decode_generic(bytes(raw)) == msg
    assert codec.decode(bytes(raw)) == msg


@settings(max_examples=100, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["base_link", "odom", "ab"]),
            st.sampled_from(["c0", "c1", "cc2", "ü3"]),
            st.sampled_from([(0, 0), (1, 2), (2**31 - 1, 999_999_999)]),
            st.tuples(*[_finite] * 7),
        ),
        min_size=12,
        max_size=40,
    )
)
def test_fast_decoder_layout_cache(
    items: list[tuple[str, str, tuple[int, int], tuple[float, ...]]],
) -> None:
    """Messages of 12+ transforms: the first of a layout is walked, later ones of the same
    count and size are unpacked whole; either way the values equal rosbags'."""
    codec = _shared_codec()
    raw = codec.encode(
        TransformStamped(
            Header(Time(*stamp), parent), child, Transform(Vector3(*v[:3]), Quaternion(*v[3:]))
        )
        for parent, child, stamp, v in items
    )
    for _ in range(3):
        assert decode_ros1_struct(raw) == codec.decode_generic(raw)


def test_fast_decoder_layout_cache_checks_every_length() -> None:
    """A message of the same count and size as a cached layout but other name lengths
    (frame ``abc``/child ``de`` where the layout had ``ab``/``cde``) is not misread."""
    codec = TFCodec()

    def message(parent: str, child: str) -> bytes:
        return codec.encode(
            [_ts("base_link", f"k{i:02d}", (i, 0, 0), Time(7)) for i in range(12)]
            + [_ts(parent, child, (1, 2, 3), Time(8))]
        )

    first, second = message("ab", "cde"), message("abc", "de")
    assert len(first) == len(second)
    for raw in (first, first, second, second, first):
        assert decode_ros1_struct(raw) == codec.decode_generic(raw)
    assert decode_ros1_struct(second)[-1].header.frame_id == "abc"


def test_fast_decoder_layout_cache_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    """Layouts are kept for a bounded number of transforms in all (a peer sending ever new
    layouts cannot grow it); past the bound messages are still decoded, one at a time."""
    from tfbus.codecs import ros1 as dec

    monkeypatch.setattr(dec, "_layouts", {})
    monkeypatch.setattr(dec, "_layout_room", 40)
    codec = TFCodec()
    for size in range(1, 8):  # 7 layouts of 12 transforms: room for 3
        raw = codec.encode(_ts("a" * size, f"c{i}", (i, 0, 0), Time(1)) for i in range(12))
        for _ in range(2):
            assert decode_ros1_struct(raw) == codec.decode_generic(raw)
    assert len(dec._layouts) == 3
    assert dec._layout_room == 40 - 36


def test_fast_decoder_bad_utf8_after_a_cached_name() -> None:
    codec = TFCodec()
    good = codec.encode([_ts("base_link", "a", (1, 2, 3), Time(1))])
    assert codec.decode(good)[0].header.frame_id == "base_link"
    bad = good.replace(b"base_link", b"base_lin\xff")
    with pytest.raises(WireDecodeError, match="'utf-8' codec can't decode"):
        codec.decode(bad)
    with pytest.raises(WireDecodeError, match=r"shorter|requires a buffer"):
        codec.decode(good[:-1])


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.binary(max_size=70), min_size=1, max_size=20),
    st.lists(st.integers(1, 90), min_size=1, max_size=40),
)
def test_frame_splitter_any_chunking(payloads: list[bytes], cuts: list[int]) -> None:
    """Frames come out whole and in order however the byte stream is cut."""
    out: list[bytes] = []
    splitter = FrameSplitter(out.append, 100, 100)
    data = b"".join(struct.pack("<I", len(p)) + p for p in payloads)
    i = k = 0
    while i < len(data):
        step = cuts[k % len(cuts)]
        splitter.feed(data[i : i + step])
        i += step
        k += 1
    assert out == payloads


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.binary(max_size=70), min_size=1, max_size=20),
    st.lists(st.integers(1, 90), min_size=1, max_size=40),
)
def test_frame_splitter_reused_view(payloads: list[bytes], cuts: list[int]) -> None:
    """Fed views of one reused read buffer (as the asyncio pump feeds it), the frames
    are the same however the stream is cut: an incomplete frame's bytes are copied
    before the buffer is overwritten by the next read."""
    out: list[bytes] = []
    splitter = FrameSplitter(lambda raw: out.append(bytes(raw)), 100, 100)
    data = b"".join(struct.pack("<I", len(p)) + p for p in payloads)
    read = bytearray(90)
    view = memoryview(read)
    i = k = 0
    while i < len(data):
        chunk = data[i : i + cuts[k % len(cuts)]]
        read[:] = b"\xaa" * len(read)  # the previous read's bytes are gone
        read[: len(chunk)] = chunk
        splitter.feed(view[: len(chunk)])
        i += len(chunk)
        k += 1
    assert out == payloads


def test_frame_splitter_limits() -> None:
    """The first frame (connection header) has its own limit; an oversized length raises
    after the whole frames before it were handed on, without waiting for its bytes."""
    out: list[bytes] = []
    splitter = FrameSplitter(out.append, 4, 10)
    with pytest.raises(ValueError, match="connection header of 5 bytes"):
        splitter.feed(struct.pack("<I", 5))
    assert out == []
    splitter = FrameSplitter(out.append, 4, 10)
    data = struct.pack("<I", 4) + b"head" + struct.pack("<I", 10) + b"x" * 10
    with pytest.raises(ValueError, match="message of 11 bytes exceeds the limit of 10"):
        splitter.feed(data + struct.pack("<I", 11))
    assert out == [b"head", b"x" * 10]


def test_codec_round_trip_is_exact_and_refuses_unrepresentable_stamps() -> None:
    codec = TFCodec()
    ts = TransformStamped(
        Header(Time(1795273241, 380839517), "base_link"),
        "base_laser",
        Transform(Vector3(0.1, -2e-300, 1e300), Quaternion(0.5, -0.5, 0.5, 0.5)),
    )
    assert codec.decode(codec.encode([ts, ts])) == [ts, ts]
    with pytest.raises(ValueError, match="outside ROS 1's time"):
        codec.encode([ts._replace(header=Header(Time.from_ns((1 << 31) * 10**9), "a"))])


def test_options_and_defaults(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ROS_MASTER_URI", raising=False)
    monkeypatch.delenv("ROS_IP", raising=False)
    monkeypatch.delenv("ROS_HOSTNAME", raising=False)
    t = Ros1Transport()
    assert t.master_uri == "http://127.0.0.1:11311"
    assert t.node_name.startswith("/tfbus_")
    monkeypatch.setenv("ROS_MASTER_URI", "http://127.0.0.1:11999")
    assert Ros1Transport().master_uri == "http://127.0.0.1:11999"
    t = open_transport("ros1:master=http://127.0.0.1:1234&name=x")
    assert isinstance(t, Ros1Transport)
    assert (t.master_uri, t.node_name) == ("http://127.0.0.1:1234", "/x")
    with pytest.raises(ValueError, match="unknown bus option 'colour'"):
        open_transport("ros1:colour=red")
    with pytest.raises(ValueError, match="remote must be 0 or 1"):
        open_transport("ros1:remote=yes")
    with pytest.raises(ValueError, match="master_uri must be"):
        Ros1Transport(master_uri="127.0.0.1:11311")
    with pytest.raises(ValueError, match="node_name"):
        Ros1Transport(node_name="/a b")


async def test_no_master_yet_starts_and_keeps_retrying() -> None:
    """Like a ROS node waiting for its master: the bus opens; nothing is registered."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # nothing listens there
    t = Ros1Transport(master_uri=f"http://127.0.0.1:{port}", master_check_period=0.05)
    async with Bus(transport=t) as bus:
        await TransformBroadcaster(bus).send_transform(_ts("a", "b", (1, 2, 3), Time(5)))
        assert not t.registered
        assert t.uri.startswith("http://127.0.0.1:")


# --------------------------------------------------------------------------- real ROS 1


async def test_cpp_broadcaster_feeds_tfbus_listener(master: Master, tutorial_nodes: Path) -> None:
    """The tutorial's C++ tf_broadcaster → tfbus listener prints the INFO line."""
    bc = master.run(str(tutorial_nodes / "tf_broadcaster"))
    lines: list[str] = []
    got = anyio.Event()

    def out(line: str) -> None:
        lines.append(line)
        if sum(bool(INFO.match(x)) for x in lines) >= 2:
            got.set()

    try:
        async with (
            Bus(transport=Ros1Transport(master_uri=master.uri)) as bus,
            anyio.create_task_group() as tg,
        ):
            tg.start_soon(lambda: run_listener(bus, listen_rate=4.0, out=out))
            with anyio.fail_after(30):
                await got.wait()
            tg.cancel_scope.cancel()
    finally:
        bc.stop()
    assert sum(bool(INFO.match(x)) for x in lines) >= 2, lines


async def test_tfbus_broadcaster_feeds_cpp_listener_at_100_hz(
    master: Master, tutorial_nodes: Path
) -> None:
    """tfbus's broadcaster → the tutorial's C++ tf_listener prints its line, and
    ``rostopic hz /tf`` measures 100 Hz ± 1 % once every node is up: the rate of the
    ticks the broadcaster's timer fired (on a machine that starves it for a period or
    more, the timer skips the ticks it missed, as ``rcl_timer`` does: then the rate
    those ticks make, ± 1 Hz)."""
    transport = Ros1Transport(master_uri=master.uri, node_name="/robot_tf_publisher")
    ticks = BroadcasterStatistics()
    async with Bus(transport=transport) as bus, anyio.create_task_group() as tg:
        tg.start_soon(broadcaster_node, bus, SystemClock(), 100.0, ticks)
        listener = master.run(str(tutorial_nodes / "tf_listener"))
        hz = master.run("rostopic", "hz", "/tf", "-w", "300")
        try:
            await anyio.to_thread.run_sync(listener.wait_for, CPP_INFO, 40.0)
            # The reports so far, and the next 3 (300 arrivals: 3 s each), time arrivals
            # from while rostopic, tf_listener and the broadcaster were starting on the
            # same cores: a 20 ms hold-up there is 2 % of a 1 s window (a clean-clone run
            # measured 97.9, 99.0, 99.3 Hz over its first three). The steady rate is in
            # the reports after those, one a second, each over the last 300 arrivals:
            # three whose windows do not overlap (the 6th, 9th and 12th), so that one
            # hold-up in rostopic's own process falls in one of them only (a loaded CI
            # run saw 97.4, 97.4, 100.1 Hz in three overlapping ones, no tick skipped).
            hz.discard()
            rates: list[float] = []
            for i in range(12):
                if i == 3:  # the steady reports' span starts
                    sent, skipped = ticks.sent, ticks.skipped
                m = await anyio.to_thread.run_sync(hz.wait_for, r"average rate: ([\d.]+)", 20.0)
                rates.append(float(m.group(1)))
            sent, skipped = ticks.sent - sent, ticks.skipped - skipped
        finally:
            listener.stop()
            hz.stop()
        tg.cancel_scope.cancel()
    # rostopic hz times arrivals in its own (rospy) process: the median of three steady
    # reports over disjoint windows, so that one late arrival there on a loaded machine
    # does not decide it
    fired = 100.0 * sent / (sent + skipped)  # 100.0 when no tick was skipped
    steady = [rates[5], rates[8], rates[11]]
    assert abs(statistics.median(steady) - fired) <= 1.0, (rates, sent, skipped)
    stats = transport.statistics()
    assert stats.sent > 0 and stats.send_errors == 0 and stats.send_dropped == 0, stats


@pytest.mark.parametrize("tfbus_first", [False, True], ids=["ros-first", "tfbus-first"])
async def test_static_transform_publisher_feeds_tfbus(master: Master, tfbus_first: bool) -> None:
    """tf2_ros's static_transform_publisher → tfbus, either side starting first."""
    args = (
        "rosrun",
        "tf2_ros",
        "static_transform_publisher",
        "1",
        "2",
        "3",
        "0",
        "0",
        "0",
        "1",
        "base_link",
        "camera",
    )
    publisher = None if tfbus_first else master.run(*args)
    buffer = Buffer(cache_time=10.0)
    try:
        async with (
            Bus(transport=Ros1Transport(master_uri=master.uri)) as bus,
            TransformListener(buffer, bus),
        ):
            if publisher is None:
                publisher = master.run(*args)
            ts = await buffer.lookup_transform_async("base_link", "camera", Time(0), timeout=40.0)
    finally:
        if publisher is not None:
            publisher.stop()
    assert ts.transform.translation == Vector3(1.0, 2.0, 3.0)
    assert ts.transform.rotation == Quaternion(0.0, 0.0, 0.0, 1.0)


async def test_tfbus_static_reaches_tf_echo_with_the_full_set(master: Master) -> None:
    """A tfbus static broadcaster → tf_echo, which joins late and gets every static
    sent so far in the latched message (tf2_ros's StaticTransformBroadcaster)."""
    async with Bus(transport=Ros1Transport(master_uri=master.uri)) as bus:
        static = StaticTransformBroadcaster(bus)
        await static.send_transform(_ts("base_link", "camera", (1.0, 2.0, 3.0), Time(10)))
        await static.send_transform(_ts("base_link", "imu", (-1.0, 0.5, 0.25), Time(10)))
        echo_cam = master.run("rosrun", "tf", "tf_echo", "base_link", "camera")
        echo_imu = master.run("rosrun", "tf", "tf_echo", "base_link", "imu")
        try:
            await anyio.to_thread.run_sync(
                echo_cam.wait_for, r"Translation: \[1\.000, 2\.000, 3\.000\]", 40.0
            )
            await anyio.to_thread.run_sync(
                echo_imu.wait_for, r"Translation: \[-1\.000, 0\.500, 0\.250\]", 40.0
            )
        finally:
            echo_cam.stop()
            echo_imu.stop()


async def test_tf_monitor_lists_the_tfbus_node(master: Master, tutorial_nodes: Path) -> None:
    """tf_monitor reports tfbus's frame and broadcaster exactly as it reports the C++
    tutorial broadcaster's, and ``rostopic info /tf`` names the tfbus node.

    Debian's tf_monitor (tf 1.13) prints ``unknown_publisher`` for every broadcaster, the
    C++ one included (``MessageEvent::getPublisherName`` gets no connection header in that
    build): the test asserts the same name for both rather than a name it never prints.
    """
    cpp = master.run(str(tutorial_nodes / "tf_broadcaster"))
    monitor = master.run("rosrun", "tf", "tf_monitor")
    try:
        m = await anyio.to_thread.run_sync(
            monitor.wait_for, r"Frame: base_laser published by (\S+) Average Delay", 40.0
        )
        cpp_name = m.group(1)
    finally:
        monitor.stop()
        cpp.stop()
    name = "/tfbus_monitored"
    async with (
        Bus(transport=Ros1Transport(master_uri=master.uri, node_name=name)) as bus,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(lambda: run_broadcaster(bus, out=lambda _: None))
        monitor = master.run("rosrun", "tf", "tf_monitor")
        info = master.run("rostopic", "info", "/tf")
        try:
            m = await anyio.to_thread.run_sync(
                monitor.wait_for, r"Frame: base_laser published by (\S+) Average Delay", 40.0
            )
            assert m.group(1) == cpp_name
            hz = await anyio.to_thread.run_sync(
                monitor.wait_for, rf"Node: {re.escape(cpp_name)} ([\d.]+) Hz", 40.0
            )
            assert float(hz.group(1)) > 50.0
            await anyio.to_thread.run_sync(info.wait_for, r"^\s*\* /tfbus_monitored ", 40.0)
        finally:
            monitor.stop()
            info.stop()
        tg.cancel_scope.cancel()


async def test_master_restart_is_noticed_and_new_publishers_reach_tfbus(
    master: Master, tutorial_nodes: Path
) -> None:
    """roscore killed and restarted on the same port: tfbus registers again by itself and
    a broadcaster started after the restart reaches it."""
    transport = Ros1Transport(master_uri=master.uri, master_check_period=0.2)
    buffer = Buffer(cache_time=10.0)
    async with Bus(transport=transport) as bus, TransformListener(buffer, bus):
        bc = master.run(str(tutorial_nodes / "tf_broadcaster"))
        try:
            await buffer.wait_for_transform("base_link", "base_laser", Time(0), timeout=40.0)
        finally:
            bc.stop()
        assert transport.statistics().registrations == 1
        master.stop()
        master.start()
        with anyio.fail_after(40):
            while transport.statistics().registrations < 2:
                await anyio.sleep(0.05)  # polling a counter the transport sets, bounded
        bc2 = master.run(str(tutorial_nodes / "tf_broadcaster"), "__name:=robot_tf_publisher2")
        try:
            newest = buffer.get_latest_common_time("base_link", "base_laser")
            # a stamp after the restart can only come from the new broadcaster
            await buffer.wait_for_transform(
                "base_link", "base_laser", Time.from_ns(newest.ns + 200_000_000), timeout=40.0
            )
        finally:
            bc2.stop()
        nodes = master.call("getSystemState", "/test")
        subscribers = dict((t, n) for t, n in nodes[1])  # type: ignore[index]
        assert transport.node_name in subscribers["/tf"]


class _BoundedHandler(SimpleXMLRPCRequestHandler):
    """A request of the fake slave API may take 2 s at most: the test leaves the publisher
    (``api.shutdown()``, which waits for the request being served) from the event loop's
    thread, so a tfbus node's ``requestTopic`` connected but not yet written (its bytes
    wait for that loop) must not hold the server, and the test, forever (CI saw it)."""

    timeout = 2.0


class _EvilPublisher:
    """A fake ROS 1 publisher of /tf: a slave API answering ``requestTopic`` and a TCPROS
    server that sends a valid header, one valid message, then a malformed frame."""

    def __init__(self, ros_master: Master, frame: bytes) -> None:
        self.tcp = socket.socket()
        self.tcp.bind(("127.0.0.1", 0))
        self.tcp.listen(4)
        self.frame = frame
        self.api = SimpleXMLRPCServer(("127.0.0.1", 0), requestHandler=_BoundedHandler,
                                      logRequests=False, allow_none=True)
        port = self.tcp.getsockname()[1]
        self.api.register_function(
            lambda *a: [1, "", ["TCPROS", "127.0.0.1", port]], "requestTopic"
        )
        self.api_uri = f"http://127.0.0.1:{self.api.server_address[1]}/"
        self.threads = [
            threading.Thread(
                target=self.api.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True
            ),
            threading.Thread(target=self._serve, daemon=True),
        ]
        self.served = threading.Event()
        self.master = ros_master

    def _serve(self) -> None:
        conn, _ = self.tcp.accept()
        with conn:
            conn.recv(65536)
            conn.sendall(
                encode_header(
                    {
                        "callerid": "/evil",
                        "md5sum": TF_MD5SUM,
                        "type": "tf2_msgs/TFMessage",
                        "topic": "/tf",
                    }
                )
            )
            good = TFCodec().encode([_ts("map", "evil_ok", (1, 1, 1), Time(1))])
            conn.sendall(struct.pack("<I", len(good)) + good + self.frame)
            self.served.set()
            conn.settimeout(5.0)
            try:
                while conn.recv(4096):
                    pass
            except OSError:
                pass

    def __enter__(self) -> _EvilPublisher:
        for t in self.threads:
            t.start()
        self.master.call("registerPublisher", "/evil", "/tf", "tf2_msgs/TFMessage", self.api_uri)
        return self

    def __exit__(self, *exc: object) -> None:
        self.api.shutdown()
        self.api.server_close()
        self.tcp.close()


@pytest.fixture(params=["garbage", "oversized"])
def evil_frame(request: pytest.FixtureRequest) -> Iterator[bytes]:
    if request.param == "garbage":
        yield struct.pack("<I", 7) + b"\xff" * 7  # claims 0xffffffff transforms
    else:
        yield struct.pack("<I", 0xFFFFFFF0)  # far over max_message_bytes


async def test_malformed_frame_closes_only_its_connection(
    master: Master, tutorial_nodes: Path, evil_frame: bytes
) -> None:
    transport = Ros1Transport(master_uri=master.uri)
    buffer = Buffer(cache_time=10.0)
    bc = master.run(str(tutorial_nodes / "tf_broadcaster"))
    try:
        async with Bus(transport=transport) as bus, TransformListener(buffer, bus):
            await buffer.wait_for_transform("base_link", "base_laser", Time(0), timeout=40.0)
            with _EvilPublisher(master, evil_frame) as evil:
                await anyio.to_thread.run_sync(evil.served.wait, 40.0)
                with anyio.fail_after(40):
                    while transport.statistics().malformed < 1:
                        await anyio.sleep(0.02)  # polling a counter, bounded
                # the valid message before the bad frame was kept
                await buffer.wait_for_transform("map", "evil_ok", Time(0), timeout=10.0)
                before = buffer.get_latest_common_time("base_link", "base_laser")
                # the C++ broadcaster's connection keeps delivering
                await buffer.wait_for_transform(
                    "base_link", "base_laser", Time.from_ns(before.ns + 100_000_000), timeout=20.0
                )
    finally:
        bc.stop()
    assert transport.statistics().malformed >= 1


class _TricklePublisher(_EvilPublisher):
    """A fake publisher that sends its header and three messages one byte per send
    (TCP_NODELAY), so frames arrive cut anywhere, headers included."""

    def _serve(self) -> None:
        conn, _ = self.tcp.accept()
        with conn:
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn.recv(65536)
            data = encode_header(
                {"callerid": "/trickle", "md5sum": TF_MD5SUM, "type": "tf2_msgs/TFMessage"}
            )
            codec = TFCodec()
            for k in range(3):
                msg = codec.encode(
                    [
                        _ts("map", f"trickle_{k}", (k, 0, 0), Time(1)),
                        _ts("map", "x", (0, 0, 0), Time(2)),
                    ]
                )
                data += struct.pack("<I", len(msg)) + msg
            for i in range(len(data)):
                conn.sendall(data[i : i + 1])
            self.served.set()
            conn.settimeout(5.0)
            try:
                while conn.recv(4096):
                    pass
            except OSError:
                pass


async def test_frames_cut_anywhere_are_reassembled(master: Master) -> None:
    transport = Ros1Transport(master_uri=master.uri)
    buffer = Buffer(cache_time=10.0)
    async with Bus(transport=transport) as bus, TransformListener(buffer, bus):
        with _TricklePublisher(master, b""):
            for k in range(3):
                await buffer.wait_for_transform("map", f"trickle_{k}", Time(0), timeout=40.0)
    stats = transport.statistics()
    assert stats.malformed == 0
    assert stats.received >= 3


async def test_latched_static_set_is_served_to_each_new_subscriber(master: Master) -> None:
    """Two tfbus nodes over the real master: statics sent before the second node exists
    arrive there (latching), as one full set."""
    async with Bus(transport=Ros1Transport(master_uri=master.uri)) as a:
        static = StaticTransformBroadcaster(a)
        await static.send_transform(_ts("base_link", "s1", (1, 0, 0), Time(1)))
        await static.send_transform(_ts("base_link", "s2", (2, 0, 0), Time(1)))
        buffer = Buffer()
        async with (
            Bus(transport=Ros1Transport(master_uri=master.uri)) as b,
            TransformListener(buffer, b),
        ):
            for child in ("s1", "s2"):
                await buffer.wait_for_transform("base_link", child, Time(0), timeout=40.0)
            assert b.latched_statics().transforms  # latched on the receiving bus too


async def test_two_publishers_and_a_restarted_publisher(
    master: Master, tutorial_nodes: Path
) -> None:
    """Two publishers on /tf at once (the C++ tutorial broadcaster and tf's
    static_transform_publisher, which re-sends on /tf every 10 ms); then the C++
    broadcaster is stopped and started again (a new URI, announced by publisherUpdate)."""
    transport = Ros1Transport(master_uri=master.uri)
    buffer = Buffer(cache_time=10.0)
    tf1 = master.run(
        "rosrun",
        "tf",
        "static_transform_publisher",
        "0",
        "0",
        "1",
        "0",
        "0",
        "0",
        "base_link",
        "mast",
        "10",
    )
    bc = master.run(str(tutorial_nodes / "tf_broadcaster"))
    try:
        async with Bus(transport=transport) as bus, TransformListener(buffer, bus):
            await buffer.wait_for_transform("base_link", "base_laser", Time(0), timeout=40.0)
            await buffer.wait_for_transform("base_link", "mast", Time(0), timeout=40.0)
            assert transport.statistics().connections_opened >= 2
            bc.stop()
            last = buffer.get_latest_common_time("base_link", "base_laser")
            bc = master.run(str(tutorial_nodes / "tf_broadcaster"))
            await buffer.wait_for_transform(
                "base_link", "base_laser", Time.from_ns(last.ns + 100_000_000), timeout=40.0
            )
            ts = buffer.lookup_transform("base_link", "mast", Time(0))
            assert ts.transform.translation == Vector3(0.0, 0.0, 1.0)
    finally:
        bc.stop()
        tf1.stop()


# --------------------------------------------------------------------------- the CLI, --bus ros1


def _cli_finish(proc: Proc, *, timeout: float = 60.0) -> list[str]:
    """Wait for a CLI process that ends by itself (``--duration``, ``-n``), bounded."""
    try:
        proc.proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.stop(signal.SIGTERM)
        raise AssertionError(
            f"{proc.args} did not finish:\n" + "\n".join(proc.drain()[-20:])
        ) from None
    proc.stop()
    return proc.drain()


def test_cli_demo_listener_over_ros1(master: Master, tutorial_nodes: Path) -> None:
    """The mixed three-terminal run: roscore, the real C++ broadcaster,
    ``tfbus demo listener --bus ros1`` printing the tutorial's INFO line."""
    bc = master.run(str(tutorial_nodes / "tf_broadcaster"))
    try:
        proc = tfbus_cli(master, "demo", "listener", "--bus", "ros1", "--duration", "30")
        try:
            proc.wait_for(INFO.pattern, 40.0)
            proc.wait_for(INFO.pattern, 10.0)  # and again a second later
        finally:
            assert proc.stop(signal.SIGTERM) == 0
    finally:
        bc.stop()


def test_cli_demo_broadcaster_over_ros1(master: Master, tutorial_nodes: Path) -> None:
    """``tfbus demo broadcaster --bus ros1`` → the tutorial's C++ tf_listener."""
    proc = tfbus_cli(master, "demo", "broadcaster", "--bus", "ros1", "--duration", "60")
    listener = master.run(str(tutorial_nodes / "tf_listener"))
    try:
        listener.wait_for(CPP_INFO, 40.0)
    finally:
        listener.stop()
        assert proc.stop(signal.SIGTERM) == 0


def test_cli_echo_monitor_frames_over_ros1(
    master: Master, tutorial_nodes: Path, tmp_path: Path
) -> None:
    bc = master.run(str(tutorial_nodes / "tf_broadcaster"))
    try:
        echo = tfbus_cli(
            master,
            "echo",
            "base_link",
            "base_laser",
            "--bus",
            "ros1",
            "-n",
            "1",
            "--duration",
            "30",
        )
        out = _cli_finish(echo)
        assert any("Translation: [0.100, 0.000, 0.200]" in line for line in out), out
        monitor = tfbus_cli(master, "monitor", "--bus", "ros1", "--duration", "6")
        out = _cli_finish(monitor)
        assert any("base_laser" in line for line in out), out
        # tf_monitor's name for a ROS 1 sender, and no (empty) liveliness table.
        assert any("base_laser" in line and "unknown_publisher" in line for line in out), out
        assert not any("liveliness" in line for line in out), out
        gv = tmp_path / "frames.gv"
        frames = tfbus_cli(master, "frames", "--bus", "ros1", "--wait", "6", "-o", str(gv))
        out = _cli_finish(frames)
        assert gv.exists(), out
        assert re.search(r'"?base_link"?\s*->\s*"?base_laser"?', gv.read_text())
    finally:
        bc.stop()


def test_cli_static_transform_over_ros1_reaches_tf_echo(master: Master) -> None:
    proc = tfbus_cli(
        master,
        "static-transform",
        "1",
        "2",
        "3",
        "0",
        "0",
        "0",
        "base_link",
        "camera",
        "--bus",
        "ros1",
    )
    echo = master.run("rosrun", "tf", "tf_echo", "base_link", "camera")
    try:
        echo.wait_for(r"Translation: \[1\.000, 2\.000, 3\.000\]", 40.0)
    finally:
        echo.stop()
        assert proc.stop(signal.SIGTERM) == 0


# ------------------------------------------------------------ sensor_msgs/LaserScan

async def test_rostopic_laser_scans_reach_the_bus(master: Master) -> None:
    """A real ROS 1 publisher (``rostopic pub sensor_msgs/LaserScan``) → a tfbus bus with
    ``scan_topics=["/scan"]``: delivered as tfbus LaserScans, equal value for value;
    the master knows this node subscribes with the LaserScan type."""
    transport = Ros1Transport(master_uri=master.uri, scan_topics=["/scan"])
    assert transport.subscriptions() == ("/tf", "/tf_static", "/scan")
    publisher = rostopic_scan_publisher(master)
    try:
        async with Bus(transport=transport) as bus:
            sub = bus.subscribe("/scan")
            with anyio.fail_after(40):
                got = await sub.receive()
            assert_is_the_yaml_scan(got)
            state = master.call("getSystemState", "/tfbus_test")
            assert [transport.node_name] in [s[1] for s in state[1] if s[0] == "/scan"]  # type: ignore[index]
            types = dict(master.call("getTopicTypes", "/tfbus_test"))  # type: ignore[arg-type]
            assert types["/scan"] == "sensor_msgs/LaserScan"
    finally:
        publisher.stop()
    stats = transport.statistics()
    assert stats.malformed == 0 and stats.delivered >= 1


def test_scan_topics_are_checked() -> None:
    with pytest.raises(ValueError, match="'/tf' is already carried"):
        Ros1Transport(scan_topics=["/tf"])
    with pytest.raises(ValueError, match="'scan' is not a global ROS graph name"):
        Ros1Transport(scan_topics=["scan"])
    assert Ros1Transport(scan_topics=["/scan", "/scan"]).subscriptions() == (
        "/tf", "/tf_static", "/scan")


def test_bus_specs_pass_scan_topics_to_ros1_only() -> None:
    """``tfbus view --bus ros1 --scan /scan`` opens a ROS 1 node subscribed to /scan
    (the CLI's open_spec_transport -> spec.open_transport -> the ros1 factory); Zenoh and
    memory carry every topic and take no such option."""
    from tfbus.cli._bus_source import BusSource
    from tfbus.cli._bus_spec import open_spec_transport
    from tfbus.transports.spec import parse_bus_spec

    ros1 = open_spec_transport(parse_bus_spec("ros1"), name="tfbus-view", scan_topics=["/scan"])
    assert isinstance(ros1, Ros1Transport)
    assert ros1.subscriptions() == ("/tf", "/tf_static", "/scan")
    assert ros1.topic_type("/scan") == "sensor_msgs/LaserScan"
    assert ros1.topic_type("/tf") == "tf2_msgs/TFMessage"
    plain = open_transport("ros1")
    assert isinstance(plain, Ros1Transport) and plain.subscriptions() == ("/tf", "/tf_static")
    assert open_transport("memory", scan_topics=["/scan"]) is not None
    assert BusSource("ros1", scan_topics=["/scan"]).scan_topics == ("/scan",)


class _EvilScanPublisher(_EvilPublisher):
    """A fake ROS 1 publisher of /scan: its header, one valid LaserScan (serialised by
    rosbags), then a LaserScan claiming 2**32-1 beams in a 64-byte frame."""

    def _serve(self) -> None:
        import numpy as np

        from tfbus.codecs.ros1 import SCAN_MD5SUM, tf_typestore

        store = tf_typestore(ros1=True)
        t = store.types
        good = bytes(store.serialize_ros1(t["sensor_msgs/msg/LaserScan"](
            header=t["std_msgs/msg/Header"](seq=1, stamp=t["builtin_interfaces/msg/Time"](
                sec=3, nanosec=0), frame_id="evil_ok"),
            angle_min=np.float32(0), angle_max=np.float32(1), angle_increment=np.float32(1),
            time_increment=np.float32(0), scan_time=np.float32(0), range_min=np.float32(0),
            range_max=np.float32(5), ranges=np.array([4.5, 2.25], np.float32),
            intensities=np.zeros(0, np.float32)), "sensor_msgs/msg/LaserScan"))
        bad = good[: 16 + 7 + 28] + struct.pack("<I", 2**32 - 1) + b"\x00" * 9
        conn, _ = self.tcp.accept()
        with conn:
            conn.recv(65536)
            conn.sendall(encode_header({"callerid": "/evil", "md5sum": SCAN_MD5SUM,
                                        "type": "sensor_msgs/LaserScan", "topic": "/scan"}))
            for msg in (good, bad):
                conn.sendall(struct.pack("<I", len(msg)) + msg)
            self.served.set()
            conn.settimeout(5.0)
            with contextlib.suppress(OSError):
                while conn.recv(4096):
                    pass

    def __enter__(self) -> _EvilScanPublisher:
        for t in self.threads:
            t.start()
        self.master.call("registerPublisher", "/evil", "/scan", "sensor_msgs/LaserScan",
                         self.api_uri)
        return self


async def test_malformed_scan_closes_only_its_connection(master: Master) -> None:
    """A damaged LaserScan from one publisher is counted and its connection closed; the
    scan before it and the real rostopic publisher's scans are delivered."""
    transport = Ros1Transport(master_uri=master.uri, scan_topics=["/scan"])
    publisher = rostopic_scan_publisher(master)
    try:
        async with Bus(transport=transport) as bus:
            sub = bus.subscribe("/scan", queue_size=1000)
            with anyio.fail_after(40):
                assert_is_the_yaml_scan(await sub.receive())
            with _EvilScanPublisher(master, b"") as evil:
                await anyio.to_thread.run_sync(evil.served.wait, 40.0)
                frames: set[str] = set()
                with anyio.fail_after(40):
                    while "evil_ok" not in frames or transport.statistics().malformed < 1:
                        frames.add((await sub.receive()).header.frame_id)
                with anyio.fail_after(40):  # rostopic's connection keeps delivering
                    assert_is_the_yaml_scan(await sub.receive())
    finally:
        publisher.stop()
    assert transport.statistics().malformed == 1
