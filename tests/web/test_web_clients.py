"""``tfbus web`` with the real clients web robot apps use: npm's ``roslib`` 2.x in Node
(``TFClient``: tf2_web_republisher's TFSubscription goal over actionlib topics;
``ROS2TFClient``: the ROS 2 action ops) and PyPI's ``roslibpy`` (``TFClient``: the
``republish_tfs`` service, then its topic), each in its own process, receiving a bus's
transforms with their thresholds and rate honoured; a client's disconnect and a slow
client harming no other. Installed by scripts/install/install_roslibjs.sh and
install_roslibpy.sh (tests/peer_install.py: under CI a missing peer fails)."""

from __future__ import annotations

import os
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import anyio
import pytest
from peer_install import require
from web_support import BOUND, Lines, RawClient, Served, served, ts

from tfbus.messages import TFMessage

pytestmark = pytest.mark.anyio

HERE = Path(__file__).resolve().parent
CLIENTS = ("roslibpy", "roslibjs-ros1", "roslibjs-ros2")


def _ready_dir(line: str) -> str:
    return line.split("(", 1)[1].split(",", 1)[0].rstrip(")")


@asynccontextmanager
async def tf_client(kind: str, port: int, *, fixed: str = "world", angular: float = 0.1,
                    trans: float = 0.01, rate: float = 20.0,
                    frames: tuple[str, ...] = ("base_link",)) -> AsyncIterator[Lines]:
    """One real TF client subscribed to ``frames`` (its output: :class:`Lines`)."""
    args = [fixed, str(angular), str(trans), str(rate), *frames]
    env = dict(os.environ)
    if kind == "roslibpy":
        env["PYTHONPATH"] = _ready_dir(require("roslibpy", "install_roslibpy.sh"))
        argv = [sys.executable, str(HERE / "roslibpy_tf_client.py"), str(port), *args]
    else:
        env["ROSLIB_DIR"] = _ready_dir(require("roslibjs", "install_roslibjs.sh"))
        argv = ["node", str(HERE / "roslibjs_tf_client.mjs"), f"ws://127.0.0.1:{port}",
                kind.rsplit("-", 1)[1], *args]
    async with Lines.run(argv, env) as lines:
        yield lines


async def _steps(w: Served, lines: Lines, xs: list[float], final: float) -> None:
    """Publish each x, waiting after each for the client's republisher to look it up,
    then ``final``, waiting for the client to print it."""
    (rep,) = await w.until(w.republishers)
    for x in xs:
        w.move(x)
        await w.next_tick(rep)
    w.move(final)
    await lines.wait_for(lambda _: final in lines.xs())


@pytest.mark.parametrize("kind", CLIENTS)
async def test_client_gets_transforms_with_trans_threshold(kind: str) -> None:
    async with served() as w:
        w.move(0.0)
        async with tf_client(kind, w.server.port, trans=0.01, rate=20.0) as lines:
            await lines.wait_for(lambda _: lines.xs() == [0.0])
            await _steps(w, lines, [0.004 * i for i in range(1, 10)], 1.0)
            # 4 mm steps against 1 cm: only moves over 1 cm from the last sent are sent
            assert lines.xs() == [0.0, 0.012, 0.024, 0.036, 1.0]
            last = lines.transforms()[-1]
            assert last["rotation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
            assert last["translation"] == {"x": 1.0, "y": 0.0, "z": 0.0}


@pytest.mark.parametrize("kind", CLIENTS)
async def test_client_gets_transforms_with_angular_threshold(kind: str) -> None:
    async with served() as w:
        w.move(0.0)
        async with tf_client(kind, w.server.port, angular=0.1, trans=10.0) as lines:
            await lines.wait_for(lambda _: len(lines.transforms()) == 1)
            (rep,) = await w.until(w.republishers)
            # tf's Quaternion::angle is half the turn: 0.15 rad is 0.075 < 0.1, not sent;
            # 0.25 rad is 0.125 > 0.1, sent
            for yaw in (0.15, 0.25):
                w.move(0.0, yaw=yaw)
                await w.next_tick(rep)
            w.move(20.0, yaw=0.25)  # over trans_thres: sent
            await lines.wait_for(lambda _: 20.0 in lines.xs())
            zs = [round(t["rotation"]["z"], 6) for t in lines.transforms()]
            assert zs == [0.0, round(0.1246747333852277, 6), round(0.1246747333852277, 6)]
            assert lines.xs() == [0.0, 0.0, 20.0]


@pytest.mark.parametrize("kind", CLIENTS)
async def test_client_rate_is_honoured(kind: str) -> None:
    async with served() as w:
        w.move(0.0)
        async with tf_client(kind, w.server.port, trans=0.0, rate=4.0) as lines:
            await lines.wait_for(lambda _: len(lines.transforms()) == 1)
            start, x = anyio.current_time(), 0.0
            while anyio.current_time() - start < 2.0:  # moving at 100 Hz for 2 s
                x += 0.5
                w.move(x)
                await anyio.sleep(0.01)
            elapsed = anyio.current_time() - start
            (rep,) = w.republishers()
            await w.next_tick(rep)
            w.move(1000.0)
            await lines.wait_for(lambda _: 1000.0 in lines.xs())
            elapsed_all = anyio.current_time() - start
            got = len(lines.transforms()) - 2  # the first and the last
            # at most `rate` per second of the window (+1 for its ends), at least one
            assert 1 <= got <= 4.0 * elapsed_all + 1, (got, elapsed, elapsed_all)
            assert got < 100  # 200 moves were published


async def test_a_client_disconnect_and_a_slow_client_harm_no_other() -> None:
    async with served(queue_size=8, send_timeout=5.0) as w:
        w.move(0.0)
        async with tf_client("roslibjs-ros1", w.server.port, trans=0.0) as js:
            await js.wait_for(lambda _: js.xs() == [0.0])
            async with RawClient.connect(w.server.port) as slow:
                await slow.send({"op": "subscribe", "topic": "/tf"})
                await w.until(lambda: any("/tf" in c.session.subscriptions
                                          for c in w.server.clients))
                async with tf_client("roslibpy", w.server.port, trans=0.0) as py:
                    await py.wait_for(lambda _: py.xs() == [0.0])
                    py.process.kill()  # roslibpy's process dies mid-session
                    await w.until(lambda: len(w.server.clients) == 2)
                names = [f"frame_{i:04d}_" + "x" * 200 for i in range(300)]
                for i in range(1, 60):  # ~30 MB of /tf for a client that never reads
                    w.stamp += 1_000_000
                    w.bus.publish_nowait("/tf", TFMessage(
                        [ts(float(i), w.stamp, child=n) for n in names]))
                    w.move(float(i))
                    if i % 10 == 0:
                        await js.wait_for(lambda _, i=i: float(i) in js.xs())
                await js.wait_for(lambda _: 59.0 in js.xs())
                await w.until(lambda: w.server.slow == 1 or w.server.dropped + sum(
                    c.dropped for c in w.server.clients) > 0)
            xs = js.xs()
            assert xs[0] == 0.0 and xs[-1] == 59.0 and xs == sorted(xs)
            assert w.server.errors == 0
        await w.until(lambda: not w.server.clients, BOUND)
