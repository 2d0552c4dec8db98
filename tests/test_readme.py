"""The README, read as a newcomer reads it: what tfbus is, how to install it (the two
``make`` commands; its install lines work from a clone, every extra it names exists, it says
how to reach the commands ``make`` installed), one example that runs as a script pasted into
a file as it is, and links to the documentation."""

from __future__ import annotations

import importlib.metadata
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from dds_domains import new_domain

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def _readme() -> str:
    return README.read_text(encoding="utf-8")


def _extras() -> set[str]:
    """The extras of the installed (editable) tfbus, as pyproject.toml declares them."""
    return set(importlib.metadata.metadata("tfbus").get_all("Provides-Extra") or ())


def _pip_installs(text: str) -> list[str]:
    """Every ``pip install ...`` command: in code blocks (one per line) and inline code."""
    found = [m.group(1).strip() for m in re.finditer(r"(?m)^\s*(pip install [^#\n]*)", text)]
    found += [m.group(1).strip() for m in re.finditer(r"`(pip install [^`]*)`", text)]
    return found


def test_every_pip_install_line_works_from_a_clone() -> None:
    """tfbus is not published: a line that installs it by name cannot work."""
    commands = _pip_installs(_readme())
    assert len(commands) >= 4, commands
    for cmd in commands:
        target = cmd.removeprefix("pip install ").strip().strip("'\"")
        assert target == "." or target.startswith(".["), (
            f"README: {cmd!r} installs from the package index, where tfbus is not published; "
            "write pip install '.[extra]' (from a clone)"
        )


def test_every_extra_the_readme_names_exists() -> None:
    text = _readme()
    extras = _extras()
    named = set()
    for m in re.finditer(r"(?:tfbus|'\.)\[([a-z0-9_,]+)\]", text):
        named |= set(m.group(1).split(","))
    listed = re.search(r"an extra: ([a-z0-9, ]+), or ([a-z0-9]+)", text)
    assert listed is not None, "README: the install block does not list the extras"
    named |= {x.strip() for x in listed.group(1).split(",")} | {listed.group(2)}
    assert named, "no extra found in the README"
    assert named <= extras, f"README names extras pyproject.toml lacks: {sorted(named - extras)}"
    # ... and lists every user extra there is (test, docs, cli and bench are not for users).
    assert extras - {"test", "docs", "cli", "bench"} <= named


def test_readme_says_how_to_reach_the_venv_commands() -> None:
    """After `make demo`, `tfbus` is in .venv/bin, not on PATH: the README says so, and
    what it names is what the Makefile and pyproject make."""
    text = _readme()
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    assert re.search(r"(?m)^VENV\s*:=\s*\.venv$", makefile)
    scripts = importlib.metadata.distribution("tfbus").entry_points.select(group="console_scripts")
    assert "tfbus" in scripts.names
    assert "`. .venv/bin/activate`" in text
    assert "`.venv/bin/tfbus`" in text
    demo = makefile[makefile.index("\ndemo:"):].split("\n\n", 1)[0]
    assert "activate" in demo, "make demo does not say how to run the next commands"


def test_the_trio_backend_the_readme_mentions_has_an_extra() -> None:
    """``backend="trio"`` needs trio, which no core dependency brings: an extra does, the
    README names it where it mentions the backend, and ``all`` includes it."""
    from packaging.requirements import Requirement

    reqs = [Requirement(r) for r in importlib.metadata.requires("tfbus") or ()]
    trio_in = {
        extra
        for r in reqs if r.name == "trio" and r.marker is not None
        for extra in _extras() if r.marker.evaluate({"extra": extra})
    }
    assert "trio" in trio_in, trio_in
    everything = [r for r in reqs if r.name == "tfbus" and r.marker is not None
                  and r.marker.evaluate({"extra": "all"})]
    assert everything and "trio" in everything[0].extras, everything
    assert not [r for r in reqs if r.name == "trio" and r.marker is None]
    text = _readme()
    use = _section(text, "Example")
    assert 'backend="trio"' in use
    assert "`pip install '.[trio]'`" in use


def _section(text: str, title: str) -> str:
    """The README's ``## title`` section, up to the next ``## `` heading."""
    start = text.index(f"\n## {title}\n")
    end = text.find("\n## ", start + 1)
    return text[start:] if end < 0 else text[start:end]


