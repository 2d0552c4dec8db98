"""Message codecs: tfbus values to and from bytes, synchronous and free of I/O (as
rosbags' ``serde``). The transports and the bag reader and writer use them; nothing here
imports an event loop, a socket or a clock.

* :mod:`tfbus.codecs.ros1` -- ROS 1 ``tf2_msgs/TFMessage`` (struct decoder, rosbags'
  serialiser, the one rosbags message builder);
* :mod:`tfbus.codecs.cdr` -- ROS 2 ``tf2_msgs/msg/TFMessage`` in XCDR1/XCDR2 (DDS samples
  and ROS 2 bags);
* :mod:`tfbus.codecs.lookup_action_cdr` -- ROS 2's ``tf2_msgs/action/LookupTransform``
  action samples (goal, result, cancel, status) in CDR;
* :mod:`tfbus.codecs.native` -- tfbus's own versioned msgpack wire (the Zenoh transport).

One error contract: a payload that does not decode raises
:class:`~tfbus.errors.WireDecodeError` (a ``ValueError``), never anything else; a value
that cannot be encoded raises :class:`~tfbus.errors.WireEncodeError`. Importing this
package imports none of the codecs (``native`` needs ``msgspec``, ``ros1``'s rosbags
parts need ``rosbags``).
"""

from __future__ import annotations

import importlib.util
from types import ModuleType

__all__: list[str] = []


def _compiled_wire() -> ModuleType | None:
    """The compiled wire decoders (:mod:`tfbus.codecs._cwire`, objects built in C with the
    compiled core's helpers) when the compiled core is loaded (:data:`tfbus.core.COMPILED`:
    not with ``TFBUS_PURE_PYTHON``) and the extension is installed; else None. An
    extension that is installed but fails to import raises, as the core's do."""
    from tfbus.core import COMPILED

    if not COMPILED or importlib.util.find_spec("tfbus.codecs._cwire") is None:
        return None
    from tfbus.codecs import _cwire

    return _cwire
