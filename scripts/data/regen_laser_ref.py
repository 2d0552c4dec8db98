"""Regenerate ``tests/laser_ref/expected.jsonl.gz``: run every differential case (edge
cases and every scan of ``tests/data/laser/*.bag``) through the real ROS 1
laser_geometry (``peers/debian/laser_geometry_ref.cpp``, compiled here with g++ and pkg-config)
and record each cloud's layout and SHA-256, or tf2's error.

Usage: ``.venv/bin/python scripts/data/regen_laser_ref.py`` (needs liblaser-geometry-dev:
``bash scripts/install/install_laser_geometry.sh``).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

from laser_ref import lgref


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        binary = Path(tmp) / "harness"
        why = lgref.build_harness(binary)
        if why is not None:
            print(f"cannot build the laser_geometry harness: {why}", file=sys.stderr)
            return 1
        records = []
        for suite in lgref.suites():
            ref = lgref.run_harness(binary, suite)
            errors = sum("error" in r for r in ref.values())
            print(f"{suite.name}: {len(suite.scans)} scans, {len(ref)} cases, {errors} errors")
            records += [ref[c.id] for c in suite.cases]
    lgref.save_expected(records)
    print(f"wrote {lgref.EXPECTED} ({lgref.EXPECTED.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
