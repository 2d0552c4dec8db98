"""``tf2_ros`` (ROS 2 call shapes, ROS 1 names where they differ) on tfbus.

``from tfbus.compat import tf2_ros`` in place of ``import tf2_ros``:

* :class:`Buffer`: ``lookup_transform(target, source, time, timeout=...)``,
  ``lookup_transform_full``, ``can_transform(..., return_debug_tuple=)``,
  ``can_transform_full``, ``transform``, ``transform_full``, ``set_transform(_static)``,
  ``clear`` answer at once from the data at hand (they never block the event loop: a
  ``timeout`` is accepted and not waited on, see below); the awaitable
  ``wait_for_transform_async``, ``wait_for_transform_full_async``,
  ``lookup_transform_async``, ``lookup_transform_full_async`` wait, with a ``timeout=``
  that works (ros2/geometry2 #327, PR #797), on :class:`tfbus.Buffer`'s event-driven
  waits.
* :class:`TransformListener` ``(buffer, node=None, *, bus=None)``: an rclpy node's
  ``/tf`` and ``/tf_static`` subscriptions, or a tfbus bus (``async with``).
* :class:`TransformBroadcaster`, :class:`StaticTransformBroadcaster` (``sendTransform``)
  on an rclpy node or a tfbus bus.
* tf2's exceptions, :class:`TransformRegistration`, :class:`ConvertRegistration`,
  :func:`convert`, :func:`Stamped`.

A synchronous call that would have to wait (ROS 2 spins or sleeps up to ``timeout``)
raises the lookup's exception at once instead: use the ``*_async`` methods to wait.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from tfbus.broadcaster import StaticTransformBroadcaster as _StaticBroadcaster
from tfbus.broadcaster import TransformBroadcaster as _Broadcaster
from tfbus.buffer import Buffer as _Buffer
from tfbus.bus import Bus
from tfbus.clock import Clock
from tfbus.compat._args import to_duration, to_stamped, to_time, to_transform_stamped
from tfbus.convert import ConvertRegistration, TransformRegistration, convert
from tfbus.errors import (
    ConnectivityException,
    ExtrapolationException,
    InvalidArgumentException,
    LookupException,
    TimeoutException,
    TransformException,
)
from tfbus.listener import TransformListener as _Listener
from tfbus.messages import Header, TFMessage, TransformStamped
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC

__all__ = [
    "Buffer",
    "ConnectivityException",
    "ConvertRegistration",
    "ExtrapolationException",
    "InvalidArgumentException",
    "LookupException",
    "Stamped",
    "StaticTransformBroadcaster",
    "TimeoutException",
    "TransformBroadcaster",
    "TransformException",
    "TransformListener",
    "TransformRegistration",
    "TransformStamped",
    "TypeException",
    "convert",
]

TypeException = TypeError
"""tf2_ros's ``TypeException`` (no registered function for a type): tfbus raises
TypeError, exported under tf2_ros's name."""


def _timeout(value: object) -> float | None:
    """A ``timeout=`` in seconds for tfbus (None: wait forever); a zero duration (tf2's
    default) means "do not wait"."""
    if value is None:
        return None
    return to_duration(value).to_sec()


def Stamped(obj: Any, stamp: object, frame_id: str) -> Any:
    """tf2_ros ``Stamped(obj, stamp, frame_id)``: ``obj`` with ``header = Header(stamp,
    frame_id)`` — a copy for tfbus's immutable messages (``_replace``), the same object
    (its attribute set) for a mutable one, as tf2_ros does."""
    header = Header(to_time(stamp, "stamp"), frame_id)
    replace = getattr(obj, "_replace", None)
    if callable(replace):
        return replace(header=header)
    obj.header = header
    return obj


