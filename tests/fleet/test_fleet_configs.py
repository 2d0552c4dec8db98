"""The JSON5 configurations of docs/fleet.md: every block loads in Zenoh, and the router,
client and peer ones run (on 127.0.0.1, a free port in place of the documented one)."""

from __future__ import annotations

import re
import socket
from pathlib import Path

import anyio
import pytest

zenoh = pytest.importorskip("zenoh")

from tfbus.buffer import Buffer  # noqa: E402
from tfbus.bus import Bus  # noqa: E402
from tfbus.listener import TransformListener  # noqa: E402
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3  # noqa: E402
from tfbus.time import Time  # noqa: E402
from tfbus.transports.zenoh import ZenohTransport  # noqa: E402
from tfbus.transports.zenoh.router import ZenohRouter  # noqa: E402

PAGE = Path(__file__).resolve().parents[2] / "docs" / "fleet.md"
pytestmark = pytest.mark.anyio


def blocks() -> list[str]:
    text = PAGE.read_text(encoding="utf-8")
    section = text.split("## Zenoh configuration files", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```json5\n(.*?)```", section, flags=re.S)


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_every_block_loads_in_zenoh() -> None:
    found = blocks()
    assert len(found) == 4
    modes = []
    for block in found:
        config = zenoh.Config.from_json5(block)
        modes.append(config.get_json("mode"))
    assert modes == ['"router"', '"client"', '"peer"', '"router"']
    tls = zenoh.Config.from_json5(found[3])
    assert tls.get_json("access_control/default_permission") == '"deny"'


async def test_router_client_and_peer_configs_run(tmp_path: Path) -> None:
    router_block, client_block, peer_block, _tls = blocks()
    port, peer_port = free_port(), free_port()
    files = {}
    for name, block in (("router", router_block), ("robot", client_block),
                        ("peer", peer_block)):
        path = tmp_path / f"{name}.json5"
        path.write_text(block.replace(":7447", f":{port}").replace(":7448", f":{peer_port}"),
                        encoding="utf-8")
        files[name] = str(path)
    laser = TransformStamped(Header(Time(0), "base"), "laser",
                             Transform(Vector3(0.5, 0.0, 0.0), Quaternion()))
    buffer = Buffer()
    async with ZenohRouter(config=files["router"]) as router:
        assert router.endpoints == [f"tcp/127.0.0.1:{port}"]
        async with Bus(transport=ZenohTransport(config=files["robot"], namespace="robot7")) \
                as robot, Bus(transport=ZenohTransport(config=files["robot"],
                                                       namespace="robot7")) as viewer, \
                TransformListener(buffer, viewer):
            robot.publish_nowait("/tf_static", TFMessage([laser]))
            t = await buffer.lookup_transform_async("base", "laser", Time(0), timeout=20.0)
            assert t.transform.translation.x == 0.5
    peer = ZenohTransport(config=files["peer"])
    async with Bus(transport=peer):
        assert peer.running
        with anyio.fail_after(5):
            assert peer.session is not None
