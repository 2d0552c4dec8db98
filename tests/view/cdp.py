"""Headless Chromium driven through the DevTools protocol (CDP) for the ``tfbus view``
tests: open a page, evaluate JavaScript in it (read the DOM, drive the GUI controls with
real input events), wait for a condition with a bound, take a screenshot.

Chromium is a child process with a fresh profile on 127.0.0.1 (``--remote-debugging-port=0``:
it picks a free port and writes it to ``DevToolsActivePort`` in the profile); it is ended
by its PID when the context exits (``headless_chromium.end_chromium``).
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path
from types import TracebackType
from typing import Any

from headless_chromium import end_chromium

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--window-size=1280,800", "--remote-debugging-port=0",
         "--remote-debugging-address=127.0.0.1"]

# what Chromium answers while a navigation swaps the page's document (or its process)
_BETWEEN_DOCUMENTS = ("Not attached to an active page", "Cannot find context",
                      "Execution context was destroyed", "Inspected target navigated")


class Chromium:
    """One headless Chromium and one page of it, driven through CDP (``with Chromium(exe)
    as c: c.open(url)``). Every wait is bounded (``timeout`` seconds)."""

    def __init__(self, exe: str, timeout: float = 60.0) -> None:
        self.exe = exe
        self.timeout = timeout
        self._next = 0
        self._ws: Any = None
        self._proc: subprocess.Popen[bytes] | None = None
        self._profile = tempfile.TemporaryDirectory(prefix="tfbus-view-cdp-")

    def __enter__(self) -> Chromium:
        from websockets.sync.client import connect

        # Chromium keeps its singleton socket in a directory of its own under TMPDIR,
        # which a killed browser leaves behind: inside the profile, it goes with it.
        scratch = Path(self._profile.name) / "tmp"
        scratch.mkdir()
        self._proc = subprocess.Popen(
            [self.exe, *FLAGS, f"--user-data-dir={self._profile.name}", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            env={**os.environ, "TMPDIR": str(scratch)},
            start_new_session=True)  # its renderer and helper processes in our child's group
        active = Path(self._profile.name) / "DevToolsActivePort"
        deadline = time.monotonic() + self.timeout
        while not (active.exists() and len(active.read_text().splitlines()) >= 2):
            if time.monotonic() > deadline or self._proc.poll() is not None:
                self.__exit__(None, None, None)
                raise TimeoutError("chromium did not open its DevTools port")
            time.sleep(0.05)
        port = int(active.read_text().splitlines()[0])
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list",
                                    timeout=self.timeout) as r:
            targets = json.load(r)
        ws_url = next(t["webSocketDebuggerUrl"] for t in targets if t["type"] == "page")
        self._ws = connect(ws_url, max_size=64 * 2**20, open_timeout=self.timeout)
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._ws is not None:
            self._ws.close()
        end_chromium(self._proc, self._profile.name, self.timeout)
        with contextlib.suppress(OSError):
            self._profile.cleanup()

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        """One CDP command; its ``result`` (events before the answer are skipped)."""
        self._next += 1
        ident = self._next
        self._ws.send(json.dumps({"id": ident, "method": method, "params": params}))
        deadline = time.monotonic() + self.timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"no answer to {method}")
            msg = json.loads(self._ws.recv(timeout=left))
            if msg.get("id") == ident:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                result: dict[str, Any] = msg["result"]
                return result

    def open(self, url: str) -> None:
        """Navigate to ``url`` and wait (bounded) until the new document has loaded.

        Until then the page target can be between two documents: Chromium answers a
        command sent there with "Not attached to an active page" or "Cannot find
        context", which this wait rides out (any other error is raised)."""
        self.call("Page.navigate", url=url)
        deadline = time.monotonic() + self.timeout
        check = f"location.href === {json.dumps(url)} && document.readyState === 'complete'"
        while True:
            try:
                if self.js(check):
                    return
            except RuntimeError as exc:
                if not any(m in str(exc) for m in _BETWEEN_DOCUMENTS):
                    raise
            if time.monotonic() > deadline:
                raise TimeoutError(f"{url} never finished loading")
            time.sleep(0.05)

    def js(self, expression: str) -> Any:
        """The value of ``expression`` in the page (awaited when a promise)."""
        out = self.call("Runtime.evaluate", expression=expression, returnByValue=True,
                        awaitPromise=True)
        if "exceptionDetails" in out:
            raise RuntimeError(f"{expression!r}: {out['exceptionDetails']}")
        return out["result"].get("value")

    def wait(self, expression: str, timeout: float | None = None) -> Any:
        """Poll ``expression`` until it is truthy (at most ``timeout`` seconds); its value."""
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while True:
            value = self.js(expression)
            if value:
                return value
            if time.monotonic() > deadline:
                raise TimeoutError(f"never true in the page: {expression}")
            time.sleep(0.1)

    def html(self) -> str:
        """The page's DOM as HTML."""
        return str(self.js("document.documentElement.outerHTML"))

    def screenshot(self, path: Path) -> bytes:
        """A PNG of the page, also written to ``path``."""
        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        path.write_bytes(data)
        return data

    def key(self, key: str, code: str, key_code: int) -> None:
        """Press and release one key in the focused element (a real input event)."""
        for kind in ("keyDown", "keyUp"):
            self.call("Input.dispatchKeyEvent", type=kind, key=key, code=code,
                      windowsVirtualKeyCode=key_code)

    def click(self, x: float, y: float) -> None:
        """A left click at page coordinates (x, y) (real mouse events)."""
        self.call("Input.dispatchMouseEvent", type="mouseMoved", x=x, y=y)
        for kind in ("mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left",
                      clickCount=1)

    def type_text(self, text: str) -> None:
        """Type ``text`` into the focused element."""
        self.call("Input.insertText", text=text)
