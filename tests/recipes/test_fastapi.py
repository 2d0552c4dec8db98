"""The FastAPI recipe (examples/fastapi_app.py) run by its real lifespan and served to an
httpx client through the ASGI transport, on asyncio and on trio."""

from __future__ import annotations

import re

import anyio
import pytest

pytest.importorskip("fastapi")
httpx = pytest.importorskip("httpx")

from examples.fastapi_app import app  # noqa: E402


@pytest.mark.anyio
async def test_lookups_map_their_timeout_to_http_errors(anyio_backend: str) -> None:
    with anyio.fail_after(60):
        async with app.router.lifespan_context(app):
            transport = httpx.ASGITransport(app=app)
            async with httpx.AsyncClient(transport=transport, base_url="http://tfbus") as client:
                # 0.2 s ahead: answered once the broadcast covering that time arrives.
                ok = await client.get("/transform/odom/base_link", params={"ahead": 0.2})
                assert ok.status_code == 200, ok.text
                body = ok.json()
                x = body["translation"][0]
                assert 0.15 <= x <= 60.0  # 1 m/s since start-up, at least the 0.2 s ahead
                assert body["translation"][1:] == [0.0, 0.0]

                # 100 s ahead cannot arrive within 0.3 s: 504 with tf2's reason.
                late = await client.get(
                    "/transform/odom/base_link", params={"ahead": 100, "timeout": 0.3}
                )
                assert late.status_code == 504
                detail = late.json()["detail"]
                assert detail.startswith("no transform within 0.3 s: Timed out after 0.3 s")
                # the requested time, printed twice, reads the same (tf2's rounding) both times
                asked = re.search(r" at time (\d+\.\d{9}): ", detail)
                again = re.search(r"Requested time (\d+\.\d{9}) ", detail)
                assert asked and again and asked.group(1) == again.group(1), detail

                unknown = await client.get("/transform/odom/gripper", params={"timeout": 0.3})
                assert unknown.status_code == 404
                assert unknown.json()["detail"] == "unknown frame 'gripper'"

                # A request whose client gives up: its wait is removed with its task.
                with anyio.move_on_after(0.3):
                    await client.get(
                        "/transform/odom/base_link", params={"ahead": 100, "timeout": 100}
                    )
                waits = await client.get("/waits")
                assert waits.json() == {"pending": 0}
            buffer = app.state.buffer
        # Shutdown: the lifespan left the bus and the listener; nothing waits.
        assert buffer.pending_waits == 0


def test_served_by_uvicorn_and_shut_down_by_sigterm() -> None:
    """The same app behind a real uvicorn on 127.0.0.1: start-up, a lookup, and SIGTERM
    (uvicorn's graceful shutdown runs the lifespan's exit: the bus closes)."""
    pytest.importorskip("uvicorn")
    import signal

    from .proc import Child

    port = _free_port()
    server = Child("-m", "uvicorn", "examples.fastapi_app:app", "--host", "127.0.0.1",
                   "--port", str(port))
    try:
        server.expect("INFO:     Application startup complete.")
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as client:
            ok = client.get("/transform/odom/base_link", params={"ahead": 0.2})
            assert ok.status_code == 200, ok.text
            late = client.get("/transform/odom/base_link", params={"ahead": 100, "timeout": 0.3})
            assert late.status_code == 504
        # uvicorn re-raises the signal once its graceful shutdown is done (0.29+).
        assert server.terminate() in (0, -signal.SIGTERM)
        server.expect("INFO:     Application shutdown complete.")
        assert not any("Traceback" in line for line in server.seen), server.seen
    finally:
        server.kill()


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _sigint_with_a_lookup_waiting(server: object, port: int) -> list[str]:
    """A request awaiting a transform an hour ahead (timeout 3600 s) is waiting (the
    app's /waits says so); SIGINT to the server's PID. The request is answered 503 within
    30 s (far less than its own 3600 s: ~0.1 s measured; bounded for load 8), the server
    exits 0 with no traceback and no cancellation printed. Returns the server's lines."""
    import signal
    import threading
    import time

    from .proc import Child

    assert isinstance(server, Child)
    answer: dict[str, object] = {}

    def request() -> None:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=120) as client:
            r = client.get("/transform/odom/base_link", params={"ahead": 3600,
                                                                "timeout": 3600})
            answer.update(status=r.status_code, body=r.text, at=time.monotonic())

    waiter = threading.Thread(target=request, daemon=True)
    waiter.start()
    with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as client:
        deadline = time.monotonic() + 60
        while client.get("/waits").json()["pending"] != 1:
            assert time.monotonic() < deadline, "the request never started waiting"
            time.sleep(0.05)  # polling the app's own count, bounded by the deadline
    sent = time.monotonic()
    server.proc.send_signal(signal.SIGINT)
    waiter.join(60)  # far less than the lookup's own 3600 s
    assert not waiter.is_alive(), "the waiting request was not answered"
    assert answer["status"] == 503 and "shutting down" in str(answer["body"])
    assert float(answer["at"]) - sent < 30  # type: ignore[arg-type]
    assert server.proc.wait(60) == 0
    lines = server.rest()
    assert not any("Traceback" in line or "Cancelled" in line for line in lines), lines
    return lines


def test_sigint_to_uvicorn_answers_a_waiting_lookup_503_and_exits_0() -> None:
    """Ctrl-C to a real uvicorn: uvicorn waits for open requests before the lifespan's
    exit, so the recipe's signal task closes the buffer first: the request waiting on a
    far-future transform is answered 503 at once, then uvicorn shuts down and exits 0,
    with no traceback."""
    pytest.importorskip("uvicorn")
    from .proc import Child

    port = _free_port()
    server = Child("-m", "uvicorn", "examples.fastapi_app:app", "--host", "127.0.0.1",
                   "--port", str(port))
    try:
        server.expect("INFO:     Application startup complete.")
        lines = _sigint_with_a_lookup_waiting(server, port)
        assert "INFO:     Application shutdown complete." in lines
    finally:
        server.kill()


def test_sigint_to_hypercorn_on_trio_answers_a_waiting_lookup_503_and_exits_0() -> None:
    """The same application served by hypercorn on trio from code
    (examples/fastapi_hypercorn_trio.py): the lifespan's signal task closes the buffer
    and triggers hypercorn's shutdown."""
    pytest.importorskip("hypercorn")
    pytest.importorskip("trio")
    from fleet_procs import Proc

    from .proc import Child

    port = _free_port()
    server = Child("examples/fastapi_hypercorn_trio.py", str(port))
    try:
        Proc.expect(server, lambda line: "Running on http://127.0.0.1" in line, 60)
        assert "server stopped" in _sigint_with_a_lookup_waiting(server, port)
    finally:
        server.kill()