class Buffer:
    """tf2_ros ``Buffer(cache_time=None, node=None)`` over a :class:`tfbus.Buffer`
    (``.buffer``; ``cache_time`` 10 s by default, a duration in any form). ``node`` is
    accepted for ROS 2's signature and not used (time comes from ``clock``, a tfbus
    clock, default the system clock)."""

    registration = TransformRegistration()
    """The transform functions by type (tf2_ros ``BufferInterface.registration``)."""

    def __init__(
        self, cache_time: object = None, node: object = None, *, clock: Clock | None = None
    ) -> None:
        """Create the buffer (see the class docs)."""
        seconds = 10.0 if cache_time is None else to_duration(cache_time, "cache_time")
        self.buffer = _Buffer(seconds, clock=clock)
        self.node = node

    # ---------------------------------------------------------------- data

    def set_transform(self, transform: Any, authority: str) -> None:
        """tf2 ``set_transform`` (returns None, as ROS 2's):
        :meth:`tfbus.BufferCore.set_transform`."""
        self.buffer.set_transform(to_transform_stamped(transform), authority)

    def set_transform_static(self, transform: Any, authority: str) -> None:
        """tf2 ``set_transform_static`` (returns None):
        :meth:`tfbus.BufferCore.set_transform_static`."""
        self.buffer.set_transform_static(to_transform_stamped(transform), authority)

    def clear(self) -> None:
        """tf2 ``clear``: :meth:`tfbus.BufferCore.clear`."""
        self.buffer.clear()

    # ---------------------------------------------------------------- at once

    def lookup_transform(
        self, target_frame: str, source_frame: str, time: object, timeout: object = None
    ) -> TransformStamped:
        """tf2_ros ``lookup_transform``: :meth:`tfbus.BufferCore.lookup_transform` now
        (``timeout`` not waited on: see the module docs)."""
        return self.buffer.lookup_transform(target_frame, source_frame, to_time(time))

    def lookup_transform_full(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
        timeout: object = None,
    ) -> TransformStamped:
        """tf2_ros ``lookup_transform_full``: :meth:`tfbus.BufferCore.lookup_transform_full`."""
        return self.buffer.lookup_transform_full(
            target_frame, to_time(target_time, "target_time"), source_frame,
            to_time(source_time, "source_time"), fixed_frame,
        )

    def can_transform(
        self,
        target_frame: str,
        source_frame: str,
        time: object,
        timeout: object = None,
        return_debug_tuple: bool = False,
    ) -> bool | tuple[bool, str]:
        """tf2_ros ``can_transform``: :meth:`tfbus.BufferCore.can_transform` now."""
        return self.buffer.can_transform(
            target_frame, source_frame, to_time(time), return_debug_tuple
        )

    def can_transform_full(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
        timeout: object = None,
        return_debug_tuple: bool = False,
    ) -> bool | tuple[bool, str]:
        """tf2_ros ``can_transform_full``: :meth:`tfbus.BufferCore.can_transform_full`."""
        return self.buffer.can_transform_full(
            target_frame, to_time(target_time, "target_time"), source_frame,
            to_time(source_time, "source_time"), fixed_frame, return_debug_tuple,
        )

    def transform(
        self,
        object_stamped: Any,
        target_frame: str,
        timeout: object = None,
        new_type: Any = None,
    ) -> Any:
        """tf2_ros ``transform``: the registered function of the object's type applied
        to :meth:`lookup_transform` ``(target_frame, header.frame_id, header.stamp)``;
        converted to ``new_type`` by :func:`convert` when given. A foreign geometry
        message is taken by its fields and returned as the tfbus type."""
        obj = to_stamped(object_stamped)
        fn = self.registration.get(type(obj))
        header = obj.header  # type: ignore[attr-defined]
        out = fn(obj, self.lookup_transform(target_frame, header.frame_id, header.stamp))
        return out if new_type is None else convert(out, new_type)

    def transform_full(
        self,
        object_stamped: Any,
        target_frame: str,
        target_time: object,
        fixed_frame: str,
        timeout: object = None,
        new_type: Any = None,
    ) -> Any:
        """tf2_ros ``transform_full``: as :meth:`transform`, through ``fixed_frame``."""
        obj = to_stamped(object_stamped)
        fn = self.registration.get(type(obj))
        header = obj.header  # type: ignore[attr-defined]
        ts = self.lookup_transform_full(
            target_frame, target_time, header.frame_id, header.stamp, fixed_frame
        )
        out = fn(obj, ts)
        return out if new_type is None else convert(out, new_type)

    # ---------------------------------------------------------------- awaitable

    async def wait_for_transform_async(
        self, target_frame: str, source_frame: str, time: object, *, timeout: object = None
    ) -> bool:
        """ROS 2 ``wait_for_transform_async``, awaitable: True once the transform is
        available (:meth:`tfbus.Buffer.wait_for_transform`).

        Raises:
            TimeoutException: not within ``timeout`` (a duration or seconds; None:
                no limit).
        """
        await self.buffer.wait_for_transform(
            target_frame, source_frame, to_time(time), _timeout(timeout)
        )
        return True

    async def wait_for_transform_full_async(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
        *,
        timeout: object = None,
    ) -> bool:
        """ROS 2 ``wait_for_transform_full_async``, awaitable: True once both legs are
        available (:meth:`tfbus.Buffer.lookup_transform_full_async`)."""
        await self.lookup_transform_full_async(
            target_frame, target_time, source_frame, source_time, fixed_frame,
            timeout=timeout,
        )
        return True

    async def lookup_transform_async(
        self, target_frame: str, source_frame: str, time: object, *, timeout: object = None
    ) -> TransformStamped:
        """ROS 2 ``lookup_transform_async``: :meth:`tfbus.Buffer.lookup_transform_async`."""
        return await self.buffer.lookup_transform_async(
            target_frame, source_frame, to_time(time), _timeout(timeout)
        )

    async def lookup_transform_full_async(
        self,
        target_frame: str,
        target_time: object,
        source_frame: str,
        source_time: object,
        fixed_frame: str,
        *,
        timeout: object = None,
    ) -> TransformStamped:
        """ROS 2 ``lookup_transform_full_async``:
        :meth:`tfbus.Buffer.lookup_transform_full_async`."""
        return await self.buffer.lookup_transform_full_async(
            target_frame, to_time(target_time, "target_time"), source_frame,
            to_time(source_time, "source_time"), fixed_frame, _timeout(timeout),
        )


