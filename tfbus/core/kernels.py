"""The core's kernels for the modules above it: what ``geometry``, ``laser`` and the command
line use of the implementation :mod:`tfbus.core._select` chose
(compiled or pure-Python, the same results bit for bit).

Nothing outside :mod:`tfbus.core` imports ``_select``; it imports these names from here:

* ``quat_multiply(ax, ay, az, aw, bx, by, bz, bw) -> (x, y, z, w)``,
  ``quat_rotate(qx, qy, qz, qw, x, y, z) -> (x, y, z)`` and
  ``slerp(ax, ..., bw, ratio) -> (x, y, z, w)``: tf2's scalar quaternion math
  (``tf2/LinearMath/Quaternion.h`` ``operator*``, ``quatRotate``, ``slerp``), quaternions
  in (x, y, z, w) order, floats;
* ``apply_transforms``, ``lerp_rows``, ``slerp_rows``: the row kernels of the batched
  paths on ``(N, 7)`` float64 rows (x, y, z, qx, qy, qz, qw; metres) and ``(N, 3)`` points;
* ``INVALID_ARGUMENT``: the core's error code of tf2's ``InvalidArgumentException``;
* ``batch_lookup(core, target_frame, source_frame, times, out, stamps, ok) -> int`` and
  ``CoreBase``: the batch kernel (every row bit for bit the single lookup's walk) and the
  base class of the buffers it takes, for :mod:`tfbus.table`'s lookups;
* ``core_description()``: which core runs, for ``--version`` and diagnostics;
* ``compiled_extension(name)``: a compiled module above the core (the listener's
  handler, the laser projection, the tables' and the doctor's accounting) when the
  compiled core is loaded and the module is installed, else None.
"""

from __future__ import annotations

from tfbus.core._select import (
    INVALID_ARGUMENT,
    CoreBase,
    apply_transforms,
    batch_lookup,
    compiled_extension,
    core_description,
    lerp_rows,
    quat_multiply,
    quat_rotate,
    slerp,
    slerp_rows,
)

__all__ = [
    "INVALID_ARGUMENT",
    "CoreBase",
    "apply_transforms",
    "batch_lookup",
    "compiled_extension",
    "core_description",
    "lerp_rows",
    "quat_multiply",
    "quat_rotate",
    "slerp",
    "slerp_rows",
]
