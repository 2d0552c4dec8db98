"""Where things live in the repository (docs/architecture.md "Where does a new X go",
CONTRIBUTING.md "Where things are"): the programs run beside tfbus in ``peers/``, the
scripts in ``scripts/`` by job, and every repository path a file names exists."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: The sub-folders of ``scripts/``, by job (docs/architecture.md's "script" row).
SCRIPT_JOBS = {"install", "release", "data", "docs"}

#: The middlewares of ``peers/`` (docs/architecture.md's "peer program" row).
PEER_FOLDERS = {"ros1", "ros2", "zenoh", "debian", "rmw_zenoh"}


def _files(folder: str) -> list[Path]:
    return [p for p in (ROOT / folder).rglob("*")
            if p.is_file() and "__pycache__" not in p.parts]


def _is_peer_program(path: Path) -> bool:
    """A side process by its name: ``*_side.py``, ``*_peer.py``, a C++ program, a build
    script for one."""
    return (path.name.endswith(("_side.py", "_peer.py", ".cpp")) or path.name == "build.sh")


def test_programs_run_beside_tfbus_live_in_peers() -> None:
    elsewhere = sorted(
        str(p.relative_to(ROOT))
        for folder in ("tests", "benchmarks", "scripts", "demos", "examples", "tfbus")
        for p in _files(folder)
        if _is_peer_program(p) and "programs" not in p.relative_to(ROOT).parts
    )
    assert not elsewhere, f"peer programs outside peers/: {elsewhere}"
    peers = _files("peers")
    assert len([p for p in peers if _is_peer_program(p)]) >= 15
    folders = {p.relative_to(ROOT / "peers").parts[0] for p in peers if p.parent != ROOT / "peers"}
    assert folders == PEER_FOLDERS, folders


def test_scripts_are_sorted_by_job() -> None:
    entries = {p.name for p in (ROOT / "scripts").iterdir() if p.name != "__pycache__"}
    assert entries == SCRIPT_JOBS, entries
    installers = {p.name for p in (ROOT / "scripts" / "install").glob("*.sh")}
    assert "install_ros1.sh" in installers and "_peer.sh" in installers
    assert all(n.startswith("install_") or n == "_peer.sh" for n in installers), installers
    for job in SCRIPT_JOBS - {"install"}:
        assert list((ROOT / "scripts" / job).glob("*.py")), job


#: A repository path as files name it: a top folder, then a file with an extension.
_PATH = re.compile(
    r"(?<![\w./-])((?:peers|scripts|benchmarks|tests|demos|examples)/[\w./-]*\w\.(?:py|sh|cpp|txt|xml|md|urdf|json|lock))\b"
)


def _naming_files() -> list[Path]:
    names = ["Makefile", "noxfile.py", "pyproject.toml", "MANIFEST.in", "README.md",
             "CONTRIBUTING.md", "mkdocs.yml", ".ci/run", ".gitignore"]
    found = [ROOT / n for n in names if (ROOT / n).is_file()]
    for folder, patterns in (("docs", ("*.md",)), ("tests", ("*.py", "*.md")),
                             ("benchmarks", ("*.py",)), ("scripts", ("*.py", "*.sh")),
                             ("peers", ("*.py", "*.sh", "*.cpp")), ("tfbus", ("*.py",))):
        for pattern in patterns:
            found += [p for p in (ROOT / folder).rglob(pattern) if "__pycache__" not in p.parts]
    return found


def test_every_repository_path_a_file_names_exists() -> None:
    """An installer's, a peer's or a script's path printed in an error message, a docs
    page or a test is where the file is (the paths move when the layout does)."""
    missing = []
    named = 0
    for path in _naming_files():
        text = path.read_text(encoding="utf-8")
        for m in _PATH.finditer(text):
            ref = m.group(1)
            if "NAME" in ref:  # a pattern (tests/transports/test_NAME.py), not a path
                continue
            named += 1
            if not (ROOT / ref).exists():
                line = text.count("\n", 0, m.start()) + 1
                missing.append(f"{path.relative_to(ROOT)}:{line}: {ref}")
    assert named >= 100
    assert not missing, "\n".join(missing)
