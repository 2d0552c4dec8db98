"""Shared fixtures: every async test runs on asyncio and on trio (anyio's pytest plugin)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

# The ROS 1 peers (ros1_peers, ros1_hostile) live in scripts/, shared with the benchmarks,
# which import nothing from tests/.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))

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


def pytest_terminal_summary(
    terminalreporter: pytest.TerminalReporter, exitstatus: int, config: pytest.Config
) -> None:
    """The intended deviation from tf2 (±Inf translations rejected) in one line at the end
    of a run that met it, instead of one warning per case; ``-v`` lists every op."""
    from conformance import DEVIATIONS

    found = config.stash.get(DEVIATIONS, {})
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