def test_readme_is_what_install_example_and_links() -> None:
    """The README's sections are, in order: what tfbus is (before any heading), Install
    (exactly the two commands ``make demo`` / ``make test``), one example of about 20 lines,
    and the documentation's links, each to a page that exists. Figures and the suite's
    timings live in docs/performance.md and CONTRIBUTING.md."""
    text = _readme()
    assert re.findall(r"(?m)^## (.+)$", text) == ["Install", "Example", "Documentation"]
    install = _section(text, "Install")
    block = re.search(r"(?ms)^```sh\n(.*?)^```$", install)
    assert block is not None, "README: no command block under Install"
    commands = [ln.split("#", 1)[0].strip() for ln in block.group(1).splitlines()]
    assert [c for c in commands if c] == ["make demo", "make test"]
    blocks = _python_blocks()
    assert len(blocks) == 1, [line for line, _ in blocks]
    assert 12 <= len(blocks[0][1].splitlines()) <= 25
    docs = _section(text, "Documentation")
    links = re.findall(r"\]\((docs/[\w/.-]+\.md)(?:#[\w-]+)?\)", docs)
    assert len(links) >= 10, links
    for link in links:
        assert (ROOT / link).is_file(), f"README links {link}, absent"
    assert "perf-quote" not in text and " µs" not in text and " min " not in text


def _python_blocks() -> list[tuple[int, str]]:
    """(line of the opening fence, code) of every ```python block of the README."""
    text = _readme()
    return [
        (text.count("\n", 0, m.start()) + 1, m.group(1))
        for m in re.finditer(r"(?m)^```python\n(.*?)^```$", text, re.DOTALL)
    ]


def _closed_port() -> int:
    """A 127.0.0.1 port nobody listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.parametrize(
    ("line", "code"), [pytest.param(ln, c, id=f"README.md:{ln}") for ln, c in _python_blocks()]
)
def test_python_block_runs_as_a_script(line: int, code: str, tmp_path: Path) -> None:
    """``python snippet.py`` with the block pasted in exits 0 (top-level ``await`` /
    ``async with`` would be a SyntaxError). The ROS peers it may reach are isolated: a
    random DDS domain on loopback, a ROS 1 master URI where nothing listens."""
    script = tmp_path / f"readme_line_{line}.py"
    script.write_text(code, encoding="utf-8")
    env = dict(os.environ, ROS_DOMAIN_ID=str(new_domain()), ROS_IP="127.0.0.1",
               ROS_MASTER_URI=f"http://127.0.0.1:{_closed_port()}")
    try:
        done = subprocess.run([sys.executable, str(script)], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=120, check=False)
    except subprocess.TimeoutExpired:
        pytest.fail(f"README.md:{line}: the block still runs after 120 s")
    assert done.returncode == 0, f"README.md:{line}:\n{done.stderr[-3000:]}"


def test_use_block_prints_what_its_comment_says(tmp_path: Path) -> None:
    """The comment under the example's ``print`` is its output, character for character."""
    text = _readme()
    use = _section(text, "Example")
    line = text.count("\n", 0, text.index("## Example")) + 1
    m = re.search(r"(?m)^```python\n(.*?)^```$", use, re.DOTALL)
    assert m is not None, "no python block in the Example section"
    code = m.group(1)
    lines = code.splitlines()
    at = next(i for i, ln in enumerate(lines) if "print(" in ln)
    expected = lines[at + 1].strip()
    assert expected.startswith("# "), f"README.md:{line}: no comment under the print"
    script = tmp_path / "use.py"
    script.write_text(code, encoding="utf-8")
    done = subprocess.run([sys.executable, str(script)], cwd=ROOT, capture_output=True,
                          text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout == expected.removeprefix("# ") + "\n"


# What each installer the tests may run puts on the machine, as the README must name it.
INSTALLERS = {
    "install_chromium.sh": "Chromium",
    "install_evo.sh": "evo",
    "install_laser_geometry.sh": "laser_geometry",
    "install_ros1.sh": "ROS 1",
    "install_ros1_rsp.sh": "ROS 1",
    "install_ros2_env.sh": "ROS 2",
    "install_tf2_msgs_py.sh": "tf2_geometry_msgs",
    "install_zenoh_ros2_sdk.sh": "zenoh-ros2-sdk",
    "install_roslibpy.sh": "roslibpy",
    "install_roslibjs.sh": "roslibjs",
}


def test_readme_names_everything_make_test_installs() -> None:
    """Each ``scripts/install/install_*.sh`` the tests run (as root they apt-get install) is named
    in the README's comment on ``make test``."""
    used = set()
    for path in (ROOT / "tests").rglob("*.py"):
        used |= set(re.findall(r"install_[a-z0-9_]+\.sh", path.read_text(encoding="utf-8")))
    assert used, "no installer found in tests/"
    unknown = sorted(used - set(INSTALLERS))
    assert not unknown, f"installers not in INSTALLERS: {unknown}"
    text = _readme()
    block = text[text.index("make test "):text.index("```", text.index("make test "))]
    missing = sorted(INSTALLERS[s] for s in used if INSTALLERS[s] not in block)
    assert not missing, f"README: `make test` does not say it installs {missing}"
