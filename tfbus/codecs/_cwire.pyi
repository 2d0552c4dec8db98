"""Type stubs for the compiled ROS 1 wire decoder (``tfbus/codecs/_cwire.pyx``)."""

from tfbus.messages import TransformStamped

def _tf_from_ros1(buf: memoryview | bytes) -> list[TransformStamped]: ...

_REUSES: bool
"""Whether this build refills the objects of a decoded message nobody holds any more."""
