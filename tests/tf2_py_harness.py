"""Debian's real tf2_py 0.7.6 in a side process (``/usr/bin/python3``
``peers/debian/tf2_py_side.py``): the reference that ``tests/core/test_chain.py`` and
``tests/compat/`` compare tfbus with. Shared helpers, not tests."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any

SIDE = Path(__file__).resolve().parents[1] / "peers" / "debian" / "tf2_py_side.py"
SYSTEM_PYTHON = "/usr/bin/python3"


def have_tf2_py() -> bool:
    """Whether Debian's python3-tf2 can be imported by the system interpreter."""
    try:
        r = subprocess.run([SYSTEM_PYTHON, "-c", "import tf2_py, rospy"], capture_output=True,
                           timeout=60, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0


def run_side(ops: list[list[Any]], cache_time_s: float = 10.0) -> list[dict[str, Any]]:
    """Run ``ops`` on the real tf2_py; one decoded JSON answer per call."""
    r = subprocess.run([SYSTEM_PYTHON, str(SIDE)],
                       input=json.dumps({"cache_time_s": cache_time_s, "ops": ops}),
                       capture_output=True, text=True, timeout=300, check=True)
    return [json.loads(line) for line in r.stdout.splitlines()]
