"""Awaitable batched lookups: :meth:`Buffer.lookup_transforms_async` and
:meth:`Buffer.transform_points_async` (issue 12).

They wait, event-driven on :meth:`~tfbus.buffer.Buffer.wait_for_transform`, until the
latest requested time can be answered, then run the synchronous batched lookup
(:mod:`tfbus.batch`). Data up to the latest time normally covers the earlier ones; a time
that has fallen out of the cache, or a gap inside the requested span, is reported by the
batched lookup as tf2's exception (or masked with ``errors="mask"``).

Layer 3 (beside :mod:`tfbus.buffer`). Usable as functions on any Buffer, or as methods
through :class:`AsyncBatchMixin` (``class Buffer(AsyncBatchMixin, BufferCore)``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, cast

import numpy as np
import numpy.typing as npt

from tfbus.batch import (
    Errors,
    Lookups,
    TransformArray,
    as_times,
    lookup_transforms,
    transform_points,
)
from tfbus.messages import TransformStamped
from tfbus.time import Duration, Time


class Buffer(Lookups, Protocol):
    """What the awaitable batched lookups need: :class:`tfbus.buffer.Buffer`'s public
    lookups and ``wait_for_transform`` (a structural type: :mod:`tfbus.buffer` imports
    this module for :class:`AsyncBatchMixin`, so this module does not import it)."""

    async def wait_for_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: Time,
        timeout: float | Duration | None = None,
    ) -> TransformStamped: ...


__all__ = ["AsyncBatchMixin", "lookup_transforms_async", "transform_points_async"]

_Times = npt.ArrayLike | Sequence[Time] | Time | int


async def _wait_latest(
    buffer: Buffer,
    target_frame: str,
    source_frame: str,
    times: npt.NDArray[np.int64],
    timeout: float | Duration | None,
) -> None:
    if times.size == 0:
        return
    latest = int(times.max())
    # Time 0 means "latest available": waiting for it waits for the frames to connect.
    await buffer.wait_for_transform(target_frame, source_frame, Time.from_ns(latest), timeout)


async def lookup_transforms_async(
    buffer: Buffer,
    target_frame: str,
    source_frame: str,
    times: _Times,
    timeout: float | Duration | None = None,
    *,
    errors: Errors = "raise",
) -> TransformArray:
    """:func:`tfbus.batch.lookup_transforms`, first waiting until the latest of ``times``
    can be looked up.

    Args:
        timeout: seconds (or a Duration) of the buffer's clock; None waits forever.

    Raises:
        TimeoutException: the latest time did not become available within ``timeout``.
        ExtrapolationException: the latest time is older than the cache window.
        TransformException subclasses, ValueError: as the synchronous lookup.
    """
    t = as_times(times)
    await _wait_latest(buffer, target_frame, source_frame, t, timeout)
    return lookup_transforms(buffer, target_frame, source_frame, t, errors=errors)


async def transform_points_async(
    buffer: Buffer,
    points: npt.ArrayLike,
    target_frame: str,
    source_frame: str,
    times: _Times,
    timeout: float | Duration | None = None,
    *,
    errors: Errors = "raise",
) -> npt.NDArray[np.float64]:
    """:func:`tfbus.batch.transform_points` (each point at its own time), first waiting
    until the latest of ``times`` can be looked up.

    Raises: as :func:`lookup_transforms_async`; ValueError for malformed points.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {p.shape}")
    t = as_times(times, p.shape[0])
    await _wait_latest(buffer, target_frame, source_frame, t, timeout)
    return transform_points(buffer, p, target_frame, source_frame, t, errors=errors)


class AsyncBatchMixin:
    """The awaitable batched lookups as :class:`~tfbus.buffer.Buffer` methods."""

    __slots__ = ()

    async def lookup_transforms_async(
        self,
        target_frame: str,
        source_frame: str,
        times: _Times,
        timeout: float | Duration | None = None,
        *,
        errors: Errors = "raise",
    ) -> TransformArray:
        """:func:`tfbus.batch_async.lookup_transforms_async` on this buffer."""
        return await lookup_transforms_async(
            cast(Buffer, self), target_frame, source_frame, times, timeout, errors=errors
        )

    async def transform_points_async(
        self,
        points: npt.ArrayLike,
        target_frame: str,
        source_frame: str,
        times: _Times,
        timeout: float | Duration | None = None,
        *,
        errors: Errors = "raise",
    ) -> npt.NDArray[np.float64]:
        """:func:`tfbus.batch_async.transform_points_async` on this buffer."""
        return await transform_points_async(
            cast(Buffer, self),
            points,
            target_frame,
            source_frame,
            times,
            timeout,
            errors=errors,
        )
