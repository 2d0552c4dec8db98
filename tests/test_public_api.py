"""The public names are a contract (docs/architecture.md): pin them, and check the hierarchy."""

import tfbus


def test_public_all_is_pinned() -> None:
    assert sorted(tfbus.__all__) == [
        "BackwardExtrapolationException", "Buffer", "BufferClosedException", "BufferCore",
        "Bus", "Clock", "ConnectivityException", "Duration", "ExtrapolationException",
        "ForwardExtrapolationException", "Header", "InvalidArgumentException", "LaserProjection",
        "LaserScan", "LookupException", "ManualClock", "MemoryTransport", "MessageFilter",
        "NoDataForExtrapolationException", "Point", "Point32", "PointCloud2", "PointField",
        "PointStamped", "Polygon",
        "PolygonStamped", "Pose", "PoseStamped", "PoseWithCovariance",
        "PoseWithCovarianceStamped", "Quaternion", "SetResult", "SimClock", "Stamped",
        "StaticTransformBroadcaster", "Subscription", "SystemClock", "TFMessage", "TfbusError",
        "Time", "TimeoutException", "Transform", "TransformArray", "TransformBroadcaster",
        "TransformException", "TransformListener", "TransformSession", "TransformStamped",
        "Transport",
        "TransportError", "Twist", "TwistStamped", "Vector3", "Vector3Stamped",
        "VelocityStamped", "Wrench", "WrenchStamped", "every", "open_session",
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
    for name in (
        "BackwardExtrapolationException",
        "ForwardExtrapolationException",
        "NoDataForExtrapolationException",
    ):
        assert issubclass(getattr(tfbus, name), tfbus.ExtrapolationException)
    assert issubclass(tfbus.TransformException, tfbus.TfbusError)
    assert issubclass(tfbus.TransportError, tfbus.TfbusError)


def test_one_tree_for_bag_and_wire_errors() -> None:
    from tfbus.bag import BagError, BagFormatError, BagNotFoundError
    from tfbus.codecs.native import WireDecodeError

    assert issubclass(BagError, tfbus.TfbusError)
    assert issubclass(BagNotFoundError, FileNotFoundError)
    assert issubclass(BagFormatError, ValueError)
    assert issubclass(WireDecodeError, tfbus.TfbusError)
    assert issubclass(WireDecodeError, ValueError)


def test_buffer_is_a_buffer_core() -> None:
    assert issubclass(tfbus.Buffer, tfbus.BufferCore)


def test_time_clock_and_convert_modules_pin_their_names() -> None:
    """The time layer's helpers beside the package's names: one exact seconds ->
    nanoseconds conversion, one stamp formatter, the clocks' deadline primitive and the
    transform registry."""
    import tfbus.clock
    import tfbus.convert
    import tfbus.time

    assert set(tfbus.time.__all__) == {
        "NSEC_PER_SEC", "TIME_MAX_NS", "Duration", "Time", "format_stamp", "seconds_to_ns",
    }  # fmt: skip
    assert set(tfbus.clock.__all__) == {
        "Clock", "JumpCallback", "ManualClock", "PeriodicTimer", "SimClock",
        "SimClockStatistics", "SystemClock", "Tick", "every", "timeout_ns",
    }  # fmt: skip
    assert set(tfbus.convert.__all__) == {
        "ConvertRegistration", "TransformFunction", "TransformRegistration", "convert",
        "do_transform_cloud", "do_transform_point", "do_transform_polygon",
        "do_transform_pose", "do_transform_pose_with_covariance", "do_transform_stamped",
        "do_transform_twist", "do_transform_vector3", "do_transform_velocity",
        "do_transform_transform", "do_transform_wrench", "get_transform_function",
        "register_transform", "registered_types", "transform_covariance",
    }  # fmt: skip
    for module in (tfbus.time, tfbus.clock, tfbus.convert):
        for name in module.__all__:
            obj = getattr(module, name)
            if callable(obj) and not name.startswith(("TransformFunction", "JumpCallback")):
                assert obj.__doc__, f"{module.__name__}.{name} has no docstring"
    for method in ("now", "sleep", "sleep_until", "on_jump", "move_on_after", "fail_after"):
        for cls in (tfbus.Clock, tfbus.SystemClock, tfbus.ManualClock, tfbus.SimClock):
            assert getattr(cls, method).__doc__, f"{cls.__name__}.{method} has no docstring"
    assert isinstance(tfbus.ManualClock(), tfbus.Clock)
    assert isinstance(tfbus.SystemClock(), tfbus.Clock)
    assert tfbus.Buffer.transform_full.__doc__
