"""The ROS 1 soak under attack in the suite: ``benchmarks/soak_ros1.py`` at 100 Hz x 50
transforms for 60 s, with three hostile publishers and 50 idle connections attached to
the subscriber, on asyncio and on trio at once (one real roscore each, all on
127.0.0.1). Nothing may be lost."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from ros1_harness import ros1_fixture  # noqa: F401  (registers the fixture)

ROOT = Path(__file__).resolve().parents[2]


def test_soak_under_attack_loses_nothing(ros1: None, tmp_path: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    # stderr (the nodes' logs, a traceback) kept in a file: its end is in any failure
    errs = {backend: (tmp_path / f"{backend}.err").open("w") for backend in ("asyncio", "trio")}
    procs = {
        backend: subprocess.Popen(
            [sys.executable, str(ROOT / "benchmarks" / "soak_ros1.py"), "--backend", backend],
            stdout=subprocess.PIPE,
            stderr=errs[backend],
            text=True,
            env=env,
            cwd=ROOT,
        )
        for backend in ("asyncio", "trio")
    }
    outputs = {}
    for backend, proc in procs.items():
        try:
            outputs[backend] = proc.communicate(timeout=400)[0]
        except subprocess.TimeoutExpired:
            for p in procs.values():
                p.kill()
            raise
    for f in errs.values():
        f.close()
    for backend, out in outputs.items():
        out += "\n--- stderr (end) ---\n" + (tmp_path / f"{backend}.err").read_text()[-4000:]
        m = re.search(r"sent (\d+) transforms \((\d+) messages\), received (\d+), lost (\d+)", out)
        assert m, f"{backend}: {out}"
        assert (int(m[1]), int(m[2])) == (300_000, 6000), out
        assert int(m[3]) == 300_000 and int(m[4]) == 0, out
        counters = re.search(r"malformed=(\d+).*bad_replies=(\d+).*bad_requests=(\d+)", out)
        assert counters and all(int(c) > 0 for c in counters.groups()), out  # attacked
        assert procs[backend].returncode == 0, out
