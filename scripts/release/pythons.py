"""Find the supported CPython interpreters installed on this machine.

Used by ``noxfile.py`` (``make test-matrix``) and ``scripts/release/build_dist.py`` (``make dist``).
Looks on ``PATH`` (``python3.X``) and in pyenv's versions directory (``$PYENV_ROOT``, else
``~/.pyenv``): pyenv's shims only answer for the versions currently selected, so the real
binaries are found there. Nothing is downloaded.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

#: The Python versions tfbus supports (pyproject's ``requires-python`` and classifiers).
VERSIONS = ["3.10", "3.11", "3.12", "3.13"]


def resolve(exe: Path | str, version: str) -> Path | None:
    """The real interpreter behind ``exe`` if it runs, is Python ``version`` and has
    ``venv``; else None."""
    code = "import sys, venv; print('%d.%d' % sys.version_info[:2]); print(sys.executable)"
    try:
        done = subprocess.run(
            [str(exe), "-c", code], capture_output=True, text=True, timeout=30, check=False
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    lines = done.stdout.split()
    if done.returncode != 0 or len(lines) != 2 or lines[0] != version:
        return None
    return Path(lines[1])


def find_pythons(versions: list[str] | None = None) -> dict[str, Path]:
    """Map each version found to an interpreter's path (newest patch release wins)."""
    root = Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv")) / "versions"
    found: dict[str, Path] = {}
    for version in versions or VERSIONS:
        on_path = shutil.which(f"python{version}")
        candidates = [Path(on_path)] if on_path else []
        candidates += sorted(root.glob(f"{version}.*/bin/python{version}"), reverse=True)
        for exe in candidates:
            real = resolve(exe, version)
            if real is not None:
                found[version] = real
                break
    return found


def where_looked(version: str) -> str:
    """Where :func:`find_pythons` looked for ``version`` (for a clear "not found")."""
    root = Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv")) / "versions"
    return f"python{version} on PATH, {root}/{version}.*/bin/python{version}"


def main(argv: list[str]) -> int:
    """``pythons.py``: list the interpreters found. ``pythons.py --require 3.10 3.13``:
    the same for those versions, exit status 1 naming where each missing one was looked
    for (CI runs the suite on them and must not skip one silently)."""
    if argv[:1] == ["--require"]:
        wanted = argv[1:]
        found = find_pythons(wanted)
        for version in wanted:
            if version in found:
                print(f"Python {version}: {found[version]}")
            else:
                print(
                    f"Python {version}: NOT FOUND (looked for a working interpreter with "
                    f"venv: {where_looked(version)}); install it, e.g. `pyenv install "
                    f"{version}`",
                    file=sys.stderr,
                )
        return 0 if len(found) == len(set(wanted)) else 1
    for version, exe in find_pythons(argv or None).items():
        print(version, exe)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
