"""Lookups served to thin clients: a process that keeps a :class:`~tfbus.buffer.Buffer`
answers lookups for others that do not subscribe to ``/tf`` (tf2_ros's ``buffer_server``
and ``BufferClient``).

One module per protocol, each built on its transport:

* :mod:`tfbus.remote.zenoh`: :class:`BufferServer` (a Zenoh queryable) and
  :class:`BufferClient` (``Buffer``'s awaitable lookups); needs the ``zenoh`` extra.
* :mod:`tfbus.remote.ros1`: tf2_ros's own ``tf2_msgs/LookupTransform`` action over ROS 1
  (:class:`~tfbus.remote.ros1.Ros1BufferServer`, :class:`~tfbus.remote.ros1.Ros1BufferClient`),
  interoperating with Debian's ``buffer_server`` and ``tf2_ros.BufferClient``.

The Zenoh names are importable from here (``from tfbus.remote import BufferServer``); they
load the Zenoh module on first use, so ``tfbus.remote.ros1`` works without the extra.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tfbus.remote.zenoh import (
        DEFAULT_MAX_WAIT,
        DEFAULT_SERVER_NAME,
        MAX_FRAME_ID_BYTES,
        BufferClient,
        BufferServer,
        ServerStatistics,
    )

__all__ = [
    "DEFAULT_MAX_WAIT",
    "DEFAULT_SERVER_NAME",
    "MAX_FRAME_ID_BYTES",
    "BufferClient",
    "BufferServer",
    "ServerStatistics",
]


def __getattr__(name: str) -> Any:
    """The Zenoh names (:mod:`tfbus.remote.zenoh`), imported on first use."""
    if name in __all__:
        from tfbus.remote import zenoh

        return getattr(zenoh, name)
    raise AttributeError(f"module 'tfbus.remote' has no attribute {name!r}")
