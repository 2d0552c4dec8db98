"""``benchmarks/`` stands alone: every benchmark imports with the
``bench`` extra alone, nothing from ``tests/`` and none of the ``test`` extra's packages.

Each benchmark module is loaded (its ``__main__`` block not run) in a fresh interpreter
where the ``test`` extra's top-level packages cannot be imported and ``tests/`` is not on
``sys.path``. The peer programs the benchmarks run beside tfbus live in ``peers/`` (they
run in other interpreters: Debian's ROS 1 Python, the ROS 2 venv) and are not loaded here.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = sorted(p for p in (ROOT / "benchmarks").glob("*.py") if not p.name.startswith("_"))

TEST_ONLY = ("pytest", "_pytest", "hypothesis", "ruff", "mypy", "build", "yaml")
"""Top-level packages of the ``test`` extra (pyproject.toml) that ``bench`` lacks."""

_LOAD = """
import importlib.abc, json, runpy, sys
blocked, tests = set(json.loads(sys.argv[2])), sys.argv[3]

class TestExtraAbsent(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.partition(".")[0] in blocked:
            raise ModuleNotFoundError(f"No module named {name!r} (the test extra)", name=name)
        return None

sys.meta_path.insert(0, TestExtraAbsent())
sys.argv = [sys.argv[1]]
runpy.run_path(sys.argv[0], run_name="benchmark_import_check")
print(json.dumps(sorted(
    name for name, mod in list(sys.modules.items())
    if str(getattr(mod, "__file__", None) or "").startswith(tests)
)))
"""


def test_the_list_of_benchmarks_is_not_empty() -> None:
    assert {p.name for p in BENCHMARKS} >= {"bench_check.py", "bench_ros1.py", "soak_ros1.py"}


@pytest.mark.parametrize("bench", BENCHMARKS, ids=lambda p: p.name)
def test_a_benchmark_imports_without_tests_or_the_test_extra(
    bench: Path, tmp_path: Path
) -> None:
    res = subprocess.run(
        [sys.executable, "-c", _LOAD, str(bench), json.dumps(TEST_ONLY), str(ROOT / "tests")],
        cwd=tmp_path,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    assert json.loads(res.stdout.strip().splitlines()[-1]) == []
