"""Who may read and drive ``tfbus view``'s page (tfbus.view.guard): requests with a
foreign ``Host`` (DNS rebinding) or ``Origin`` (another site's page) are refused with
403 and counted, this machine's names pass; the opt-in token lets a remote browser in;
a connection that opens and closes, or a WebSocket message the page cannot read, is
counted and logged as one line, never a traceback. Plain sockets with forged headers on
127.0.0.1, and Debian's headless Chromium running a page of another origin."""

from __future__ import annotations

import base64
import http.server
import os
import shutil
import socket
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Iterator

import pytest

pytest.importorskip("viser")

from tfbus.view.guard import PageGuard
from tfbus.view.server import TfPage

PROTOCOL = "viser-v" + __import__("viser").__version__


def _request(port: int, host: str, origin: str | None = None, *, ws: bool = True,
             path: str = "/", cookie: str | None = None) -> tuple[socket.socket, bytes]:
    """One HTTP request with forged headers; the socket and the response's head."""
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    head = f"GET {path} HTTP/1.1\r\nHost: {host}\r\n"
    if ws:
        key = base64.b64encode(os.urandom(16)).decode()
        head += ("Upgrade: websocket\r\nConnection: Upgrade\r\n"
                 f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                 f"Sec-WebSocket-Protocol: {PROTOCOL}\r\n")
    if origin is not None:
        head += f"Origin: {origin}\r\n"
    if cookie is not None:
        head += f"Cookie: {cookie}\r\n"
    s.sendall((head + "\r\n").encode())
    data = b""
    while b"\r\n\r\n" not in data and len(data) < 65536:
        chunk = s.recv(4096)
        if not chunk:
            break
        data += chunk
    return s, data.split(b"\r\n\r\n")[0]


def _status(port: int, host: str, origin: str | None = None, **kw: object) -> int:
    s, head = _request(port, host, origin, **kw)  # type: ignore[arg-type]
    s.close()
    return int(head.split(b" ")[1])


def _until(cond: Callable[[], bool], bound: float = 20.0) -> None:
    deadline = time.monotonic() + bound
    while not cond():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.01)


def test_foreign_host_and_origin_are_refused_this_machines_pass(page: TfPage) -> None:
    p = page.port
    own = f"127.0.0.1:{p}"
    # DNS rebinding: the attacker's name resolving to 127.0.0.1, page and WebSocket
    assert _status(p, f"evil.example:{p}", ws=False) == 403
    assert _status(p, f"evil.example:{p}", f"http://evil.example:{p}") == 403
    # cross-site WebSocket: our Host, another site's Origin (also another local port)
    assert _status(p, own, "http://evil.example") == 403
    assert _status(p, own, f"http://127.0.0.1:{p + 1}") == 403
    assert _status(p, own, "null") == 403
    assert page.guard.refused == 5
    # this machine's names, with and without the browser's same-origin Origin
    assert _status(p, own, ws=False) == 200
    assert _status(p, own, f"http://{own}") == 101
    assert _status(p, f"localhost:{p}", f"http://localhost:{p}") == 101
    assert _status(p, f"[::1]:{p}") == 101
    assert _status(p, f"LOCALHOST:{p}", ws=False) == 200
    assert page.guard.refused == 5


def test_the_token_lets_a_remote_browser_in_and_only_with_it() -> None:
    page = TfPage("127.0.0.1", 0, token="s3cret-Token")  # the Host header says remote
    try:
        p = page.port
        remote = f"robot.lan:{p}"
        assert _status(p, remote, ws=False) == 403  # no token
        assert _status(p, remote, ws=False, path="/?token=wrong") == 403
        s, head = _request(p, remote, ws=False, path="/?token=s3cret-Token")
        s.close()
        assert head.startswith(b"HTTP/1.1 200")
        assert b"Set-Cookie: tfbus_view_token=s3cret-Token; Path=/; HttpOnly; SameSite=Strict" \
            in head
        # the page's WebSocket carries the cookie: its own origin passes, another not
        cookie = "tfbus_view_token=s3cret-Token"
        assert _status(p, remote, f"http://{remote}", cookie=cookie) == 101
        assert _status(p, remote, "http://evil.example", cookie=cookie) == 403
        assert _status(p, f"127.0.0.1:{p}", f"http://127.0.0.1:{p}") == 101  # loopback
        assert page.guard.refused == 3
    finally:
        page.close()
    with pytest.raises(ValueError, match="token"):
        PageGuard("0.0.0.0", 1, token="has space")
    with pytest.raises(ValueError, match="token"):
        TfPage("127.0.0.1", 0, token="")


