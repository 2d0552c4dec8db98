"""The "Sensor streams" page's example (docs/sensors.md) runs and prints what its comments
say."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

PAGE = Path(__file__).resolve().parents[2] / "docs" / "sensors.md"


def _example() -> str:
    text = PAGE.read_text(encoding="utf-8")
    match = re.search(r"```python\n(.*?)```", text, re.DOTALL)
    assert match is not None, "no python block on the Sensor streams page"
    return match.group(1)


def test_sensor_streams_example_runs() -> None:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(_example(), str(PAGE), "exec"), {"__name__": "__docs_example__"})
    lines = out.getvalue().splitlines()
    # beam 1 (straight ahead, 2 m) at t = 1.01 s: robot at x = 1.01, laser 0.1 ahead
    first = [float(x) for x in re.findall(r"-?\d+\.\d*", lines[0])]
    assert first[2:4] == [3.11, 0.0]
    rows = [[float(x) for x in re.findall(r"-?\d+\.\d*", line)] for line in lines[1:]]
    assert rows == [[1.1, 0.0, 0.2], [1.125, 0.0, 0.2]]
