"""tfbus's rmw_zenoh transport against an independent implementation of the wire:
ROBOTIS' ``zenoh-ros2-sdk`` (PyPI), run as ``peers/rmw_zenoh/sdk_peer.py`` in its own venv
(``scripts/install/install_zenoh_ros2_sdk.sh``), through a Zenoh router on 127.0.0.1.

Both directions, ``/tf`` and ``/tf_static``, values exact. The SDK computes the type hash
from the message definitions in ``peers/rmw_zenoh/msg/`` itself, builds its keys and
tokens its own way, and puts its own attachment (sequence from 0: tfbus reads any int64).
The SDK's static publisher is a plain Zenoh publisher (no cache), so tfbus hears its
``/tf_static`` live; the SDK's TRANSIENT_LOCAL subscriber asks tfbus's AdvancedPublisher
cache (``<key>/@adv/pub/<zid>/**``), so it gets tfbus's statics late. Every wait is bounded
(output lines read with a deadline; no sleeps).
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import pytest

pytest.importorskip("zenoh")

from peer_install import require

from tfbus.bus import Bus
from tfbus.messages import (
    Header,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import Time
from tfbus.transports.rmw_zenoh import RmwZenohTransport
from tfbus.transports.rmw_zenoh.wire import decode_attachment
from tfbus.transports.zenoh.router import ZenohRouter

pytestmark = pytest.mark.anyio

ROOT = Path(__file__).resolve().parents[2]
PEER = ROOT / "peers" / "rmw_zenoh" / "sdk_peer.py"


def sdk_python() -> Path:
    line = require("zenoh-ros2-sdk", "install_zenoh_ros2_sdk.sh", timeout=900)
    venv = Path(line.split("(", 1)[1].split(",", 1)[0].rstrip(")"))
    return venv / "bin" / "python"


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Peer:
    """The SDK peer process: its stdout read line by line with a deadline."""

    def __init__(self, process: anyio.abc.Process) -> None:
        self.process = process
        self.buffer = b""
        self.skipped: list[str] = []  # lines passed over by expect(), read by line() first

    async def line(self, timeout: float = 30.0) -> str:
        if self.skipped:
            return self.skipped.pop(0)
        assert self.process.stdout is not None
        with anyio.fail_after(timeout):
            while b"\n" not in self.buffer:
                chunk = await self.process.stdout.receive()
                self.buffer += chunk
        raw, self.buffer = self.buffer.split(b"\n", 1)
        return raw.decode()

    async def expect(self, prefix: str, timeout: float = 30.0) -> str:
        """The next line starting with ``prefix``; the lines before it are kept."""
        passed: list[str] = []
        with anyio.fail_after(timeout):
            while True:
                text = await self.line(timeout)
                if text.startswith(prefix):
                    self.skipped = passed + self.skipped
                    return text
                passed.append(text)

    async def send(self, text: str) -> None:
        assert self.process.stdin is not None
        await self.process.stdin.send(text.encode())


@asynccontextmanager
async def sdk(port: int, *args: str) -> AsyncIterator[Peer]:
    python = sdk_python()
    env = dict(os.environ, HOME=str(python.parents[1] / "home"), PYTHONPATH="")
    process = await anyio.open_process([str(python), str(PEER), str(port), *args], env=env,
                                       stderr=subprocess.DEVNULL)
    try:
        peer = Peer(process)
        await peer.expect("ready")
        yield peer
    finally:
        with anyio.CancelScope(shield=True):
            if process.stdin is not None:
                await process.stdin.aclose()
            with anyio.move_on_after(15):
                await process.wait()
            if process.returncode is None:
                process.kill()
                await process.wait()


def ts(parent: str, child: str, sec: int, x: float) -> TransformStamped:
    return TransformStamped(Header(Time(sec, 375), parent), child,
                            Transform(Vector3(x, 4.5, -0.25), Quaternion(0.0, 0.0, 0.8, 0.6)))


def as_json(topic: str, t: TransformStamped) -> dict[str, Any]:
    tr, q = t.transform.translation, t.transform.rotation
    return {"topic": topic, "frame_id": t.header.frame_id, "child_frame_id": t.child_frame_id,
            "sec": t.header.stamp.sec, "nanosec": t.header.stamp.nanosec,
            "t": [tr.x, tr.y, tr.z], "q": [q.x, q.y, q.z, q.w]}


def test_sdk_computes_rosidls_type_hash() -> None:
    out = subprocess.run([str(sdk_python()), str(PEER), "0", "hash"], capture_output=True,
                         text=True, timeout=120, check=True)
    assert out.stdout.strip().splitlines()[-1] == (
        "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087")


async def test_tfbus_to_sdk_tf_and_late_tf_static() -> None:
    """tfbus publishes /tf_static first; the SDK's listener, started later, gets it from
    the AdvancedPublisher's cache; then /tf live."""
    port = free_port()
    static = TFMessage((ts("base_link", "laser", 21, 0.75), ts("base_link", "imu", 21, -0.5)))
    async with ZenohRouter(listen=f"tcp/127.0.0.1:{port}"):
        t = RmwZenohTransport(connect=f"tcp/127.0.0.1:{port}", name="tfbus_talker",
                              connect_timeout=20.0)
        async with Bus(transport=t) as bus:
            bus.publish_nowait("/tf_static", static)
            async with sdk(port, "sub") as peer:
                got: list[dict[str, Any]] = []
                want_static = [as_json("/tf_static", x) for x in static.transforms]
                while len(got) < 2:
                    got.append(json.loads(await peer.line()))
                assert sorted(got, key=str) == sorted(want_static, key=str)
                dynamic = TFMessage((ts("odom", "base_link", 22, 1.5),))
                with anyio.fail_after(30):
                    while True:  # the SDK's live route may come up after its ready line
                        bus.publish_nowait("/tf", dynamic)
                        with anyio.move_on_after(0.3):
                            line = json.loads(await peer.line())
                            while line["topic"] != "/tf":  # a repeated static, if any
                                line = json.loads(await peer.line())
                            break
                assert line == as_json("/tf", dynamic.transforms[0])


