"""The lines a ``tfbus view`` process writes to a pipe, waited for with a bound.

Reads the pipe's file descriptor itself (``select`` + ``os.read``): a buffered
``readline()`` may take two lines from the pipe and return one, leaving the second in
Python's buffer where ``select`` cannot see it."""

from __future__ import annotations

import os
import select
import subprocess
import time
from collections.abc import Callable


class ProcLines:
    """The lines ``proc`` has written to its ``stderr`` pipe so far (``stream="stdout"``
    for its stdout), without their line ends."""

    def __init__(self, proc: subprocess.Popen[str], stream: str = "stderr") -> None:
        pipe = getattr(proc, stream)
        assert pipe is not None, f"the process's {stream} is not a pipe"
        self._fd: int = pipe.fileno()
        self._buf = b""
        self.lines: list[str] = []
        self.ended = False
        """True once the pipe was closed (the process ended)."""

    def until(self, what: Callable[[list[str]], bool], bound: float = 60.0) -> list[str]:
        """Read until ``what(lines)`` is true and return the lines; AssertionError after
        ``bound`` seconds or when the pipe closes first, naming the lines read."""
        deadline = time.monotonic() + bound
        while not what(self.lines):
            assert not self.ended, f"the process ended: {self.lines}"
            left = deadline - time.monotonic()
            assert left > 0, f"not printed in {bound} s: {self.lines}"
            ready, _, _ = select.select([self._fd], [], [], left)
            if not ready:
                continue
            chunk = os.read(self._fd, 65536)
            if not chunk:
                self.ended = True
                continue
            *done, self._buf = (self._buf + chunk).split(b"\n")
            self.lines += [d.decode().rstrip("\r") for d in done]
        return self.lines

    def first(self, bound: float = 60.0) -> str:
        """The first line (waited for at most ``bound`` s)."""
        return self.until(lambda lines: len(lines) >= 1, bound)[0]
