"""A missing optional dependency is named at import of the subpackage that needs it
(:class:`tfbus.errors.MissingExtraError`, a ModuleNotFoundError), with the extra to
install from the index and from a clone; every ``tfbus`` command prints it on one line
and exits with one status, 2 (``MISSING_EXTRA_STATUS``).

Each case runs in a child process whose ``sys.meta_path`` starts with a finder that
refuses the dependency, as if it were not installed.
"""

from __future__ import annotations

import subprocess
import sys

import pytest
from cli_support import ROOT, TURTLE

REFUSE = """
import sys

class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] == {package!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None

sys.meta_path.insert(0, Refuse())
"""


def _child(package: str, code: str, *argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", REFUSE.format(package=package) + code,
                           *argv], capture_output=True, text=True, timeout=120, check=False,
                          cwd=ROOT)


def _advice(extra: str) -> str:
    """The install advice the child prints: the same tfbus and interpreter as here (its
    text, editable clone or not: tests/test_extras.py)."""
    from tfbus._extras import extra_advice

    return extra_advice("", extra)


@pytest.mark.parametrize(("module", "package", "extra"), [
    ("tfbus.bag", "rosbags", "bag"),
    ("tfbus.bag", "mcap", "bag"),
    ("tfbus.transports.zenoh", "zenoh", "zenoh"),
    ("tfbus.transports.zenoh", "msgspec", "zenoh"),
    ("tfbus.transports.ros2", "cyclonedds", "ros2"),
    ("tfbus.transports.ros1", "rosbags", "ros1"),
    ("tfbus.robot", "urdf_parser_py", "robot"),
    ("tfbus.robot", "lxml", "robot"),
])
def test_import_names_the_extra(module: str, package: str, extra: str) -> None:
    """``import tfbus.bag`` without rosbags (and each extra's subpackage without its
    dependency) raises MissingExtraError naming the package and the extra, not a bare
    ``No module named 'rosbags'`` from deep inside."""
    proc = _child(package, f"""
try:
    import {module}
except ModuleNotFoundError as err:
    from tfbus.errors import MissingExtraError
    assert isinstance(err, MissingExtraError), repr(err)
    print(err.name, err.extra, err.needed_by)
    print(err)
""")
    assert proc.returncode == 0, proc.stderr
    first, message = proc.stdout.strip().split("\n")
    assert first == f"{package} {extra} {module}"
    assert message == f"{module} needs the '{package}' package: {_advice(extra)}"


def test_import_with_every_dependency_installed_is_quiet() -> None:
    """The check costs no import of the dependencies themselves (find_spec only)."""
    proc = subprocess.run([sys.executable, "-c", "import sys, tfbus.bag, tfbus.robot\n"
                           "print('rosbags' in sys.modules, 'urdf_parser_py' in sys.modules)"],
                          capture_output=True, text=True, timeout=120, check=False, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["False", "False"]


MAIN = "from tfbus.cli import main\nsys.exit(main(sys.argv[1:]))"


@pytest.mark.parametrize(("package", "argv", "message"), [
    ("rosbags", ["bag-info", str(TURTLE)],
     f"tfbus.bag needs the 'rosbags' package: {_advice('bag')}"),
    ("rosbags", ["echo", "world", "turtle1", "--bag", str(TURTLE)],
     f"tfbus.bag needs the 'rosbags' package: {_advice('bag')}"),
    ("rosbags", ["monitor", "--bus", "ros1", "--duration", "0.1"],
     f"the 'ros1' bus needs the 'rosbags' package: {_advice('ros1')}"),
    ("zenoh", ["echo", "a", "b", "--bus", "zenoh", "--duration", "0.1"],
     f"the 'zenoh' bus needs the 'zenoh' package: {_advice('zenoh')}"),
    ("zenoh", ["static-transform", "0", "0", "0", "0", "0", "0", "a", "b", "--once"],
     f"the 'zenoh' bus needs the 'zenoh' package: {_advice('zenoh')}"),
    ("urdf_parser_py", ["robot-state-publisher", str(ROOT / "demos" / "robot.urdf"),
                        "--local", "--duration", "0"],
     f"tfbus.robot needs the 'urdf_parser_py' package: {_advice('robot')}"),
    ("urdf_parser_py", ["joint-states", str(ROOT / "demos" / "robot.urdf"), "--local",
                        "--duration", "0"],
     f"tfbus.robot needs the 'urdf_parser_py' package: {_advice('robot')}"),
])
def test_every_command_says_it_in_one_line_with_one_status(
    package: str, argv: list[str], message: str
) -> None:
    """bag-info, echo, monitor, static-transform, robot-state-publisher, joint-states
    without their extra: ``tfbus: error: <the message>``, exit status 2 (it was 1 for
    some commands and 2 for others, and a bare ModuleNotFoundError for the library)."""
    proc = _child(package, MAIN, *argv)
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert proc.stderr.strip().splitlines() == [f"tfbus: error: {message}"]