async def test_sdk_to_tfbus_tf_and_tf_static() -> None:
    port = free_port()
    async with ZenohRouter(listen=f"tcp/127.0.0.1:{port}"):
        t = RmwZenohTransport(connect=f"tcp/127.0.0.1:{port}", name="tfbus_listener",
                              connect_timeout=20.0)
        async with Bus(transport=t) as bus, bus.subscribe("/tf") as tf_sub, \
                bus.subscribe("/tf_static") as static_sub, \
                sdk(port, "pub", "wheel", "2.25") as peer:
            with anyio.fail_after(30):
                while True:
                    await peer.send("\n")
                    await peer.expect("sent")
                    with anyio.move_on_after(0.3):
                        got = await tf_sub.receive()
                        break
            with anyio.fail_after(30):
                static = await static_sub.receive()
            # the SDK declares a node token per publisher, both named sdk_talker
            with anyio.fail_after(30):
                while {t for p in t.broadcasters().values() if p.name == "sdk_talker"
                       for t in p.topics} != {"/tf", "/tf_static"}:
                    await anyio.sleep(0.05)
    rotation = Quaternion(0.0, 0.6, 0.0, 0.8)
    assert got == TFMessage((TransformStamped(
        Header(Time(12, 125), "odom"), "wheel",
        Transform(Vector3(2.25, -0.5, 2.0), rotation)),))
    assert static == TFMessage((TransformStamped(
        Header(Time(11, 125), "base_link"), "wheel_static",
        Transform(Vector3(-2.25, -0.5, 2.0), rotation)),))
    stats = t.statistics()
    assert stats.no_attachment == stats.bad_attachment == stats.malformed == 0


async def test_sdk_attachment_is_the_positional_form() -> None:
    """The SDK's own attachment bytes read as the 33-byte form."""
    port = free_port()
    async with ZenohRouter(listen=f"tcp/127.0.0.1:{port}"), sdk(port, "pub", "w", "1") as peer:
        line = await peer.expect("attachment ")
    raw = bytes.fromhex(line.split()[1])
    assert len(raw) == 33
    att = decode_attachment(raw)
    assert (att.sequence_number, att.source_timestamp, len(att.gid)) == (0, 0, 16)
