"""The tutorial's three terminals as real processes: ``tfbus demo listener``,
``tfbus demo broadcaster`` and ``tfbus echo/monitor/frames --bus`` over Zenoh.

Every process runs on 127.0.0.1 with explicit endpoints on a free port (the transport's
defaults keep multicast scouting off); every wait polls the children's output against a
deadline (these are the only tests on wall-clock time, because they cross processes);
children are killed in ``finally``.
"""

from __future__ import annotations

import os
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from itertools import pairwise
from pathlib import Path

import pytest

pytest.importorskip("zenoh")
pytest.importorskip("msgspec")
pytest.importorskip("click")
pytest.importorskip("rich")

ROOT = Path(__file__).resolve().parents[2]

INFO = re.compile(
    r"^\[ INFO\] (\d+\.\d{9}): base_laser: \(1\.00, 0\.20\. 0\.00\) -----> "
    r"base_link: \(1\.10, 0\.20, 0\.20\) at time (\d+\.\d\d)$"
)
ERROR = re.compile(
    r'^\[ERROR\] (\d+\.\d{9}): Received an exception trying to transform a point from '
    r'"base_laser" to "base_link": "base_link" passed to lookupTransform argument '
    r"target_frame does not exist\. $"
)
LISTENER_SUMMARY = re.compile(
    r"^\[ INFO\] summary: (\d+) lookups, (\d+) transformed, (\d+) failed$"
)
BROADCASTER_SUMMARY = re.compile(
    r"^\[ INFO\] summary: (\d+) transforms sent, broadcast rate (\d+\.\d\d) Hz, "
    r"timer jitter p50 \d+\.\d{3} ms, p99 \d+\.\d{3} ms$"
)


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def listen_spec(port: int) -> str:
    return f"zenoh?listen=tcp/127.0.0.1:{port}"


def connect_spec(port: int) -> str:
    return f"zenoh?connect=tcp/127.0.0.1:{port}"


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["PYTHONUNBUFFERED"] = "1"
    env["PYTHONIOENCODING"] = "utf-8"
    env.pop("COLUMNS", None)
    return env


