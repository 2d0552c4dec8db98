"""Type stubs for the compiled scalar math and row kernels (``tfbus/core/_cmath.pyx``)."""

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

_Tf7 = tuple[float, float, float, float, float, float, float]

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
