"""``tfbus replay`` (rosbag play for /tf and /tf_static): fast replay, the progress bar,
damaged bags, and SIGTERM mid-replay."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

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

from tfbus import Time
from tfbus.bag import read_messages


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
