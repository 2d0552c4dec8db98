"""Real ROS 1 peers for the tests and the benchmarks: Debian's roscore and tools.

Everything runs on 127.0.0.1: each master gets a free port, ``ROS_IP=127.0.0.1`` and a
private ``ROS_HOME``. Processes are started here, read by threads line by line, waited on
with a bound, and ended by their PID (SIGINT, then SIGKILL after a bound).

Needs nothing but the standard library (no pytest): ``benchmarks/bench_ros1.py``,
``bench_check.py`` and ``soak_ros1.py`` put ``peers/ros1/`` on ``sys.path`` and import it
with the ``bench`` extra alone; the tests' fixtures (``tests/ros1_harness.py``) build on it.
"""

from __future__ import annotations

import contextlib
import os
import queue
import re
import signal
import socket
import subprocess
import threading
import time
import xmlrpc.client
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
INSTALL = ROOT / "scripts" / "install" / "install_ros1.sh"
ROS_BIN = Path("/usr/bin")


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def ros1_missing(packages: tuple[str, ...] = ("tf",)) -> str | None:
    """Why ROS 1 cannot be used here (after trying to install it with
    ``scripts/install/install_ros1.sh``), or None: roscore, rosrun and the pkg-config
    ``packages`` (the tests' C++ nodes need ``tf``; the benchmarks' ``roscpp`` and
    ``tf2_msgs``)."""
    need = [ROS_BIN / "roscore", ROS_BIN / "rosrun"]

    def ready() -> bool:
        return all(p.exists() for p in need) and all(_has_pkg(p) for p in packages)

    if ready():
        return None
    if not INSTALL.exists():
        return f"{INSTALL} missing"
    try:
        out = subprocess.run(
            ["bash", str(INSTALL)], capture_output=True, text=True, timeout=1900, check=False
        ).stdout.strip()
    except subprocess.TimeoutExpired:
        return "installing ROS 1 timed out"
    if ready():
        return None
    return out or "ROS 1 not installed"


def _has_pkg(name: str) -> bool:
    return (
        subprocess.run(
            ["pkg-config", "--exists", name], env=_path_env(), capture_output=True, check=False
        ).returncode
        == 0
    )


def _path_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
    return env


