"""Type stubs for the compiled core (``tfbus/core/_ccore.pyx``)."""

from collections.abc import Iterable, Sequence
from typing import Any, Final, Literal

import numpy as np
import numpy.typing as npt

from tfbus.messages import TransformStamped
from tfbus.time import Time

OK: Final[int]
OLD_DATA: Final[int]
REPEATED_DATA: Final[int]
NO_ERROR: Final[int]
LOOKUP_ERROR: Final[int]
CONNECTIVITY_ERROR: Final[int]
EXTRAPOLATION_ERROR: Final[int]
MAX_GRAPH_DEPTH: Final[int]
INVALID: Final[int]
INVALID_ARGUMENT: Final[int]
UNKNOWN_FRAME: Final[int]
_BATCH_VECTOR_SIN: Final[bool]

_Tf7 = tuple[float, float, float, float, float, float, float]

def format_sec(ns: int) -> str: ...
def quat_multiply(
    ax: float, ay: float, az: float, aw: float, bx: float, by: float, bz: float, bw: float
) -> tuple[float, float, float, float]: ...
def quat_rotate(
    qx: float, qy: float, qz: float, qw: float, vx: float, vy: float, vz: float
) -> tuple[float, float, float]: ...
def compose(a: Sequence[float], b: Sequence[float]) -> _Tf7: ...
def inverse(a: Sequence[float]) -> _Tf7: ...
def slerp(
    ax: float,
    ay: float,
    az: float,
    aw: float,
    bx: float,
    by: float,
    bz: float,
    bw: float,
    ratio: float,
) -> tuple[float, float, float, float]: ...
def compose_full(leg2: Sequence[float], leg1: Sequence[float]) -> _Tf7: ...

class Link:
    @property
    def is_static(self) -> bool: ...
    @property
    def cache_time_ns(self) -> int: ...
    def gather(self, time: int) -> tuple[int, _Tf7] | str: ...
    def latest(self) -> tuple[int, int]: ...
    def insert(self, stamp: int, parent: int, values: _Tf7) -> int: ...
    def latest_stamp(self) -> int: ...
    def oldest_stamp(self) -> int: ...
    def nbytes(self) -> int: ...
    def clear(self) -> None: ...
    def __len__(self) -> int: ...

class TimeCache(Link):
    def __init__(self, cache_time_ns: int) -> None: ...
    def stamps(self) -> npt.NDArray[np.int64]: ...
    def values(self) -> npt.NDArray[np.float64]: ...

class StaticCache(Link):
    def __init__(self) -> None: ...
    def stamp_sent(self) -> int: ...

# A failed query: (code, ...) as documented on CoreBase._query.
_Failure = tuple[int, ...]

class CoreBase:
    _frame_ids: dict[str, int]
    _frame_names: list[str]
    _caches: list[Link | None]
    _authority: dict[int, str]
    _generation: int
    def __init__(self, *args: Any, **kwargs: Any) -> None: ...
    @property
    def cache_time_ns(self) -> int: ...
    def _set_cache_time_ns(self, ns: int) -> None: ...
    def _store(
        self, transforms: Iterable[Any], authority: str, is_static: bool
    ) -> tuple[
        int,
        int,
        list[tuple[int, Exception | tuple[str, str, _Tf7]]],
        set[str],
        bool,
        list[tuple[int, str, int]],
    ]: ...
    def _store_one(
        self, ts: Any, authority: str, is_static: bool
    ) -> Literal[True] | tuple[int, str, int] | tuple[int, str, str, _Tf7]: ...
    def _last_touched(self) -> tuple[str, str, bool]: ...
    def _id_status(self, frame_id: object) -> int: ...
    def _query(self, target: str, source: str, time: Time) -> TransformStamped | _Failure: ...
    def _chain(self, target_frame: str, source_frame: str, time: Time | None = None) -> list[
        str
    ]: ...
    def _ccommon_time(self, target_id: int, source_id: int) -> tuple[int, int]: ...
    def _cwalk(
        self, target_id: int, source_id: int, time: int
    ) -> tuple[int, _Tf7 | int | None, int]: ...

# batched lookups (issue 12)
def batch_lookup(
    core: CoreBase,
    target_frame: str,
    source_frame: str,
    times: npt.NDArray[np.int64],
    out: npt.NDArray[np.float64],
    stamps: npt.NDArray[np.int64],
    ok: npt.NDArray[np.int8],
) -> int: ...
def lookup_rows(
    core: CoreBase,
    target_frame: str,
    source_frame: str,
    times: npt.NDArray[np.int64],
    out: npt.NDArray[np.float64],
    stamps: npt.NDArray[np.int64],
    ok: npt.NDArray[np.int8],
) -> int: ...
def slerp_rows(
    a: Sequence[float],
    b: Sequence[float],
    ratios: npt.NDArray[np.float64],
    out: npt.NDArray[np.float64],
) -> None: ...
def apply_transforms(
    q: npt.NDArray[np.float64],
    v: npt.NDArray[np.float64],
    p: npt.NDArray[np.float64],
    out: npt.NDArray[np.float64],
) -> None: ...
def lerp_rows(
    a: Sequence[float],
    b: Sequence[float],
    ratios: npt.NDArray[np.float64],
    out: npt.NDArray[np.float64],
) -> None: ...
def _batch_simd(enable: bool) -> bool: ...
