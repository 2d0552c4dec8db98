"""The batched lookups' kernel in pure Python: the twin of the compiled
:mod:`tfbus.core._cbatch` (``batch_lookup`` / ``lookup_rows``): each row is the single
walk (tf2 ``walkToTopParent`` per time), bit for bit the single lookup."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from tfbus.core._pycore import NO_ERROR, CoreBase
from tfbus.core._pymath import _F64, _I64, _tp_name, _view

__all__ = [
    "batch_lookup",
    "lookup_rows",
]

def batch_lookup(
    core: CoreBase,
    target_frame: str,
    source_frame: str,
    times: _I64,
    out: _F64,
    stamps: _I64,
    ok: npt.NDArray[np.int8],
) -> int:
    """``lookupTransform(target_frame, source_frame, t)`` for every t of ``times``, into
    caller-owned arrays (the entry of :func:`tfbus.core.batch.lookup_transforms`).

    Args:
        core: the buffer (a CoreBase of this module).
        times: ``(N,) int64`` ns, C-contiguous.
        out: ``(N, 7) float64`` rows (tx, ty, tz, qx, qy, qz, qw), written for rows
            answered.
        stamps: ``(N,) int64``, filled by the caller with ``times``; a row at time 0 gets
            the time used.
        ok: ``(N,) int8``, set to 1 for each row answered, 0 otherwise.

    Returns:
        The number of rows answered (each bit-for-bit ``lookup_transform``'s result), or
        -1 when a frame id is not a known, queryable id, or both ids are equal (then no
        row is answered: the caller asks the single lookup).

    Raises:
        TypeError: ``core`` is not a CoreBase; an array is not a buffer.
        ValueError: an array has the wrong dtype, layout or shape.

    Each row is the single walk (tf2 ``walkToTopParent`` per time); the compiled core's
    resolve-once plan gives the same numbers, faster.
    """
    if not isinstance(core, CoreBase):
        raise TypeError(
            "Argument 'core' has incorrect type (expected tfbus.core._pycore.CoreBase, got "
            f"{_tp_name(core)})"
        )
    t = _view(times, "i", 8, "const int64_t", 1, False)
    o = _view(out, "f", 8, "double", 2, True)
    s = _view(stamps, "i", 8, "int64_t", 1, True)
    k = _view(ok, "i", 1, "signed char", 1, True)
    n_rows = t.shape[0]
    if o.shape[0] != n_rows or o.shape[1] != 7 or k.shape[0] != n_rows or s.shape[0] != n_rows:
        raise ValueError("batch_lookup: out must be (N, 7), stamps and ok (N,) for N times")
    k[:] = 0
    target_id = core._frame(target_frame)
    source_id = core._frame(source_frame)
    if target_id < 0 or source_id < 0 or target_id == source_id:
        return -1
    answered = 0
    walk = core._walk
    for r, requested in enumerate(t.tolist()):
        err, v, _, used = walk(target_id, source_id, requested)
        if err == NO_ERROR:
            o[r] = v
            s[r] = used
            k[r] = 1
            answered += 1
    return answered


lookup_rows = batch_lookup
"""The rows of :meth:`tfbus.core.BufferCore.lookup_transforms`: the compiled core's may
take slerp's per-time sines from libmvec; the pure-Python core has no vector sine, so its
``lookup_rows`` is :func:`batch_lookup`, bit for bit the single lookup."""