def _children(pid: int) -> list[int]:
    """The PIDs of the live processes whose parent is ``pid`` (``/proc/*/stat``, field 4)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue  # a process that ended meanwhile
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


class Proc:
    """A child process whose stdout+stderr lines are collected by a thread."""

    def __init__(self, args: list[str], env: dict[str, str], cwd: Path | None = None) -> None:
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
            cwd=cwd,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def discard(self) -> None:
        """Forget every line printed so far: later waits see only what comes next."""
        self.drain()
        self.seen.clear()

    def wait_for(self, pattern: str, timeout: float = 20.0) -> re.Match[str]:
        """The first line (from now on, or already seen) matching ``pattern``.

        Raises:
            AssertionError: none within ``timeout`` s, with the output seen.
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
        raise AssertionError(
            f"no line matching {pattern!r} from {self.args} in {timeout} s:\n{tail}"
        )

    def drain(self) -> list[str]:
        """Every line read so far that was not consumed by :meth:`wait_for`."""
        while True:
            try:
                self.seen.append(self.lines.get_nowait())
            except queue.Empty:
                return list(self.seen)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 15.0) -> int:
        """End the process by its PID and wait for it; the exit code. If ``sig`` does not
        end it within ``timeout`` s it is killed, and so are the processes it started (by
        their PIDs, read before it is killed): roscore starts rosmaster and rosout in
        sessions of their own, which a killed roscore would leave running."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                children = _children(self.proc.pid)
                self.proc.kill()
                self.proc.wait(5)
                for child in children:
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(child, signal.SIGKILL)
        self._reader.join(timeout=2.0)
        return int(self.proc.returncode)


@dataclass
class Master:
    """A roscore on 127.0.0.1:port and the environment for nodes that use it."""

    port: int
    env: dict[str, str]
    proc: Proc | None = None

    @property
    def uri(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> None:
        """Start roscore and wait (bounded) until the master and /rosout are up.

        Raises:
            PortTaken: another process bound the port first (roscore is stopped).
            AssertionError: roscore did not come up within 60 s.
        """
        self.proc = Proc([str(ROS_BIN / "roscore"), "-p", str(self.port)], self.env)
        try:
            # roscore prints this once the master and /rosout are up: wait on it, bounded.
            # If the port was taken meanwhile it says so and never comes up: stop waiting.
            m = self.proc.wait_for(
                r"started core service \[/rosout\]|(port \d+ is already in use)", timeout=60.0
            )
            if m.group(1):
                raise PortTaken(f"roscore on 127.0.0.1:{self.port}: {m.group(1)}")
            xmlrpc.client.ServerProxy(self.uri).getPid("/tfbus_test")
        except BaseException:
            self.stop()  # never leave a roscore that did not come up running
            raise

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.stop(signal.SIGINT, timeout=20.0)
            self.proc = None

    def run(self, *args: str) -> Proc:
        """A ROS 1 command (``rosrun``, ``rostopic``, a built node) on this master."""
        return Proc(list(args), self.env)

    def call(self, method: str, *args: object) -> object:
        code, status, value = getattr(xmlrpc.client.ServerProxy(self.uri), method)(*args)
        assert code == 1, status
        return value


class PortTaken(RuntimeError):
    """The port chosen for roscore was bound by another process before roscore bound it."""


def start_master(home: Path, attempts: int = 3) -> Master:
    """A roscore started on a free 127.0.0.1 port, its ROS_HOME ``home``.

    A free port is only free when it is chosen: another process (any outgoing
    connection takes an ephemeral port) may bind it before roscore does. Then another
    port is chosen, up to ``attempts`` times.

    Raises:
        PortTaken: every port chosen was taken first.
        AssertionError: roscore did not come up within 60 s.
    """
    while True:
        port = free_port()
        master = Master(port, master_env(port, home))
        try:
            master.start()
        except PortTaken:
            attempts -= 1
            if attempts <= 0:
                raise
            continue
        return master


def master_env(port: int, home: Path) -> dict[str, str]:
    env = _path_env()
    env.update(
        ROS_MASTER_URI=f"http://127.0.0.1:{port}",
        ROS_IP="127.0.0.1",
        ROS_HOME=str(home),
        ROS_LOG_DIR=str(home / "log"),
        PYTHONUNBUFFERED="1",
        # rosconsole writes ROS_INFO lines to a pipe fully buffered (4 KiB) unless told:
        # a 1 Hz C++ node's first line would arrive some 30 s late.
        ROSCONSOLE_STDOUT_LINE_BUFFERED="1",
    )
    env.pop("ROS_HOSTNAME", None)
    (home / "log").mkdir(parents=True, exist_ok=True)
    return env


def check_master() -> str | None:
    """Why a roscore started here does not work, or None: one is started on a free
    127.0.0.1 port with a private ``ROS_HOME``, must answer the master API's ``getPid``
    and ``lookupNode`` for ``/rosout``, and is stopped by its PID.
    ``scripts/install/install_ros1.sh`` runs it (``ros1_peers.py --check-master``) after its
    install."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="tfbus-roscore-check-") as home:
        try:
            master = start_master(Path(home))
        except (AssertionError, OSError, PortTaken) as exc:
            return f"roscore did not come up on 127.0.0.1: {exc or type(exc).__name__}"
        try:
            master.call("getPid", "/tfbus_check")
            # roscore says /rosout started before the node has registered: wait, bounded.
            deadline = time.monotonic() + 30.0
            while True:
                code, status, _ = xmlrpc.client.ServerProxy(master.uri).lookupNode(
                    "/tfbus_check", "/rosout"
                )
                if code == 1:
                    break
                if time.monotonic() > deadline:
                    return f"roscore answers but /rosout did not register in 30 s: {status}"
                time.sleep(0.1)
        except (AssertionError, OSError, xmlrpc.client.Error) as exc:
            return f"roscore does not answer its master API: {exc}"
        finally:
            master.stop()
    return None


if __name__ == "__main__":
    import sys

    if sys.argv[1:] != ["--check-master"]:
        sys.exit("usage: ros1_peers.py --check-master")
    why = check_master()
    if why is not None:
        print(why)
        sys.exit(1)
