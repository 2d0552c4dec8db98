"""A real ``tfbus web --bag`` process while real clients leave with a close handshake as
transforms flow: roslibpy (``Ros.close()``), npm roslib in Node (``Ros.close()``, as a
browser tab closing), raw WebSocket clients (a Close frame, then the TCP close), and one
aborting (RST). A raw client that stays subscribed keeps getting ``/tf`` throughout;
Ctrl-C (SIGINT) then ends the server with status 0 and no traceback."""

from __future__ import annotations

import os
import signal
import socket
import struct
import sys
from pathlib import Path

import anyio
import pytest
from peer_install import require
from web_support import BOUND, Lines, RawClient
from wsproto.events import CloseConnection

pytestmark = pytest.mark.anyio

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
TURTLE = ROOT / "tests" / "data" / "webviz_turtle_tf_example.bag"


def _ready_dir(line: str) -> str:
    return line.split("(", 1)[1].split(",", 1)[0].rstrip(")")


async def _tf(keeper: RawClient) -> None:
    await keeper.receive_until(lambda m: m.get("topic") == "/tf")


async def _raw_leaver(port: int, how: str) -> None:
    async with RawClient.connect(port) as c:
        await c.send({"op": "subscribe", "topic": "/tf"})
        await c.receive_until(lambda m: m.get("topic") == "/tf")
        if how == "abort":
            sock = c.stream.extra(anyio.abc.SocketAttribute.raw_socket)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            return
        await c.stream.send(c.ws.send(CloseConnection(code=1000)))
        with anyio.fail_after(BOUND):
            while not c.closed:
                try:
                    await c.receive(BOUND)
                except anyio.EndOfStream:
                    break


async def test_real_clients_leaving_mid_stream_leave_tfbus_web_serving() -> None:
    argv = [sys.executable, "-m", "tfbus.cli", "web", "--bag", str(TURTLE), "--port", "0"]
    proc = await anyio.open_process(argv, env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert proc.stderr is not None
        err = b""
        with anyio.fail_after(BOUND):
            while b"ws://" not in err or not err.endswith(b"\n"):
                err += await proc.stderr.receive()
        port = int(err.decode().strip().rsplit(":", 1)[1].strip("/"))
        async with RawClient.connect(port) as keeper:
            await keeper.send({"op": "subscribe", "topic": "/tf"})
            await _tf(keeper)
            async with anyio.create_task_group() as tg:
                for k in range(20):
                    tg.start_soon(_raw_leaver, port, "abort" if k % 5 == 0 else "close")
            await _tf(keeper)
            env = {**os.environ,
                   "PYTHONPATH": _ready_dir(require("roslibpy", "install_roslibpy.sh"))}
            async with Lines.run([sys.executable, str(HERE / "roslibpy_leaving_client.py"),
                                  str(port), "10"], env) as py:
                await py.wait_for(lambda lines: "left 10" in lines)
            await _tf(keeper)
            env = {**os.environ,
                   "ROSLIB_DIR": _ready_dir(require("roslibjs", "install_roslibjs.sh"))}
            async with Lines.run(["node", str(HERE / "roslibjs_leaving_client.mjs"),
                                  f"ws://127.0.0.1:{port}", "20"], env) as js:
                await js.wait_for(lambda lines: "left 20" in lines)
            for _ in range(3):  # still served after every client left
                await _tf(keeper)
        assert proc.returncode is None, "tfbus web ended while clients left"
        proc.send_signal(signal.SIGINT)  # the process this test started
        with anyio.fail_after(BOUND):
            code = await proc.wait()
            rest = b"".join([chunk async for chunk in proc.stderr])
        assert code == 0, rest
        assert b"Traceback" not in rest and b"LocalProtocolError" not in rest, rest
    finally:
        if proc.returncode is None:
            proc.kill()
        with anyio.CancelScope(shield=True), anyio.move_on_after(BOUND):
            await proc.aclose()
