"""A recipe's program as a child process: ``tests/fleet_procs.Proc`` (output lines
collected by a thread, bounded waits, no sleeps), read line after line by prefix."""

from __future__ import annotations

import signal
import sys

from fleet_procs import Proc


class Child(Proc):
    """``python <args>`` from the repository root; ``expect`` waits for the next line
    that starts with a prefix (the lines before it stay in ``seen``)."""

    def __init__(self, *args: str) -> None:
        super().__init__(argv=[sys.executable, *args])
        self._next = 0

    def expect(self, prefix: str, timeout: float = 60.0) -> str:  # type: ignore[override]
        """The next line starting with ``prefix``, within ``timeout`` seconds."""
        i = super().expect(lambda line: line.startswith(prefix), timeout, start=self._next)
        self._next = i + 1
        return self.seen[i]

    def terminate(self, timeout: float = 30.0) -> int:
        """SIGTERM (to this child's PID only), then its exit code."""
        return self.stop(signal.SIGTERM, timeout)

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=30)