def _is_bus(value: object) -> bool:
    return isinstance(value, Bus)


def _describe(value: object) -> str:
    """``value``'s type and a short repr, for an error message."""
    text = repr(value)
    return f"{type(value).__name__} {text[:60] + '...' if len(text) > 60 else text}"


def _check_node(who: str, node: object, method: str) -> None:
    """A TypeError naming ``node`` and its type unless it is a tfbus Bus or has an rclpy
    node's ``method`` (so a wrong argument is not reported as a missing rclpy)."""
    if not callable(getattr(node, method, None)):
        raise TypeError(f"{who}: node must be an rclpy Node or a tfbus.Bus, got "
                        f"{_describe(node)}")


class TransformListener:
    """tf2_ros ``TransformListener(buffer, node)``: fills ``buffer`` (a compat
    :class:`Buffer` or a :class:`tfbus.Buffer`) from an rclpy node's ``/tf`` and
    ``/tf_static`` (subscribed here, as ROS 2 does; messages taken by their fields), or,
    with ``bus=``, from a tfbus bus through :class:`tfbus.TransformListener` (enter it
    with ``async with``)."""

    def __init__(
        self, buffer: Buffer | _Buffer, node: object = None, *, bus: Bus | None = None,
        **_ros_options: object,
    ) -> None:
        """Attach to ``node`` (rclpy) or ``bus``; ``qos``, ``spin_thread`` and other
        ROS 2 options are accepted and unused."""
        self.buffer = buffer.buffer if isinstance(buffer, Buffer) else buffer
        self._inner: _Listener | None = None
        self._subscriptions: list[Any] = []
        if bus is not None or _is_bus(node):
            chosen = bus if bus is not None else node
            if not isinstance(chosen, Bus):
                raise TypeError("TransformListener: bus must be a tfbus.Bus, got "
                                f"{_describe(chosen)}")
            self._inner = _Listener(self.buffer, chosen)
        elif node is not None:
            _check_node("TransformListener", node, "create_subscription")
            self._attach_rclpy(node)
        else:
            raise InvalidArgumentException("TransformListener needs an rclpy node or bus=")

    def _attach_rclpy(self, node: Any) -> None:
        from rclpy.qos import (  # type: ignore[import-not-found]
            DurabilityPolicy,
            HistoryPolicy,
            QoSProfile,
        )
        from tf2_msgs.msg import TFMessage as RosTFMessage  # type: ignore[import-not-found]

        dynamic = QoSProfile(depth=100)
        static = QoSProfile(
            depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL,
            history=HistoryPolicy.KEEP_LAST,
        )
        self._subscriptions = [
            node.create_subscription(RosTFMessage, TF_TOPIC, self._on_tf, dynamic),
            node.create_subscription(RosTFMessage, TF_STATIC_TOPIC, self._on_static, static),
        ]

    def _on_tf(self, message: Any) -> None:
        self.buffer.set_transforms([to_transform_stamped(t) for t in message.transforms],
                                   "default_authority")

    def _on_static(self, message: Any) -> None:
        self.buffer.set_transforms([to_transform_stamped(t) for t in message.transforms],
                                   "default_authority", is_static=True)

    async def __aenter__(self) -> TransformListener:
        """Start the bus listener (a node's subscriptions are live already)."""
        if self._inner is not None:
            await self._inner.__aenter__()
        return self

    async def __aexit__(self, *exc: object) -> None:
        """Stop the bus listener."""
        if self._inner is not None:
            await self._inner.__aexit__(*exc)  # type: ignore[arg-type]

    def unregister(self) -> None:
        """tf2_ros ``unregister``: drop an rclpy node's subscriptions (the bus listener
        stops when its ``async with`` ends)."""
        for sub in self._subscriptions:
            sub.destroy()
        self._subscriptions = []


