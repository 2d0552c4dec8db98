"""Type stubs for the compiled wire decoders (``tfbus/codecs/_cwire.pyx``)."""

from tfbus.messages import TFMessage, TransformStamped

def _tf_from_ros1(buf: memoryview | bytes) -> list[TransformStamped]: ...

_REUSES: bool
"""Whether this build refills the objects of a decoded message nobody holds any more."""

def _tf_from_native(
    payload: bytes, max_bytes: int, max_transforms: int, max_id: int, magic: int, version: int
) -> tuple[int, int, TFMessage] | None: ...

def _clock_stamp_native(payload: bytes, magic: int, version: int) -> int: ...

def _tf_to_native(
    transforms: object, sender: object, seq: object, magic: int, version: int
) -> bytes | None: ...
