"""``tfbus.compat.tf2_ros`` with the real rclpy (ROS 2 wheels in ``.venv-ros2``, built by
``scripts/install/install_ros2_env.sh``): ``TransformListener(buffer, node)`` fills the buffer
from an rclpy node's ``/tf`` and ``/tf_static``, sent by the compat broadcasters on
another node. Runs in a subprocess (``peers/ros2/compat_rclpy_peer.py``) on a
random ``ROS_DOMAIN_ID``, Fast DDS restricted to 127.0.0.1 by a profile written here."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest
from dds_domains import new_domain
from peer_install import peer_unavailable, require

ROOT = Path(__file__).resolve().parents[2]
ROS_PYTHON = ROOT / ".venv-ros2" / "bin" / "python"
PEER = ROOT / "peers" / "ros2" / "compat_rclpy_peer.py"

FASTDDS_LOOPBACK = """<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com">
  <profiles>
    <transport_descriptors>
      <transport_descriptor>
        <transport_id>udp_lo</transport_id>
        <type>UDPv4</type>
        <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>
      </transport_descriptor>
    </transport_descriptors>
    <participant profile_name="tfbus_compat_lo" is_default_profile="true">
      <rtps>
        <userTransports><transport_id>udp_lo</transport_id></userTransports>
        <useBuiltinTransports>false</useBuiltinTransports>
      </rtps>
    </participant>
  </profiles>
</dds>
"""


@pytest.fixture(scope="module", name="ros_python")
def ros_python_fixture() -> Path:
    if sys.platform != "linux":
        peer_unavailable("ros2-env", "the ROS 2 wheels are manylinux only")
    require("ros2-env", "install_ros2_env.sh", timeout=1200)
    assert ROS_PYTHON.exists()
    return ROS_PYTHON


def _run_peer(ros_python: Path, tmp_path: Path, script: Path) -> subprocess.CompletedProcess[str]:
    """``script`` run to its end under the ROS 2 venv's python, on a random domain, Fast DDS
    on 127.0.0.1 only; it must exit with status 0."""
    if sys.version_info[:2] != (3, 11):
        pytest.skip("the ROS 2 venv is Python 3.11: this environment's packages cannot be shared")
    profile = tmp_path / "fastdds_lo.xml"
    profile.write_text(FASTDDS_LOOPBACK)
    paths = sysconfig.get_paths()  # the test runner's own environment (anyio, numpy, ...)
    site = os.pathsep.join(dict.fromkeys([paths["purelib"], paths["platlib"]]))
    env = dict(
        os.environ,
        ROS_DOMAIN_ID=str(new_domain()),
        RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        FASTDDS_DEFAULT_PROFILES_FILE=str(profile),
        # tfbus from this checkout; its dependencies (anyio, ...) from the project venv
        PYTHONPATH=os.pathsep.join([str(ROOT), site]),
        PYTHONUNBUFFERED="1",
    )
    env.pop("ROS_LOCALHOST_ONLY", None)
    r = subprocess.run([str(ros_python), str(script)], env=env, capture_output=True, text=True,
                       timeout=120, check=False)
    assert r.returncode == 0, (r.returncode, r.stderr[-2000:])
    return r


def test_listener_on_an_rclpy_node(ros_python: Path, tmp_path: Path) -> None:
    answer = json.loads(_run_peer(ros_python, tmp_path, PEER).stdout.strip().splitlines()[-1])
    assert answer == {
        "frame_id": "map",
        "child_frame_id": "laser",
        "stamp_ns": 2_000_000_000,
        "translation": [2.5, 0.0, 0.0],
        # an rclpy Time given: an rclpy message returned (the caller's type)
        "type": "geometry_msgs.msg._transform_stamped.TransformStamped",
        # ROS 2's non-blocking forms under rclpy's executor: rclpy Futures
        "future_type": "rclpy.task.Future",
        "done_before": False,
        "wait_result": True,
        "awaited_x": 8.5,
        "timeout_error": "TimeoutException",
    }


SIM_TIME_PEER = ROOT / "peers" / "ros2" / "compat_sim_time_peer.py"


def test_buffer_under_an_rclpy_node_with_use_sim_time_follows_clock(
    ros_python: Path, tmp_path: Path
) -> None:
    """``Buffer()`` + ``TransformListener(buffer, node)`` (and ``Buffer(node=node)``)
    under a node whose ``use_sim_time`` is true run on a SimClock following ``/clock``
    as the node hears it: the same time as the node's own rclpy clock; a ``/clock``
    2e9 s ahead is counted and dropped. A node without it stays on the system clock."""
    r = _run_peer(ros_python, tmp_path, SIM_TIME_PEER)
    answer = json.loads(r.stdout.strip().splitlines()[-1])
    published = answer.pop("published_ns")
    assert published > 101_000_000_000 and published % 100_000_000 == 0
    assert answer == {
        "clock": "SimClock",
        "same_clock_for_node_buffer": True,
        "now_ns": published,
        "rclpy_now_ns": published,  # rclpy's own TimeSource reads the same /clock
        "x": answer["expected_x"],
        "expected_x": (published - 100_000_000_000) / 1e9,
        "dropped": 1,  # the /clock 2e9 s ahead
        "jumps": 0,
        "wall_clock": "SystemClock",
        "wall_now_after_2020": True,
    }


MALFORMED_PEER = ROOT / "peers" / "ros2" / "compat_malformed_peer.py"


def test_an_undecodable_tf_message_on_an_rclpy_node_is_counted_and_dropped(
    ros_python: Path, tmp_path: Path
) -> None:
    """Among valid ``/tf`` messages, three the listener cannot decode (a stamp before 1970,
    a frame id that is not UTF-8, a truncated sample: see the peer's docstring) are
    counted, logged once and dropped; the node keeps spinning and stores the messages
    after them; a NaN transform is refused alone, the valid one beside it stored."""
    r = _run_peer(ros_python, tmp_path, MALFORMED_PEER)
    answer = json.loads(r.stdout.strip().splitlines()[-1])
    assert answer["malformed"] == 3
    # map -> base halfway between x = 1 (1 s) and 2 (2 s), then base -> laser 0.5
    assert answer["map_laser_x_at_1.5"] == 2.0
    assert answer["ghost"] is False
    frames = sorted(line[:-2] for line in answer["yaml"].splitlines() if line.endswith(": "))
    assert frames == ["base", "laser"]  # no "ghost" and nothing from the malformed ones
    warnings = [line for line in r.stderr.splitlines() if "cannot be decoded" in line]
    assert len(warnings) == 1, r.stderr[-2000:]  # one line per 5 s, the rest counted
    assert "TransformListener: a TFMessage on /tf that cannot be decoded was dropped" in (
        warnings[0])
    assert "Traceback" not in r.stderr
