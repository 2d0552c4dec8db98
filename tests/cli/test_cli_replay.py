"""``tfbus replay`` (rosbag play for /tf and /tf_static): fast replay, the progress bar,
damaged bags, and SIGTERM mid-replay."""

from __future__ import annotations

import itertools
import os
import re
import signal
import socket
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("click")
pytest.importorskip("rich")
pytest.importorskip("rosbags")

from cli_support import (
    ROOT,
    TURTLE,
    assert_usage_error,
    run,
)

from tfbus import Duration, Time
from tfbus.bag import read_messages


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_replay_fast() -> None:
    code, out, _ = run("replay", str(TURTLE), "--rate", "0", "-q", "--local")
    assert code == 0 and "replayed 2689 messages" in out
    code, out, _ = run("replay", str(TURTLE), "--rate", "0", "-q", "--local",
                       "--start", "1396293900", "--stop", "1396293901")
    assert code == 0
    n = int(re.search(r"replayed (\d+)", out).group(1))  # type: ignore[union-attr]
    assert n == 1 + len(list(read_messages(TURTLE, start=Time(1396293900),
                                           stop=Time(1396293901), latched=False)))


def test_replay_progress_bar() -> None:
    code, _, err = run("replay", str(TURTLE), "--rate", "0", "--local")
    assert code == 0 and "2689/2689" in err


def test_replay_truncated_and_bad_args(tmp_path: Path) -> None:
    cut = tmp_path / "cut.bag"
    data = TURTLE.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    code, _, err = run("replay", str(cut), "--rate", "0", "-q", "--local")
    assert code == 1 and "reading stopped" in err and len(err.strip().splitlines()) == 1
    code, _, err = run("replay", str(TURTLE), "--rate", "-2")
    assert_usage_error(code, err, "--rate")


def test_sigterm_during_replay() -> None:
    """Replay stops on SIGTERM with its count line and status 130."""
    proc = subprocess.Popen([sys.executable, "-m", "tfbus.cli", "replay", str(TURTLE),
                             "--local"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT, env={**os.environ, "COLUMNS": "80"})
    try:
        assert proc.stderr is not None
        seen = ""
        while "replaying" not in seen:  # it has started (bounded: EOF ends the loop)
            char = proc.stderr.read(1)
            if not char:
                break
            seen += char
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130 and "Traceback" not in seen + err
    assert "(interrupted)" in out


@pytest.mark.anyio
async def test_space_key_on_a_terminal_pauses_and_resumes_replay_and_its_clock() -> None:
    """Standard input a terminal (a pty): space pauses ``tfbus replay --clock`` -- no
    message, /clock repeating one time, as rosbag play -- and space resumes it; /clock is
    read over Zenoh by a SimClock in this process. Every wait is bounded."""
    import pty

    import anyio

    pytest.importorskip("zenoh")
    from tfbus import Bus, SimClock
    from tfbus.messages import Clock
    from tfbus.topics import CLOCK_TOPIC
    from tfbus.transports.zenoh import ZenohTransport

    port = free_port()
    start = Time(1396293904)
    master, slave = pty.openpty()
    env = {**os.environ, "COLUMNS": "80", "PYTHONUNBUFFERED": "1",
           "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    command = [sys.executable, "-m", "tfbus.cli", "replay", str(TURTLE), "--clock", "-q",
               "--start", str(start.to_sec()), "--bus", f"zenoh?listen=tcp/127.0.0.1:{port}"]
    err = b""
    stamps: list[int] = []
    try:
        proc = await anyio.open_process(command, stdin=slave, cwd=ROOT, env=env)
        try:
            assert proc.stderr is not None

            async def expect(needle: bytes) -> None:
                nonlocal err
                with anyio.fail_after(30):
                    while needle not in err:
                        err += await proc.stderr.receive()  # type: ignore[union-attr]

            transport = ZenohTransport(connect=f"tcp/127.0.0.1:{port}", name="pty-test")
            async with Bus(transport=transport) as bus, SimClock(bus) as clock:
                bus.subscribe_callback(
                    CLOCK_TOPIC, lambda m: stamps.append(m.clock.ns)
                    if isinstance(m, Clock) else None)

                async def until(condition: Callable[[], bool]) -> None:
                    with anyio.fail_after(30):
                        while not condition():
                            await anyio.sleep(0.01)

                await until(lambda: clock.now() > start + Duration(0, 300_000_000))
                os.write(master, b" ")
                await expect(b"[PAUSED]")
                paused_from = len(stamps) + 10  # past any /clock in flight at the pause
                await until(lambda: len(stamps) >= paused_from + 20)  # 0.2 s at 100 Hz
                held = stamps[paused_from:paused_from + 20]
                assert len(set(held)) == 1, held  # /clock stands still, still published
                assert clock.now().ns == held[0]
                os.write(master, b"x ")  # another key is ignored
                await expect(b"[RUNNING]")
                await until(lambda: clock.now().ns > held[0])  # runs on from there
                with anyio.fail_after(60):
                    code = await proc.wait()
                err += await _rest(proc.stderr)
                assert proc.stdout is not None
                out = (await _rest(proc.stdout)).decode()
        finally:
            if proc.returncode is None:  # a failure above: end it, by its PID
                proc.kill()
                with anyio.move_on_after(10, shield=True):
                    await proc.wait()
    finally:
        os.close(master)
        os.close(slave)
    assert code == 0, err
    assert err.count(b"[PAUSED]") == 1 and err.count(b"[RUNNING]") == 1 and b"Traceback" not in err
    n = sum(1 for _ in read_messages(TURTLE, start=start))
    assert f"replayed {n} messages" in out
    assert all(a <= b for a, b in itertools.pairwise(stamps))


async def _rest(stream: Any) -> bytes:
    """Everything left on a process's output stream, to its end."""
    import anyio

    data = b""
    with anyio.fail_after(10):
        while True:
            try:
                data += await stream.receive()
            except anyio.EndOfStream:
                return data


def test_pause_needs_a_terminal() -> None:
    code, _, err = run("replay", str(TURTLE), "--pause", "--local", "-q")
    assert_usage_error(code, err, "--pause", "needs a terminal")
