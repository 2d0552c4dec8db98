"""Every package tfbus imports is declared: by the core dependencies or by an extra.

A package that tfbus imports but ``pyproject.toml`` does not declare works in the test
environment as long as something else there brings it (trio brought sniffio, viser brings
trimesh and websockets, dask brings pandas), and breaks for a user whose environment lacks
that something. This reads every ``import`` of ``tfbus/`` (top level and inside functions)
and finds the distribution of each third-party name in the test environment; that
distribution must be named by ``[project] dependencies`` or by an extra. Which extra is the
right one is checked by ``scripts/release/check_installs.py`` (CI's first stage), which
installs each extra alone and imports every module there.
"""

from __future__ import annotations

import ast
import importlib.metadata
import re
import sys
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parents[1]

# Python packages of a ROS installation (Debian's ROS 1, a ROS 2 workspace or its rclpy
# wheels), imported by tfbus.compat only when a rospy / rclpy program hands it their
# messages: not installable from PyPI, never declared.
ROS_PACKAGES = frozenset({
    "builtin_interfaces", "genpy", "geometry_msgs", "rclpy", "rosgraph", "rosgraph_msgs",
    "rospy", "sensor_msgs", "std_msgs", "tf2_msgs", "tf2_ros", "tf2_py",
})


def _normal(name: str) -> str:
    """A distribution name as PEP 503 compares them."""
    return re.sub(r"[-_.]+", "-", name).lower()


def _requirement_name(requirement: str) -> str:
    return _normal(re.split(r"[\s\[;<>=!~]", requirement.strip(), maxsplit=1)[0])


def _declared() -> dict[str, str]:
    """Distribution name -> where pyproject.toml declares it ("core" or "extra NAME")."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    found = {_requirement_name(r): "core" for r in project["dependencies"]}
    for extra, requirements in project["optional-dependencies"].items():
        for r in requirements:
            found.setdefault(_requirement_name(r), f"extra {extra}")
    return found


def _imports() -> dict[str, set[str]]:
    """Top-level name -> the tfbus files that import it (absolute imports only)."""
    names: dict[str, set[str]] = {}
    for path in sorted((ROOT / "tfbus").rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                modules = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules = [node.module]
            else:
                continue
            for module in modules:
                names.setdefault(module.split(".")[0], set()).add(
                    str(path.relative_to(ROOT)))
    return names


def _undeclared(imports: dict[str, set[str]], declared: dict[str, str],
                distributions: dict[str, list[str]]) -> list[str]:
    """The imported third-party names whose distribution ``declared`` does not name."""
    undeclared = []
    for name, files in sorted(imports.items()):
        if name == "tfbus" or name in sys.stdlib_module_names or name in ROS_PACKAGES:
            continue
        dists = distributions.get(name)
        if not dists:  # not installed here (exceptiongroup on 3.11+): by its own name
            if _normal(name) not in declared:
                undeclared.append(f"{name} (imported by {', '.join(sorted(files))}): no "
                                  "installed distribution provides it")
        elif not any(_normal(d) in declared for d in dists):
            undeclared.append(f"{name} (distribution {', '.join(dists)}; imported by "
                              f"{', '.join(sorted(files))})")
    return undeclared


def test_every_third_party_import_is_declared() -> None:
    undeclared = _undeclared(_imports(), _declared(),
                             dict(importlib.metadata.packages_distributions()))
    assert not undeclared, ("imported by tfbus but declared neither as a dependency nor "
                            "in an extra of pyproject.toml:\n  " + "\n  ".join(undeclared))


def test_a_package_brought_only_by_another_is_reported() -> None:
    """sniffio is installed here (trio, an extra, requires it) and tfbus.session imports
    it: with its declaration taken out of pyproject.toml's, the check names it."""
    imports = _imports()
    assert "tfbus/session.py" in imports["sniffio"]
    declared = {d: where for d, where in _declared().items() if d != "sniffio"}
    found = _undeclared(imports, declared, dict(importlib.metadata.packages_distributions()))
    assert len(found) == 1 and found[0].startswith("sniffio (distribution sniffio;"), found
