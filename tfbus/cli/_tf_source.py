"""What echo, monitor and frames read transforms from: :class:`TfSource`, the common face
of a bag (:class:`~tfbus.cli._bag_source.BagSource`) and a live bus
(:class:`~tfbus.cli._bus_source.BusSource`): :meth:`TfSource.buffer` and
:meth:`TfSource.summary`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tfbus.core import BufferCore
    from tfbus.monitor import TfSummary

__all__ = ["TfSource"]


class TfSource:
    """Where echo / monitor / frames get their transforms.

    :class:`BagSource` reads a recording; :class:`BusSource` listens to a live bus (other
    processes, over Zenoh) and fills the same two structures while it is attached.
    """

    label: str = ""

    def buffer(self) -> BufferCore:
        """A BufferCore holding the transforms (for lookups and the frame tree)."""
        raise NotImplementedError

    def summary(self) -> TfSummary:
        """tf_monitor's per-frame and per-broadcaster tables (:mod:`tfbus.monitor`)."""
        raise NotImplementedError

    @property
    def problem(self) -> str | None:
        """A one-line warning when the data was incomplete (a damaged bag)."""
        return None
