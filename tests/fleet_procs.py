"""Child processes for the fleet tests: output lines collected by a thread, bounded waits.

Helper module (not a test file); importable because ``tests/`` is on ``sys.path``.
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


class Proc:
    """A child process (``python -m tfbus.cli ARGS`` by default; ``argv`` for another
    command, ``netns`` to run it in a network namespace); its merged stdout/stderr lines
    are collected by a thread; ``stdin`` kept open when ``interactive``."""

    def __init__(self, *args: str, argv: Sequence[str] | None = None, netns: str | None = None,
                 interactive: bool = False) -> None:
        env = dict(os.environ, PYTHONUNBUFFERED="1", PYTHONIOENCODING="utf-8")
        env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
        env.pop("COLUMNS", None)
        command = list(argv) if argv is not None else [sys.executable, "-m", "tfbus.cli", *args]
        if netns is not None:  # `ip netns exec` execs the command: the PID is the child's
            command = ["ip", "netns", "exec", netns, *command]
        self.proc = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            stdin=subprocess.PIPE if interactive else subprocess.DEVNULL,
            text=True, encoding="utf-8", env=env, cwd=ROOT,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def send(self, line: str) -> None:
        """Write one line to the child's stdin."""
        assert self.proc.stdin is not None
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()

    def expect(self, predicate: Callable[[str], bool], timeout: float = 30.0,
               start: int = 0) -> int:
        """Index of the first line from ``start`` on that matches (bounded wait).

        Raises:
            AssertionError: no such line within ``timeout`` or before the child exited.
        """
        deadline = time.monotonic() + timeout
        i = start
        while True:
            while i < len(self.seen):
                if predicate(self.seen[i]):
                    return i
                i += 1
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError("no matching line in:\n" + "\n".join(self.seen))
            try:
                self.seen.append(self.lines.get(timeout=min(remaining, 0.2)))
            except queue.Empty:
                if self.proc.poll() is not None and self.lines.empty():
                    raise AssertionError(
                        f"exited {self.proc.returncode}:\n" + "\n".join(self.seen)
                    ) from None

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 20.0) -> int:
        """Send ``sig`` (if running) and wait for the exit status (SIGKILL after
        ``timeout``)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait(timeout)

    def rest(self, timeout: float = 10.0) -> list[str]:
        """Every line, once the process has ended and its output has been read to the end
        (both bounded by ``timeout``: an exited child's last lines may still be in the pipe
        when its exit status is already there)."""
        deadline = time.monotonic() + timeout
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(max(deadline - time.monotonic(), 0.0))
        self._reader.join(max(deadline - time.monotonic(), 0.0))
        while True:
            try:
                self.seen.append(self.lines.get_nowait())
            except queue.Empty:
                return self.seen

    def kill(self) -> None:
        """SIGKILL the child by its PID if it still runs, and reap it."""
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(10)
