"""The ROS 1 peers' harness (``peers/ros1/ros1_peers.py``): a roscore whose port another
process bound between choosing it and roscore binding it is started on another port
(seen once in a clean-clone run: ``port 45591 is already in use``, then a 60 s wait)."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import ros1_peers
from ros1_harness import ros1_fixture  # noqa: F401  (registers the fixture)

_free_port = ros1_peers.free_port


def _taken_then_free(taken: int) -> Iterator[int]:
    yield taken
    while True:
        yield _free_port()


def test_a_taken_port_is_chosen_again(
    ros1: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Bound, not listening: as a port an outgoing connection holds (a listening socket
    # would answer roscore's "is a master running?" probe and hang it instead).
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as holder:
        holder.bind(("127.0.0.1", 0))
        taken = int(holder.getsockname()[1])
        ports = _taken_then_free(taken)
        monkeypatch.setattr(ros1_peers, "free_port", lambda: next(ports))
        master = ros1_peers.start_master(tmp_path / "ros_home", attempts=2)
        try:
            assert master.port != taken
            assert master.call("getUri", "/tfbus_test") == master.uri + "/"
        finally:
            master.stop()
        # One attempt only: the taken port is reported at once, not after 60 s.
        ports = _taken_then_free(taken)
        start = time.monotonic()
        with pytest.raises(ros1_peers.PortTaken, match=f"port {taken} is already in use"):
            ros1_peers.start_master(tmp_path / "ros_home", attempts=1)
        assert time.monotonic() - start < 50.0
        assert not _roscores_on(taken)  # the one that could not bind was stopped


def _roscores_on(port: int) -> list[int]:
    """PIDs of roscore processes started with ``-p port``."""
    found = []
    for proc in Path("/proc").iterdir():
        try:
            args = (proc / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if any(a.endswith(b"roscore") for a in args) and str(port).encode() in args:
            found.append(int(proc.name))
    return found
