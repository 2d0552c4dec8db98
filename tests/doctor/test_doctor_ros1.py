"""``tfbus doctor --bus ros1`` against the real ROS 1 (Debian's roscore, the tutorial's C++
``tf_broadcaster``): the C++ node sends ``base_link -> base_laser`` on /tf while ``tfbus
static-transform --bus ros1`` sends it on /tf_static; the doctor names the fault and both
senders by their caller ids. All on 127.0.0.1; waits on output lines, each bounded."""

from __future__ import annotations

import json
import signal
import subprocess
from pathlib import Path

import pytest
from ros1_harness import (  # noqa: F401  (the *_fixture names register fixtures)
    Master,
    Proc,
    master_fixture,
    ros1_fixture,
    tfbus_cli,
    tutorial_nodes_fixture,
)

pytest.importorskip("rosbags")


def _finish(proc: Proc, timeout: float = 90.0) -> list[str]:
    try:
        proc.proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.stop(signal.SIGTERM)
        raise AssertionError(f"{proc.args} did not finish: {proc.drain()[-20:]}") from None
    proc.stop()
    return proc.drain()


def test_static_and_dynamic_over_ros1_names_both_caller_ids(
    master: Master, tutorial_nodes: Path
) -> None:
    bc = master.run(str(tutorial_nodes / "tf_broadcaster"))
    static = tfbus_cli(master, "static-transform", "0.1", "0", "0.2", "0", "0", "0",
                       "base_link", "base_laser", "--bus", "ros1")
    try:
        match = static.wait_for(r"publishing static transform", 60.0)
        assert match is not None
        doctor = tfbus_cli(master, "doctor", "--bus", "ros1", "--duration", "6", "--json")
        lines = _finish(doctor)
    finally:
        static.stop(signal.SIGTERM)
        bc.stop()
    assert doctor.proc.returncode == 1, lines
    start = next(i for i, line in enumerate(lines) if line.startswith("{"))
    end = max(i for i, line in enumerate(lines) if line.startswith("}"))
    report = json.loads("\n".join(lines[start:end + 1]))
    (found,) = report["findings"]
    assert (found["check"], found["frames"]) == ("static_and_dynamic",
                                                 ["base_laser", "base_link"])
    dynamic, static_id = found["senders"]  # sorted: the C++ node's id sorts first
    assert dynamic == "/robot_tf_publisher"
    assert static_id.startswith("/static_transform_publisher")
    assert f"on /tf_static (by {static_id})" in found["message"]
    assert f"on /tf (by {dynamic})" in found["message"]
