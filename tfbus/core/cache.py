"""Per-link transform storage: ``TimeCache`` (dynamic) and ``StaticCache`` (static).

Both come from the core (:mod:`tfbus.core._select`: compiled :mod:`tfbus.core._ccache`, or
the pure-Python :mod:`tfbus.core._pycache`) and are re-exported here. Semantics are tf2's
(geometry2 0.7.6, ``tf2/src/cache.cpp`` and ``static_cache.cpp``):

* ``insert``: refused as TF_OLD_DATA iff ``newest > stamp + cache_time``; refused as
  TF_REPEATED_DATA if a sample with the same stamp exists (the first one wins, whatever its
  values or parent); otherwise stored, then every sample older than
  ``newest - cache_time`` is dropped (``TimeCache::insertData`` / ``pruneList``).
* ``gather(t)``: t = 0 gives the newest sample; a single sample answers only at its exact
  stamp; otherwise t must lie in [oldest, newest] (no extrapolation, not even 1 ns);
  between two samples with the same parent the result is interpolated (linear
  translation, tf2 slerp rotation, ratio from integer ns), between samples with
  different parents the older one is used (``TimeCache::findClosest`` / ``getData`` /
  ``interpolate``).
* A static link holds one value, valid at every time; each insert overwrites it.

Storage of a dynamic link: contiguous arrays (C buffers in the compiled core, numpy
arrays in the pure one) — ``cap`` int64 stamps (ns) and ``cap`` rows of 7 float64 (tx,
ty, tz, qx, qy, qz, qw) — holding the live samples sorted by stamp, plus a parent id per
sample only once the link has had two different parents (64 bytes per sample otherwise),
searched by binary search. The capacity doubles from 8 up to 256 samples (a new link's
first 200 samples take 5 reallocations) and grows by 1/16 beyond, when sliding the live
samples down cannot free 1/16 of it (``nbytes()`` is the capacity in bytes).
"""

from __future__ import annotations

from tfbus.core._select import OK, OLD_DATA, REPEATED_DATA, StaticCache, TimeCache, format_sec

__all__ = ["OK", "OLD_DATA", "REPEATED_DATA", "StaticCache", "TimeCache", "format_sec"]
