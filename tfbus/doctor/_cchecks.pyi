from collections.abc import Iterable, Iterator
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

RECENT_STAMPS: int

class RecentStamps:
    def append(self, stamp: int) -> None: ...
    def __contains__(self, stamp: object) -> bool: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[int]: ...

class LinkFields:
    period: float | None
    newest: int | None
    recent: RecentStamps
    sender_stamp: dict[str, int]

def account(
    doctor: Any,
    t: int,
    transforms: Iterable[TransformStamped],
    sender: str,
    static: bool,
    sim_time_gap: float,
) -> None: ...
