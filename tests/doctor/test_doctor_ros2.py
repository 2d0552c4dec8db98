"""``tfbus doctor --bus ros2`` over DDS (Cyclone DDS), as real processes on one random
domain: ``tfbus demo broadcaster`` sends ``base_link -> base_laser`` on /tf while
``tfbus static-transform`` sends it on /tf_static. ROS 2 does not say which node sent a
sample, so the finding names the fault and the frames, with the placeholder sender
``unknown`` (as ``tfbus monitor`` names it). Waits on output lines, each bounded; the
children are ended by PID."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from dds_domains import new_domain

pytest.importorskip("cyclonedds")

from doctor_procs import ROOT, Child, child_env


def test_static_and_dynamic_over_ros2() -> None:
    domain = new_domain()
    spec = f"ros2:domain={domain}"
    env = child_env()
    env.pop("CYCLONEDDS_URI", None)  # the transport's defaults: loopback, no multicast
    children: list[Child] = []
    try:
        dynamic = Child("demo", "broadcaster", "--bus", spec, "--duration", "120", env=env)
        children.append(dynamic)
        static = Child("static-transform", "0.1", "0", "0.2", "0", "0", "0", "base_link",
                       "base_laser", "--bus", spec, env=env)
        children.append(static)
        dynamic.expect("running the broadcaster node")
        static.expect("publishing static transform")
        doctor = subprocess.run(
            [sys.executable, "-m", "tfbus.cli", "doctor", "--bus", spec, "--duration", "5",
             "--json"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=90)
    finally:
        for child in children:
            child.end()
    assert doctor.returncode == 1, doctor.stderr
    assert "Traceback" not in doctor.stderr
    report = json.loads(doctor.stdout)
    found = [(f["check"], f["frames"], f["senders"]) for f in report["findings"]]
    assert found == [("static_and_dynamic", ["base_laser", "base_link"], ["unknown"])]
    assert report["messages"] > 50