class Tfbus:
    """A ``tfbus`` child process; its stdout and stderr lines are collected by threads."""

    def __init__(self, *args: str) -> None:
        self.args = args
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tfbus.cli", *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            encoding="utf-8",
            env=_env(),
            cwd=ROOT,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        self.err: list[str] = []
        self.err_seen = threading.Condition()  # notified at each stderr line
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        threading.Thread(target=self._read_err, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def _read_err(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            with self.err_seen:
                self.err.append(line.rstrip("\n"))
                self.err_seen.notify_all()

    def expect_err(self, predicate: Callable[[str], bool], timeout: float = 15.0) -> str:
        """The first stderr line that matches, waiting up to ``timeout`` s for it."""
        with self.err_seen:
            found = self.err_seen.wait_for(
                lambda: any(predicate(line) for line in self.err) or self.proc.poll() is not None,
                timeout=timeout,
            )
            line = next((line for line in self.err if predicate(line)), None)
        if not found or line is None:
            raise AssertionError(self.describe("no matching stderr line"))
        return line

    def _more(self, deadline: float) -> bool:
        """Move one line into ``seen``; False when the deadline passed or stdout ended."""
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            try:
                self.seen.append(self.lines.get(timeout=min(remaining, 0.2)))
                return True
            except queue.Empty:
                if self.proc.poll() is not None and self.lines.empty():
                    # The process ended: wait for the reader to hand over its last lines.
                    self._reader.join(timeout=max(0.0, deadline - time.monotonic()))
                    if self.lines.empty():
                        return False

    def expect(
        self, predicate: Callable[[str], bool], timeout: float = 15.0, start: int = 0
    ) -> int:
        """Index in ``seen`` of the first line from ``start`` on that matches."""
        deadline = time.monotonic() + timeout
        i = start
        while True:
            while i < len(self.seen):
                if predicate(self.seen[i]):
                    return i
                i += 1
            if not self._more(deadline):
                raise AssertionError(self.describe("no matching line"))

    def finish(self, sig: int | None = None, timeout: float = 15.0) -> int:
        """Send ``sig`` (if still running), wait for the exit status and all output."""
        if sig is not None and self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            code = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(self.describe("did not exit")) from None
        deadline = time.monotonic() + 5.0
        while self._more(deadline):
            pass
        return code

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(timeout=10)

    def describe(self, what: str) -> str:
        return (
            f"tfbus {' '.join(self.args)}: {what} (exit {self.proc.poll()}); "
            f"stdout tail {self.seen[-8:]}; stderr tail {self.err[-8:]}"
        )


@contextmanager
def processes() -> Iterator[list[Tfbus]]:
    started: list[Tfbus] = []
    try:
        yield started
    finally:
        for p in started:
            p.kill()


def _sec(stamp: str) -> float:
    return float(stamp)


def test_listener_first_prints_error_then_info_lines() -> None:
    port = free_port()
    with processes() as ps:
        listener = Tfbus("demo", "listener", "--bus", connect_spec(port), "--duration", "40")
        ps.append(listener)
        # Nobody broadcasts yet: the tutorial's ERROR line, once a second.
        first = listener.expect(lambda line: line.startswith("[ERROR]"))
        second = listener.expect(lambda line: line.startswith("[ERROR]"), start=first + 1)
        e1, e2 = (ERROR.match(listener.seen[i]) for i in (first, second))
        assert e1 and e2, listener.seen[first : second + 1]
        assert abs(_sec(e2.group(1)) - _sec(e1.group(1)) - 1.0) < 0.25
        broadcaster = Tfbus("demo", "broadcaster", "--bus", listen_spec(port), "--duration", "40")
        ps.append(broadcaster)
        # ... then, once the broadcaster is up, the INFO lines, a second apart.
        i = listener.expect(lambda line: line.startswith("[ INFO]"), timeout=20.0)
        j = listener.expect(lambda line: line.startswith("[ INFO]"), start=i + 1)
        m1, m2 = (INFO.match(listener.seen[k]) for k in (i, j))
        assert m1 and m2, listener.seen[i : j + 1]
        assert abs(_sec(m2.group(1)) - _sec(m1.group(1)) - 1.0) < 0.25
        for m in (m1, m2):  # Time(0): the newest broadcast (stamp printed rounded to 10 ms)
            assert -0.006 < _sec(m.group(1)) - _sec(m.group(2)) < 0.5
        assert all(line.startswith("[ERROR]") for line in listener.seen[:i])
        assert all(line.startswith("[ INFO]") for line in listener.seen[i : j + 1])
        # Ctrl-C / SIGTERM: both exit cleanly with their summary lines.
        assert listener.finish(signal.SIGINT) == 0
        summary = LISTENER_SUMMARY.match(listener.seen[-1])
        assert summary, listener.seen[-3:]
        lookups, transformed, failed = (int(g) for g in summary.groups())
        assert failed >= 2 and transformed >= 2 and lookups == failed + transformed
        assert broadcaster.finish(signal.SIGTERM) == 0
        assert broadcaster.seen and broadcaster.seen[:-1] == []  # nothing but the summary
        bsummary = BROADCASTER_SUMMARY.match(broadcaster.seen[-1])
        assert bsummary, broadcaster.seen
        assert int(bsummary.group(1)) > 50


@pytest.mark.parametrize("backend", ["asyncio", "trio", "uvloop"])
def test_ctrl_c_at_any_moment_ends_the_listener_without_a_traceback(backend: str) -> None:
    """Ctrl-C (SIGINT) on ``tfbus demo listener`` at six moments of its run: as soon as it
    says it is running (bus open, signal handler not yet installed), at its first line,
    and after its 2nd, 3rd, 5th and 8th lines (lookups at 20 Hz in between). Each ends
    with status 0 (its summary line printed) or 130 (before the handler), never a
    traceback; on asyncio's own loop, trio and uvloop."""
    if backend != "asyncio":
        pytest.importorskip(backend)
    port = free_port()
    with processes() as ps:
        broadcaster = Tfbus("demo", "broadcaster", "--bus", listen_spec(port), "--duration", "120")
        ps.append(broadcaster)
        for moment in (0, 1, 2, 3, 5, 8):
            listener = Tfbus("demo", "listener", "--backend", backend, "--listen-rate", "20",
                             "--bus", connect_spec(port), "--duration", "60")
            ps.append(listener)
            if moment == 0:
                listener.expect_err(lambda line: "running the listener node" in line)
            else:
                listener.expect(lambda line: line.startswith("["), start=moment - 1)
            code = listener.finish(signal.SIGINT)
            what = listener.describe(f"SIGINT at moment {moment}")
            assert code in (0, 130), what
            assert not any("Traceback" in line for line in listener.err), what
            if code == 0:
                assert LISTENER_SUMMARY.match(listener.seen[-1]), what
        assert broadcaster.finish(signal.SIGINT) == 0


_INTERRUPT_WHILE_LOADING = """
import importlib.abc, os, signal, sys

class InterruptAtImport(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "tfbus.cli.demo":  # one of the command modules tfbus.cli.main loads
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C, delivered inside the import
        return None

from tfbus.cli import main
sys.meta_path.insert(0, InterruptAtImport())
sys.exit(main(["demo", "listener", "--help"]))
"""


def test_ctrl_c_while_the_commands_load_exits_130_without_a_traceback() -> None:
    """Ctrl-C while ``tfbus`` loads click, rich and its command modules (the second of
    start-up before any command runs): exit status 130, nothing on stdout, no
    traceback. The SIGINT is sent by an import hook at the import of a command module,
    so the moment is exact."""
    done = subprocess.run(
        [sys.executable, "-c", _INTERRUPT_WHILE_LOADING], capture_output=True, text=True,
        env=_env(), cwd=ROOT, timeout=60,
    )
    assert done.returncode == 130, done.stderr
    assert "Traceback" not in done.stderr and "KeyboardInterrupt" not in done.stderr
    assert done.stdout == ""


def test_echo_and_frames_attach_to_a_running_broadcaster(tmp_path: Path) -> None:
    port = free_port()
    with processes() as ps:
        broadcaster = Tfbus("demo", "broadcaster", "--bus", listen_spec(port), "--duration", "40")
        ps.append(broadcaster)
        echo = Tfbus(
            "echo", "base_link", "base_laser", "--bus", connect_spec(port), "-n", "1",
            "--duration", "20",
        )
        ps.append(echo)
        assert echo.finish(timeout=25.0) == 0, echo.describe("failed")
        assert echo.seen[0].startswith("At time ")
        assert "- Translation: [0.100, 0.000, 0.200]" in echo.seen
        assert "- Rotation: in Quaternion [0.000, 0.000, 0.000, 1.000]" in echo.seen
        assert sum(line.startswith("At time") for line in echo.seen) == 1

        out = tmp_path / "live.gv"
        frames = Tfbus("frames", "--bus", connect_spec(port), "--duration", "1", "-o", str(out))
        ps.append(frames)
        assert frames.finish(timeout=25.0) == 0, frames.describe("failed")
        dot = out.read_text()
        assert "base_link -> base_laser" in dot
        assert "Broadcaster: robot_tf_publisher" in dot


def test_monitor_lists_the_broadcaster_alive_then_reports_it_dead() -> None:
    port = free_port()
    alive_row = re.compile(r"robot_tf_publisher\s*[│|]\s*alive\s*[│|]\s*[0-9a-f]+\s*[│|]\s*/tf")
    gone_row = re.compile(r"robot_tf_publisher\s*[│|]\s*gone\s*[│|]")
    frame_row = re.compile(
        r"base_laser\s*[│|]\s*base_link\s*[│|]\s*robot_tf_publisher\s*[│|]\s*(\d+\.\d+)"
    )
    with processes() as ps:
        broadcaster = Tfbus("demo", "broadcaster", "--bus", listen_spec(port), "--duration", "40")
        ps.append(broadcaster)
        monitor = Tfbus(
            "monitor", "--bus", connect_spec(port), "--interval", "0.5", "--duration", "40"
        )
        ps.append(monitor)
        monitor.expect(lambda line: line.startswith("[alive] broadcaster robot_tf_publisher"))
        k = monitor.expect(lambda line: alive_row.search(line) is not None)
        f = monitor.expect(lambda line: frame_row.search(line) is not None)
        assert float(frame_row.search(monitor.seen[f]).group(1)) > 10  # type: ignore[union-attr]
        t = monitor.expect(lambda line: line.startswith("transport: "), start=f)
        counts = re.fullmatch(r"transport: (\d+) received, (\d+) lost \(gaps in the "
                              r"publishers' sequence numbers\), (\d+) dropped on receipt",
                              monitor.seen[t].strip())
        assert counts is not None and int(counts.group(1)) > 0, monitor.seen[t]
        broadcaster.kill()  # SIGKILL: no goodbye, Zenoh notices the link drop
        d = monitor.expect(
            lambda line: line.startswith("[dead] broadcaster robot_tf_publisher"), start=k
        )
        monitor.expect(lambda line: gone_row.search(line) is not None, start=d)
        assert monitor.finish(signal.SIGINT) == 0
        assert any(gone_row.search(line) for line in monitor.seen[-12:])  # final report


def test_static_transform_and_replay_reach_echo_over_the_bus() -> None:
    """``tfbus static-transform --bus`` and ``tfbus replay --bus``
    publish where ``tfbus echo --bus`` (another process) sees them; SIGTERM ends both
    cleanly (status 130, no traceback)."""
    turtle = ROOT / "tests" / "data" / "webviz_turtle_tf_example.bag"
    port = free_port()
    with processes() as ps:
        static = Tfbus("static-transform", "0.1", "0", "0.2", "0", "0", "0", "base_link",
                       "base_laser", "--bus", listen_spec(port))
        ps.append(static)
        static.expect(lambda line: line.startswith("publishing static transform"))
        echo = Tfbus("echo", "base_link", "base_laser", "--bus", connect_spec(port), "-n", "1",
                     "--duration", "20")
        ps.append(echo)
        assert echo.finish(timeout=25.0) == 0, echo.describe("failed")
        assert "- Translation: [0.100, 0.000, 0.200]" in echo.seen
        assert static.finish(signal.SIGTERM) == 0, static.describe("SIGTERM")

        port = free_port()
        replay = Tfbus("replay", str(turtle), "--bus", listen_spec(port))
        ps.append(replay)
        echo = Tfbus("echo", "turtle1", "carrot", "--bus", connect_spec(port), "-n", "1",
                     "--duration", "20")
        ps.append(echo)
        assert echo.finish(timeout=25.0) == 0, echo.describe("failed")
        assert "- Translation: [1.000, 0.000, 0.000]" in echo.seen  # the bag's static
        assert replay.finish(signal.SIGTERM) == 130, replay.describe("SIGTERM")
        assert any(line.endswith("(interrupted)") for line in replay.seen), replay.seen


class Simulator:
    """A simulation in a thread of this process, on its own event loop: ``/clock`` at
    ten times real time (0.1 s of simulated time every 10 ms of wall time, from 100 s)
    and the tutorial's base_link -> base_laser on ``/tf`` stamped with it, over Zenoh
    listening on ``port``; it runs until :meth:`close` or 120 s of wall time."""

    START_NS = 100_000_000_000
    STEP_NS = 100_000_000

    def __init__(self, port: int) -> None:
        self.port = port
        self.done = threading.Event()
        self.sim_ns = 0
        self.joint_stamps: list[int] = []  # /joint_states header stamps heard (ns)
        self.failure: BaseException | None = None
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import anyio

        try:
            anyio.run(self._main)
        except BaseException as err:  # reported by close()
            self.failure = err

    async def _main(self) -> None:
        import anyio

        from tfbus import Bus
        from tfbus.messages import (
            Clock,
            Header,
            TFMessage,
            Transform,
            TransformStamped,
            Vector3,
        )
        from tfbus.time import Time
        from tfbus.topics import CLOCK_TOPIC, JOINT_STATES_TOPIC, TF_TOPIC
        from tfbus.transports.zenoh import ZenohTransport

        def on_joint_state(message: object) -> None:
            self.joint_stamps.append(message.header.stamp.ns)  # type: ignore[attr-defined]

        transport = ZenohTransport(listen=f"tcp/127.0.0.1:{self.port}", name="simulator")
        async with Bus(transport=transport) as bus:
            bus.subscribe_callback(JOINT_STATES_TOPIC, on_joint_state)
            with anyio.move_on_after(120):
                k = 0
                while not self.done.is_set():
                    self.sim_ns = self.START_NS + k * self.STEP_NS
                    now = Time.from_ns(self.sim_ns)
                    bus.publish_nowait(CLOCK_TOPIC, Clock(now))
                    bus.publish_nowait(TF_TOPIC, TFMessage((TransformStamped(
                        Header(now, "base_link"), "base_laser",
                        Transform(Vector3(0.1, 0.0, 0.2))),)))
                    k += 1
                    await anyio.sleep(0.01)

    def close(self) -> None:
        self.done.set()
        self._thread.join(timeout=20)
        assert not self._thread.is_alive(), "the simulator thread did not end"
        if self.failure is not None:
            raise self.failure


def test_listener_with_use_sim_time_prints_one_line_per_simulated_second() -> None:
    port = free_port()
    sim = Simulator(port)
    try:
        with processes() as ps:
            listener = Tfbus("demo", "listener", "--use-sim-time", "--bus", connect_spec(port),
                             "--duration", "60")
            ps.append(listener)
            # The timer's schedule is anchored where its first wait began (rcl_timer's):
            # at simulated 0 if no /clock had arrived yet, and then its first tick is the
            # catch-up on the jump to 100 s (the latest passed deadline, late); or at the
            # /clock already heard when the listener started (a loaded machine). The lines
            # after the first count.
            i = listener.expect(lambda line: line.startswith("[ INFO]"), timeout=30.0)
            i = listener.expect(lambda line: line.startswith("[ INFO]"), start=i + 1)
            lines = [listener.seen[i]]
            for _ in range(4):
                i = listener.expect(lambda line: line.startswith("[ INFO]"), start=i + 1)
                lines.append(listener.seen[i])
            matches = [INFO.match(line) for line in lines]
            assert all(matches), lines
            nows = [_sec(m.group(1)) for m in matches if m]
            stamps = [_sec(m.group(2)) for m in matches if m]
            # Simulated time: 100 s and on, not the wall clock's 1.7e9 s.
            assert all(100.0 <= t < 100.0 + 120 * 10 for t in nows), lines
            # A line per simulated second on one grid (no drift). A tick prints the time it
            # reads when it runs, never before its deadline and late by what the listener
            # was kept from running meanwhile: the simulator steps 0.1 s a 10 ms of wall
            # time, so a listener held off the CPU for 40 ms on a loaded machine (seen at
            # load 8) prints a time 0.4 s past its deadline, as a /clock lost on the way
            # (Zenoh drops under load) makes it 0.1 s late. The grid's phase is the one
            # that leaves every tick late by the least (at most 0.5 s: half a period, so
            # a grid 1 s apart stays unambiguous), and the deadlines are 1 s apart.
            tenths = [round(t * 10) for t in nows]
            lags = min(([(k - phase) % 10 for k in tenths] for phase in range(10)), key=max)
            assert max(lags) <= 5, nows
            deadlines = [k - lag for k, lag in zip(tenths, lags, strict=True)]
            assert all(b - a == 10 for a, b in pairwise(deadlines)), nows
            # The lookup at Time(0) answers the newest /tf: stamped at or just before the
            # time the tick reads (0.3 s, and the tick's lateness).
            assert all(0.0 <= n - s <= 0.3 + lag / 10 + 1e-6
                       for n, s, lag in zip(nows, stamps, lags, strict=True)), lines
            assert listener.finish(signal.SIGINT) == 0

            echo = Tfbus("echo", "base_link", "base_laser", "--use-sim-time", "--bus",
                         connect_spec(port), "-n", "1", "--duration", "30")
            ps.append(echo)
            assert echo.finish(timeout=35.0) == 0, echo.describe("failed")
            at = next(line for line in echo.seen if line.startswith("At time "))
            assert 100.0 <= float(at.split()[2]) <= sim.sim_ns / 1e9, echo.seen
            assert "- Translation: [0.100, 0.000, 0.200]" in echo.seen
    finally:
        sim.close()


def test_joint_states_with_use_sim_time_stamps_with_clock() -> None:
    port = free_port()
    sim = Simulator(port)
    try:
        with processes() as ps:
            joints = Tfbus("joint-states", "demos/robot.urdf", "--use-sim-time", "--rate", "10",
                           "--bus", connect_spec(port), "--duration", "60")
            ps.append(joints)
            deadline = time.monotonic() + 30
            while len([t for t in sim.joint_stamps if t > 0]) < 5:
                assert time.monotonic() < deadline, joints.describe("no stamped joint states")
                time.sleep(0.05)
            stamps = [t / 1e9 for t in sim.joint_stamps if t > 0]
            # Simulated time (100 s on), not the wall clock's, each a /clock step (0.1 s);
            # at 10 Hz of simulated time: 0.1 s apart (10 ms of wall time at 10x), or a
            # step or two more where Zenoh dropped a /clock or a JointState under load.
            assert all(100.0 <= t <= sim.sim_ns / 1e9 for t in stamps), stamps
            assert all(abs(t * 10 - round(t * 10)) < 1e-6 for t in stamps), stamps
            gaps = [round((b - a) * 10) for a, b in pairwise(stamps[1:])]
            assert all(1 <= g <= 3 for g in gaps) and gaps.count(1) >= len(gaps) // 2, stamps
            assert joints.finish(signal.SIGTERM) == 0
    finally:
        sim.close()
