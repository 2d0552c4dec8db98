"""StaticLatch: the latest valid static transform of every child frame.

``/tf_static`` is latched per child frame, as tf2_ros's static broadcaster does with a
transient-local publisher (ROS 2 ``StaticTransformBroadcaster``) or a latched one (ROS 1
``tf2_ros::StaticTransformBroadcaster``: it re-sends every static it has ever sent, one
per child). The :class:`~tfbus.bus.Bus` keeps one for its late subscribers and every
transport keeps one for its late-joining peers; this class is that one piece of logic.

Two rules:

* only a transform the core would store is latched -- the check *is*
  :meth:`BufferCore.set_transform_static <tfbus.core.BufferCore.set_transform_static>`
  on a private core, so a NaN, an infinite translation, a denormalised quaternion, an
  empty or self-referencing frame id, or something not shaped like a
  ``TransformStamped`` never replaces a valid entry;
* the key is the child frame id without its leading slash (tf2's ``stripSlash``):
  ``laser`` and ``/laser`` are one entry; the latest valid one sent wins, in the
  position the child first took.

Synchronous and without I/O: it uses the core, nothing above it.
"""

from __future__ import annotations

from tfbus.core import BufferCore
from tfbus.errors import TransformException
from tfbus.messages import TFMessage, TransformStamped

__all__ = ["StaticLatch"]

_AUTHORITY = "tfbus latch"


class StaticLatch:
    """The latest valid static transform per (normalised) child frame id.

    ::

        latch = StaticLatch()
        latch.add(TFMessage([ts]))      # -> number of transforms latched
        latch.message()                 # one TFMessage holding every latched transform
    """

    __slots__ = ("_check", "_entries", "_snapshot")

    def __init__(self) -> None:
        """An empty latch."""
        self._entries: dict[str, TransformStamped] = {}
        self._check = BufferCore()
        self._snapshot: TFMessage | None = TFMessage(())

    def add(self, message: object) -> int:
        """Latch every valid transform of ``message`` (a :class:`TFMessage`).

        Anything else, and every transform the core would refuse, is ignored (the bus
        still delivers it: the listener counts and reports it).

        Returns:
            How many transforms were latched.
        """
        if not isinstance(message, TFMessage):
            return 0
        try:
            items = tuple(message.transforms)
        except TypeError:
            return 0
        latched = 0
        entries = self._entries
        check = self._check
        for ts in items:
            if not isinstance(ts, TransformStamped):
                continue
            try:
                check.set_transform_static(ts, _AUTHORITY)
            except (TransformException, TypeError, ValueError, AttributeError, OverflowError):
                continue
            child = ts.child_frame_id
            entries[child[1:] if child.startswith("/") else child] = ts
            latched += 1
        if latched:
            self._snapshot = None
        return latched

    def message(self) -> TFMessage:
        """One ``TFMessage`` of every latched transform (what a late subscriber gets)."""
        snapshot = self._snapshot
        if snapshot is None:
            snapshot = self._snapshot = TFMessage(tuple(self._entries.values()))
        return snapshot

    def clear(self) -> None:
        """Forget every latched transform."""
        self._entries.clear()
        self._check = BufferCore()
        self._snapshot = TFMessage(())

    def __len__(self) -> int:
        """The number of latched child frames."""
        return len(self._entries)

    def __contains__(self, child_frame_id: object) -> bool:
        """Whether ``child_frame_id`` (with or without its leading slash) is latched."""
        if not isinstance(child_frame_id, str):
            return False
        key = child_frame_id[1:] if child_frame_id.startswith("/") else child_frame_id
        return key in self._entries

    def __repr__(self) -> str:
        return f"<StaticLatch {len(self._entries)} child frame(s)>"
