"""What a tf recording is: the topics, the record type, the formats and their detection.

Format detection reads the first 16 bytes of a file (its magic number: ROS 1 bag v2.0
``#ROSBAG V2.0\\n``, MCAP ``\\x89MCAP0\\r\\n``, SQLite ``SQLite format 3\\0``) or, for a
folder, the files of a ROS 2 bag (``metadata.yaml`` beside ``.db3`` / ``.mcap`` files).
"""

from __future__ import annotations

from enum import Enum
from os import PathLike
from pathlib import Path
from typing import Final, NamedTuple

from tfbus.errors import BagFormatError, BagNotFoundError
from tfbus.messages import TFMessage
from tfbus.time import Time
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC, TF_TOPICS

__all__ = [
    "DEFAULT_TOPICS",
    "ROS2_AUTHORITY",
    "TF_MSGTYPES",
    "TF_STATIC_TOPIC",
    "TF_TOPIC",
    "BagFormat",
    "BagMessage",
    "detect_format",
]

DEFAULT_TOPICS: Final = TF_TOPICS

#: Message types carried on /tf and /tf_static (rosbags' normalised names).
TF_MSGTYPES: Final = frozenset({"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"})
#: tf2_ros (ROS 2) has no per-message publisher: its listener uses this authority.
ROS2_AUTHORITY: Final = "Authority undetectable"

ROS1_MAGIC: Final = b"#ROSBAG V2.0\n"
MCAP_MAGIC: Final = b"\x89MCAP0\r\n"
SQLITE_MAGIC: Final = b"SQLite format 3\x00"


def fmt_time(t: Time) -> str:
    """``sec.nanosec`` with nine digits, as bag times are printed."""
    return f"{t.sec}.{t.nanosec:09d}"


class BagMessage(NamedTuple):
    """One ``/tf`` or ``/tf_static`` message read from a bag.

    ``time`` is the bag (receive) time, ``topic`` the topic name, ``message`` the
    :class:`~tfbus.messages.TFMessage` as tfbus values, ``authority`` who sent it (ROS 1:
    the publisher's caller id; ROS 2: ``"Authority undetectable"`` as tf2_ros says).
    """

    time: Time
    topic: str
    message: TFMessage
    authority: str = ROS2_AUTHORITY

    @property
    def is_static(self) -> bool:
        """True for ``/tf_static`` (latched / transient-local) messages."""
        return self.topic == TF_STATIC_TOPIC


class BagFormat(str, Enum):  # not StrEnum: that is Python 3.11+, tfbus supports 3.10
    """On-disk formats: ``ros1`` (.bag), ``sqlite3`` (ROS 2 .db3), ``mcap``.

    A ``str`` enum: ``BagFormat.MCAP == "mcap"`` and ``str(BagFormat.MCAP) == "mcap"``.
    """

    ROS1 = "ros1"
    SQLITE3 = "sqlite3"
    MCAP = "mcap"

    def __str__(self) -> str:
        return str(self.value)

    def __format__(self, spec: str) -> str:
        return format(str(self.value), spec)


def detect_format(path: str | PathLike[str]) -> BagFormat:
    """Tell a bag's format from its magic bytes (a folder: from the files inside it).

    Raises:
        BagNotFoundError: the path does not exist.
        BagFormatError: not a ROS 1 bag, ROS 2 sqlite3 bag or MCAP file, or an MCAP
            file not named ``*.mcap``.
    """
    p = Path(path)
    if not p.exists():
        raise BagNotFoundError(f"{p}: no such file or directory", p)
    if p.is_dir():
        if not (p / "metadata.yaml").exists():
            raise BagFormatError(f"{p}: a folder but not a ROS 2 bag (no metadata.yaml)", p)
        files = sorted(x for x in p.iterdir() if x.suffix in (".db3", ".mcap"))
        if not files:
            raise BagFormatError(f"{p}: ROS 2 bag folder without .db3 or .mcap files", p)
        return detect_format(files[0])
    try:
        with p.open("rb") as f:
            head = f.read(16)
    except OSError as err:
        raise BagFormatError(f"{p}: cannot read: {err.strerror}", p) from None
    if head.startswith(ROS1_MAGIC):
        return BagFormat.ROS1
    if head.startswith(MCAP_MAGIC):
        if p.suffix != ".mcap":  # rosbags opens a bare MCAP file by its suffix only
            raise BagFormatError(f"{p}: an mcap file must be named *.mcap", p)
        return BagFormat.MCAP
    if head.startswith(SQLITE_MAGIC):
        return BagFormat.SQLITE3
    if head.startswith(b"#ROSBAG"):
        raise BagFormatError(f"{p}: unsupported ROS bag version {head[:12]!r} (need V2.0)", p)
    raise BagFormatError(f"{p}: unknown format (not a ROS 1 .bag, ROS 2 .db3 or .mcap file)", p)
