"""Code, tests, docs and benchmark output name behaviours, not the tracker's numbers.

Every text file of the repository (``git ls-files``; a walk of the tree when it is not a
git checkout, e.g. an unpacked sdist) is read line by line; a reference to a numbered
issue of this project -- the word followed by a number, also run together as in a test
name -- fails the test with ``path:line: text`` for each. Kept: a numbered issue of
another project named by its repository (``owner/repo issue N``) and URLs. Skipped:
binary files, generated C (``*.c``) and this file, which spells the pattern out.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
THIS = Path(__file__).resolve()

# The word, then a number: "issue 22", "Issue #5", "test_issue21_...", "issue_3".
NUMBERED = re.compile(r"(?<![A-Za-z])issue[\s_#]*\d+", re.IGNORECASE)
# What may precede a kept reference on the same line: another project's repository
# ("ros2/geometry2 issue 327", "ros/geometry2's issue 5"), or a URL running into it.
REPOSITORY = re.compile(r"[\w.-]+/[\w.-]+(?:'s)?[\s,:]*$")
URL = re.compile(r"\w+://\S*$")

# Lines let through, as (path, text): none today.
KEPT: set[tuple[str, str]] = set()

# Folders of a checkout that are not the project's text (tools, builds, caches).
NOT_SOURCE = {".git", ".venv", "build", "dist", "site", "__pycache__", ".mypy_cache",
              ".ruff_cache", ".pytest_cache", ".hypothesis", "node_modules"}


def numbered_references(line: str) -> list[str]:
    """The numbered issue references of ``line`` that name no other repository or URL."""
    found = []
    for m in NUMBERED.finditer(line):
        before = line[: m.start()]
        if REPOSITORY.search(before) or URL.search(before):
            continue
        found.append(m.group(0))
    return found


def project_files(root: Path) -> list[Path]:
    """The tracked files of ``root`` (``git ls-files``), or every file of the tree outside
    :data:`NOT_SOURCE` when ``root`` is not a git checkout."""
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=root, capture_output=True,
                             check=True, timeout=60).stdout
        return [root / name for name in out.decode().split("\0") if name]
    except (OSError, subprocess.CalledProcessError):
        return [p for p in sorted(root.rglob("*"))
                if p.is_file() and not NOT_SOURCE.intersection(p.relative_to(root).parts)
                and not any(part.endswith(".egg-info") for part in p.parts)]


def text_lines(path: Path) -> list[str] | None:
    """The lines of a UTF-8 text file; None for a binary (a NUL byte, or not UTF-8)."""
    data = path.read_bytes()
    if b"\0" in data[:8192]:
        return None
    try:
        return data.decode("utf-8").splitlines()
    except UnicodeDecodeError:
        return None


def offending_lines(root: Path) -> list[str]:
    """``path:line: text`` for every numbered issue reference in the project's text files
    under ``root`` (minus :data:`KEPT`)."""
    offending = []
    for path in project_files(root):
        if path.suffix == ".c" or path.resolve() == THIS or not path.is_file():
            continue
        lines = text_lines(path)
        if lines is None:
            continue
        rel = path.relative_to(root).as_posix()
        for number, line in enumerate(lines, 1):
            if numbered_references(line) and (rel, line.strip()) not in KEPT:
                offending.append(f"{rel}:{number}: {line.strip()}")
    return offending


@pytest.mark.parametrize(("line", "found"), [
    ("### Changed (issue 22: ROS 1 receive latency)", ["issue 22"]),
    ("DEEP_DEPTH = 10_000  # Issue 11 item 16", ["Issue 11"]),
    ("def test_issue21_item8_db3_timestamp(tmp_path):", ["issue21"]),
    ("see issue #7 and issue 8", ["issue #7", "issue 8"]),
    ("tf2_ros: ros2/geometry2 issue 327 (a citation)", []),
    ("ros/geometry2's issue 5, then issue 6", ["issue 6"]),
    ("https://github.com/ros/geometry2/issues/222", []),
    ("an issue of timing; tissue 3; 1 issue", []),
])
def test_numbered_references_are_found_and_citations_kept(line: str, found: list[str]) -> None:
    """The detector itself: numbered references found, other repositories' kept."""
    assert numbered_references(line) == found


def test_no_issue_numbers_in_the_project() -> None:
    """No code, test, doc, benchmark result, Makefile or CHANGELOG line refers to a
    numbered issue: each names the behaviour or the target instead."""
    offending = offending_lines(ROOT)
    assert not offending, "name the behaviour, not the issue:\n" + "\n".join(offending)
