"""The trio WebSocket recipe (examples/trio_websocket_server.py) on 127.0.0.1 with a real
trio-websocket client (trio only: trio-websocket is a trio library)."""

from __future__ import annotations

import json

import pytest

trio = pytest.importorskip("trio")
trio_websocket = pytest.importorskip("trio_websocket")

from examples.trio_websocket_server import serve  # noqa: E402


async def _ask(ws: object, **request: object) -> dict[str, object]:
    await ws.send_message(json.dumps(request))  # type: ignore[attr-defined]
    return json.loads(await ws.get_message())  # type: ignore[attr-defined,no-any-return]


def test_lookups_over_a_websocket_and_shutdown() -> None:
    async def main() -> None:
        with trio.fail_after(60):
            async with trio.open_nursery() as nursery:
                port = await nursery.start(serve, 0)
                async with trio_websocket.open_websocket(
                    "127.0.0.1", port, "/", use_ssl=False
                ) as ws:
                    ok = await _ask(ws, target="odom", source="base_link", ahead=0.2)
                    assert 0.15 <= float(ok["x"]) <= 60.0  # type: ignore[arg-type]
                    late = await _ask(
                        ws, target="odom", source="base_link", ahead=100, timeout=0.3
                    )
                    assert late["error"] == "timeout"
                    unknown = await _ask(ws, target="odom", source="gripper", timeout=0.3)
                    assert unknown == {"error": "unknown frame", "frame": "gripper"}
                    bad = await _ask(ws, source="base_link")
                    assert bad == {"error": "bad request", "detail": "'target'"}
                nursery.cancel_scope.cancel()  # shutdown: server, listener, bus

    trio.run(main)
