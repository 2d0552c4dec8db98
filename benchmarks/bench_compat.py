"""tf2_py's API on tfbus (``tfbus.compat.tf2_py``) against Debian's real tf2_py 0.7.6,
in the same run: ``set_transform``, ``lookup_transform_core`` (a 5-link chain,
interpolated, never-repeated times), ``can_transform_core`` and ``_chain``, best of 7
rounds, microseconds per call. Needs ``/usr/bin/python3`` with python3-tf2.

    .venv/bin/python benchmarks/bench_compat.py
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def side(python: str, which: str) -> dict[str, float]:
    r = subprocess.run([python, str(HERE / "_compat_side.py"), which], capture_output=True,
                       text=True, check=True, timeout=600)
    result: dict[str, float] = json.loads(r.stdout)
    return result


def main() -> None:
    real = side("/usr/bin/python3", "real")
    ours = side(sys.executable, "compat")
    print(f"{'call':24} {'tf2_py 0.7.6 us':>16} {'tfbus.compat us':>16} {'ratio':>7}")
    for name in real:
        print(f"{name:24} {real[name] * 1e6:16.2f} {ours[name] * 1e6:16.2f} "
              f"{real[name] / ours[name]:6.1f}x")


if __name__ == "__main__":
    main()
