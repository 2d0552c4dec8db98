"""The transform buffer's core: tf2's ``BufferCore``, synchronous and sans-I/O.

One package, one job per module:

* :mod:`tfbus.core.buffer_core` -- :class:`BufferCore` (tf2 ``tf2/src/buffer_core.cpp``):
  the frame graph, per-link time caches, single and batched lookups, tf2's messages;
* :mod:`tfbus.core.results` -- what the inserts return (:class:`SetResult`,
  :class:`BatchResult`, :class:`TouchedFrames`) and the argument checks;
* :mod:`tfbus.core.batch` -- :class:`~tfbus.core.batch.TransformArray` and the time-array
  helper of the batched lookups;
* :mod:`tfbus.core.velocity` -- tf2 ``lookupVelocity`` from two lookups;
* :mod:`tfbus.core.text` -- tf2's frame listings (``allFramesAsString`` / YAML / dot) and
  exception messages;
* :mod:`tfbus.core.cache` -- the per-link storage (``TimeCache``, ``StaticCache``);
* :mod:`tfbus.core._select` -- the one place that chooses the implementation: compiled
  (Cython: ``_cmath``, ``_ccache``, ``_ccore``, ``_cbatch``) or its pure-Python
  twins (``_pymath``, ``_pycache``, ``_pycore``, ``_pybatch``), same results bit for bit
  (:data:`COMPILED`).

``from tfbus.core import BufferCore`` is the supported import; the names below are this
package's public surface.
"""

from __future__ import annotations

from tfbus.core.batch import TransformArray
from tfbus.core.buffer_core import (
    COMPILED,
    MAX_GRAPH_DEPTH,
    BatchResult,
    BufferCore,
    FrameInfo,
    SetResult,
    Tf7,
    frame_path,
)
from tfbus.core.results import TouchedFrames

__all__ = [
    "COMPILED",
    "MAX_GRAPH_DEPTH",
    "BatchResult",
    "BufferCore",
    "FrameInfo",
    "SetResult",
    "Tf7",
    "TouchedFrames",
    "TransformArray",
    "frame_path",
]
