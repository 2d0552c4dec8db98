from collections.abc import Iterable
from typing import Any

from tfbus.messages import TransformStamped

class SpanFields:
    count: int
    first: int
    last: int

class SampleFields:
    cap: int
    n: int
    stride: int
    values: list[float]

class MeanFields:
    total: float
    count: int

class LinkFields:
    period: float | None

def account(
    doctor: Any,
    t: int,
    transforms: Iterable[TransformStamped],
    sender: str,
    static: bool,
    sim_time_gap: float,
) -> None: ...
