"""``tfbus doctor --bus`` over Zenoh, as real processes: ``tfbus demo broadcaster`` sends
``base_link -> base_laser`` on /tf while ``tfbus static-transform`` sends the same link on
/tf_static; the doctor names the fault and both senders (Zenoh liveliness), and ``tfbus
monitor --bus`` prints the same finding below its tables.

Every process runs on 127.0.0.1 with explicit endpoints on free ports (the transport's
defaults keep multicast scouting off); every wait is on an output line against a
deadline; the children are ended by PID in ``finally``.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytest.importorskip("zenoh")
pytest.importorskip("msgspec")

from doctor_procs import ROOT, Child, child_env, free_port


def test_static_and_dynamic_over_zenoh_names_both_senders() -> None:
    a, b = free_port(), free_port()
    children: list[Child] = []
    try:
        dynamic = Child("demo", "broadcaster", "--bus", f"zenoh?listen=tcp/127.0.0.1:{a}",
                         "--duration", "120")
        children.append(dynamic)
        static = Child("static-transform", "0.1", "0", "0.2", "0", "0", "0", "base_link",
                        "base_laser", "--bus", f"zenoh?listen=tcp/127.0.0.1:{b}")
        children.append(static)
        dynamic.expect("running the broadcaster node")
        static.expect("publishing static transform")
        doctor = subprocess.run(
            [sys.executable, "-m", "tfbus.cli", "doctor", "--bus",
             f"zenoh:connect=tcp/127.0.0.1:{a},tcp/127.0.0.1:{b}", "--duration", "5",
             "--json"],
            cwd=ROOT, env=child_env(), capture_output=True, text=True, timeout=90)
        monitor = subprocess.run(
            [sys.executable, "-m", "tfbus.cli", "monitor", "--bus",
             f"zenoh:connect=tcp/127.0.0.1:{a},tcp/127.0.0.1:{b}", "--duration", "6",
             "--interval", "60"],
            cwd=ROOT, env=child_env(), capture_output=True, text=True, timeout=90)
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
    # tfbus monitor prints the live findings below its tables, with the same senders
    assert monitor.returncode == 0, monitor.stderr
    table = monitor.stdout.split("Findings (tfbus doctor)", 1)[1]
    row = next(line for line in table.splitlines() if "static_and_dynamic" in line)
    assert [c.strip() for c in row.split("│")[:4]] == [
        "error", "static_and_dynamic", "base_laser", "robot_tf_publisher"]
