"""Shared fixtures: every async test runs on asyncio and on trio (anyio's pytest plugin)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

# The ROS 1 peers (ros1_peers, ros1_hostile) live in peers/ros1/, shared with the benchmarks,
# which import nothing from tests/.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "peers" / "ros1"))

from tfbus.core import _select


def pytest_report_header() -> str:
    """Which core the run uses (``TFBUS_PURE_PYTHON=1`` selects the pure-Python one)."""
    kind = "compiled" if _select.COMPILED else "pure-Python"
    return f"tfbus core: {kind} ({_select.IMPLEMENTATION.__name__}), COMPILED={_select.COMPILED}"


@pytest.fixture(params=["asyncio", "trio"], scope="module")
def anyio_backend(request: pytest.FixtureRequest) -> str:
    """The anyio backend of ``pytest.mark.anyio`` tests: each runs once per backend.

    Module scope, so module-scoped async fixtures (as in ``test_bag.py``) may use it.
    """
    return str(request.param)


@pytest.fixture(scope="session")
def tf2_py_installed() -> None:
    """Debian's tf2_py (python3-tf2, installed with ROS 1 by ``scripts/install/install_ros1.sh``):
    the reference of the tests that run the same operations on tf2_py and tfbus."""
    from peer_install import require
    from tf2_py_harness import have_tf2_py

    require("ros1", "install_ros1.sh")
    assert have_tf2_py(), "install_ros1.sh said ready, but /usr/bin/python3 cannot import tf2_py"


def pytest_terminal_summary(
    terminalreporter: pytest.TerminalReporter, exitstatus: int, config: pytest.Config
) -> None:
    """The intended deviation from tf2 (±Inf translations rejected) in one line at the end
    of a run that met it, instead of one warning per case; ``-v`` lists every op."""
    _skip_summary(terminalreporter, config)
    found = _DEVIATIONS
    if not found:
        return
    ops = sum(len(lines) for lines in found.values())
    verbose = config.get_verbosity() > 0
    terminalreporter.write_line(
        f"tfbus conformance: {ops} corpus ops in {len(found)} cases differ from tf2 by design "
        "(tfbus rejects ±Inf translations)" + (":" if verbose else "; -v lists them")
    )
    if verbose:
        for case_id, lines in sorted(found.items()):
            for line in lines:
                terminalreporter.write_line(f"  {case_id} {line}")


# Every skip of the run (not expected failures): (node id, reason), in order.
_SKIPS: list[tuple[str, str]] = []
# The corpus ops that differ from tf2 by design, by case id (conformance.DEVIATIONS).
_DEVIATIONS: dict[str, list[str]] = {}


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    """Keep every skip with its reason, for the summary and the CI check below, and the
    corpus's deviations a test reported (in the main process, pytest-xdist's workers' too)."""
    from conformance import DEVIATIONS

    if report.skipped and not hasattr(report, "wasxfail"):
        longrepr = report.longrepr
        reason = longrepr[2] if isinstance(longrepr, tuple) else str(longrepr)
        _SKIPS.append((report.nodeid, reason.removeprefix("Skipped: ")))
    for name, value in report.user_properties:
        if name == DEVIATIONS and report.when == "call":
            case_id, lines = value
            _DEVIATIONS[case_id] = list(lines)


def _unexpected_skips() -> list[tuple[str, str]]:
    from peer_install import legitimate

    return [(nodeid, why) for nodeid, why in _SKIPS if not legitimate(nodeid, why)]


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Under CI, a run that skipped a test not listed in ``peer_install.LEGITIMATE_SKIPS``
    fails: a skip there hides a peer or an extra that did not install."""
    from peer_install import in_ci

    if in_ci() and exitstatus == pytest.ExitCode.OK and _unexpected_skips():
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def _skip_summary(reporter: pytest.TerminalReporter, config: pytest.Config) -> None:
    """The skips of the run counted by reason, the unexpected ones marked."""
    from collections import Counter

    from peer_install import in_ci, legitimate

    skips = _SKIPS
    if not skips:
        return
    by_reason = Counter(
        ("listed" if legitimate(nodeid, why) else "NOT LISTED", why) for nodeid, why in skips
    )
    reporter.write_sep("-", f"skips by reason ({len(skips)})")
    for (kind, why), n in sorted(by_reason.items(), key=lambda kv: (-kv[1], kv[0])):
        reporter.write_line(f"{n:4d}  [{kind}] {why}")
    unexpected = _unexpected_skips()
    if unexpected and in_ci():
        reporter.write_line(
            f"CI: {len(unexpected)} skip(s) not listed in tests/peer_install.py "
            "LEGITIMATE_SKIPS: the run fails", red=True
        )
        for nodeid, why in unexpected:
            reporter.write_line(f"  {nodeid}: {why}", red=True)
