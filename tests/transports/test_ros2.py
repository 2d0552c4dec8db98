"""tfbus.transports.ros2: the codec against cyclonedds' serializer, and the transport
against real ROS 2 nodes (rclpy + rmw_fastrtps_cpp from the ros-kilted-* wheels).

The rclpy peers run as subprocesses of the ROS 2 venv built by
``scripts/install/install_ros2_env.sh`` (session fixture; the tests skip with its reason only
when the wheels cannot be installed). Network rule: every test uses a fresh random
``ROS_DOMAIN_ID``; the rclpy side runs with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
plus the loopback Fast DDS profile ``peers/ros2/fastdds_lo.xml``, tfbus with its
loopback Cyclone configuration (or ``peers/ros2/cyclone_lo.xml``); peers stop on
SIGTERM. Every wait is on data or output, with
a bound; none is a fixed sleep.
"""

from __future__ import annotations

import json
import math
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import anyio
import pytest
from dds_domains import new_domain
from peer_install import peer_unavailable, require

pytest.importorskip("cyclonedds", reason="needs the ros2 extra: pip install 'tfbus[ros2]'")


from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import SimClock, SystemClock
from tfbus.codecs.cdr import (
    SEC_MAX,
    decode_clock,
    decode_tf,
    encode_clock,
    encode_tf,
)
from tfbus.demos.tutorial import broadcaster_node, run_listener
from tfbus.errors import TransportError, WireDecodeError, WireEncodeError
from tfbus.listener import TransformListener
from tfbus.messages import (
    Clock,
    Header,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import Duration, Time
from tfbus.transports.ros2 import Ros2Transport
from tfbus.transports.ros2.dds import (
    Clock_,
    Header_,
    Quaternion_,
    TFMessage_,
    Time_,
    Transform_,
    TransformStamped_,
    Vector3_,
    cyclone_config,
    dds_topic_name,
)
from tfbus.transports.spec import open_transport

ROOT = Path(__file__).resolve().parents[2]
PEERS = ROOT / "peers" / "ros2"
PEER = PEERS / "tf_peer.py"
ROS_VENV_PYTHON = ROOT / ".venv-ros2" / "bin" / "python"
INSTALL = ROOT / "scripts" / "install" / "install_ros2_env.sh"
WAIT = 30.0  # bound of every wait on a peer (Fast DDS -> Cyclone takes 3-4 s to match)



@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


Vec = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def ts(
    parent: str, child: str, sec: int = 1, nanosec: int = 0,
    t: Vec = (0.0, 0.0, 0.0), r: Quat = (0.0, 0.0, 0.0, 1.0),
) -> TransformStamped:  # fmt: skip
    return TransformStamped(
        Header(Time(sec, nanosec), parent), child, Transform(Vector3(*t), Quaternion(*r))
    )


def as_dict(x: TransformStamped, stamp: bool = True) -> dict[str, Any]:
    d: dict[str, Any] = {
        "parent": x.header.frame_id,
        "child": x.child_frame_id,
        "t": list(x.transform.translation),
        "r": list(x.transform.rotation),
    }
    if stamp:
        d["stamp"] = [x.header.stamp.sec, x.header.stamp.nanosec]
    return d


def reference_bytes(transforms: list[TransformStamped], big_endian: bool = False) -> bytes:
    """The same message serialized by cyclonedds-python's own (reference) serializer."""
    from cyclonedds.idl._support import Endianness

    msg = TFMessage_(
        [
            TransformStamped_(
                Header_(Time_(x.header.stamp.sec, x.header.stamp.nanosec), x.header.frame_id),
                x.child_frame_id,
                Transform_(
                    Vector3_(*map(float, x.transform.translation)),
                    Quaternion_(*map(float, x.transform.rotation)),
                ),
            )
            for x in transforms
        ]
    )
    data = msg.serialize(endianness=Endianness.Big if big_endian else Endianness.Little)
    return data.ljust((len(data) + 3) & ~3, b"\0")


# -- the codec, against cyclonedds' serializer ---------------------------------------------

CODEC_CASES = [
    [],
    [ts("base_link", "base_laser", 1248138528, 200823000, (0.1, 0.0, 0.2))],
    # frame id lengths 0..9 hit every padding case of the strings and the doubles
    [
        ts("p" * n, "c" * (n * 3 % 10), n, n * 7, (n, -n, 0.5), (0, 0, math.sin(n), math.cos(n)))
        for n in range(10)
    ],
    [ts("mäp", "ödom/ü", SEC_MAX, 999_999_999, (1e300, -0.0, 5e-324))],
]


@pytest.mark.parametrize("transforms", CODEC_CASES, ids=["empty", "one", "paddings", "edges"])
def test_encode_is_byte_identical_to_cyclonedds(transforms: list[TransformStamped]) -> None:
    data = encode_tf(transforms)
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR_LE: XCDR1 little-endian, as rmw sends
    assert data == reference_bytes(transforms)


@pytest.mark.parametrize("transforms", CODEC_CASES, ids=["empty", "one", "paddings", "edges"])
@pytest.mark.parametrize("big_endian", [False, True], ids=["le", "be"])
def test_decode_inverts_cyclonedds(transforms: list[TransformStamped], big_endian: bool) -> None:
    decoded = decode_tf(reference_bytes(transforms, big_endian))
    assert list(decoded.transforms) == transforms


def test_tf2_msgs_layout_by_hand() -> None:
    # TFMessage[1]: count, sec, nanosec, "a\0" (len 2), pad 2, "b\0", pad to 8, 7 doubles
    data = encode_tf([ts("a", "b", 3, 4, (1.0, 2.0, 3.0))])
    body = data[4:]
    assert body[:4] == (1).to_bytes(4, "little")
    assert body[4:8] == (3).to_bytes(4, "little") and body[8:12] == (4).to_bytes(4, "little")
    assert body[12:16] == (2).to_bytes(4, "little") and body[16:20] == b"a\0\0\0"
    assert body[20:24] == (2).to_bytes(4, "little") and body[24:26] == b"b\0"
    assert len(body) == 32 + 56  # doubles start at offset 32 (8-aligned)


def test_encode_refuses_stamps_ros2_cannot_carry() -> None:
    ok = ts("a", "b", SEC_MAX, 999_999_999)
    assert decode_tf(encode_tf([ok])).transforms == (ok,)
    with pytest.raises(WireEncodeError, match=r"transforms\[1\]\.header\.stamp: sec=2147483648"):
        encode_tf([ok, ts("a", "c", SEC_MAX + 1)])
    with pytest.raises(WireEncodeError, match=r"transforms\[0\]: a frame id holds a NUL"):
        encode_tf([ts("a\0", "b")])
    with pytest.raises(WireEncodeError, match=r"transforms\[0\]: not a TransformStamped"):
        encode_tf(["junk"])  # type: ignore[list-item]


def _body(*chunks: bytes) -> bytes:
    return b"\x00\x01\x00\x00" + b"".join(chunks)


def _u32(n: int) -> bytes:
    return n.to_bytes(4, "little")


GOOD = encode_tf([ts("a", "b", 3, 4, (1.0, 2.0, 3.0))])
MALFORMED = {
    "empty": b"",
    "header only": b"\x00\x01\x00\x00",
    "xcdr2 delimited": b"\x00\x09\x00\x00" + GOOD[4:],
    "truncated": GOOD[:-9],
    "count too large": _body(_u32(1000), GOOD[8:]),
    "count huge": _body(_u32(0xFFFFFFFF)),
    # GOOD: header [0:4], count [4:8], sec [8:12], nanosec [12:16], len [16:20], "a\0"
    "string not NUL-terminated": GOOD[:20] + b"ax" + GOOD[22:],
    "string length 0": GOOD[:16] + _u32(0) + GOOD[20:],
    "string past the end": GOOD[:16] + _u32(1 << 30) + GOOD[20:],
    "invalid utf-8": GOOD[:20] + b"\xff\0" + GOOD[22:],
    "negative sec": GOOD[:8] + (-1).to_bytes(4, "little", signed=True) + GOOD[12:],
}


@pytest.mark.parametrize("data", MALFORMED.values(), ids=MALFORMED.keys())
def test_decode_raises_only_wire_decode_error(data: bytes) -> None:
    with pytest.raises(WireDecodeError):
        decode_tf(data)


def test_decode_limits_the_transform_count() -> None:
    data = encode_tf([ts("a", f"c{i}") for i in range(5)])
    assert len(decode_tf(data, max_transforms=5).transforms) == 5
    with pytest.raises(WireDecodeError, match="limit 4"):
        decode_tf(data, max_transforms=4)


# -- configuration and options ---------------------------------------------------------------


def _xml(text: str) -> ET.Element:
    root = ET.fromstring(text)
    for el in root.iter():  # drop the namespace for simple paths
        el.tag = el.tag.split("}")[-1]
    return root


def test_default_cyclone_config_is_loopback_only() -> None:
    root = _xml(Ros2Transport(domain_id=1).config)
    nics = root.findall("./Domain/General/Interfaces/NetworkInterface")
    assert [n.attrib for n in nics] == [{"address": "127.0.0.1", "multicast": "false"}]
    assert root.findtext("./Domain/General/AllowMulticast") == "false"
    assert [p.attrib["address"] for p in root.iter("Peer")] == ["127.0.0.1"]
    assert root.findtext("./Domain/Compatibility/IgnoreTypeInformation") == "1.15"


def test_robot_network_config() -> None:
    root = _xml(cyclone_config(interfaces=["eth0", "192.168.1.5"], peers=["10.0.0.2"]))
    nics = root.findall("./Domain/General/Interfaces/NetworkInterface")
    assert [n.attrib for n in nics] == [{"name": "eth0"}, {"address": "192.168.1.5"}]
    assert root.findtext("./Domain/General/AllowMulticast") == "default"
    assert [p.attrib["address"] for p in root.iter("Peer")] == ["10.0.0.2"]
    assert root.findtext("./Domain/Compatibility/IgnoreTypeInformation") == "1.15"
    with pytest.raises(ValueError, match="interfaces"):
        cyclone_config(interfaces="eth0")


def test_options_and_arguments(tmp_path: Path) -> None:
    t = open_transport("ros2:domain=7")
    assert isinstance(t, Ros2Transport)
    assert t.domain_id == 7 and "127.0.0.1" in t.config
    t = open_transport("ros2:domain=8&interfaces=eth0,wlan0")
    assert isinstance(t, Ros2Transport)
    assert 'name="wlan0"' in t.config and 'name="eth0"' in t.config
    xml = tmp_path / "c.xml"
    xml.write_text(cyclone_config(interfaces=["eth1"]))
    t = open_transport(f"ros2:config={xml}")
    assert isinstance(t, Ros2Transport) and 'name="eth1"' in t.config
    assert 'name="eth1"' in Ros2Transport(config=f"file://{xml}").config
    with pytest.raises(ValueError, match="unknown bus option 'domian'"):
        open_transport("ros2:domian=7")
    with pytest.raises(ValueError, match="'domain' must be an integer, got 'x'"):
        open_transport("ros2:domain=x")
    with pytest.raises(ValueError, match=r"domain_id must be in 0\.\.232, got 233"):
        Ros2Transport(domain_id=233)
    with pytest.raises(ValueError, match="not both"):
        Ros2Transport(config=str(xml), interfaces=["eth0"])
    with pytest.raises(ValueError, match="cannot read the Cyclone XML file"):
        Ros2Transport(config=str(tmp_path / "missing.xml"))
    with pytest.raises(ValueError, match="'/chatter' is not"):
        Ros2Transport(topics=["/chatter"])


def test_domain_id_defaults_to_ros_domain_id(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    assert Ros2Transport().domain_id == 42
    monkeypatch.delenv("ROS_DOMAIN_ID")
    assert Ros2Transport().domain_id == 0
    monkeypatch.setenv("ROS_DOMAIN_ID", "robot")
    with pytest.raises(ValueError, match="ROS_DOMAIN_ID must be an integer, got 'robot'"):
        Ros2Transport()


# -- tfbus <-> tfbus over DDS (no ROS needed) -------------------------------------------------


async def receive_where(sub: Any, pred: Callable[[Any], bool], timeout: float = WAIT) -> Any:
    with anyio.fail_after(timeout):
        while True:
            msg = await sub.receive()
            if pred(msg):
                return msg


@pytest.mark.anyio
async def test_tfbus_to_tfbus(anyio_backend: str) -> None:
    d = new_domain()
    a_t, b_t = Ros2Transport(domain_id=d), Ros2Transport(domain_id=d)
    a_static = [ts("base_link", "base_laser", 5, 6, (0.1, 0.0, 0.2))]
    b_static = [ts("base_link", "camera", 5, 7, (0.0, 0.1, 0.3))]
    async with Bus(transport=a_t) as a:
        # static before the other side exists, in two sends: a late joiner gets the set
        await StaticTransformBroadcaster(a).send_transform(a_static)
        await StaticTransformBroadcaster(a).send_transform(b_static)
        async with Bus(transport=b_t) as b:
            statics = b.subscribe("/tf_static")
            tf = b.subscribe("/tf")
            msg = await receive_where(statics, lambda m: len(m.transforms) == 2)
            assert list(msg.transforms) == a_static + b_static  # ONE message: the full set
            dyn = ts("odom", "base_link", SEC_MAX, 999_999_999, (1.5, -2.0, 0.0))
            with anyio.fail_after(WAIT):
                while True:  # /tf is volatile: publish until matched and received
                    await TransformBroadcaster(a).send_transform(dyn)
                    with anyio.move_on_after(0.1):
                        got = await tf.receive()
                        break
            assert got.transforms == (dyn,)
            with pytest.raises(WireEncodeError, match=r"sec=2147483648"):
                a.publish_nowait("/tf", TFMessage([dyn, ts("a", "b", SEC_MAX + 1)]))
            a.publish_nowait("/chatter", "not for ROS 2")
            stats = a_t.statistics()
            assert stats.send_errors == 1 and stats.not_mapped == 1
            assert a_t.matched_publishers("/tf") == 1
    assert b_t.statistics().malformed == 0
    assert not a_t.running and not b_t.running


@pytest.mark.anyio
async def test_one_cyclone_configuration_per_domain_in_a_process(anyio_backend: str) -> None:
    d = new_domain()
    async with Bus(transport=Ros2Transport(domain_id=d)):
        other = Ros2Transport(domain_id=d, config=cyclone_config(max_participant_index=5))
        with pytest.raises(TransportError, match=f"DDS domain {d} is already open"):
            async with Bus(transport=other):
                pass
    async with Bus(transport=other):  # the domain was released: now it can be created
        assert other.running


RAW_WRITER = PEERS / "raw_writer.py"


class RawWriter:
    """A raw DDS writer on rt/tf in its own process (peers/ros2/raw_writer.py): a
    writer and a listening reader in one process can deadlock inside Cyclone."""

    def __init__(self, domain_id: int, *topic: str) -> None:
        env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
        env.pop("CYCLONEDDS_URI", None)
        self.proc = subprocess.Popen(
            [sys.executable, str(RAW_WRITER), str(domain_id), *topic],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
        )  # fmt: skip
        self.lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()
        self._answer("READY")

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.strip())

    def _answer(self, prefix: str) -> str:
        try:
            line = self.lines.get(timeout=WAIT)
        except queue.Empty:
            raise AssertionError(f"raw writer: no {prefix!r} in {WAIT} s") from None
        assert line.startswith(prefix), line
        return line[len(prefix):].strip()

    def _ask(self, command: str, prefix: str) -> str:
        assert self.proc.stdin is not None
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()
        return self._answer(prefix)

    async def write(self, data: bytes) -> int:
        """Write one serialized sample; Cyclone's return code (0 written, < 0 refused)."""
        return int(await anyio.to_thread.run_sync(self._ask, f"W {data.hex()}", "RC"))

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            self.proc.wait(30)
        except subprocess.TimeoutExpired:
            self.proc.terminate()
            self.proc.wait(10)


# Structurally invalid CDR never leaves or enters Cyclone: it normalizes (validates) every
# serialized sample against the type (dds_stream_normalize) on write and on receive.
STRUCTURAL = {k: v for k, v in MALFORMED.items() if k not in ("invalid utf-8", "negative sec")}
# What valid CDR can still carry that tfbus cannot take: counted in ``malformed``.
SEMANTIC = [
    MALFORMED["invalid utf-8"],
    MALFORMED["negative sec"],
    encode_tf([ts("a", f"c{i}") for i in range(5)]),  # over max_transforms=4
]


@pytest.mark.anyio
async def test_malformed_samples_are_counted_and_dropped(anyio_backend: str) -> None:
    """A raw DDS writer on rt/tf sends samples tfbus cannot decode between valid ones."""
    d = new_domain()
    transport = Ros2Transport(domain_id=d, max_transforms=4)
    async with Bus(transport=transport) as bus:
        tf = bus.subscribe("/tf")
        writer = await anyio.to_thread.run_sync(RawWriter, d)
        try:
            for name, junk in STRUCTURAL.items():
                assert await writer.write(junk) < 0, name  # refused by Cyclone itself
            valid = encode_tf([ts("odom", "base_link", 1, 0, (1.0, 0.0, 0.0))])
            with anyio.fail_after(WAIT):
                while transport.matched_publishers("/tf") == 0:
                    await anyio.sleep(0.01)  # polling a bounded condition, not a fixed wait
            for junk in SEMANTIC:
                assert await writer.write(junk) == 0
                assert await writer.write(valid) == 0
            msgs = [await receive_where(tf, lambda m: True) for _ in SEMANTIC]
            assert all(m.transforms[0].child_frame_id == "base_link" for m in msgs)
            stats = transport.statistics()
            assert (stats.received, stats.malformed, stats.delivered) == (6, 3, 3)
        finally:
            writer.close()


# -- real ROS 2 peers -----------------------------------------------------------------------------


@pytest.fixture(scope="session")
def ros2_python() -> Path:
    """The ROS 2 venv's python, installed by scripts/install/install_ros2_env.sh when missing."""
    if sys.platform != "linux":
        peer_unavailable("ros2-env", "the ROS 2 wheels of the recipe are manylinux only")
    require("ros2-env", INSTALL.name, timeout=1200)
    assert ROS_VENV_PYTHON.exists()
    return ROS_VENV_PYTHON


class Peer:
    """An rclpy process: stdout lines queued by a reader thread; SIGTERM to stop."""

    def __init__(self, python: Path, script: Path, args: list[str], domain: int) -> None:
        # Without its profile Fast DDS would fall back to every interface: never run so.
        assert (PEERS / "fastdds_lo.xml").is_file(), "peers/ros2/fastdds_lo.xml missing"
        env = dict(
            os.environ,
            ROS_DOMAIN_ID=str(domain),
            RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
            ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
            FASTDDS_DEFAULT_PROFILES_FILE=str(PEERS / "fastdds_lo.xml"),
            PYTHONUNBUFFERED="1",
        )
        env.pop("ROS_LOCALHOST_ONLY", None)
        env.pop("CYCLONEDDS_URI", None)
        self.proc = subprocess.Popen(
            [str(python), str(script), *args],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        self.lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()
        self.wait_line(lambda line: line == "READY")

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))
        self.lines.put(None)

    def wait_line(self, pred: Callable[[str], bool], timeout: float = WAIT) -> str:
        end = time.monotonic() + timeout
        while True:
            remaining = end - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"no matching line from the peer in {timeout} s")
            try:
                line = self.lines.get(timeout=remaining)
            except queue.Empty:
                continue
            if line is None:
                raise RuntimeError(f"the peer exited with {self.proc.wait()}")
            if pred(line):
                return line

    def wait_message(self, pred: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
        line = self.wait_line(lambda s: s.startswith("{") and pred(json.loads(s)))
        return dict(json.loads(line))

    async def await_message(self, pred: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
        return await anyio.to_thread.run_sync(self.wait_message, pred)

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout=WAIT)
        except subprocess.TimeoutExpired:
            self.proc.kill()  # last resort only: leaves Fast DDS files in /dev/shm
            self.proc.wait()
            raise


@pytest.fixture
def peers(ros2_python: Path) -> Iterator[Callable[..., Peer]]:
    started: list[Peer] = []

    def start(args: list[str], domain: int, script: Path = PEER) -> Peer:
        peer = Peer(ros2_python, script, args, domain)
        started.append(peer)
        return peer

    yield start
    for peer in started:
        peer.stop()


def write_json(path: Path, transforms: list[TransformStamped]) -> Path:
    path.write_text(json.dumps([as_dict(x) for x in transforms]))
    return path


LOOPBACK_PROFILES = {
    "tfbus-default": lambda: None,
    "cyclone_lo.xml": lambda: str(PEERS / "cyclone_lo.xml"),
}


@pytest.mark.anyio
@pytest.mark.parametrize("profile", LOOPBACK_PROFILES, ids=list(LOOPBACK_PROFILES))
async def test_tutorial_rclpy_broadcaster_to_tfbus_listener(
    anyio_backend: str, profile: str, peers: Callable[..., Peer], tmp_path: Path
) -> None:
    """The tutorial's robot_tf_publisher in rclpy (base_link -> base_laser at 100 Hz),
    the tutorial's listener on tfbus: the INFO line with the tutorial's numbers."""
    d = new_domain()
    dyn = write_json(tmp_path / "d.json", [ts("base_link", "base_laser", t=(0.1, 0.0, 0.2))])
    peers(["--tf", str(dyn), "--rate", "100"], d)
    lines: list[str] = []
    got = anyio.Event()

    def out(line: str) -> None:
        lines.append(line)
        if "[ INFO]" in line:
            got.set()

    transport = Ros2Transport(domain_id=d, config=LOOPBACK_PROFILES[profile]())
    async with Bus(transport=transport) as bus, anyio.create_task_group() as tg:
        tg.start_soon(lambda: run_listener(bus, listen_rate=10.0, out=out))
        with anyio.fail_after(WAIT):
            await got.wait()
        tg.cancel_scope.cancel()
    info = next(line for line in lines if "[ INFO]" in line)
    assert "base_laser: (1.00, 0.20. 0.00) -----> base_link: (1.10, 0.20, 0.20)" in info
    assert transport.statistics().malformed == 0


@pytest.mark.anyio
async def test_tutorial_tfbus_broadcaster_to_rclpy_subscriber(
    anyio_backend: str, peers: Callable[..., Peer]
) -> None:
    d = new_domain()
    echo = peers(["--echo"], d)
    async with Bus(transport=Ros2Transport(domain_id=d)) as bus, anyio.create_task_group() as tg:
        tg.start_soon(broadcaster_node, bus, SystemClock(), 100.0)
        msg = await echo.await_message(lambda m: m["topic"] == "/tf")
        tg.cancel_scope.cancel()
    (x,) = msg["transforms"]
    assert (x["parent"], x["child"]) == ("base_link", "base_laser")
    assert x["t"] == [0.1, 0.0, 0.2] and x["r"] == [0.0, 0.0, 0.0, 1.0]  # exact doubles
    assert 1_700_000_000 < x["stamp"][0] < 2**31 and 0 <= x["stamp"][1] < 1_000_000_000


@pytest.mark.anyio
async def test_statics_from_ros2_reach_a_late_tfbus_listener(
    anyio_backend: str, peers: Callable[..., Peer], tmp_path: Path
) -> None:
    d = new_domain()
    statics = [
        ts("base_link", "base_laser", 10, 20, (0.1, 0.0, 0.2)),
        ts("base_link", "imu", 10, 20, (0.0, 0.05, 0.1), (0, 0, math.sqrt(0.5), math.sqrt(0.5))),
    ]
    peers(["--publish", str(write_json(tmp_path / "s.json", statics)), "--static"], d)
    # the peer published before READY: tfbus joins after the only /tf_static message
    buffer = Buffer()
    async with Bus(transport=Ros2Transport(domain_id=d)) as bus, TransformListener(buffer, bus):
        got = await buffer.lookup_transform_async("base_link", "imu", Time(0), timeout=WAIT)
        laser = buffer.lookup_transform("base_link", "base_laser", Time(0))
    # a static lookup at Time(0) is stamped 0 (tf2); frames and values are exact
    assert got == statics[1]._replace(header=Header(Time(0), "base_link"))
    assert laser == statics[0]._replace(header=Header(Time(0), "base_link"))


@pytest.mark.anyio
async def test_statics_from_tfbus_reach_a_late_rclpy_subscriber(
    anyio_backend: str, peers: Callable[..., Peer]
) -> None:
    d = new_domain()
    a = ts("base_link", "base_laser", 10, 20, (0.1, 0.0, 0.2))
    b = ts("base_link", "camera", 11, 21, (0.3, 0.0, 0.4), (0.5, 0.5, 0.5, 0.5))
    a2 = a._replace(transform=Transform(Vector3(0.15, 0.0, 0.2)))
    async with Bus(transport=Ros2Transport(domain_id=d)) as bus:
        broadcaster = StaticTransformBroadcaster(bus)
        await broadcaster.send_transform(a)
        await broadcaster.send_transform(b)
        await broadcaster.send_transform(a2)  # replaces base_laser, keeps camera
        echo = peers(["--echo"], d)  # joins after every send
        msg = await echo.await_message(lambda m: m["topic"] == "/tf_static")
    # keep-last 1 on the writer: one message with the full set, latest per child
    assert msg["transforms"] == [as_dict(a2), as_dict(b)]


@pytest.mark.anyio
async def test_two_ros2_publishers_at_once(
    anyio_backend: str, peers: Callable[..., Peer], tmp_path: Path
) -> None:
    d = new_domain()
    one_s, one_d = [ts("base_link", "base_laser", t=(0.1, 0.0, 0.2))], [ts("odom", "base_link")]
    two_s, two_d = [ts("map", "world", t=(0.0, 0.0, 1.0))], [ts("world", "odom", t=(2.0, 0, 0))]
    for name, s, dyn in (("one", one_s, one_d), ("two", two_s, two_d)):
        peers(["--tf-static", str(write_json(tmp_path / f"{name}s.json", s)),
               "--tf", str(write_json(tmp_path / f"{name}d.json", dyn)),
               "--rate", "50"], d)  # fmt: skip
    buffer = Buffer()
    async with Bus(transport=Ros2Transport(domain_id=d)) as bus, TransformListener(buffer, bus):
        got = await buffer.lookup_transform_async("map", "base_laser", Time(0), timeout=WAIT)
    assert got.transform.translation == Vector3(2.1, 0.0, 1.2)
    assert got.header.frame_id == "map" and got.child_frame_id == "base_laser"


def _many(n: int) -> list[TransformStamped]:
    return [
        ts("base_link", f"link_{i:03d}", 100 + i, i * 1000, (i * 0.001, -i * 0.5, 1.0 / (i + 1)),
           (0.0, math.sin(i / 200), 0.0, math.cos(i / 200)))
        for i in range(n)
    ]  # fmt: skip


@pytest.mark.anyio
async def test_a_400_transform_message_both_ways(
    anyio_backend: str, peers: Callable[..., Peer], tmp_path: Path
) -> None:
    d = new_domain()
    many = _many(400)
    echo = peers(["--echo"], d)
    peers(["--publish", str(write_json(tmp_path / "m.json", many)), "--rate", "5"], d)
    async with Bus(transport=Ros2Transport(domain_id=d)) as bus, anyio.create_task_group() as tg:
        tf = bus.subscribe("/tf")
        msg = await receive_where(tf, lambda m: len(m.transforms) == 400)
        assert list(msg.transforms) == many  # rclpy -> tfbus, exact

        mine = [x._replace(child_frame_id="tfbus_" + x.child_frame_id) for x in many]

        async def publish_until_stopped() -> None:
            while True:
                bus.publish_nowait("/tf", TFMessage(mine))
                await anyio.sleep(0.2)

        tg.start_soon(publish_until_stopped)
        got = await echo.await_message(
            lambda m: m["transforms"] and m["transforms"][0]["child"].startswith("tfbus_")
        )
        tg.cancel_scope.cancel()
    assert got["transforms"] == [as_dict(x) for x in mine]  # tfbus -> rclpy, exact


@pytest.mark.anyio
async def test_stamps_at_the_edges_of_ros2_time(
    anyio_backend: str, peers: Callable[..., Peer], tmp_path: Path
) -> None:
    d = new_domain()
    edges = [
        ts("base_link", "first", 0, 1),
        ts("base_link", "last", SEC_MAX, 999_999_999),
        ts("base_link", "y2038", SEC_MAX, 0),
    ]
    echo = peers(["--echo"], d)
    peers(["--publish", str(write_json(tmp_path / "e.json", edges)), "--rate", "10"], d)
    transport = Ros2Transport(domain_id=d)
    async with Bus(transport=transport) as bus, anyio.create_task_group() as tg:
        tf = bus.subscribe("/tf")
        msg = await receive_where(tf, lambda m: m.transforms[0].child_frame_id == "first")
        assert list(msg.transforms) == edges
        assert msg.transforms[1].header.stamp.ns == SEC_MAX * 10**9 + 999_999_999

        mine = [x._replace(header=x.header._replace(frame_id="tfbus")) for x in edges]

        async def publish_until_stopped() -> None:
            while True:
                bus.publish_nowait("/tf", TFMessage(mine))
                await anyio.sleep(0.1)

        tg.start_soon(publish_until_stopped)
        got = await echo.await_message(lambda m: m["transforms"][0]["parent"] == "tfbus")
        tg.cancel_scope.cancel()
        assert got["transforms"] == [as_dict(x) for x in mine]
        sent = transport.statistics().sent
        with pytest.raises(WireEncodeError, match=r"transforms\[0\]\.header\.stamp: sec=2\d+"):
            bus.publish_nowait("/tf", TFMessage([ts("tfbus", "beyond", SEC_MAX + 1)]))
        assert transport.statistics().sent == sent  # nothing of it went out


@pytest.mark.anyio
async def test_rclpy_peer_killed_and_restarted(
    anyio_backend: str, peers: Callable[..., Peer], tmp_path: Path
) -> None:
    """SIGTERM the rclpy broadcaster, start a new one: the tfbus listener resumes and gets
    the (new) statics again."""
    d = new_domain()
    dyn = write_json(tmp_path / "d.json", [ts("odom", "base_link", t=(1.0, 0.0, 0.0))])
    s1 = write_json(tmp_path / "s1.json", [ts("base_link", "base_laser", t=(0.1, 0.0, 0.2))])
    s2 = write_json(tmp_path / "s2.json", [ts("base_link", "base_laser", t=(0.3, 0.0, 0.2))])
    async with Bus(transport=Ros2Transport(domain_id=d)) as bus:
        statics, tf = bus.subscribe("/tf_static"), bus.subscribe("/tf")
        first = peers(["--tf-static", str(s1), "--tf", str(dyn), "--rate", "50"], d)
        msg = await receive_where(statics, lambda m: True)
        assert msg.transforms[0].transform.translation == Vector3(0.1, 0.0, 0.2)
        await receive_where(tf, lambda m: True)
        assert await anyio.to_thread.run_sync(first.stop) == 0  # SIGTERM: a clean exit
        peers(["--tf-static", str(s2), "--tf", str(dyn), "--rate", "50"], d)
        msg = await receive_where(
            statics, lambda m: m.transforms[0].transform.translation == Vector3(0.3, 0.0, 0.2)
        )
        while tf.statistics().queued:  # /tf resumes: a sample stamped after the restart
            tf.receive_nowait()
        restarted = msg.transforms[0].header.stamp
        await receive_where(tf, lambda m: m.transforms[0].header.stamp > restarted)


@pytest.mark.anyio
async def test_malformed_samples_beside_a_real_ros2_publisher(
    anyio_backend: str, peers: Callable[..., Peer], tmp_path: Path
) -> None:
    """rclpy publishes valid /tf and a stamp before 1970 (sec = -1, which ROS 2 allows
    and tfbus cannot hold); a raw DDS writer adds junk: the bad ones are counted and
    dropped, the rclpy stream keeps flowing."""
    d = new_domain()
    good = [ts("odom", "base_link", 5, 0, (1.0, 0.0, 0.0))]
    peers(["--publish", str(write_json(tmp_path / "g.json", good)), "--rate", "20"], d)
    bad = json.dumps([{**as_dict(good[0]), "child": "before_1970", "stamp": [-1, 0]}])
    (tmp_path / "b.json").write_text(bad)
    peers(["--publish", str(tmp_path / "b.json"), "--rate", "20"], d)
    transport = Ros2Transport(domain_id=d)
    async with Bus(transport=transport) as bus:
        tf = bus.subscribe("/tf")
        everything = bus.subscribe("/tf", queue_size=1_000_000)
        await receive_where(tf, lambda m: True)
        with anyio.fail_after(WAIT):
            while transport.statistics().malformed == 0:  # the sec = -1 samples
                await receive_where(tf, lambda m: True)
        writer = await anyio.to_thread.run_sync(RawWriter, d)
        try:
            with anyio.fail_after(WAIT):
                while transport.matched_publishers("/tf") < 3:
                    await receive_where(tf, lambda m: True)
            before = transport.statistics().malformed
            for junk in SEMANTIC[:2]:
                assert await writer.write(junk) == 0
            assert await writer.write(encode_tf([ts("odom", "marker")])) == 0
            await receive_where(tf, lambda m: m.transforms[0].child_frame_id == "marker")
            assert transport.statistics().malformed >= before + 2
            # the rclpy stream still flows after the junk
            await receive_where(tf, lambda m: m.transforms == tuple(good))
        finally:
            writer.close()
        delivered = [everything.receive_nowait() for _ in range(everything.statistics().queued)]
    assert everything.statistics().dropped == 0
    children = {x.child_frame_id for m in delivered for x in m.transforms}
    assert children == {"base_link", "marker"}  # never "before_1970", never junk


# -- the command line with --bus ros2 ------------------------------------------------------------


TFBUS = Path(sys.executable).parent / "tfbus"  # the console script of this venv


def tfbus_cmd(*args: str, domain: int) -> subprocess.Popen[str]:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED="1")
    env.pop("CYCLONEDDS_URI", None)
    return subprocess.Popen(
        [str(TFBUS), *args],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def finish(proc: subprocess.Popen[str], stop: bool = False) -> tuple[str, str]:
    if stop and proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        return proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
        raise AssertionError(f"tfbus did not finish in time: {out[-500:]} {err[-500:]}") from None


def tutorial_peer(peers: Callable[..., Peer], tmp_path: Path, d: int) -> Peer:
    dyn = write_json(tmp_path / "d.json", [ts("base_link", "base_laser", t=(0.1, 0.0, 0.2))])
    return peers(["--tf", str(dyn), "--rate", "100"], d)


def test_cli_demo_listener_over_ros2(peers: Callable[..., Peer], tmp_path: Path) -> None:
    d = new_domain()
    tutorial_peer(peers, tmp_path, d)
    proc = tfbus_cmd("demo", "listener", "--bus", f"ros2:domain={d}", "--duration", "12",
                     "--listen-rate", "2", domain=d)  # fmt: skip
    out, err = finish(proc)
    assert "base_laser: (1.00, 0.20. 0.00) -----> base_link: (1.10, 0.20, 0.20)" in out, err


def test_cli_demo_broadcaster_over_ros2(peers: Callable[..., Peer]) -> None:
    d = new_domain()
    echo = peers(["--echo"], d)
    proc = tfbus_cmd("demo", "broadcaster", "--bus", f"ros2:domain={d}", "--duration", "30",
                     domain=d)  # fmt: skip
    try:
        msg = echo.wait_message(lambda m: m["topic"] == "/tf")
    finally:
        finish(proc, stop=True)
    (x,) = msg["transforms"]
    assert (x["parent"], x["child"], x["t"], x["r"]) == (
        "base_link", "base_laser", [0.1, 0.0, 0.2], [0.0, 0.0, 0.0, 1.0]
    )  # fmt: skip


def test_cli_echo_over_ros2(peers: Callable[..., Peer], tmp_path: Path) -> None:
    d = new_domain()
    tutorial_peer(peers, tmp_path, d)
    out, err = finish(tfbus_cmd("echo", "base_link", "base_laser", "--bus", f"ros2:domain={d}",
                                "-n", "1", "--duration", "30", domain=d))  # fmt: skip
    assert "Translation: [0.100, 0.000, 0.200]" in out, err


def test_cli_monitor_over_ros2(peers: Callable[..., Peer], tmp_path: Path) -> None:
    d = new_domain()
    tutorial_peer(peers, tmp_path, d)
    out, err = finish(tfbus_cmd("monitor", "--bus", f"ros2:domain={d}", "--duration", "8",
                                domain=d))  # fmt: skip
    assert "base_laser" in out and "base_link" in out, err


def test_cli_frames_over_ros2(peers: Callable[..., Peer], tmp_path: Path) -> None:
    d = new_domain()
    tutorial_peer(peers, tmp_path, d)
    gv = tmp_path / "frames.gv"
    _, err = finish(tfbus_cmd("frames", "--bus", f"ros2:domain={d}", "--wait", "8",
                              "-o", str(gv), domain=d))  # fmt: skip
    assert gv.exists(), err
    assert re.search(r'"?base_link"?\s*->\s*"?base_laser"?', gv.read_text())


def test_cli_static_transform_over_ros2(peers: Callable[..., Peer]) -> None:
    d = new_domain()
    proc = tfbus_cmd("static-transform", "0.1", "0", "0.2", "0", "0", "0", "base_link",
                     "base_laser", "--bus", f"ros2:domain={d}", domain=d)  # fmt: skip
    try:
        echo = peers(["--echo"], d)  # a late subscriber: transient-local delivers it
        msg = echo.wait_message(lambda m: m["topic"] == "/tf_static")
    finally:
        finish(proc, stop=True)
    (x,) = msg["transforms"]
    assert (x["parent"], x["child"], x["t"], x["r"]) == (
        "base_link", "base_laser", [0.1, 0.0, 0.2], [0.0, 0.0, 0.0, 1.0]
    )  # fmt: skip


# -- simulated time: rosgraph_msgs/msg/Clock on rt/clock ------------------------------------------

CLOCK_PEER = PEERS / "clock_peer.py"


def test_clock_codec_against_cyclonedds() -> None:
    from cyclonedds.idl._support import Endianness

    clock = Clock(Time(123, 456_789))
    data = encode_clock(clock)
    # encapsulation CDR_LE, int32 sec, uint32 nanosec: 12 bytes, as rmw sends them
    assert data == b"\x00\x01\x00\x00" + _u32(123) + _u32(456_789)
    assert data == Clock_(Time_(123, 456_789)).serialize(endianness=Endianness.Little)
    big = Clock_(Time_(123, 456_789)).serialize(endianness=Endianness.Big)
    assert decode_clock(data) == decode_clock(big) == clock
    edge = Clock(Time(SEC_MAX, 999_999_999))
    assert decode_clock(encode_clock(edge)) == edge
    with pytest.raises(WireEncodeError, match=r"Clock\.clock: sec=2147483648"):
        encode_clock(Clock(Time(SEC_MAX + 1)))
    with pytest.raises(WireEncodeError, match="must be a Time"):
        encode_clock("junk")  # type: ignore[arg-type]
    bad = {
        "short": data[:11],
        "xcdr2 delimited": b"\x00\x09\x00\x00" + data[4:],
        "negative sec": data[:4] + (-1).to_bytes(4, "little", signed=True) + data[8:],
        "nanosec 1e9": data[:8] + _u32(1_000_000_000),
    }
    for name, junk in bad.items():
        with pytest.raises(WireDecodeError):
            decode_clock(junk)
        assert name  # every case raised WireDecodeError only


def test_clock_topic_option() -> None:
    assert Ros2Transport(domain_id=1).clock_topic is None  # off by default
    assert dds_topic_name("/clock") == "rt/clock"  # rmw's "rt" prefix
    assert dds_topic_name("/sim_1/clock") == "rt/sim_1/clock"
    t = open_transport("ros2:domain=3", clock_topic="/clock")
    assert isinstance(t, Ros2Transport) and t.clock_topic == "/clock"
    with pytest.raises(ValueError, match="clock_topic '/tf' is already carried"):
        Ros2Transport(clock_topic="/tf")
    with pytest.raises(ValueError, match="clock_topic: topic 'clock' is not a global ROS"):
        Ros2Transport(clock_topic="clock")
    with pytest.raises(ValueError, match="clock_topic: topic '/sim//clock' is not a global"):
        Ros2Transport(clock_topic="/sim//clock")
    with pytest.raises(TypeError, match="unexpected ros2 transport override"):
        open_transport("ros2", clock="/clock")
    t = Ros2Transport(domain_id=1, clock_topic="/clock")
    t.send_nowait("/clock", Clock(Time(5)))  # not running: counted, not sent
    with pytest.raises(WireEncodeError, match="must be a Time"):
        t.send_nowait("/clock", TFMessage(()))
    plain = Ros2Transport(domain_id=1)
    plain.send_nowait("/clock", Clock(Time(5)))  # not carried without clock_topic
    assert t.statistics().not_connected == 1 and t.statistics().send_errors == 1
    assert plain.statistics().not_mapped == 1
    with pytest.raises(ValueError, match="'/clock' is not received"):
        plain.matched_publishers("/clock")


@pytest.mark.anyio
async def test_tfbus_clock_to_a_tfbus_sim_clock_with_malformed_samples(anyio_backend: str) -> None:
    """tfbus publishes Clock on one transport, a SimClock on another follows it over DDS;
    a raw writer's samples that are valid CDR but no tfbus Clock (a negative sec, a
    nanosec of 1e9) are counted in ``malformed`` and dropped, the valid ones kept."""
    d = new_domain()
    a_t = Ros2Transport(domain_id=d, clock_topic="/clock")
    b_t = Ros2Transport(domain_id=d, clock_topic="/clock")
    async with Bus(transport=a_t) as a, Bus(transport=b_t) as b, SimClock(b) as clock:
        assert clock.now() == Time(0)
        with anyio.fail_after(WAIT):
            while clock.now() != Time(42, 5):  # best effort, volatile: until matched
                a.publish_nowait("/clock", Clock(Time(42, 5)))
                with anyio.move_on_after(0.1):
                    await clock.sleep_until(Time(42, 5))
        writer = await anyio.to_thread.run_sync(RawWriter, d, "clock")
        try:
            with anyio.fail_after(WAIT):
                while b_t.matched_publishers("/clock") < 2:
                    await anyio.sleep(0.01)  # polling a bounded condition, not a fixed wait
            good = encode_clock(Clock(Time(50)))
            for junk in (good[:4] + (-1).to_bytes(4, "little", signed=True) + good[8:],
                         good[:8] + _u32(1_000_000_000)):  # fmt: skip
                before = b_t.statistics().malformed
                with anyio.fail_after(WAIT):
                    while b_t.statistics().malformed == before:  # best effort: resend
                        assert await writer.write(junk) == 0
                        await anyio.sleep(0.01)
            with anyio.fail_after(WAIT):
                while clock.now() != Time(50):
                    assert await writer.write(good) == 0
                    with anyio.move_on_after(0.1):
                        await clock.sleep_until(Time(50))
        finally:
            writer.close()
    assert clock.dropped == 0 and clock.jumps == 0  # the junk never reached the bus
    stats = b_t.statistics()
    assert stats.malformed >= 2
    assert stats.delivered + stats.coalesced + stats.kept == stats.received - stats.malformed
    assert a_t.statistics().sent >= 1 and a_t.statistics().send_errors == 0


@pytest.mark.anyio
async def test_sim_clock_follows_dds_clock_newest_only(anyio_backend: str) -> None:
    """A SimClock on the ROS 2 transport follows /clock newest-only
    (Ros2Transport.keep_newest): 300 samples sent back to back, stamps 1 ms apart, reach
    the event loop only when due (the first, the sleeper's deadline, every 10 ms), the
    rest counted in ``coalesced``; the clock ends at the last stamp; a step back is
    delivered at once and counted as one jump."""
    d = new_domain()
    a_t = Ros2Transport(domain_id=d, clock_topic="/clock")
    b_t = Ros2Transport(domain_id=d, clock_topic="/clock")
    async with Bus(transport=a_t) as a, Bus(transport=b_t) as b, SimClock(b) as clock:
        with anyio.fail_after(WAIT):
            while clock.now() != Time(100):  # best effort, volatile: until matched
                a.publish_nowait("/clock", Clock(Time(100)))
                with anyio.move_on_after(0.1):
                    await clock.sleep_until(Time(100))
        received0, coalesced0 = b_t.statistics().received, b_t.statistics().coalesced
        seen0 = clock.received
        last = Time(100) + Duration.from_sec(0.3)
        async with anyio.create_task_group() as tg:
            tg.start_soon(clock.sleep_until, last)
            await anyio.sleep(0)  # the deadline is filed before the samples are sent
            for k in range(1, 301):
                a.publish_nowait("/clock", Clock(Time.from_ns(Time(100).ns + k * 1_000_000)))
            with anyio.fail_after(WAIT):
                while clock.now() != last:  # best effort: the last one again until heard
                    a.publish_nowait("/clock", Clock(last))
                    with anyio.move_on_after(0.1):
                        await clock.sleep_until(last)
        stats = b_t.statistics()
        taken = stats.received - received0
        seen = clock.received - seen0
        assert 1 <= seen < taken  # the loop saw fewer samples than Cyclone delivered
        assert stats.coalesced - coalesced0 == taken - seen
        assert stats.delivered + stats.coalesced == stats.received - stats.malformed
        assert clock.jumps == 0 and clock.dropped == 0
        with anyio.fail_after(WAIT):
            while clock.jumps == 0:  # a step back reaches the loop at once
                a.publish_nowait("/clock", Clock(Time(50)))
                await anyio.sleep(0.01)  # polling a bounded condition, not a fixed wait
        assert clock.now() == Time(50) and clock.jumps == 1


@pytest.mark.anyio
async def test_sim_clock_reads_the_newest_dds_clock_kept(anyio_backend: str) -> None:
    """On the ROS 2 transport, with no deadline filed and no other listener of /clock,
    a SimClock's ``now()`` reads the newest stamp Cyclone's thread kept, with no
    delivery to the event loop (``kept`` in the statistics); a jump back delivered makes
    the stamps kept before it no longer the time."""
    d = new_domain()
    a_t = Ros2Transport(domain_id=d, clock_topic="/clock")
    b_t = Ros2Transport(domain_id=d, clock_topic="/clock")
    async with Bus(transport=a_t) as a, Bus(transport=b_t) as b, SimClock(b) as clock:

        async def publish_until_now(t: Time) -> None:
            with anyio.fail_after(WAIT):
                while clock.now() != t:  # best effort, volatile: until heard
                    a.publish_nowait("/clock", Clock(t))
                    await anyio.sleep(0.01)  # polling a bounded condition

        await publish_until_now(Time(100))
        seen = clock.received
        for sec in range(101, 111):
            await publish_until_now(Time(sec))
        # not one per /clock nor one per 10 ms (ten or more); a wake-up of the loop for
        # other DDS data also hands it the /clock kept
        assert clock.received - seen < 5
        await publish_until_now(Time(50))  # a jump back: delivered at once
        assert clock.jumps == 1
        await publish_until_now(Time(60))  # before the 110 s kept earlier: the time
        assert clock.now() == Time(60) and clock.jumps == 1 and clock.dropped == 0


@pytest.mark.anyio
async def test_rclpy_simulator_drives_a_tfbus_sim_clock(
    anyio_backend: str, peers: Callable[..., Peer], tmp_path: Path
) -> None:
    """An rclpy "simulator" publishes /clock at 10x real time from 100 s (a step of 0.1
    simulated seconds every 10 ms) and /tf stamped with it: a SimClock on the ROS 2
    transport follows it, a lookup at clock.now() answers the broadcast values, and a
    sleep of one simulated second ends after about 0.1 s of wall time."""
    d = new_domain()
    dyn = write_json(tmp_path / "d.json", [ts("base_link", "base_laser", t=(0.1, 0.0, 0.2))])
    peers(["--simulate", "100", "--factor", "10", "--tf", str(dyn)], d, script=CLOCK_PEER)
    transport = Ros2Transport(domain_id=d, clock_topic="/clock")
    async with Bus(transport=transport) as bus, SimClock(bus) as clock:
        buffer = Buffer(clock=clock)
        async with TransformListener(buffer, bus, clock=clock):
            with anyio.fail_after(WAIT):  # wall-time bound: DDS discovery, then /clock
                await clock.sleep_until(Time(100))
            start = clock.now()
            assert start >= Time(100) and start.ns % 100_000_000 == 0  # a simulator step
            wall = time.monotonic()
            with anyio.fail_after(WAIT):
                await clock.sleep(1.0)  # one simulated second
            wall = time.monotonic() - wall
            now = clock.now()
            assert Duration(1) <= now - start < Duration(30) and now.ns % 100_000_000 == 0
            with anyio.fail_after(WAIT):  # 300 simulated seconds: ~30 s of wall time
                got = await buffer.lookup_transform_async("base_link", "base_laser", now,
                                                          timeout=300.0)  # fmt: skip
    assert got.header == Header(now, "base_link") and got.child_frame_id == "base_laser"
    assert got.transform == Transform(Vector3(0.1, 0.0, 0.2), Quaternion(0.0, 0.0, 0.0, 1.0))
    assert wall < WAIT  # ~0.1 s at 10x; bounded only (no timing assertion)
    assert clock.dropped == 0 and clock.jumps == 0
    # the loop was given /clock at its deadlines; the transport took every step
    stats = transport.statistics()
    assert stats.malformed == 0 and stats.received >= 10 and clock.accepted >= 2


@pytest.mark.anyio
async def test_tfbus_clock_drives_an_rclpy_node_with_use_sim_time(
    anyio_backend: str, peers: Callable[..., Peer]
) -> None:
    """tfbus publishes Clock on /clock: an rclpy node with use_sim_time follows it (its
    get_clock().now() takes each value, a step back included, as rclpy's TimeSource)."""
    d = new_domain()
    follower = peers(["--follow"], d, script=CLOCK_PEER)
    transport = Ros2Transport(domain_id=d, clock_topic="/clock")
    current = [Clock(Time(42, 5))]

    async def publish_until_stopped(bus: Bus) -> None:
        while True:  # best effort, volatile: a late subscriber needs repeated messages
            bus.publish_nowait("/clock", current[0])
            await anyio.sleep(0.05)

    seen: list[list[int]] = []
    async with Bus(transport=transport) as bus, anyio.create_task_group() as tg:
        tg.start_soon(publish_until_stopped, bus)
        for clock, expected in ((Time(42, 5), [42, 5]), (Time(43, 500_000_000), [43, 500_000_000]),
                                (Time(7), [7, 0])):  # fmt: skip
            current[0] = Clock(clock)
            msg = await follower.await_message(lambda m, e=expected: m["now"] == e)
            seen.append(msg["now"])
        tg.cancel_scope.cancel()
    assert seen == [[42, 5], [43, 500_000_000], [7, 0]]
    assert transport.statistics().send_errors == 0
