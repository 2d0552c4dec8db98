"""The real peers the interop tests run against, and what a test does when one is missing.

Each peer is installed by its ``scripts/install/install_*.sh``, whose exit status tells the truth
(0 and a ``ready`` line only when the peer works, else 1 and an ``unavailable: REASON``
line). A test whose peer could not be installed calls :func:`peer_unavailable`:

* under CI (``CI=true``) the test **fails** with the reason: a green CI means every peer
  ran;
* elsewhere it skips, saying which command installs the peer.

The skips that stay legitimate on a machine with every peer are listed by name in
:data:`LEGITIMATE_SKIPS` (one place); ``conftest.py`` prints the skips of a run by reason
at its end and, under CI, fails a run that skipped anything else.
"""

from __future__ import annotations

import fnmatch
import os
import re
import subprocess
import tempfile
from pathlib import Path
from typing import NoReturn

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = ROOT / "scripts" / "install"
LOCK_TIMEOUT = 75
"""flock(1)'s exit status when another process held an install script's lock too long."""

# The command that installs each peer (what a skip outside CI tells the user to run).
INSTALL: dict[str, str] = {
    "ros1": "sudo bash scripts/install/install_ros1.sh",
    "ros1-robot-state-publisher": "sudo bash scripts/install/install_ros1_rsp.sh",
    "laser_geometry": "sudo bash scripts/install/install_laser_geometry.sh",
    "tf2-msgs-py": "sudo bash scripts/install/install_tf2_msgs_py.sh",
    "chromium": "sudo bash scripts/install/install_chromium.sh",
    "ros2-env": "bash scripts/install/install_ros2_env.sh",
    "evo": "bash scripts/install/install_evo.sh",
    "zenoh-ros2-sdk": "bash scripts/install/install_zenoh_ros2_sdk.sh",
    "roslibjs": "bash scripts/install/install_roslibjs.sh",
    "roslibpy": "bash scripts/install/install_roslibpy.sh",
}

# Skips that remain legitimate with every peer installed, by name: (test id pattern, fnmatch
# on the node id without its parameters; reason pattern, a regular expression searched in the
# skip's reason) -> why. Nothing else may skip under CI.
LEGITIMATE_SKIPS: dict[tuple[str, str], str] = {
    ("tests/test_docs.py::test_example", r"Not run: "): (
        "a documentation example marked 'Not run: <reason>' in its page: it needs other "
        "hosts, a full ROS install or a user's own files"
    ),
    ("tests/fleet/test_fleet_netns.py::test_netem_delay_and_loss", r"tc qdisc netem"): (
        "the delay-and-loss part of the multi-host test needs the kernel's netem qdisc "
        "(sch_netem), which some kernels lack"
    ),
}


def in_ci() -> bool:
    """Whether this run is CI's (``CI`` set to ``true`` or ``1``, as CI services set it)."""
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def peer_unavailable(peer: str, reason: str) -> NoReturn:
    """Fail (under CI) or skip (elsewhere) the calling test: ``peer`` could not be used.

    Raises:
        pytest.fail.Exception: under CI, with the peer, the reason and the install command.
        pytest.skip.Exception: elsewhere, with the same text.
    """
    text = f"{peer} unavailable: {reason.strip()} (install it with: {INSTALL[peer]})"
    if in_ci():
        pytest.fail(f"CI needs every real peer: {text}", pytrace=False)
    pytest.skip(text)


def install(peer: str, script: str, timeout: float = 1900.0) -> str:
    """Run ``scripts/install/<script>`` (idempotent) and return its ``ready`` line; when it exits
    non-zero, waits over ``timeout`` seconds for another process's run of the same script or
    does not finish within twice that, :func:`peer_unavailable`."""
    # One run of a script at a time across the processes of a run (``make test``'s
    # pytest-xdist workers): flock(1) holds a lock file of its own per script while it runs,
    # so a second worker needing the same peer waits (within ``timeout``), then finds it
    # installed, instead of a second apt-get or venv build beside the first.
    lock = Path(tempfile.gettempdir()) / f"tfbus-peer-install-{os.getuid()}-{script}.lock"
    wait = max(1, int(timeout))
    try:
        out = subprocess.run(
            ["flock", "--wait", str(wait), "--conflict-exit-code", str(LOCK_TIMEOUT),
             str(lock), "bash", str(SCRIPTS / script)],
            capture_output=True,
            text=True,
            timeout=2 * timeout,
            check=False,
        )  # fmt: skip
    except subprocess.TimeoutExpired:
        peer_unavailable(peer, f"scripts/install/{script} did not finish in {2 * timeout:.0f} s")
    if out.returncode == LOCK_TIMEOUT:
        peer_unavailable(peer, f"another process ran scripts/install/{script} for over {wait} s")
    lines = out.stdout.strip().splitlines()
    if out.returncode != 0:
        why = next((ln for ln in lines if "unavailable" in ln), None)
        peer_unavailable(
            peer, why or f"scripts/install/{script} exited {out.returncode}: {out.stderr[-500:]}"
        )
    return lines[-1] if lines else ""


def legitimate(nodeid: str, reason: str) -> str | None:
    """Why skipping the test ``nodeid`` for ``reason`` is legitimate, or None."""
    base = nodeid.split("[", 1)[0]
    for (pattern, why_pattern), why in LEGITIMATE_SKIPS.items():
        if fnmatch.fnmatchcase(base, pattern) and re.search(why_pattern, reason):
            return why
    return None


_READY: dict[str, str] = {}


def require(peer: str, script: str, timeout: float = 1900.0) -> str:
    """:func:`install` once per run for each peer that installed (its ``ready`` line is
    kept); a peer that did not is tried again by the next test that needs it."""
    if peer not in _READY:
        _READY[peer] = install(peer, script, timeout)
    return _READY[peer]
