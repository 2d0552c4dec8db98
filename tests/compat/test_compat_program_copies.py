"""The public tf2 programs copied into ``tests/compat/programs/`` differ from their
upstream files only in import lines: ``NAME.imports.diff`` applied in reverse to the copy
gives back, byte for byte, the upstream file at the recorded commit (its git blob id), and
every line that diff changes is an ``import`` / ``from ... import`` line."""

from __future__ import annotations

import hashlib
import re
import shutil
import subprocess
from pathlib import Path

import pytest

PROGRAMS = Path(__file__).resolve().parent / "programs"

GEOMETRY2 = ("ros2/geometry2", "1b005c6556cf350d7670812ef30eefed8443a759")
TUTORIALS_ROS2 = ("ros/geometry_tutorials", "6481e8fa9b5cef611f3d6d3aea2ea338701c481a")
TUTORIALS_ROS1 = ("ros/geometry_tutorials", "c9bc222f286562dfbc8c02789cb1fb8ea00e31a2")

# name -> (repository, commit, path there, git blob id of that file at that commit)
UPSTREAM: dict[str, tuple[str, str, str, str]] = {
    "static_broadcaster": (*GEOMETRY2, "examples_tf2_py/examples_tf2_py/static_broadcaster.py",
                           "7c2d550fc9a4db4714af7453e6c82eb41c854c8a"),
    "frame_dumper": (*GEOMETRY2, "examples_tf2_py/examples_tf2_py/frame_dumper.py",
                     "2e61ac2050d7454764572e2ec68f7109e254e607"),
    "waits_for_transform": (*GEOMETRY2, "examples_tf2_py/examples_tf2_py/waits_for_transform.py",
                            "25d144f0163434ed7689440d7544fb3662265838"),
    "async_waits_for_transform": (
        *GEOMETRY2, "examples_tf2_py/examples_tf2_py/async_waits_for_transform.py",
        "08434af4c139cf074c8340d3525e70094b9c07c1"),
    "blocking_waits_for_transform": (
        *GEOMETRY2, "examples_tf2_py/examples_tf2_py/blocking_waits_for_transform.py",
        "bbdfd4967c51b7228cf4cb1204994423a09849af"),
    "static_turtle_tf2_broadcaster": (
        *TUTORIALS_ROS2, "turtle_tf2_py/turtle_tf2_py/static_turtle_tf2_broadcaster.py",
        "c5fd9b6eef7caaa2f0d652547d6f7810b37b32e3"),
    "fixed_frame_tf2_broadcaster": (
        *TUTORIALS_ROS2, "turtle_tf2_py/turtle_tf2_py/fixed_frame_tf2_broadcaster.py",
        "b8f5cc0da0b8b1d8e9881e3439e027ce967b3447"),
    "dynamic_frame_tf2_broadcaster": (
        *TUTORIALS_ROS2, "turtle_tf2_py/turtle_tf2_py/dynamic_frame_tf2_broadcaster.py",
        "44030c4cd4beac647f3deb6c36631649e5d4910c"),
    "fixed_tf2_broadcaster": (*TUTORIALS_ROS1, "turtle_tf2/nodes/fixed_tf2_broadcaster.py",
                              "da5ac42dc5d52d1bc0811229a6448efd1cef9e4f"),
    "dynamic_tf2_broadcaster": (*TUTORIALS_ROS1, "turtle_tf2/nodes/dynamic_tf2_broadcaster.py",
                                "1776ff71fe0fe0ab1c5c2f2759b047620037403f"),
    "turtle_tf2_listener": (*TUTORIALS_ROS1, "turtle_tf2/nodes/turtle_tf2_listener.py",
                            "b82c6ca669ed083471c7c15721f43f6d9a0cde7c"),
    "turtle_tf2_broadcaster": (*TUTORIALS_ROS1, "turtle_tf2/nodes/turtle_tf2_broadcaster.py",
                               "13a28565f2a68899e91245e6b98d15a05acab3ee"),
}

IMPORT_LINE = re.compile(r"^[+-](import [\w.]+( as \w+)?|from [\w.]+ import [\w, ]+)$")


def git_blob_id(data: bytes) -> str:
    """The id git gives a file of these bytes (``git hash-object``)."""
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def test_every_copy_is_recorded() -> None:
    copies = {p.stem for p in PROGRAMS.glob("*.py")}
    assert copies == set(UPSTREAM)
    assert {p.name.removesuffix(".imports.diff") for p in PROGRAMS.glob("*.imports.diff")} \
        == set(UPSTREAM)


@pytest.mark.parametrize("name", sorted(UPSTREAM))
def test_copy_differs_from_upstream_only_in_imports(name: str, tmp_path: Path) -> None:
    diff = PROGRAMS / f"{name}.imports.diff"
    original = tmp_path / f"{name}.py"
    shutil.copy(PROGRAMS / f"{name}.py", original)
    r = subprocess.run(["patch", "-R", "-s", "--no-backup-if-mismatch", str(original),
                        str(diff)], capture_output=True, text=True, timeout=30, check=False)
    assert r.returncode == 0, r.stdout + r.stderr
    assert git_blob_id(original.read_bytes()) == UPSTREAM[name][3]
    changed = [line for line in diff.read_text().splitlines()
               if line[:1] in "+-" and not line.startswith(("+++ ", "--- "))]
    assert changed, "the copy must differ (its tf2 imports point at tfbus.compat)"
    assert [line for line in changed if not IMPORT_LINE.match(line)] == []
    assert all("tfbus.compat" in line for line in changed if line.startswith("+"))
