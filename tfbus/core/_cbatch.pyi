"""Type stubs for the compiled batch kernel (``tfbus/core/_cbatch.pyx``)."""

from typing import Final

import numpy as np
import numpy.typing as npt

from tfbus.core._ccore import CoreBase

_BATCH_VECTOR_SIN: Final[bool]

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
def _batch_simd(enable: bool) -> bool: ...
def _split_after(
    wall_ns: int, own_ns: int, own_rows: int, n_rows: int, worker_ran: bool
) -> int: ...
def _split_reset() -> None: ...
def _worker_stop(timeout: float = 5.0) -> bool: ...
def _worker_forget() -> None: ...
def _worker_threads_started() -> int: ...
