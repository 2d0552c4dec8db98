"""Read, replay and record ``/tf`` and ``/tf_static`` in ROS bags.

Formats:

* ROS 1 ``.bag`` (v2.0; message types ``tf2_msgs/TFMessage`` and the legacy
  ``tf/tfMessage``, which has the same layout and MD5), through rosbags;
* ROS 2 sqlite3 (a bag folder with ``metadata.yaml``, or a bare ``.db3`` file), through
  rosbags;
* MCAP: a bare ``.mcap`` file through the format's own ``mcap`` package, a ROS 2 bag
  folder through rosbags.

Reading::

    for rec in read_messages("turtle.bag"):          # bag time, topic, TFMessage, authority
        print(rec.time, rec.topic, len(rec.message.transforms))
    core = load_buffer("turtle.bag")                 # BufferCore with every transform
    core.lookup_transform("world", "turtle1", Time(0))

Replaying onto a :class:`~tfbus.bus.Bus` while a :class:`~tfbus.clock.ManualClock` follows
bag time (``await replay(path, bus, clock=clock, rate=2.0)``), and recording a bus to a bag
that the ROS tools read (``async with BagRecorder(bus, "out.bag", clock=clock): ...``).

Damage: a truncated file lacks the index (ROS 1) or summary (MCAP) that indexed readers
need; it is read record by record (:mod:`tfbus.bag.salvage`) and everything before the
damage is returned, then :class:`BagReadError` says where reading stopped (byte offset and
the last bag time read). Every error a read raises is a :class:`BagError`.

The package, one job per module:

* :mod:`~tfbus.bag.formats`: topics, :class:`BagMessage`, :class:`BagFormat`,
  :func:`detect_format`;
* :mod:`~tfbus.bag.decode`: which codec (:mod:`tfbus.codecs`) decodes a connection's
  serialized ``TFMessage``;
* :mod:`~tfbus.bag.reader`: :func:`read_messages`, :func:`read_window` (statics of the
  whole file plus one window, through the format's index);
* :mod:`~tfbus.bag.salvage`: reading damaged files up to the damage;
* :mod:`~tfbus.bag.loader`: :func:`load_buffer` (whole, or a window), :func:`iter_windows`;
* :mod:`~tfbus.bag.playback`: :func:`replay`, :class:`ReplayControl` (pause, resume);
* :mod:`~tfbus.bag.writer`: :func:`write_bag`, :class:`BagRecorder`;
* :mod:`~tfbus.bag.summary`: :func:`summarize` (tf_monitor statistics, :mod:`tfbus.monitor`).
"""

from __future__ import annotations

from tfbus._extras import require

require(__name__, "rosbags", "mcap")

from tfbus.bag.formats import (
    DEFAULT_TOPICS,
    ROS2_AUTHORITY,
    TF_MSGTYPES,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    BagFormat,
    BagMessage,
    detect_format,
)
from tfbus.bag.loader import Window, iter_windows, load_buffer
from tfbus.bag.playback import DEFAULT_CLOCK_HZ, ReplayControl, replay
from tfbus.bag.reader import read_messages, read_window
from tfbus.bag.summary import AuthoritySummary, BagSummary, FrameSummary, summarize
from tfbus.bag.writer import BagRecorder, write_bag
from tfbus.errors import BagError, BagFormatError, BagNotFoundError, BagReadError

__all__ = [
    "DEFAULT_CLOCK_HZ",
    "DEFAULT_TOPICS",
    "ROS2_AUTHORITY",
    "TF_MSGTYPES",
    "TF_STATIC_TOPIC",
    "TF_TOPIC",
    "AuthoritySummary",
    "BagError",
    "BagFormat",
    "BagFormatError",
    "BagMessage",
    "BagNotFoundError",
    "BagReadError",
    "BagRecorder",
    "BagSummary",
    "FrameSummary",
    "ReplayControl",
    "Window",
    "detect_format",
    "iter_windows",
    "load_buffer",
    "read_messages",
    "read_window",
    "replay",
    "summarize",
    "write_bag",
]