def test_closed_connections_and_garbage_messages_are_counted_not_tracebacks(
        page: TfPage, capfd: pytest.CaptureFixture[str]) -> None:
    p = page.port
    for _ in range(5):  # opened and closed before a request
        socket.create_connection(("127.0.0.1", p), timeout=10).close()
    s = socket.create_connection(("127.0.0.1", p), timeout=10)
    s.sendall(b"\x16\x03\x01\x02\x00 not http\r\n\r\n")  # a TLS hello, say
    s.close()
    _until(lambda: page.guard.failed_handshakes == 6)
    for frame in (b"\x82\x85" + os.urandom(4) + b"junk!",  # binary, not the page's format
                  b"\x81\x83" + b"\0\0\0\0" + b"abc",  # text: the page reads binary only
                  b"\x82\xff" + b"\xff" * 8):  # 2**64-1 bytes: closed by websockets
        s, head = _request(p, f"127.0.0.1:{p}", f"http://127.0.0.1:{p}")
        assert head.startswith(b"HTTP/1.1 101")
        s.sendall(frame)
        s.settimeout(10)
        try:
            while s.recv(65536):  # until the server closes the connection
                pass
        except OSError:
            pass
        s.close()
    # the first two are counted; the third websockets itself closes (1009, too big)
    _until(lambda: page.guard.bad_messages == 2)
    err = capfd.readouterr().err
    assert "Traceback" not in err
    # one line per kind per 5 s, not one per connection
    assert err.count("failed handshakes on port") <= 2
    assert err.count("bad messages on port") <= 2
    # the page still serves
    assert _status(p, f"127.0.0.1:{p}", ws=False) == 200


@pytest.fixture
def attacker(page: TfPage) -> Iterator[tuple[str, list[str]]]:
    """A page on another origin (127.0.0.1, another port) whose script opens the view's
    WebSocket and reports what happened; its URL and the reports its script sent."""
    results: list[str] = []
    body = f"""<html><body><p id=out>pending</p><script>
const ws = new WebSocket("ws://127.0.0.1:{page.port}/", "{PROTOCOL}");
ws.binaryType = "arraybuffer";
let got = 0;
ws.onmessage = (e) => {{ got += 1; }};
function report(what) {{ document.getElementById("out").textContent = what;
  fetch("/result?r=" + what); }}
ws.onopen = () => setTimeout(() => report("open-" + got), 1500);
ws.onerror = () => report("refused");
</script></body></html>""".encode()

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            out = body
            if self.path.startswith("/result"):
                results.append(self.path.split("=", 1)[1])
                out = b"ok"
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(out)))
            self.end_headers()
            self.wfile.write(out)

        def log_message(self, *_args: object) -> None:
            pass

    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    thread = threading.Thread(target=srv.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{srv.server_address[1]}/", results
    finally:
        srv.shutdown()
        srv.server_close()
        thread.join(timeout=10)


def test_another_origins_page_in_chromium_cannot_open_the_views_websocket(
        page: TfPage, attacker: tuple[str, list[str]]) -> None:
    """A site the user visits (here 127.0.0.1 on another port: another origin) opens
    ``ws://127.0.0.1:PORT/`` from its script: the view refuses it (the script sees an
    error, never a message), and counts it."""
    exe = shutil.which("chromium")
    if exe is None:
        pytest.skip("Debian chromium not installed (scripts/install/install_chromium.sh)")
    url, results = attacker
    text = ""
    from headless_chromium import run_headless

    for _ in range(3):  # a loaded machine can end the virtual-time budget too early
        done = run_headless(
            exe, ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update",
                  "--virtual-time-budget=5000", "--dump-dom"],
            url, timeout=90.0, prefix="tfbus-view-guard-")
        text = done.stdout.decode("utf-8", "replace")
        if "pending" not in text:
            break
    assert '<p id="out">refused</p>' in text, text[-500:]
    assert page.guard.refused >= 1
    assert not any(r.startswith("open") for r in results)


