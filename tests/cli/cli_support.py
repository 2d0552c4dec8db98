"""What the ``tfbus`` command tests share: running a command through click's CliRunner,
the one-line error checks, the recordings they read and the hostile ids they write.

Imported by name from ``tests/cli/test_cli*.py`` (pytest puts this folder on ``sys.path``;
the bag fixtures built from these are in ``tests/cli/conftest.py``).
"""

from __future__ import annotations

import re
from pathlib import Path

from click.testing import CliRunner

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.cli import cli

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
TURTLE = DATA / "webviz_turtle_tf_example.bag"
"""A ROS 1 bag of turtlesim's tf (Apache-2.0, tests/data/SOURCES.md)."""
NAV2 = DATA / "nav2_like.mcap"
"""An MCAP of a Nav2-like tree (scripts/data/make_test_bags.py, tests/data/SOURCES.md)."""

LONG_ID = "L" * 16384
HOSTILE = [
    "[/]",
    "[bold red]x[/]",
    "\x1b]0;title\x07",
    "\x1b[2J",
    '<x>; injected [URL="http://e.invalid"]; <y>',
    "cam:left",
    "back\\",
    "<script>",
    LONG_ID,
]
"""Frame ids that are rich markup, terminal escapes, DOT injections or very long."""
EVIL_CALLER = "[bold red]evil[/]\x1b]0;pwned\x07"
T0 = 1_700_000_000 * 10**9
# Control characters that must never reach a terminal (newline excepted).
RAW_CONTROL = re.compile("[\x00-\x09\x0b-\x1f\x7f-\x9f]")


def tf(parent: str, child: str, ns: int, x: float = 1.0) -> TransformStamped:
    """``parent -> child`` at ``ns``, ``x`` metres along x, no rotation."""
    return TransformStamped(Header(Time.from_ns(ns), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def run(*args: str) -> tuple[int, str, str]:
    """``tfbus ARGS`` in this process: (exit code, stdout, stderr)."""
    result = CliRunner().invoke(cli, list(args), catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def assert_usage_error(code: int, err: str, *needles: str) -> None:
    """Exit status 2 and one ``tfbus [command]: error:`` line holding every needle."""
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert re.match(r"^tfbus( [a-z-]+)?: error: ", lines[0]), lines[0]
    for needle in needles:
        assert needle in lines[0]


def assert_one_line_error(code: int, err: str) -> None:
    """A failure told in one ``tfbus ...: error:`` (or ``warning:``) line, no traceback."""
    assert code != 0
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert re.match(r"^tfbus( [a-z-]+)*: (error|warning): ", lines[0]), lines[0]


def numbers(line: str) -> list[float]:
    """The decimal numbers of an output line, in order (``-?d+.d+``)."""
    return [float(x) for x in re.findall(r"-?\d+\.\d+", line)]
