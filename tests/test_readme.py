"""The README, read as a newcomer reads it: its install lines work from a clone, every
extra it names exists, and it says how to reach the commands `make` installed."""

from __future__ import annotations

import importlib.metadata
import re
from pathlib import Path

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
    # ... and lists every user extra there is (test, docs and cli are not for users).
    assert extras - {"test", "docs", "cli"} <= named


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
    use = text[text.index("## Use"):text.index("## Sensor streams")]
    assert 'backend="trio"' in use
    assert "`pip install '.[trio]'`" in use
