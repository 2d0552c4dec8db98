"""Feeding a :class:`~tfbus.doctor.checks.Doctor`: :func:`diagnose` (a recording, or any
iterable of :class:`~tfbus.bag.BagMessage`, in one streaming pass) and
:class:`DoctorSink` (a live bus: a :class:`~tfbus.listener.TransformListener` feeds it).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from tfbus.doctor.checks import Doctor, Thresholds
from tfbus.doctor.report import Report

if TYPE_CHECKING:
    from tfbus.bag import BagMessage
    from tfbus.clock import Clock
    from tfbus.core import BatchResult
    from tfbus.messages import TransformStamped

__all__ = ["DoctorSink", "diagnose"]


def diagnose(
    source: str | PathLike[str] | Iterable[BagMessage],
    *,
    thresholds: Thresholds | None = None,
    label: str | None = None,
) -> Report:
    """Diagnose a tf tree from a recording, in one streaming pass (memory bounded by the
    number of frames and broadcasters, not of messages).

    Args:
        source: a bag path (every format :func:`tfbus.bag.read_messages` reads: ROS 1
            ``.bag``, ROS 2 folder, ``.db3``, ``.mcap``) or an iterable of
            :class:`~tfbus.bag.BagMessage` records in receive-time order.
        thresholds: the numbers the checks use (:class:`Thresholds`).
        label: the report's ``source`` (default: the path, or ``"<messages>"``).

    Returns:
        The :class:`~tfbus.doctor.report.Report`. A damaged recording is diagnosed up to
        the damage and gets a ``damaged_recording`` finding (no exception).

    Raises:
        BagNotFoundError: the path does not exist.
        BagFormatError: the path is not a bag format tfbus reads.
    """
    from tfbus.errors import BagReadError

    if isinstance(source, (str, PathLike)):
        from tfbus.bag import read_messages

        records: Iterable[BagMessage] = read_messages(Path(source))
        name = str(source) if label is None else label
    else:
        records = source
        name = "<messages>" if label is None else label
    doctor = Doctor(thresholds, source=name)
    add = doctor.add
    try:
        for rec in records:
            add(rec.time, rec.message.transforms, rec.authority, static=rec.is_static)
    except BagReadError as err:
        doctor.note_damage(str(err))
    return doctor.report()


class _Store(Protocol):
    def set_transforms(
        self, transforms: Iterable[TransformStamped], authority: str, is_static: bool, /
    ) -> BatchResult: ...

    def clear(self) -> None: ...


class DoctorSink:
    """A :class:`~tfbus.listener.TransformSink` that feeds a :class:`Doctor` (receive time
    = ``clock.now()``) and, when given, stores into ``buffer`` too::

        doctor = Doctor(source="zenoh")
        async with TransformListener(DoctorSink(doctor, clock), bus):
            await anyio.sleep(10)
        report = doctor.report(now=clock.now())

    Args:
        doctor: what to feed.
        clock: the receive clock.
        buffer: a ``BufferCore`` / ``Buffer`` to store into as well (None: store nothing;
            ``set_transforms`` then returns an empty result).
        authority: ``authority(is_static, listener_authority) -> str`` names the sender
            of a message; by default the listener's authority (the transport's, where
            it knows the publisher: ROS 1's caller id).
    """

    def __init__(
        self,
        doctor: Doctor,
        clock: Clock,
        buffer: _Store | None = None,
        *,
        authority: Callable[[bool, str], str] | None = None,
    ) -> None:
        self.doctor = doctor
        self.buffer = buffer
        self._clock = clock
        self._authority = authority

    def set_transforms(
        self, transforms: Iterable[TransformStamped], authority: str = "default",
        is_static: bool = False,
    ) -> BatchResult:
        """Account one message in the doctor, then store it (when there is a buffer)."""
        from tfbus.core import BatchResult

        items: Sequence[TransformStamped] = list(transforms)
        if self._authority is not None:
            authority = self._authority(is_static, authority)
        self.doctor.add(self._clock.now(), items, authority, static=is_static)
        if self.buffer is None:
            return BatchResult(0, 0, [])
        return self.buffer.set_transforms(items, authority, is_static)

    def clear(self) -> None:
        """The clock jumped back: clear the buffer's dynamic data (the doctor keeps what it
        saw; the jump shows as stamps going back)."""
        if self.buffer is not None:
            self.buffer.clear()
