"""``tfbus doctor --bus`` over Zenoh, as real processes: ``tfbus demo broadcaster`` sends
``base_link -> base_laser`` on /tf while ``tfbus static-transform`` sends the same link on
/tf_static; the doctor names the fault and both senders (Zenoh liveliness).

Every process runs on 127.0.0.1 with explicit endpoints on free ports (the transport's
defaults keep multicast scouting off); every wait is on an output line against a
deadline; the children are ended by PID in ``finally``.
"""

from __future__ import annotations

import json
import os
import queue
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("zenoh")
pytest.importorskip("msgspec")

ROOT = Path(__file__).resolve().parents[2]


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["PYTHONUNBUFFERED"] = "1"
    return env


class _Child:
    """A ``tfbus`` child process whose output lines a thread collects."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tfbus.cli", *args], cwd=ROOT, env=_env(),
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def expect(self, needle: str, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while not any(needle in line for line in self.seen):
            left = deadline - time.monotonic()
            assert left > 0, f"no line with {needle!r} in {timeout} s: {self.seen}"
            try:
                self.seen.append(self.lines.get(timeout=min(left, 1.0)))
            except queue.Empty:
                assert self.proc.poll() is None, f"exited {self.proc.returncode}: {self.seen}"

    def end(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=20)


def test_static_and_dynamic_over_zenoh_names_both_senders() -> None:
    a, b = _free_port(), _free_port()
    children: list[_Child] = []
    try:
        dynamic = _Child("demo", "broadcaster", "--bus", f"zenoh?listen=tcp/127.0.0.1:{a}",
                         "--duration", "120")
        children.append(dynamic)
        static = _Child("static-transform", "0.1", "0", "0.2", "0", "0", "0", "base_link",
                        "base_laser", "--bus", f"zenoh?listen=tcp/127.0.0.1:{b}")
        children.append(static)
        dynamic.expect("running the broadcaster node")
        static.expect("publishing static transform")
        doctor = subprocess.run(
            [sys.executable, "-m", "tfbus.cli", "doctor", "--bus",
             f"zenoh:connect=tcp/127.0.0.1:{a},tcp/127.0.0.1:{b}", "--duration", "5",
             "--json"],
            cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=90)
    finally:
        for child in children:
            child.end()
    assert doctor.returncode == 1, doctor.stderr  # an error: --fail-on error
    assert "Traceback" not in doctor.stderr
    report = json.loads(doctor.stdout)
    found = [(f["check"], f["frames"], f["senders"]) for f in report["findings"]]
    assert found == [("static_and_dynamic", ["base_laser", "base_link"],
                      ["robot_tf_publisher", "static_transform_publisher"])]
    assert report["messages"] > 50