class TransformBroadcaster:
    """tf2_ros ``TransformBroadcaster(node)``: ``sendTransform(t)`` publishes one
    transform or a list as one TFMessage on ``/tf`` — on an rclpy node (its own
    publisher; rclpy messages built from the fields) or a tfbus bus."""

    _topic = TF_TOPIC
    _static = False

    def __init__(self, node: object, qos: object = None) -> None:
        """Publish on ``node`` (rclpy) or on a tfbus :class:`~tfbus.Bus`."""
        self._bus_side: _Broadcaster | None = None
        self._publisher: Any = None
        if isinstance(node, Bus):
            self._bus_side = _StaticBroadcaster(node) if self._static else _Broadcaster(node)
        else:
            _check_node(type(self).__name__, node, "create_publisher")
            from rclpy.qos import DurabilityPolicy, QoSProfile
            from tf2_msgs.msg import TFMessage as RosTFMessage

            profile = qos if qos is not None else QoSProfile(depth=100)
            if self._static and qos is None:
                profile = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self._publisher = node.create_publisher(  # type: ignore[attr-defined]
                RosTFMessage, self._topic, profile
            )
        self._latched: dict[str, TransformStamped] = {}

    def sendTransform(self, transform: Any) -> None:
        """Publish ``transform`` (one, or an iterable of them, any flavour)."""
        items = [transform] if not isinstance(transform, Iterable) or hasattr(
            transform, "child_frame_id"
        ) else list(transform)
        ours = [to_transform_stamped(t) for t in items]
        if self._static:  # tf2_ros keeps every static transform sent, by child frame
            self._latched.update((t.child_frame_id, t) for t in ours)
            ours = list(self._latched.values())
        if self._bus_side is not None:
            self._bus_side.send_transform_nowait(ours)
        else:
            self._publisher.publish(_to_rclpy(TFMessage(ours)))


class StaticTransformBroadcaster(TransformBroadcaster):
    """tf2_ros ``StaticTransformBroadcaster(node)``: as :class:`TransformBroadcaster`
    on ``/tf_static`` (transient local); every transform sent so far is re-sent, one
    per child frame, as tf2_ros does."""

    _topic = TF_STATIC_TOPIC
    _static = True


def _to_rclpy(message: TFMessage) -> Any:
    """A ``tf2_msgs.msg.TFMessage`` (rclpy) with the fields of a tfbus TFMessage."""
    from builtin_interfaces.msg import Time as RosTime  # type: ignore[import-not-found]
    from geometry_msgs.msg import (  # type: ignore[import-not-found]
        TransformStamped as RosTransformStamped,
    )
    from tf2_msgs.msg import TFMessage as RosTFMessage

    out = []
    for t in message.transforms:
        m = RosTransformStamped()
        m.header.frame_id = t.header.frame_id
        m.header.stamp = RosTime(sec=t.header.stamp.sec, nanosec=t.header.stamp.nanosec)
        m.child_frame_id = t.child_frame_id
        tr, q = t.transform
        m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = tr
        (m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z,
         m.transform.rotation.w) = q
        out.append(m)
    return RosTFMessage(transforms=out)
