"""Loading a bag into a :class:`~tfbus.core.BufferCore` for lookups."""

from __future__ import annotations

import gc
import logging
from collections.abc import Collection
from os import PathLike
from typing import TYPE_CHECKING, Literal

from tfbus.bag.formats import DEFAULT_TOPICS, TF_STATIC_TOPIC
from tfbus.bag.reader import read_messages
from tfbus.errors import BagReadError
from tfbus.messages import TransformStamped
from tfbus.time import NSEC_PER_SEC

if TYPE_CHECKING:
    from tfbus.core import BufferCore

__all__ = ["load_buffer"]

log = logging.getLogger(__name__)

def load_buffer(
    path: str | PathLike[str],
    *,
    cache_time: float | None = None,
    topics: Collection[str] = DEFAULT_TOPICS,
    errors: Literal["raise", "warn"] = "raise",
) -> BufferCore:
    """Load every ``/tf`` and ``/tf_static`` transform of a bag into a new BufferCore.

    ``/tf_static`` transforms are stored with ``set_transform_static``, others with
    ``set_transform``; the authority is the publisher's caller id (ROS 1) or
    ``"Authority undetectable"`` (ROS 2).

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder, or a ``.db3`` / ``.mcap`` file.
        cache_time: cache length in seconds; default: the span of the recorded header
            stamps plus one second, so nothing is pruned and every sample can be looked up.
        topics: topics to read (default ``/tf`` and ``/tf_static``).
        errors: on a truncated / corrupt bag, ``"raise"`` raises :class:`BagReadError`
            whose ``partial`` holds the buffer with everything readable; ``"warn"`` logs a
            warning and returns that buffer.

    Raises:
        BagNotFoundError, BagFormatError: see :func:`read_messages`.
        BagReadError: truncated or corrupt bag (``errors="raise"``).
    """
    from tfbus.core import BufferCore

    statics: list[tuple[TransformStamped, str]] = []
    dynamics: list[tuple[list[TransformStamped], str]] = []
    lo_ns = hi_ns = None
    problem: BagReadError | None = None
    # Millions of small immutable objects and no cycles: the cyclic GC would rescan the
    # growing heap again and again (it tripled the load time), so pause it meanwhile.
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        for rec in read_messages(path, topics=topics):
            ts_list = list(rec.message.transforms)
            if rec.topic == TF_STATIC_TOPIC:
                statics.extend((ts, rec.authority) for ts in ts_list)
            elif ts_list:
                dynamics.append((ts_list, rec.authority))
                for ts in ts_list:
                    ns = ts.header.stamp.ns
                    if lo_ns is None or ns < lo_ns:
                        lo_ns = ns
                    if hi_ns is None or ns > hi_ns:
                        hi_ns = ns
        if cache_time is None:
            span = 0.0 if lo_ns is None or hi_ns is None else (hi_ns - lo_ns) / NSEC_PER_SEC
            cache_time = max(10.0, span + 1.0)
        core = BufferCore(cache_time=cache_time)
        _fill(core, statics, dynamics)
    except BagReadError as err:
        problem = err
        if cache_time is None:
            span = 0.0 if lo_ns is None or hi_ns is None else (hi_ns - lo_ns) / NSEC_PER_SEC
            cache_time = max(10.0, span + 1.0)
        core = BufferCore(cache_time=cache_time)
        _fill(core, statics, dynamics)
    finally:
        if gc_was_enabled:
            gc.enable()
    if problem is not None:
        problem.partial = core
        if errors == "raise":
            raise problem
        log.warning("%s", problem)
    return core


def _fill(
    core: BufferCore,
    statics: list[tuple[TransformStamped, str]],
    dynamics: list[tuple[list[TransformStamped], str]],
) -> None:
    from tfbus.errors import TransformException

    set_static = core.set_transform_static
    set_dynamic = core.set_transform
    bad = 0
    for ts, auth in statics:
        try:
            set_static(ts, auth)
        except TransformException:
            bad += 1
    for ts_list, auth in dynamics:
        for ts in ts_list:
            try:
                set_dynamic(ts, auth)
            except TransformException:
                bad += 1
    if bad:
        log.warning("%d invalid transform(s) in the bag were skipped", bad)