def test_view_token_option_is_checked_before_anything_is_served() -> None:
    """``tfbus view --token`` with a space or empty: one usage line, exit status 2."""
    from click.testing import CliRunner

    from tfbus.cli.view import command

    for bad in ("has space", "", "x" * 257):
        result = CliRunner().invoke(command, ["--bus", "memory", "--port", "0", "--token", bad])
        assert result.exit_code == 2, result.output
        assert "--token" in result.output and "Traceback" not in result.output


def test_foxglove_server_refuses_foreign_host_and_origin() -> None:
    """The Foxglove WebSocket (``--foxglove``) is checked as the page is: a foreign
    ``Host`` or ``Origin`` gets 403 and is counted; this machine's names and Foxglove's
    web app (another origin by design) are relayed to the SDK's server (101)."""
    pytest.importorskip("foxglove")
    from tfbus.view.foxglove_bridge import FoxgloveBridge

    bridge = FoxgloveBridge("127.0.0.1", 0)
    try:
        p = bridge.port

        def status(host: str, origin: str | None) -> int:
            s = socket.create_connection(("127.0.0.1", p), timeout=10)
            key = base64.b64encode(os.urandom(16)).decode()
            head = (f"GET / HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\n"
                    f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                    "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n")
            if origin is not None:
                head += f"Origin: {origin}\r\n"
            s.sendall((head + "\r\n").encode())
            line = s.recv(200).split(b"\r\n")[0]
            s.close()
            return int(line.split(b" ")[1])

        assert status(f"evil.example:{p}", None) == 403  # DNS rebinding
        assert status(f"127.0.0.1:{p}", "http://evil.example") == 403  # another site
        assert bridge.guard.refused == 2
        assert status(f"127.0.0.1:{p}", None) == 101
        assert status(f"localhost:{p}", "https://app.foxglove.dev") == 101
        assert bridge.guard.refused == 2
    finally:
        bridge.close()


def _foxglove_upgrade(port: int) -> bytes:
    """A Foxglove client's WebSocket upgrade, plain ``ws://``, to ``port``; what the
    server answered before it closed (bounded: 10 s)."""
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
               f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
               "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n"
               "\r\n").encode())
    data = b""
    try:
        while b"\r\n\r\n" not in data and len(data) < 65536:
            chunk = s.recv(4096)
            if not chunk:
                break
            data += chunk
    except OSError:
        pass
    s.close()
    return data


