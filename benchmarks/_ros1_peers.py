"""ROS 1 peers for the benchmarks: Debian's roscore and built C++ nodes, on 127.0.0.1.

What ``bench_ros1.py`` and ``bench_check.py`` need, with nothing from ``tests/`` (the
benchmarks run with the ``bench`` extra alone, no pytest): a free port, whether ROS 1 is
installed (never installs it: ``scripts/install_ros1.sh`` does), a child process whose
output lines are read by a thread and waited on with a bound, and a roscore on its own
port with a private ``ROS_HOME``. Processes are ended by their PID (SIGINT, then SIGKILL
after a bound).
"""

from __future__ import annotations

import os
import queue
import re
import signal
import socket
import subprocess
import threading
import time
import xmlrpc.client
from pathlib import Path

ROS_BIN = Path("/usr/bin")


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _path_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
    return env


def ros1_missing() -> str | None:
    """Why ROS 1 cannot be used here, or None (roscore, and roscpp and tf2_msgs for the
    C++ nodes)."""
    if not (ROS_BIN / "roscore").exists():
        return "no /usr/bin/roscore (scripts/install_ros1.sh installs Debian's ROS 1)"
    for pkg in ("roscpp", "tf2_msgs"):
        found = subprocess.run(
            ["pkg-config", "--exists", pkg], env=_path_env(), capture_output=True, check=False
        )
        if found.returncode:
            return f"pkg-config does not know {pkg} (scripts/install_ros1.sh)"
    return None


class Proc:
    """A child process whose stdout+stderr lines are collected by a thread."""

    def __init__(self, args: list[str], env: dict[str, str]) -> None:
        self.args = args
        self.proc = subprocess.Popen(
            args,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            text=True,
            encoding="utf-8",
            errors="replace",
            env=env,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def wait_for(self, pattern: str, timeout: float = 20.0) -> re.Match[str]:
        """The first line (from now on, or already seen) matching ``pattern``.

        Raises:
            TimeoutError: none within ``timeout`` s (the last lines seen in the message).
        """
        rx = re.compile(pattern)
        for line in self.seen:
            if m := rx.search(line):
                self.seen.remove(line)
                return m
        deadline = time.monotonic() + timeout
        while (remaining := deadline - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=min(remaining, 0.2))
            except queue.Empty:
                if self.proc.poll() is not None and self.lines.empty():
                    self._reader.join(timeout=1.0)
                    if self.lines.empty():
                        break
                continue
            if m := rx.search(line):
                return m
            self.seen.append(line)
        tail = "\n".join(self.seen[-30:])
        raise TimeoutError(f"no line matching {pattern!r} from {self.args} in {timeout} s:\n{tail}")

    def drain(self) -> list[str]:
        """Every line read so far that was not consumed by :meth:`wait_for`."""
        while True:
            try:
                self.seen.append(self.lines.get_nowait())
            except queue.Empty:
                return list(self.seen)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 15.0) -> int:
        """End the process by its PID and wait for it; the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self._reader.join(timeout=2.0)
        return int(self.proc.returncode)


def master_env(port: int, home: Path) -> dict[str, str]:
    """The environment of a node on the master at ``port`` (ROS_IP=127.0.0.1)."""
    env = _path_env()
    env.update(
        ROS_MASTER_URI=f"http://127.0.0.1:{port}",
        ROS_IP="127.0.0.1",
        ROS_HOME=str(home),
        ROS_LOG_DIR=str(home / "log"),
        PYTHONUNBUFFERED="1",
    )
    env.pop("ROS_HOSTNAME", None)
    (home / "log").mkdir(parents=True, exist_ok=True)
    return env


class Master:
    """A roscore on 127.0.0.1:``port`` and the environment for nodes that use it."""

    def __init__(self, port: int, env: dict[str, str]) -> None:
        self.port = port
        self.env = env
        self.proc: Proc | None = None

    def start(self) -> None:
        """Start roscore and wait (bounded) until it answers."""
        self.proc = Proc([str(ROS_BIN / "roscore"), "-p", str(self.port)], self.env)
        self.proc.wait_for(r"started core service \[/rosout\]", timeout=60.0)
        xmlrpc.client.ServerProxy(f"http://127.0.0.1:{self.port}").getPid("/tfbus_bench")

    def stop(self) -> None:
        """Stop roscore (SIGINT, then SIGKILL after 20 s)."""
        if self.proc is not None:
            self.proc.stop(signal.SIGINT, timeout=20.0)
            self.proc = None

    def run(self, *args: str) -> Proc:
        """A command (a built node) on this master."""
        return Proc(list(args), self.env)
