from collections.abc import Callable, Iterable
from typing import Any

from tfbus.messages import TransformStamped

class RateWindowFields:
    window_ns: int
    maxlen: int
    distinct: bool
    last_received: int | None

class FrameFields:
    authorities: dict[str, int]
    count: int
    distinct_stamps: int
    delay_count: int
    delay_sum: float
    delay_max: float

class AuthorityFields:
    messages: int
    delay_count: int
    delay_sum: float
    delay_max: float

def account(
    summary: Any,
    frame_summary: Callable[[str, str, bool], Any],
    t: int,
    transforms: Iterable[TransformStamped],
    authority: str,
    static: bool,
    auth: AuthorityFields,
    sim_time_gap: float,
) -> bool: ...