def test_the_foxglove_sdks_own_port_refuses_clients_that_go_around_the_front(
        caplog: pytest.LogCaptureFixture) -> None:
    """foxglove-sdk's server checks no ``Host`` or ``Origin``; it listens on 127.0.0.1
    behind the front. A client that finds its port and connects straight to it is
    refused: a plain ``ws://`` upgrade gets no WebSocket (the SDK serves TLS only) and
    TLS with a browser's certificate checks fails (the run's certificate is trusted by
    the front alone); through the front the same upgrade is let in. The SDK's line per
    dropped connection becomes at most one line per 5 s, no traceback."""
    pytest.importorskip("foxglove")
    import ssl

    from tfbus.view import foxglove_bridge
    from tfbus.view.foxglove_bridge import FoxgloveBridge

    bridge = FoxgloveBridge("127.0.0.1", 0)
    try:
        inner = bridge.server.port  # the SDK's own server
        assert inner != bridge.port
        for _ in range(4):
            answer = _foxglove_upgrade(inner)
            assert not answer.startswith(b"HTTP/1.1 101"), answer
            assert b"sec-websocket-accept" not in answer.lower()
        browser_checks = ssl.create_default_context()  # the system's authorities
        with pytest.raises(ssl.SSLCertVerificationError), \
                socket.create_connection(("127.0.0.1", inner), timeout=10) as raw, \
                browser_checks.wrap_socket(raw, server_hostname="127.0.0.1"):
            pass
        # counted (by this process: at least these five), not printed one by one
        _until(lambda: sum(n for k, n in foxglove_bridge.sdk_lines.items()
                           if "not made through its front" in k) >= 5)
        # the front relays the same upgrade to the SDK (over TLS) and it is let in
        assert _foxglove_upgrade(bridge.port).startswith(b"HTTP/1.1 101")
        assert bridge.guard.refused == 0
    finally:
        bridge.close()
    lines = [r.getMessage() for r in caplog.records]
    assert not any("Traceback" in x or x.startswith("Dropping client") for x in lines), lines
    assert sum("not made through its front" in x for x in lines) <= 2, lines


def test_another_origins_page_in_chromium_cannot_open_the_foxglove_sdks_port() -> None:
    """A site the user visits finds the SDK's port (a port scan from its script) and
    opens ``ws://`` and ``wss://127.0.0.1:PORT/`` with Foxglove's subprotocol: both fail
    (no TLS, then a certificate no authority vouches for), the script never sees a
    message."""
    pytest.importorskip("foxglove")
    exe = shutil.which("chromium")
    if exe is None:
        pytest.skip("Debian chromium not installed (scripts/install/install_chromium.sh)")
    from tfbus.view.foxglove_bridge import FoxgloveBridge

    bridge = FoxgloveBridge("127.0.0.1", 0)
    results: list[str] = []
    reported = threading.Event()
    inner = bridge.server.port
    body = f"""<html><body><p id=out>pending</p><script>
const said = {{}};
function report() {{
  if (Object.keys(said).length < 2) return;
  const what = said.ws + "-" + said.wss;
  document.getElementById("out").textContent = what;
  fetch("/result?r=" + what);
}}
for (const scheme of ["ws", "wss"]) {{
  const ws = new WebSocket(scheme + "://127.0.0.1:{inner}/", "foxglove.sdk.v1");
  ws.onopen = () => {{ said[scheme] = "open"; report(); }};
  ws.onerror = () => {{ said[scheme] = "refused"; report(); }};
}}
</script></body></html>""".encode()

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            out = body
            if self.path.startswith("/result"):
                results.append(self.path.split("=", 1)[1])
                reported.set()
                out = b"ok"
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(out)))
            self.end_headers()
            self.wfile.write(out)

        def log_message(self, *_args: object) -> None:
            pass

    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    thread = threading.Thread(target=srv.serve_forever, daemon=True)
    thread.start()
    try:
        # The page reports by fetching /result once both sockets have ended: wait for
        # that (bounded), not for a virtual-time budget a loaded machine may outrun.
        profile = tempfile.mkdtemp(prefix="tfbus-view-guard-")
        browser = subprocess.Popen(
            [exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
             "--disable-background-networking", "--disable-component-update",
             f"--user-data-dir={profile}", f"http://127.0.0.1:{srv.server_address[1]}/"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            env={**os.environ, "TMPDIR": profile},
            start_new_session=True)  # its renderer and helpers in our child's group
        try:
            assert reported.wait(90), "the page never reported"
        finally:
            from headless_chromium import end_chromium

            end_chromium(browser, profile, 30.0)
        assert results == ["refused-refused"]
    finally:
        srv.shutdown()
        srv.server_close()
        thread.join(timeout=10)
        bridge.close()
