"""``tfbus web`` as a command: a bag served (its first transform reaches a client), SIGTERM
ends it with status 0 and no traceback, bad options are one line and status 2."""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import anyio
import pytest
from web_support import BOUND, RawClient

from tfbus.bag.reader import read_messages
from tfbus.web.rosbridge import transform_from_json

pytestmark = pytest.mark.anyio

ROOT = Path(__file__).resolve().parents[2]
TURTLE = ROOT / "tests" / "data" / "webviz_turtle_tf_example.bag"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


async def test_bag_served_until_sigterm() -> None:
    argv = [sys.executable, "-m", "tfbus.cli", "web", "--bag", str(TURTLE), "--port", "0"]
    proc = await anyio.open_process(argv, env=ENV)
    try:
        assert proc.stderr is not None
        err = b""
        with anyio.move_on_after(BOUND):
            while b"ws://" not in err or not err.endswith(b"\n"):
                err += await proc.stderr.receive()
        line = err.decode().strip()
        assert line.startswith("tfbus web: ws://127.0.0.1:"), line
        port = int(line.rsplit(":", 1)[1].strip("/"))
        async with RawClient.connect(port) as c:
            await c.send({"op": "subscribe", "topic": "/tf"})
            m = await c.receive_until(lambda m: m.get("topic") == "/tf")
            got = transform_from_json(m["msg"]["transforms"][0])
        # one of the bag's transforms, exactly (which one: where the replay is now)
        assert got in {t for bm in read_messages(TURTLE) for t in bm.message.transforms}
        assert got.header.frame_id == "world"
        assert got.child_frame_id in ("turtle1", "turtle2")
        proc.send_signal(signal.SIGTERM)  # the process this test started
        with anyio.fail_after(BOUND):
            code = await proc.wait()
            rest = b"".join([chunk async for chunk in proc.stderr])
        assert code == 0, rest
        assert b"Traceback" not in rest
    finally:
        if proc.returncode is None:
            proc.kill()
        with anyio.CancelScope(shield=True), anyio.move_on_after(BOUND):
            await proc.aclose()


@pytest.mark.parametrize(("args", "needle"), [
    (["--bag", str(TURTLE), "--bus", "memory"], "give --bag PATH or --bus SPEC, not both"),
    (["--token", "a b"], "--token: token must be"),
    (["--port", "70000"], "70000"),
])
async def test_bad_options_one_line_status_2(args: list[str], needle: str) -> None:
    out = await anyio.run_process([sys.executable, "-m", "tfbus.cli", "web", *args],
                                  env=ENV, check=False)
    err = out.stderr.decode()
    assert out.returncode == 2, err
    assert needle in err and "Traceback" not in err


async def test_port_in_use_one_line() -> None:
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    async with listener:
        port = listener.extra(anyio.abc.SocketAttribute.local_port)
        out = await anyio.run_process([sys.executable, "-m", "tfbus.cli", "web", "--bag",
                                       str(TURTLE), "--port", str(port)], env=ENV,
                                      check=False)
    err = out.stderr.decode()
    assert out.returncode == 2 and f"cannot serve on 127.0.0.1:{port}" in err, err
    assert len(err.strip().splitlines()) <= 2 and "Traceback" not in err


async def test_help_has_examples() -> None:
    out = await anyio.run_process([sys.executable, "-m", "tfbus.cli", "web", "--help"],
                                  env=ENV)
    text = out.stdout.decode()
    assert "Examples:" in text and "tfbus web --bus zenoh --port 9090" in text
