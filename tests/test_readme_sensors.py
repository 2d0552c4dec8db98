"""The README's "Sensor streams" example runs and prints what its comments say."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def _example() -> str:
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Sensor streams") :]
    match = re.search(r"```python\n(.*?)```", section, re.DOTALL)
    assert match is not None, "no python block in the Sensor streams section"
    return match.group(1)


def test_sensor_streams_example_runs() -> None:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(_example(), str(README), "exec"), {"__name__": "__readme__"})
    lines = out.getvalue().splitlines()
    # beam 1 (straight ahead, 2 m) at t = 1.01 s: robot at x = 1.01, laser 0.1 ahead
    first = [float(x) for x in re.findall(r"-?\d+\.\d*", lines[0])]
    assert first[2:4] == [3.11, 0.0]
    rows = [[float(x) for x in re.findall(r"-?\d+\.\d*", line)] for line in lines[1:]]
    assert rows == [[1.1, 0.0, 0.2], [1.125, 0.0, 0.2]]
