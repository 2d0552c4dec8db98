"""``make test-matrix``: the test suite on every supported Python found on this machine.

Each session makes a fresh venv with that interpreter's own ``venv`` module (nox's default
backend), installs tfbus editable with its extras — which builds the compiled core for
that interpreter beside the others (``tfbus/core/_c*.cpython-3XY-*.so``) — and runs pytest.
An interpreter that is not installed is skipped, not failed: the matrix runs "on each
interpreter found" (``scripts/release/pythons.py`` looks on ``PATH`` and in pyenv's versions).

    nox                      # every version found
    nox -s tests-3.10        # one
    nox -s tests-3.13 -- tests/core/test_core.py -x     # arguments after -- go to pytest

Without arguments a session runs the core subset (CORE_TESTS): the storage, walk, values,
geometry, codecs, clocks, tf2's own test cases, the bus and the Zenoh transport, what
differs between interpreters (the compiled core, numpy, wire decoding). The whole matrix,
every real peer included, runs once on the default Python (`make test`); `nox -- tests`
runs all of it here too.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import nox

sys.path.insert(0, str(Path(__file__).resolve().parent / "scripts" / "release"))
from pythons import VERSIONS, find_pythons

nox.options.sessions = ["tests"]
nox.options.error_on_missing_interpreters = False
# Never fetch an interpreter from the network: test only what is installed.
nox.options.download_python = "never"
nox.options.reuse_existing_virtualenvs = True

# pyenv's shim for `python3.X` fails unless that version is selected: put the real
# interpreters' directories first on PATH so that nox's discovery finds them.
_bins = [str(exe.parent) for exe in find_pythons().values()]
os.environ["PATH"] = os.pathsep.join([*dict.fromkeys(_bins), os.environ.get("PATH", "")])


# The subset run on the other interpreters (paths relative to the repository root).
CORE_TESTS = [
    "tests/core",
    "tests/values",
    "tests/geometry/test_geometry.py",
    "tests/geometry/test_convert.py",
    "tests/codecs",
    "tests/clock",
    "tests/upstream",
    "tests/test_bus.py",
    "tests/test_broadcaster_listener.py",
    "tests/test_public_api.py",
    "tests/test_layers.py",
    "tests/transports/test_zenoh.py",
]

CORE_SKIP = [
    # the whole core suite again in a subprocess on the pure-Python core: plain Python,
    # run on the default interpreter by `make test`; the matrix checks the compiled core
    "--deselect",
    "tests/core/test_pycore.py::test_core_suite_and_conformance_corpus_pass_on_the_pure_core",
]


@nox.session(python=VERSIONS, venv_backend="venv")
def tests(session: nox.Session) -> None:
    """Install tfbus (compiled core, every extra) and run the core subset (or the pytest
    arguments given after ``--``)."""
    session.install("--upgrade", "pip")
    session.install("-e", ".[all,test,docs]")
    session.run(
        "python",
        "-c",
        "import sys, tfbus, tfbus.core as c; "
        "print(sys.version, tfbus.__version__, 'COMPILED =', c.COMPILED)",
    )
    session.run("python", "-m", "pytest", "-q", *(session.posargs or [*CORE_TESTS, *CORE_SKIP]))
