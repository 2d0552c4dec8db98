"""The public names are a contract (DESIGN.md): pin them, and check the hierarchy."""

import tfbus


def test_public_all_is_pinned() -> None:
    assert sorted(tfbus.__all__) == [
        "Buffer", "BufferCore", "Bus", "Clock", "ConnectivityException", "Duration",
        "ExtrapolationException", "Header", "InvalidArgumentException", "LookupException",
        "ManualClock", "MemoryTransport", "Point", "PointStamped", "Pose", "PoseStamped",
        "Quaternion", "SetResult", "StaticTransformBroadcaster", "Subscription",
        "SystemClock", "TFMessage", "TfbusError", "Time", "TimeoutException", "Transform",
        "TransformBroadcaster", "TransformException", "TransformListener",
        "TransformStamped", "Transport", "TransportError", "Vector3", "Vector3Stamped", "every",
    ]  # fmt: skip
    for name in tfbus.__all__:
        assert getattr(tfbus, name).__doc__, f"{name} has no docstring"


def test_exceptions_derive_from_transform_exception() -> None:
    for name in (
        "LookupException",
        "ConnectivityException",
        "ExtrapolationException",
        "InvalidArgumentException",
        "TimeoutException",
    ):
        assert issubclass(getattr(tfbus, name), tfbus.TransformException)
    assert issubclass(tfbus.TransformException, tfbus.TfbusError)
    assert issubclass(tfbus.TransportError, tfbus.TfbusError)


def test_one_tree_for_bag_and_wire_errors() -> None:
    from tfbus.bag import BagError, BagFormatError, BagNotFoundError
    from tfbus.transports.wire import WireDecodeError

    assert issubclass(BagError, tfbus.TfbusError)
    assert issubclass(BagNotFoundError, FileNotFoundError)
    assert issubclass(BagFormatError, ValueError)
    assert issubclass(WireDecodeError, tfbus.TfbusError)
    assert issubclass(WireDecodeError, ValueError)


def test_buffer_is_a_buffer_core() -> None:
    assert issubclass(tfbus.Buffer, tfbus.BufferCore)
